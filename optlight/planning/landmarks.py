"""Landmarks (paper Section 4, docs/design.md §5): where on the light sphere the light should go.

Azimuth mode (the paper's). For ``M`` equally spaced azimuths ``φ_j = 2πj/M`` find

    θ_j* = argmin_{θ ∈ [θ_min, θ_max]} D(θ, φ_j),

``D`` the problem's objective (:class:`optlight.objectives.Objective`) of the image rendered with the
light at ``a(θ, φ_j)``. ``D`` is multimodal in θ, so per azimuth:

1. *sweep*: ``D`` at the zeniths ``θ_min, θ_min + Δ, …, θ_max`` (``Δ ≤ sweep_step_deg``), NumPy
   renderer with shadow rays at every sample (one ray-caster call per azimuth; the pole θ = 0,
   one light for every azimuth, rendered once);
2. *seeds*: the ``seeds`` lowest local minima of the sweep;
3. *refine*: per seed, a bounded Brent search (:class:`ZenithSearch`) of ``D`` over the seed's
   bracket, the zeniths between its two sweep neighbours, with the cast shadows ``v`` a fixed
   visibility mask: shadow rays at the seed; when the mask at the solution differs from the one
   searched with, the search runs again with the mask there (at most :data:`VISIBILITY_ROUNDS`
   searches per seed). ``D`` is a smooth function of θ on a bracket of a sweep minimum once the mask
   is fixed, so a derivative-free 1-D search converges in ~10 renders. A seed on an end of the
   allowed zeniths that ``D`` rises from (``D`` at :data:`REFINE_TOL` inside, mask fixed, above the
   seed's) is not searched: the search would end on it within its tolerance (the default face's
   landmarks lie on the view's boundary, so skipping those seeds saves a tenth of its search);
4. *select*: the best sweep sample and the refined zeniths are scored with the NumPy renderer and
   shadow rays; the lowest wins, so the landmark is never worse than the best sweep sample;
5. *polish* (only when the search resolution is below the camera's): one parabolic step of the
   objective at the camera's resolution around the winner (mask fixed there, three points
   :data:`POLISH_STEP` apart and the parabola's vertex), then the sweep sample, the winner and the
   polish's points are scored at the camera's resolution and the lowest is the landmark. This
   removes what the lower resolution shifts the minimiser by (~0.1–0.2° on the default face).

Why not an NLP per seed, or one batched solve across azimuths: a render and its objective are
compute-bound NumPy (the P×K histogram kernel), so batching evaluations across azimuths saves only
Python overhead, while each IPOPT solve of the 1-D NLP cost ~8 iterations of a CasADi graph three
times slower to evaluate than the NumPy objective, with its gradient. Measured on the default face
(``benchmarks/bench_landmarks.py``): the time goes to the sweep's shadow rays and to the
camera-resolution work, which the steps above keep to a few renders per azimuth.

Free mode. The ``count`` best light positions on the allowed cap, pairwise at least
``min_separation_deg`` apart: a 2-D sweep over a (θ, φ) grid, then greedily, best sample first,
each sample farther than the separation from every accepted landmark is refined by the 2-D NLP
``min_{θ,φ} D̃`` with the separation constraints ``d(θ, φ)·d_k ≤ cos(min_separation)`` to the
accepted directions ``d_k`` (constraints of unused slots are switched off through their bounds,
so this NLP too is built once) and the better of sample and refined point, scored at the camera's
resolution, is accepted (no polish). The grid has zeniths as above and azimuths at most
``sweep_step_deg`` apart; landmarks come best first.

Resolution. The search (sweeps, NLPs, candidate scores) renders at ``landmarks.resolution`` (the
longer image side, the camera's aspect kept; the camera's own resolution when that is smaller); the
reported costs and histograms use the camera's resolution. The soft histogram of a downsampled image
is close to the full-resolution one, so the minimisers move little (step 5 takes care of the rest)
while every evaluation gets cheaper by the pixel ratio (default 64 px against the 256² camera: 16×).

Angles are radians in code, degrees only in reports. Lengths are metres.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Literal

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import minimize_scalar

from optlight.errors import ProblemError
from optlight.geometry import LightSphere, direction_in_sphere_frame
from optlight.objectives import Objective
from optlight.planning.nlp import Solve, ipopt_options, run, sphere_position
from optlight.scene import Scene
from optlight.setup import Setup
from optlight.spec import SolverSpec
from optlight.threads import in_background

Array = NDArray[np.float64]
Progress = Callable[[int, int], None]

#: Largest number of solves per seed: the first with the mask at the seed, then one more each time
#: the mask at the solution differs from the one the solve used.
VISIBILITY_ROUNDS = 3
#: Zenith tolerance (rad) of the azimuth-mode refinement at the search resolution, 0.06°: the
#: camera-resolution polish moves the zenith by about that much anyway.
REFINE_TOL = 1e-3
#: Spacing (rad) of the three points of the camera-resolution polish, 0.25°.
POLISH_STEP = math.radians(0.25)


@dataclass(frozen=True)
class Landmark:
    """One landmark: light at ``zenith``, ``azimuth`` (rad) = ``position`` (world, m).

    ``cost``: the objective there (NumPy renderer, shadow rays, the camera's resolution).
    ``status``: "refined" when a refinement's solution won, "polished" when the camera-resolution
    polish did, "sweep" when a sweep sample did; "placed" when the robot could not reach the search's
    landmark and the joint-space placement (:mod:`optlight.planning.placement`) moved it along its
    azimuth to the best light the robot reaches.
    ``solver_status``: the return status of the winning solve (IPOPT's in free mode, "converged" or
    scipy's message for the zenith search of azimuth mode; of the first solve when the sweep won; ""
    when no solve ran). ``iterations``: over all solves of this landmark, IPOPT iterations (free
    mode) or objective evaluations of the zenith search (azimuth mode).
    ``time_s``: wall time of this landmark's own work (azimuth mode: from the previous landmark's
    end, the wait for its sweep included, which ran during the previous one's refinement; free mode:
    its refinement, the shared 2-D sweep excluded)."""

    index: int
    zenith: float
    azimuth: float
    position: Array
    cost: float
    status: Literal["refined", "polished", "sweep", "placed", "set", "grid"]
    solver_status: str
    iterations: int
    time_s: float


@dataclass(frozen=True)
class CostGrid:
    """Objective values of a sweep: ``cost[j, i]`` at ``azimuth[j]``, ``zenith[i]`` (rad), at the
    search resolution."""

    zenith: Array
    azimuth: Array
    cost: Array


@dataclass(frozen=True)
class LandmarkSet:
    """The result of :func:`find_landmarks`.

    ``landmarks`` in azimuth order (azimuth mode) or best first (free mode); ``histograms`` (n, K)
    their soft histograms and ``reference_histogram`` (K,) the reference's, at the camera's
    resolution; ``sweep`` the coarse sweep; ``resolution`` (width, height) of the search renders;
    ``time_s`` the total wall time, setup (scenes, reference, NLP build) included. ``view_zenith``
    (rad): lights nearer the camera's axis were left out, their housing being in the camera's view;
    ``notes``: the landmarks whose best light lay there, and where the best clear light is.
    ``shadows``: each landmark's cast-shadow visibility at the camera's resolution, the one its
    shadow rays gave as it was scored, bits packed along the object pixels (:meth:`visibility`);
    None when they were not kept."""

    landmarks: tuple[Landmark, ...]
    mode: Literal["azimuth", "free", "set"]
    reference_histogram: Array
    reference_label: str
    histograms: Array
    sweep: CostGrid
    resolution: tuple[int, int]
    time_s: float
    view_zenith: float = 0.0
    notes: tuple[str, ...] = ()
    shadows: NDArray[np.uint8] | None = None

    def __len__(self) -> int:
        return len(self.landmarks)

    def visibility(self, pixels: int) -> Array | None:
        """The landmarks' cast-shadow visibility (n, ``pixels``) in {0., 1.} over the camera's
        ``pixels`` object pixels (:meth:`optlight.scene.Scene.visibility` at each landmark's light);
        None when :attr:`shadows` were not kept."""
        if self.shadows is None:
            return None
        return np.unpackbits(self.shadows, axis=1, count=pixels).astype(float)

    @property
    def zeniths(self) -> Array:
        """Zeniths (n,), rad."""
        return np.array([lm.zenith for lm in self.landmarks])

    @property
    def azimuths(self) -> Array:
        """Azimuths (n,), rad."""
        return np.array([lm.azimuth for lm in self.landmarks])

    @property
    def positions(self) -> Array:
        """Light positions (n, 3), world frame, m."""
        return np.array([lm.position for lm in self.landmarks]).reshape(-1, 3)

    @property
    def costs(self) -> Array:
        """Objective values (n,) at the camera's resolution."""
        return np.array([lm.cost for lm in self.landmarks])

    @property
    def iterations(self) -> int:
        """Solver iterations (see :class:`Landmark`) over all landmarks."""
        return sum(lm.iterations for lm in self.landmarks)


# --------------------------------------------------------------------------------------------
# Evaluation with the NumPy renderer
# --------------------------------------------------------------------------------------------


def exact_cost(scene: Scene, objective: Objective, position: ArrayLike) -> float:
    """The objective of the NumPy render (shadow rays) with the light at ``position`` (world, m)."""
    return objective.numpy(scene.pixels(position))


def sweep_costs(
    scene: Scene,
    objective: Objective,
    zenith: ArrayLike,
    azimuth: ArrayLike,
    progress: Progress | None = None,
) -> Array:
    """The objective at every (azimuth[j], zenith[i]) (rad), shape (M, N): NumPy renderer with shadow
    rays at every sample, the histograms of one azimuth batched. ``progress(j + 1, M)`` after each
    azimuth."""
    zenith, azimuth = np.atleast_1d(np.asarray(zenith, float)), np.atleast_1d(np.asarray(azimuth, float))
    out = np.empty((azimuth.size, zenith.size))
    pole = _has_pole(zenith) and azimuth.size > 1
    # an azimuth's objective is computed in the background while the next one's shadow rays are
    # cast (on both threads): the objective alone would leave a core idle; the same numbers either way
    pending = None
    for j, phi in enumerate(azimuth):
        rest = zenith[1:] if pole and j else zenith  # the pole is the first azimuth's
        positions = scene.sphere.position(rest, float(phi))
        masks = scene.visibility(positions)
        if pending is not None:
            out[j - 1, -pending[1] :] = pending[0].result()
            if progress is not None:
                progress(j, azimuth.size)
        pending = in_background(partial(_sweep_objective, scene, objective, positions, masks)), rest.size
    if pending is not None:
        out[-1, -pending[1] :] = pending[0].result()
        if progress is not None:
            progress(azimuth.size, azimuth.size)
    if pole:
        out[1:, 0] = out[0, 0]
    return out


def _has_pole(zenith: Array) -> bool:
    """Whether the first of the (sorted) sweep zeniths is the pole, θ = 0: the one light all azimuths
    share (a(0, φ) does not depend on φ, to the bit), which a sweep renders once."""
    return bool(zenith.size) and zenith[0] == 0.0


def _sweep_objective(scene: Scene, objective: Objective, positions: Array, masks: Array) -> Array:
    """The objective (N,) of the renders with the lights at ``positions`` (N, 3) and the visibility
    ``masks`` (N, P)."""
    return objective.numpy_batch(np.stack([scene.pixels(a, v) for a, v in zip(positions, masks, strict=True)]))


def zenith_grid(sphere: LightSphere, step: float) -> Array:
    """Zeniths from ``zenith_min`` to ``zenith_max`` (both included), at most ``step`` (rad) apart."""
    n = max(1, math.ceil((sphere.zenith_max - sphere.zenith_min) / step - 1e-9))
    return np.linspace(sphere.zenith_min, sphere.zenith_max, n + 1)


def local_minima(values: ArrayLike) -> NDArray[np.intp]:
    """Indices of the local minima of a 1-D sequence (ends included, plateaus give their first
    index), lowest first."""
    c = np.asarray(values, float)
    left = np.r_[np.inf, c[:-1]]
    right = np.r_[c[1:], np.inf]
    idx = np.flatnonzero((c < left) & (c <= right))
    return idx[np.argsort(c[idx], kind="stable")]


# --------------------------------------------------------------------------------------------
# The refinements: a 1-D search (azimuth mode), a 2-D NLP built once (free mode)
# --------------------------------------------------------------------------------------------


class ZenithSearch:
    """The refinement of azimuth mode: ``min_{θ ∈ [lo, hi]} D(a(θ, φ), v)`` by bounded Brent search
    (golden section with parabolic steps, :func:`scipy.optimize.minimize_scalar`, zenith tolerance
    :data:`REFINE_TOL`), ``D`` the objective of the NumPy render at ``scene``'s resolution with the
    visibility mask ``v`` fixed."""

    def __init__(self, scene: Scene, objective: Objective, sphere: LightSphere) -> None:
        self.scene = scene
        self.objective = objective
        self.sphere = sphere

    def solve(self, azimuth: float, visibility: Array, bracket: tuple[float, float]) -> Solve:
        """The zenith (rad) in ``bracket`` minimising ``D`` along ``azimuth`` (rad) with the mask
        ``visibility`` (P,); ``iterations`` counts the objective's evaluations."""

        def cost(zenith: float) -> float:
            return self.objective.numpy(self.scene.pixels(self.sphere.position(zenith, azimuth), visibility))

        result = minimize_scalar(cost, bounds=bracket, method="bounded", options={"xatol": REFINE_TOL})
        status = "converged" if result.success else str(result.message)
        return Solve(np.array([float(result.x)]), int(result.nfev), status, bool(result.success))

    def rises_from_end(self, azimuth: float, zenith: float, cost: float, visibility: Array) -> bool:
        """Whether ``zenith`` (rad) is an end of the allowed zeniths and ``D`` rises from it: ``D`` at
        :data:`REFINE_TOL` inside, with the mask ``visibility`` held, above ``cost`` (``D`` there).
        Then the search would end there, on the end, within its tolerance."""
        lo, hi = self.sphere.zenith_min, self.sphere.zenith_max
        if zenith not in (lo, hi) or lo == hi:
            return False
        inside = zenith + REFINE_TOL if zenith == lo else zenith - REFINE_TOL
        pixels = self.scene.pixels(self.sphere.position(inside, azimuth), visibility)
        return float(self.objective.numpy(pixels)) > cost


class CapRefiner:
    """The 2-D NLP of free mode, built once: ``min_{θ,φ} D̃(a(θ, φ), v)`` s.t. ``θ_min ≤ θ ≤ θ_max``
    and ``d(θ, φ)·d_k ≤ cos(separation)`` for up to ``slots`` accepted directions ``d_k`` (sphere
    frame); parameters ``p = (v, d_1, …, d_slots)``; unused slots have an infinite upper bound."""

    def __init__(
        self, scene: Scene, objective: Objective, solver: SolverSpec, slots: int, sphere: LightSphere
    ) -> None:
        self.sphere = sphere
        self.slots = slots
        x = ca.MX.sym("x", 2)
        size = scene.gbuffer.size
        p = ca.MX.sym("p", size + 3 * slots)
        d = ca.vertcat(ca.sin(x[0]) * ca.cos(x[1]), ca.sin(x[0]) * ca.sin(x[1]), ca.cos(x[0]))
        accepted = ca.reshape(p[size:], 3, slots).T
        cost = objective.function(sphere_position(self.sphere, x[0], x[1]), p[:size])
        nlp = {"x": x, "p": p, "f": cost, "g": ca.mtimes(accepted, d)}
        self.nlp = ca.nlpsol("cap_refiner", "ipopt", nlp, ipopt_options(solver))

    def solve(
        self, zenith: float, azimuth: float, visibility: Array, accepted: Array, separation: float
    ) -> Solve:
        """Refine from (``zenith``, ``azimuth``) with the mask ``visibility`` (P,), keeping at least
        ``separation`` (rad) from each row of ``accepted`` (k, 3), unit directions, sphere frame."""
        dirs = np.zeros((self.slots, 3))
        dirs[: len(accepted)] = accepted
        ubg = np.full(self.slots, np.inf)
        ubg[: len(accepted)] = math.cos(separation)
        return run(
            self.nlp,
            {
                "x0": [zenith, azimuth],
                "p": np.r_[visibility, dirs.ravel()],
                "lbx": [self.sphere.zenith_min, -np.inf],
                "ubx": [self.sphere.zenith_max, np.inf],
                "lbg": -np.inf,
                "ubg": ubg,
            },
        )


# --------------------------------------------------------------------------------------------
# The search
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Candidate:
    zenith: float
    azimuth: float
    cost: float
    status: Literal["refined", "polished", "sweep"]
    solver_status: str = ""


#: A candidate scored at the camera's resolution: (cost, soft histogram (K,), candidate).
_Scored = tuple[float, Array, _Candidate]


class _Search:
    """What both modes share: the camera-resolution scene and objective (reported costs), the search
    scene and objective (sweeps, NLPs, candidate scores), all from the built setup; the refinement of
    one seed with the visibility mask recomputed between solves, and the final scoring."""

    def __init__(self, setup: Setup) -> None:
        self.spec = setup.landmark_spec
        self.solver = setup.solver
        self.file = setup.file
        self.scene = setup.scene
        self.objective = setup.objective
        self.search = setup.search_scene
        self.search_objective = setup.search_objective
        #: The lights the search may use (the view's lights taken away) and the cap as requested.
        self.sphere = setup.sphere
        self.requested = setup.scene.sphere

    def refine(
        self, seed: _Candidate, solve: Callable[[float, float, Array], Solve], mask: Array | None = None
    ) -> tuple[_Candidate | None, int, str]:
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
            candidate = _Candidate(zenith, azimuth, cost, "refined", result.status)
            if np.array_equal(new_mask, mask):
                break
            mask = new_mask
        return candidate, iterations, first_status

    def polish(self, start: _Candidate, cost: float, mask: Array) -> list[_Scored]:
        """One parabolic step of the objective at the camera's resolution along ``start``'s azimuth,
        with ``start``'s visibility ``mask`` (P,) held fixed: the objective at θ ± s
        (s = :data:`POLISH_STEP`, each where it is allowed) and, when both are and the parabola
        through them and (θ, ``cost``) is convex, at its vertex θ − s (f₊ − f₋) / (2 (f₊ − 2f + f₋)),
        clipped to θ ± 2s and to the allowed zeniths. Returns those points, scored."""
        theta, azimuth = start.zenith, start.azimuth
        lo, hi = self.sphere.zenith_min, self.sphere.zenith_max

        def score(zenith: float) -> _Scored:
            value, histogram = self.objective.evaluate(self.scene.pixels(self.sphere.position(zenith, azimuth), mask))
            return value, histogram, _Candidate(zenith, azimuth, value, "polished", start.solver_status)

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
        self, index: int, sample: _Candidate, best: _Candidate, iterations: int, t0: float, polish: bool
    ) -> tuple[Landmark, Array, Array]:
        """The landmark, its histogram and its visibility mask at the camera's resolution, from the
        best sweep sample and the best candidate at the search resolution. When the search ran at a
        lower resolution, both (and, with ``polish``, the result of :meth:`polish` from the best) are
        scored again at the camera's, shadow rays included, and the lowest wins. The mask is the
        landmark's own (a polished winner, scored with the best's mask held fixed, casts its rays,
        as does one whose azimuth was wrapped into [0, 2π))."""
        masks: dict[tuple[float, float], Array] = {}

        def score(c: _Candidate) -> _Scored:
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


