"""The light-set design NLP (docs/design.md §10): :class:`LightSetDesigner` builds
``min_x cost(D(x); p)`` over the cap (with an optional extra inequality ``allowed(D) ≤ 0``) once;
:func:`design_light_set` solves it from several random starts and keeps the best;
:func:`design_ring` optimises the slant of an N-light ring, the classical baseline.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike

from optlight.errors import OptlightError, ProblemError
from optlight.geometry import LightSphere, direction_in_sphere_frame
from optlight.planning.lightsets.cost import SetTerm
from optlight.planning.lightsets.directions import Array, Cap, angles_of, casadi_directions, ring_directions
from optlight.planning.nlp import ipopt_options, run
from optlight.spec import SolverSpec

#: An extra inequality ``allowed(D) ≤ 0`` (elementwise) on the N×3 MX of directions.
AllowedHook = Callable[[ca.MX], ca.MX]

#: Largest number of solves per start: the first with the parameters (visibility masks) at the
#: start, then one more each time the parameters at the solution differ from those solved with.
PARAMETER_ROUNDS = 3


#: Slant (rad) of the classical photometric-stereo ring, arccos(1/√3) = 54.7356°.
CLASSICAL_SLANT = math.acos(1.0 / math.sqrt(3.0))
#: Solver settings when none are given: a set has 2N variables on a flat landscape (the Riesz energy
#: of 48 lights needed ~400 L-BFGS iterations to IPOPT's acceptable level, more than [solver]'s 300).
DESIGN_SOLVER = SolverSpec(max_iter=1000)
#: Zeniths of the slant sweep that seeds :func:`design_ring`.
RING_SWEEP = 37


@dataclass(frozen=True)
class LightSetResult:
    """A designed set: ``directions`` (N, 3) sphere frame, ``zenith`` and ``azimuth`` (N,) rad,
    ``cost`` (NumPy twin, parameters at the solution), IPOPT ``iterations`` (all rounds of the best
    start), its ``status`` and ``success``, and the final cost of every start (``start_costs``)."""

    directions: Array
    zenith: Array
    azimuth: Array
    cost: float
    iterations: int
    status: str
    success: bool
    start_costs: tuple[float, ...] = field(default=())

    @property
    def count(self) -> int:
        return int(len(self.directions))

    def world_directions(self, sphere: LightSphere) -> Array:
        """The directions (N, 3) in the world frame."""
        return self.directions @ sphere.rotation.T


def check_in_cap(directions: ArrayLike, cap: Cap, file: str = "<api>", key: str = "start") -> Array:
    """``directions`` as a unit (N, 3) array on the cap, or :class:`ProblemError` naming ``key``."""
    d = np.asarray(directions, float)
    if d.ndim != 2 or d.shape[1] != 3 or not np.allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-6):
        raise ProblemError(file, key, "unit light directions, shape (N, 3)", f"shape {d.shape}")
    outside = np.flatnonzero(~cap.contains(d, tol=1e-6))
    if outside.size:
        zenith = math.degrees(float(angles_of(d[outside[0]])[0]))
        raise ProblemError(
            file,
            key,
            f"directions inside the cap (zenith {math.degrees(cap.zenith_min):g}°–"
            f"{math.degrees(cap.zenith_max):g}°)",
            f"direction {outside[0]} at zenith {zenith:.3f}°",
        )
    return d


class LightSetDesigner:
    """The NLP of one set size, built once: ``min_x cost(D(x); p)`` s.t. ``θ_min ≤ θ_i ≤ θ_max``
    and, when given, ``allowed(D(x)) ≤ 0``; ``p`` the objective's parameters."""

    def __init__(
        self,
        objective: SetTerm,
        n: int,
        cap: Cap,
        solver: SolverSpec | None = None,
        allowed: AllowedHook | None = None,
    ) -> None:
        if n < 1:
            raise OptlightError(f"a light set needs at least one light, got {n}")
        self.objective, self.n, self.cap = objective, n, cap
        x = ca.MX.sym("x", 2 * n)
        p = ca.MX.sym("p", objective.parameter_size(n))
        d = casadi_directions(x)
        cost = objective.casadi(d, p)
        nlp: dict[str, ca.MX] = {"x": x, "p": p, "f": cost}
        self.constraints = 0
        if allowed is not None:
            g = ca.vec(allowed(d))
            nlp["g"] = g
            self.constraints = int(g.size1())
        self.nlp = ca.nlpsol("light_set", "ipopt", nlp, ipopt_options(solver or DESIGN_SOLVER))
        #: ``(x, p) -> (cost, ∂cost/∂x)``, for checks against finite differences.
        self.cost_gradient = ca.Function("set_cost", [x, p], [cost, ca.gradient(cost, x)])

    def solve(self, start: ArrayLike) -> LightSetResult:
        """Solve from ``start`` (N, 3) directions on the cap, re-solving while the parameters at the
        solution differ from those solved with (at most :data:`PARAMETER_ROUNDS` solves)."""
        d = check_in_cap(start, self.cap)
        if len(d) != self.n:
            raise OptlightError(f"this designer places {self.n} lights, the start has {len(d)}")
        zenith, azimuth = angles_of(d)
        x = np.r_[zenith, azimuth]
        p = self.objective.parameters(d)
        iterations, status, success = 0, "", False
        for _ in range(PARAMETER_ROUNDS):
            solved = run(
                self.nlp,
                {
                    "x0": x,
                    "p": p,
                    "lbx": np.r_[np.full(self.n, self.cap.zenith_min), np.full(self.n, -np.inf)],
                    "ubx": np.r_[np.full(self.n, self.cap.zenith_max), np.full(self.n, np.inf)],
                    "lbg": -np.inf,
                    "ubg": 0.0,
                },
            )
            iterations += solved.iterations
            status, success, x = solved.status, solved.success, solved.x
            d = direction_in_sphere_frame(x[: self.n], x[self.n :])
            p_new = self.objective.parameters(d)
            if np.array_equal(p_new, p):
                break
            p = p_new
        zenith, azimuth = angles_of(d)
        return LightSetResult(d, zenith, azimuth, self.objective.numpy(d, p), iterations, status, success)


