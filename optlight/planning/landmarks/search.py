"""The landmark search scene (docs/design.md §5): :class:`LandmarkSearch` holds what both modes
share (the camera-resolution and search scenes and objectives, the refinements) and turns a seed
into a landmark: refine with the visibility mask re-cast until it holds, polish at the camera's
resolution, score the candidates and keep the best.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from optlight.planning.landmarks.types import Array, Landmark
from optlight.planning.nlp import Solve
from optlight.spec import LandmarksSpec, SolverSpec
from optlight.workcell import ImageCosts, Workcell

#: Largest number of solves per seed: the first with the mask at the seed, then one more each time
#: the mask at the solution differs from the one the solve used.
VISIBILITY_ROUNDS = 3


#: Spacing (rad) of the three points of the camera-resolution polish, 0.25°.
POLISH_STEP = math.radians(0.25)


# --------------------------------------------------------------------------------------------
# The search
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Candidate:
    zenith: float
    azimuth: float
    cost: float
    status: Literal["refined", "polished", "sweep"]
    solver_status: str = ""


#: A candidate scored at the camera's resolution: (cost, soft histogram (K,), candidate).
Scored = tuple[float, Array, Candidate]


class LandmarkSearch:
    """What both modes share: the camera-resolution scene and objective (reported costs), the search
    scene and objective (sweeps, NLPs, candidate scores) of ``costs``, the lights ``cell``'s sphere
    allows, ``spec`` (``[landmarks]``), ``solver`` (``[solver]``) and the problem ``file`` its errors
    name; the refinement of one seed with the visibility mask recomputed between solves, and the
    final scoring."""

    def __init__(
        self, cell: Workcell, costs: ImageCosts, spec: LandmarksSpec, solver: SolverSpec, file: str
    ) -> None:
        self.spec = spec
        self.solver = solver
        self.file = file
        self.scene = costs.scene
        self.objective = costs.objective
        self.search = costs.search_scene
        self.search_objective = costs.search_objective
        #: The lights the search may use (the view's lights taken away) and the cap as requested.
        self.sphere = cell.sphere
        self.requested = costs.scene.sphere

    def refine(
        self, seed: Candidate, solve: Callable[[float, float, Array], Solve], mask: Array | None = None
    ) -> tuple[Candidate | None, int, str]:
        """Refine from ``seed``; ``solve(θ, φ, v)`` runs the NLP; ``mask`` the seed's visibility at the
        search resolution when known (the sweep's). Returns the refined candidate scored at the
        search resolution (None when IPOPT failed on the first solve), the iterations of all solves
        and the first solve's status."""
        zenith, azimuth = seed.zenith, seed.azimuth
        if mask is None:
            mask = self.search.visibility(self.sphere.position(zenith, azimuth))
        iterations, first_status, candidate = 0, "", None
        for _ in range(VISIBILITY_ROUNDS):
            result = solve(zenith, azimuth, mask)
            iterations += result.iterations
            first_status = first_status or result.status
            if not result.success:
                break
            # IPOPT may leave a bound by its relaxation (~1e-8): clip back onto the allowed range.
            zenith = float(np.clip(result.x[0], self.sphere.zenith_min, self.sphere.zenith_max))
            if result.x.size == 2:
                azimuth = float(result.x[1])
            position = self.sphere.position(zenith, azimuth)
            new_mask = self.search.visibility(position)  # the exact cost's: cast once for both
            cost = float(self.search_objective.numpy(self.search.pixels(position, new_mask)))
            candidate = Candidate(zenith, azimuth, cost, "refined", result.status)
            if np.array_equal(new_mask, mask):
                break
            mask = new_mask
        return candidate, iterations, first_status

    def polish(self, start: Candidate, cost: float, mask: Array) -> list[Scored]:
        """One parabolic step of the objective at the camera's resolution along ``start``'s azimuth,
        with ``start``'s visibility ``mask`` (P,) held fixed: the objective at θ ± s
        (s = :data:`POLISH_STEP`, each where it is allowed) and, when both are and the parabola
        through them and (θ, ``cost``) is convex, at its vertex θ − s (f₊ − f₋) / (2 (f₊ − 2f + f₋)),
        clipped to θ ± 2s and to the allowed zeniths. Returns those points, scored."""
        theta, azimuth = start.zenith, start.azimuth
        lo, hi = self.sphere.zenith_min, self.sphere.zenith_max

        def score(zenith: float) -> Scored:
            value, histogram = self.objective.evaluate(self.scene.pixels(self.sphere.position(zenith, azimuth), mask))
            return value, histogram, Candidate(zenith, azimuth, value, "polished", start.solver_status)

        sides = {z: score(z) for z in (theta - POLISH_STEP, theta + POLISH_STEP) if lo <= z <= hi}
        if len(sides) < 2:
            return list(sides.values())
        f_minus, f_plus = (s[0] for s in sides.values())
        curvature = f_plus - 2 * cost + f_minus
        if curvature <= 0:
            return list(sides.values())
        vertex = theta - POLISH_STEP * (f_plus - f_minus) / (2 * curvature)
        vertex = float(np.clip(vertex, max(lo, theta - 2 * POLISH_STEP), min(hi, theta + 2 * POLISH_STEP)))
        return [*sides.values(), score(vertex)]

    def finish(
        self, index: int, sample: Candidate, best: Candidate, iterations: int, t0: float, polish: bool
    ) -> tuple[Landmark, Array, Array]:
        """The landmark, its histogram and its visibility mask at the camera's resolution, from the
        best sweep sample and the best candidate at the search resolution. When the search ran at a
        lower resolution, both (and, with ``polish``, the result of :meth:`polish` from the best) are
        scored again at the camera's, shadow rays included, and the lowest wins. The mask is the
        landmark's own (a polished winner, scored with the best's mask held fixed, casts its rays,
        as does one whose azimuth was wrapped into [0, 2π))."""
        masks: dict[tuple[float, float], Array] = {}

        def score(c: Candidate) -> Scored:
            position = self.sphere.position(c.zenith, c.azimuth)
            masks[c.zenith, c.azimuth] = mask = self.scene.visibility(position)
            return (*self.objective.evaluate(self.scene.pixels(position, mask)), c)

        scored = [score(best)]
        if self.search is not self.scene:
            # a sample at the best's light scores the same: only a sample elsewhere is scored
            if (sample.zenith, sample.azimuth) != (best.zenith, best.azimuth):
                scored.append(score(sample))
            if polish:
                scored.extend(self.polish(best, scored[0][0], masks[best.zenith, best.azimuth]))
        cost, histogram, winner = min(scored, key=lambda s: s[0])
        azimuth = float(np.mod(winner.azimuth, 2 * np.pi))
        position = self.sphere.position(winner.zenith, azimuth)
        mask = masks.get((winner.zenith, winner.azimuth)) if azimuth == winner.azimuth else None
        lm = Landmark(
            index=index,
            zenith=winner.zenith,
            azimuth=azimuth,
            position=position,
            cost=cost,
            status=winner.status,
            solver_status=winner.solver_status,
            iterations=iterations,
            time_s=time.perf_counter() - t0,
        )
        return lm, histogram, self.scene.visibility(position) if mask is None else mask