def find_landmarks(
    setup: Setup, *, progress: Progress | None = None, found: Callable[[Landmark], None] | None = None
) -> LandmarkSet:
    """The landmarks of a built problem (``[landmarks]``, ``[objective]``, ``[solver]``): see the
    module docstring. ``progress(done, total)`` is called after each azimuth (azimuth mode) or each
    sweep row and landmark (free mode); ``found(landmark)`` with each landmark as it is found, in
    the order of the result (e.g. to place it meanwhile, :class:`~optlight.pipeline.PlacementAhead`)."""
    t0 = time.perf_counter()
    search = _Search(setup)
    found = found or (lambda landmark: None)
    if search.spec.mode == "azimuth":
        landmarks, histograms, visibilities, grid = _azimuth_mode(search, progress, found)
    else:
        landmarks, histograms, visibilities, grid = _free_mode(search, progress, found)
    return LandmarkSet(
        landmarks=tuple(landmarks),
        mode=search.spec.mode,
        reference_histogram=search.objective.reference.histogram,
        reference_label=search.objective.reference.label,
        histograms=np.array(histograms).reshape(len(landmarks), -1),
        sweep=grid,
        resolution=(search.search.camera.width, search.search.camera.height),
        time_s=time.perf_counter() - t0,
        view_zenith=setup.view_zenith,
        notes=tuple(_view_notes(search, landmarks, grid)),
        shadows=np.packbits(np.array(visibilities, bool).reshape(len(landmarks), -1), axis=1),
    )


