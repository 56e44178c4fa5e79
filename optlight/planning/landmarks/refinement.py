"""The landmark refinements (docs/design.md §5): a bounded 1-D Brent search of the zenith
(:class:`ZenithSearch`, azimuth mode) and a 2-D NLP on the cap with separation constraints, built
once (:class:`CapRefiner`, free mode); the cast shadows are a fixed visibility mask in both.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
from scipy.optimize import minimize_scalar

from optlight.geometry import LightSphere
from optlight.objectives import Objective
from optlight.planning.landmarks.types import Array
from optlight.planning.nlp import Solve, ipopt_options, run, sphere_position
from optlight.scene import Scene
from optlight.spec import SolverSpec

#: Zenith tolerance (rad) of the azimuth-mode refinement at the search resolution, 0.06°: the
#: camera-resolution polish moves the zenith by about that much anyway.
REFINE_TOL = 1e-3


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