def design_light_set(
    objective: SetTerm,
    n: int,
    cap: Cap,
    start: ArrayLike | None = None,
    *,
    starts: int = 8,
    seed: int = 0,
    allowed: AllowedHook | None = None,
    solver: SolverSpec | None = None,
    designer: LightSetDesigner | None = None,
    start_pool: ArrayLike | None = None,
) -> LightSetResult:
    """The best of several solves of the set NLP (:class:`LightSetDesigner`, built once).

    Starts: ``start`` (N, 3) directions on the cap when given (then it is the only start), else
    ``starts`` sets drawn with ``np.random.default_rng(seed)``: N distinct directions of
    ``start_pool`` (P ≥ N, 3; on the cap) each when given — where ``allowed`` holds, so that IPOPT
    starts feasible (from uniform starts on the cap it reported a thin band of reachable lights
    infeasible) — else uniformly on the cap's area. A ``designer`` built before for the same
    objective, N and cap is reused. Returns the start with the lowest final cost; ``start_costs``
    lists every start's."""
    if designer is None:
        designer = LightSetDesigner(objective, n, cap, solver, allowed)
    elif designer.n != n or designer.cap != cap or designer.objective is not objective:
        raise OptlightError("the designer was built for another objective, light count or cap")
    rng = np.random.default_rng(seed)
    if start is not None:
        candidates = [check_in_cap(start, cap)]
    elif start_pool is not None:
        pool = check_in_cap(start_pool, cap)
        if len(pool) < n:
            raise OptlightError(f"{len(pool)} start directions for a set of {n} lights")
        candidates = [pool[rng.choice(len(pool), n, replace=False)] for _ in range(max(1, starts))]
    else:
        candidates = [cap.random(n, rng) for _ in range(max(1, starts))]
    results = [designer.solve(s) for s in candidates]
    best = min(results, key=lambda r: (not r.success, r.cost))
    return _with_start_costs(best, tuple(r.cost for r in results))


def _with_start_costs(result: LightSetResult, costs: tuple[float, ...]) -> LightSetResult:
    return LightSetResult(
        result.directions,
        result.zenith,
        result.azimuth,
        result.cost,
        result.iterations,
        result.status,
        result.success,
        costs,
    )


def design_ring(
    objective: SetTerm, n: int, cap: Cap, phase: float = 0.0, solver: SolverSpec | None = None
) -> LightSetResult:
    """The best ring of N lights (azimuths ``phase + 2πi/N``): the slant is swept over the cap
    (:data:`RING_SWEEP` zeniths, NumPy twin with parameters at each), then refined by IPOPT from the
    best sample (parameters re-computed between solves as in :meth:`LightSetDesigner.solve`)."""
    slants = np.linspace(cap.zenith_min, cap.zenith_max, RING_SWEEP)
    with np.errstate(divide="ignore", invalid="ignore"):  # slant 0 puts every light in one place
        sweep = np.array([objective.numpy(ring_directions(n, s, phase)) for s in slants])
    sweep[~np.isfinite(sweep)] = np.inf
    slant = ca.MX.sym("slant")
    p = ca.MX.sym("p", objective.parameter_size(n))
    azimuths = ca.DM(phase + 2 * math.pi * np.arange(n) / n)
    d = ca.horzcat(
        ca.sin(slant) * ca.cos(azimuths), ca.sin(slant) * ca.sin(azimuths), ca.cos(slant) * ca.DM.ones(n)
    )
    nlp = ca.nlpsol(
        "light_ring",
        "ipopt",
        {"x": slant, "p": p, "f": objective.casadi(d, p)},
        ipopt_options(solver or DESIGN_SOLVER),
    )
    s = float(slants[int(np.argmin(sweep))])
    params = objective.parameters(ring_directions(n, s, phase))
    iterations, status, success = 0, "", False
    for _ in range(PARAMETER_ROUNDS):
        solved = run(nlp, {"x0": s, "p": params, "lbx": cap.zenith_min, "ubx": cap.zenith_max})
        iterations += solved.iterations
        status, success, s = solved.status, solved.success, float(solved.x[0])
        new = objective.parameters(ring_directions(n, s, phase))
        if np.array_equal(new, params):
            break
        params = new
    directions = ring_directions(n, s, phase)
    zenith, azimuth = angles_of(directions)
    cost = objective.numpy(directions, params)
    return LightSetResult(directions, zenith, azimuth, cost, iterations, status, success, (cost,))