def _view_notes(search: _Search, landmarks: list[Landmark], grid: CostGrid) -> list[str]:
    """One line on the landmarks whose azimuth's best sweep sample lies in the camera's view (zenith
    below the smallest allowed one): which they are, where those samples were and how far the
    landmarks, the best clear lights, are from them (azimuth mode; in free mode, whether the cap's
    best sample lies there)."""
    limit = search.sphere.zenith_min
    inside = grid.zenith < limit - 1e-12
    if not inside.any():
        return []
    view = f"in the camera's view (zenith < {math.degrees(limit):.1f}°)"
    if search.spec.mode == "free":
        best = int(np.unravel_index(int(np.argmin(grid.cost)), grid.cost.shape)[1])
        if not inside[best]:
            return []
        return [f"the cap's best light (zenith {math.degrees(grid.zenith[best]):.1f}°) is left out: it is {view}"]
    moved: dict[int, tuple[float, float]] = {}
    for lm, row in zip(landmarks, grid.cost, strict=True):
        i = int(np.argmin(row))
        if inside[i] and row[i] < row[~inside].min():
            moved[lm.index] = (math.degrees(grid.zenith[i]), math.degrees(lm.zenith - grid.zenith[i]))
    if not moved:
        return []
    inside_best = [z for z, _ in moved.values()]
    away = [d for _, d in moved.values()]
    return [
        f"landmarks {_index_ranges(sorted(moved))} ({len(moved)} of {len(landmarks)}): the best light of "
        f"their azimuth (zenith {min(inside_best):.1f}–{max(inside_best):.1f}°) is {view}; each is the best clear "
        f"light instead, {min(away):.1f}–{max(away):.1f}° from it"
    ]


def _index_ranges(indices: Sequence[int]) -> str:
    """Sorted indices as runs: [0, 1, 2, 5, 7, 8] → "0–2, 5, 7–8"."""
    runs: list[list[int]] = []
    for i in indices:
        if runs and i == runs[-1][-1] + 1:
            runs[-1].append(i)
        else:
            runs.append([i])
    return ", ".join(f"{r[0]}–{r[-1]}" if len(r) > 1 else f"{r[0]}" for r in runs)


def distinct_landmarks(landmarks: Sequence[Landmark], tolerance: float) -> tuple[list[Landmark], list[str]]:
    """The landmarks that are distinct captures: of landmarks whose directions from O are within
    ``tolerance`` (rad) of each other, only the lowest-cost one is kept (they would give the same
    image); the notes name the ones merged. The order of ``landmarks`` is kept."""
    kept: list[int] = []
    merged: dict[int, list[int]] = {}
    directions = direction_in_sphere_frame([lm.zenith for lm in landmarks], [lm.azimuth for lm in landmarks])
    limit = math.cos(tolerance) - 1e-12
    for i in sorted(range(len(landmarks)), key=lambda i: landmarks[i].cost):
        twin = next((k for k in kept if directions[k] @ directions[i] >= limit), None)
        if twin is None:
            kept.append(i)
        else:
            merged.setdefault(twin, []).append(i)
    notes = [
        f"landmarks {', '.join(str(landmarks[i].index) for i in sorted([k, *others]))} are one capture "
        f"(within {math.degrees(tolerance):g}° of each other): landmark {landmarks[k].index} is kept"
        for k, others in sorted(merged.items())
    ]
    return [landmarks[i] for i in sorted(kept)], notes


#: What a mode finds: the landmarks, their histograms and visibility masks at the camera's
#: resolution, and the sweep.
_Found = tuple[list[Landmark], list[Array], list[Array], CostGrid]


def _azimuth_mode(search: _Search, progress: Progress | None, found: Callable[[Landmark], None]) -> _Found:
    spec = search.spec
    refiner = ZenithSearch(search.search, search.search_objective, search.sphere)
    zenith = _sweep_zeniths(search, math.radians(spec.sweep_step_deg))
    allowed = np.flatnonzero(zenith >= search.sphere.zenith_min)
    azimuth = 2 * np.pi * np.arange(spec.count) / spec.count
    costs = np.empty((spec.count, zenith.size))
    landmarks: list[Landmark] = []
    histograms: list[Array] = []
    visibilities: list[Array] = []

    has_pole = _has_pole(zenith)

    def shadows(j: int, skip_pole: bool) -> tuple[Array, Array]:
        """The lights of azimuth j's sweep (the pole left out when ``skip_pole``) and their masks."""
        positions = search.search.sphere.position(zenith[1:] if skip_pole else zenith, float(azimuth[j]))
        return positions, search.search.visibility(positions)

    # The next azimuth's shadow rays are cast in the background while this one's sweep objective,
    # refinement and camera-resolution scores are computed here: ~12 ms of rays there against
    # ~16 ms here on the default face (with the objective there too, the background would take ~15 ms
    # against ~10 ms here, and this thread would wait). The same numbers either way.
    pending = in_background(partial(shadows, 0, False))
    pole: tuple[float, Array] | None = None
    t0 = time.perf_counter()
    for j, phi in enumerate(azimuth):
        positions, masks = pending.result()
        if j + 1 < spec.count:
            pending = in_background(partial(shadows, j + 1, has_pole))
        costs[j, -len(positions) :] = _sweep_objective(search.search, search.search_objective, positions, masks)
        if pole is not None:  # the pole, the one light every azimuth shares, is the first azimuth's
            costs[j, 0], masks = pole[0], np.vstack([pole[1], masks])
        elif has_pole:
            pole = (float(costs[0, 0]), masks[0])
        seeds = [
            _Candidate(float(zenith[i]), float(phi), float(costs[j, i]), "sweep")
            for i in allowed[local_minima(costs[j, allowed])]
        ]
        best, iterations, first_status = seeds[0], 0, ""
        for seed in seeds[: spec.seeds]:
            mask = masks[int(np.searchsorted(zenith, seed.zenith))]
            # a seed on the view's boundary (or the cap's edge) the objective rises from needs no search
            if refiner.rises_from_end(float(phi), seed.zenith, seed.cost, mask):
                iterations += 1
                continue
            bracket = _bracket(zenith, seed.zenith, search.sphere)

            def solve(_zenith: float, azimuth: float, mask: Array, bracket: tuple[float, float] = bracket) -> Solve:
                return refiner.solve(azimuth, mask, bracket)

            refined, its, status = search.refine(seed, solve, mask)
            iterations += its
            first_status = first_status or status
            if refined is not None and refined.cost < best.cost:
                best = refined
        sample = dataclasses.replace(seeds[0], solver_status=first_status)
        best = sample if best is seeds[0] else best
        lm, hist, mask = search.finish(j, sample, best, iterations, t0, polish=True)
        t0 = time.perf_counter()
        landmarks.append(lm)
        histograms.append(hist)
        visibilities.append(mask)
        found(lm)
        if progress is not None:
            progress(j + 1, spec.count)
    return landmarks, histograms, visibilities, CostGrid(zenith, azimuth, costs)


def _bracket(zenith: Array, seed: float, sphere: LightSphere) -> tuple[float, float]:
    """The zeniths (rad) between the sweep neighbours of the sweep sample ``seed`` (a local minimum
    of the sweep, so the objective's minimum near it lies there), within ``sphere``'s allowed range."""
    i = int(np.searchsorted(zenith, seed))
    lo = zenith[max(i - 1, 0)]
    hi = zenith[min(i + 1, zenith.size - 1)]
    return max(float(lo), sphere.zenith_min), min(float(hi), sphere.zenith_max)


def _sweep_zeniths(search: _Search, step: float) -> Array:
    """The sweep's zeniths: the whole ``[light_sphere]`` range (the cost map shows what the view takes
    away), at most ``step`` apart, plus the smallest allowed zenith (the view's boundary) itself."""
    full = zenith_grid(search.requested, step)
    return np.unique(np.r_[full, search.sphere.zenith_min])


def _free_mode(search: _Search, progress: Progress | None, found: Callable[[Landmark], None]) -> _Found:
    spec = search.spec
    step = math.radians(spec.sweep_step_deg)
    separation = math.radians(spec.min_separation_deg)
    zenith = _sweep_zeniths(search, step)
    azimuth = np.linspace(0.0, 2 * np.pi, max(3, math.ceil(2 * np.pi / step - 1e-9)), endpoint=False)
    total = azimuth.size + spec.count
    costs = sweep_costs(
        search.search,
        search.search_objective,
        zenith,
        azimuth,
        None if progress is None else (lambda done, _n: progress(done, total)),
    )
    refiner = CapRefiner(search.search, search.search_objective, search.solver, spec.count, search.sphere)
    # Samples as unique directions: the pole (θ = 0) once, not once per azimuth; only allowed ones.
    jj, ii = np.meshgrid(np.arange(azimuth.size), np.arange(zenith.size), indexing="ij")
    keep = ((zenith[ii] > 0) | (jj == 0)) & (zenith[ii] >= search.sphere.zenith_min)
    jj, ii = jj[keep], ii[keep]
    order = np.argsort(costs[jj, ii], kind="stable")
    directions = direction_in_sphere_frame(zenith[ii], azimuth[jj])
    accepted: list[Array] = []
    landmarks: list[Landmark] = []
    histograms: list[Array] = []
    visibilities: list[Array] = []
    for k in order:
        if len(landmarks) == spec.count:
            break
        if not _separated(directions[k], accepted, separation):
            continue
        t0 = time.perf_counter()
        sample = _Candidate(float(zenith[ii[k]]), float(azimuth[jj[k]]), float(costs[jj[k], ii[k]]), "sweep")
        refined, iterations, status = search.refine(
            sample, lambda t, p, v: refiner.solve(t, p, v, np.array(accepted).reshape(-1, 3), separation)
        )
        sample = dataclasses.replace(sample, solver_status=status)
        best = sample
        if (
            refined is not None
            and refined.cost < sample.cost
            and _separated(direction_in_sphere_frame(refined.zenith, refined.azimuth), accepted, separation)
        ):
            best = refined
        lm, hist, mask = search.finish(len(landmarks), sample, best, iterations, t0, polish=False)
        landmarks.append(lm)
        histograms.append(hist)
        visibilities.append(mask)
        accepted.append(direction_in_sphere_frame(lm.zenith, lm.azimuth))
        found(lm)
        if progress is not None:
            progress(azimuth.size + len(landmarks), total)
    if len(landmarks) < spec.count:
        raise ProblemError(
            search.file,
            "landmarks.count",
            f"at most {len(landmarks)} landmarks {spec.min_separation_deg:g}° apart on the allowed cap "
            "(or a smaller landmarks.min_separation_deg)",
            spec.count,
        )
    return landmarks, histograms, visibilities, CostGrid(zenith, azimuth, costs)


def _separated(direction: Array, accepted: list[Array], separation: float) -> bool:
    """True when ``direction`` is at least ``separation`` (rad) from every accepted direction (up to
    a 1e-9 tolerance on the cosine)."""
    return not accepted or float((np.array(accepted) @ direction).max()) <= math.cos(separation) + 1e-9
