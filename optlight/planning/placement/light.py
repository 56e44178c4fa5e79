"""The light placement NLP (docs/design.md §5): :class:`LightPlacement`, the best light the robot
can reach on an azimuth (or anywhere on the cap), with the environment's rows when it is on, moved
off the reach boundary when the solution lies on it; :class:`PlacementResult` what it returns. The
formulation is in :mod:`optlight.planning.placement`. Angles are radians, lengths metres.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections import OrderedDict
from dataclasses import dataclass

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.environment import CAPTURE_SLACK
from optlight.geometry import h_residual
from optlight.objectives import Objective
from optlight.planning.landmarks import exact_cost
from optlight.planning.nlp import (
    Solve,
    ipopt_options,
    knot_bounds,
    light_rows,
    run,
    selected_rows,
)
from optlight.planning.trajectory import solve_active_rows
from optlight.robot import KinematicState, generalized_ik
from optlight.scene import Scene
from optlight.spec import SolverSpec
from optlight.workcell import ImageCosts, Workcell

Array = NDArray[np.float64]

#: Largest number of IPOPT solves per placement: the first with the mask at the warm start, then
#: one more when the mask at its solution differs.
VISIBILITY_ROUNDS = 2
#: Largest |h|∞ (m) of a successful placement, checked with pinocchio.
H_TOL = 1e-8
#: σ_min/σ_max of the 5-D light task Jacobian below which the light is on the reach boundary (0.1°
#: inside the boundary found on the default face the ratio is ~9e-3; on it, ~5e-8).
SINGULAR_TOL = 1e-3
#: How far (rad) a light on the reach boundary is moved back inside, along its meridian.
BOUNDARY_MARGIN = math.radians(0.1)
#: A joint closer than this (rad or m) to a limit is taken as held by it (IPOPT's interior point stops
#: ~1e-8 inside an active bound).
AT_LIMIT = 1e-6
#: IPOPT's absolute constraint tolerance (m for h, unit-sphere units for the direction rows), also
#: at its "acceptable" stop.
CONSTRAINT_TOL = 1e-10
#: Smallest environment row (m) of a successful placement, checked with pinocchio (IPOPT stops
#: ~1e-10 outside its feasible set, :data:`CONSTRAINT_TOL`).
CLEARANCE_TOL = 1e-8


#: Clear-posture and placement NLPs (one per clearance row set, each) kept for reuse: the scaling
#: benchmark's 144 captures among 3 obstacles used 94 row sets in 186 clear-posture solves.
SOLVERS_KEPT = 128
#: Index of the zenith row u_z in the NLP's constraints g = [h (3), plane, side, u_z, c, v].
ZENITH_ROW = 5
#: The cost-scale sample: zeniths from θ_min to θ_max at each of as many azimuths (see
#: :func:`_objective_scale`).
SCALE_ZENITHS, SCALE_AZIMUTHS = 4, 8


@dataclass(frozen=True)
class PlacementResult:
    """One placement: joint angles ``theta`` (n, rad, within the limits) and where they put the light:
    ``position`` (world, m), ``zenith``/``azimuth`` (rad, azimuth in [0, 2π)) seen from O.

    ``cost``: the objective there (NumPy renderer, shadow rays, the camera's resolution).
    ``success``: IPOPT converged, |h|∞ ≤ :data:`H_TOL`, the environment's rows ≥
    −:data:`CLEARANCE_TOL` (when it is on) and the light off the reach boundary (see the module
    docstring); θ is within the joint limits. ``status``: IPOPT's return status of the solve kept.
    ``message``: what happened, in words. ``on_boundary``: the NLP's optimum was on the reach
    boundary (the light was then moved :data:`BOUNDARY_MARGIN` inside, when it could be).
    ``iterations``: IPOPT's, over all solves. ``max_h_residual``: |h(θ)|∞ (m, pinocchio).
    ``conditioning``: σ_min/σ_max of the 5-D light task Jacobian over the free joints at θ.
    ``min_clearance_m``: the smallest environment row (clearance and view, sphere model, m) at θ and
    ``clearance_row`` its label; inf and "" without an environment. ``time_s``: wall time of
    :meth:`LightPlacement.solve`.
    """

    theta: Array
    position: Array
    zenith: float
    azimuth: float
    cost: float
    success: bool
    status: str
    message: str
    on_boundary: bool
    iterations: int
    max_h_residual: float
    conditioning: float
    min_clearance_m: float
    clearance_row: str
    time_s: float

    @property
    def clear(self) -> bool:
        """The light is one the robot holds at ``theta``, whether or not IPOPT converged there (an
        iterate at its iteration limit): |h|∞ ≤ :data:`H_TOL`, the environment's rows ≥
        −:data:`CLEARANCE_TOL` and off the reach boundary (σ_min/σ_max ≥ :data:`SINGULAR_TOL`)."""
        return (
            self.max_h_residual <= H_TOL
            and self.min_clearance_m >= -CLEARANCE_TOL
            and self.conditioning >= SINGULAR_TOL
        )


class LightPlacement:
    """The joint-space placement NLP of ``cell``'s robot on its sphere (see the module docstring):
    its objective built once, one ``nlpsol`` per set of clearance rows on first use
    (:data:`SOLVERS_KEPT` kept), with IPOPT's settings from ``solver``.

    The NLP renders the search scene with its search objective (``costs``); reported costs use the
    camera-resolution scene and objective. The cell's environment (None when it has none) adds its
    clearance and view rows.
    """

    def __init__(self, cell: Workcell, costs: ImageCosts, solver: SolverSpec) -> None:
        self.cell = cell
        self.scene = costs.scene
        self.robot = robot = cell.robot
        self._lower, self._upper = knot_bounds(robot)
        self.sphere = sphere = cell.sphere
        self.objective = costs.objective
        self.search = costs.search_scene
        self.search_objective = costs.search_objective
        #: The environment whose rows are constraints, or None.
        self.environment = cell.environment
        self._ik = dict(cell.ik)

        theta = ca.MX.sym("theta", robot.n)
        visibility = ca.MX.sym("v", self.search.gbuffer.size)
        a, rot = robot.symbolic_light_pose(theta)
        #: CasADi Function (θ (n), v (P)) -> D̃(a(θ), v): the NLP's cost, at the search resolution.
        self.cost_function = ca.Function(
            "placement_cost",
            [theta, visibility],
            [self.search_objective.function(a, visibility)],
            ["theta", "v"],
            ["cost"],
        )
        p = ca.MX.sym("p", 1 + self.search.gbuffer.size)
        phi = p[0]
        u = ca.DM(sphere.rotation.T) @ (a - ca.DM(sphere.center)) / sphere.radius
        plane = -ca.sin(phi) * u[0] + ca.cos(phi) * u[1]
        side = ca.cos(phi) * u[0] + ca.sin(phi) * u[1]
        self.objective_scale = _objective_scale(self.search, self.search_objective)
        # As for ClearPosture: most solves that fail are of an azimuth the arm cannot hold clear, and
        # IPOPT told to expect that gives up sooner, out of its costly restoration phase (on the
        # scaling benchmark's 144 captures with 3 obstacles, half the iterations and a third of the
        # time, the same solves succeeding and the same plan)
        self._options = ipopt_options(
            solver,
            ipopt__obj_scaling_factor=self.objective_scale,
            ipopt__constr_viol_tol=CONSTRAINT_TOL,
            ipopt__acceptable_constr_viol_tol=CONSTRAINT_TOL,
            ipopt__expect_infeasible_problem="yes",
        )
        self._theta, self._p = theta, p
        self._cost = self.cost_function(theta, p[1:])
        self._light = [light_rows(a, rot, sphere.center, sphere.radius), plane, side, u[2]]
        self._solvers: OrderedDict[tuple[tuple[int, ...] | None, bool], tuple[ca.Function, int]] = OrderedDict()
        # g = [h (3), plane, side, u_z, c, v]; "free" switches the two azimuth rows off through their
        # bounds; the environment rows are ≥ 0.
        # A zenith bound at the pole (θ_min = 0, θ_max = π) is implied by h = 0 and dropped: u_z ≤ 1 is
        # active there with a gradient that vanishes on the sphere, which stalls IPOPT (no LICQ).
        lo = math.cos(sphere.zenith_max) if sphere.zenith_max < math.pi else -np.inf
        hi = math.cos(sphere.zenith_min) if sphere.zenith_min > 0.0 else np.inf
        self._bounds = {
            "fixed": (np.r_[0.0, 0.0, 0.0, 0.0, 0.0, lo], np.r_[0.0, 0.0, 0.0, 0.0, np.inf, hi]),
            "free": (np.r_[0.0, 0.0, 0.0, -np.inf, -np.inf, lo], np.r_[0.0, 0.0, 0.0, np.inf, np.inf, hi]),
        }

    def _solver(self, active: NDArray[np.bool_] | None, beam: bool) -> tuple[ca.Function, int]:
        """The NLP with the clearance rows ``active`` ((1, m) over the environment's clearance rows;
        None: all of them) and the view rows (with ``beam``, the beam's rows too), and its number of
        environment rows: built on first use (~5 ms, the objective's graph shared), the
        :data:`SOLVERS_KEPT` last used kept."""
        key = (None if active is None else tuple(int(i) for i in np.flatnonzero(active[0])), beam)
        if key not in self._solvers:
            rows, env, theta = list(self._light), self.environment, self._theta
            if env is not None and env.collisions:
                clearance = env.clearance_function(self.robot)
                rows.append(clearance(theta) if active is None else selected_rows(clearance, theta, [0], 0, active)[0])
            if env is not None and env.view_cone is not None:
                # the beam's rows only when asked (from a clear posture): left to the check of the
                # result (worst_sphere_row), started from the IK's posture of a light out of reach,
                # the arm stretched through the beam, IPOPT reported the placement infeasible
                # (point_light)
                rows.append(env.view_cone_function(self.robot, beam=beam)(theta))
            g = ca.vertcat(*rows)
            nlp = ca.nlpsol("light_placement", "ipopt", {"x": theta, "p": self._p, "f": self._cost, "g": g}, self._options)
            self._solvers[key] = (nlp, g.size1() - (ZENITH_ROW + 1))
            if len(self._solvers) > SOLVERS_KEPT:
                self._solvers.popitem(last=False)
        self._solvers.move_to_end(key)
        return self._solvers[key]

    def solve(self, azimuth: float | None, theta0: ArrayLike, *, beam: bool = False) -> PlacementResult:
        """The best light on the half-plane of ``azimuth`` (rad; None: anywhere on the allowed cap)
        that the robot reaches, IPOPT warm-started at ``theta0`` (n, rad): a local optimum, the one
        ``theta0`` leads to, kept off the reach boundary. With ``beam`` the arm's distance to the
        light's beam is a row of the NLP too (otherwise only the check of the result holds it): for
        a start clear of it, where the optimum without it puts the arm in the beam. Never raises for
        an unreachable azimuth: returns ``success=False`` and says why in ``message``."""
        t0 = time.perf_counter()
        lbg, ubg = self._bounds["free" if azimuth is None else "fixed"]
        phi = 0.0 if azimuth is None else float(azimuth)
        theta = np.asarray(theta0, float)
        mask = self.search.visibility(self._on_sphere(self.robot.light_pose(theta)[0]))
        best: PlacementResult | None = None
        iterations = 0
        for _ in range(VISIBILITY_ROUNDS):
            solved = self._run(theta, np.r_[phi, mask], lbg, ubg, beam=beam)
            iterations += solved.iterations
            candidate = self._result(solved.x, solved.success, solved.status)
            # a failed re-solve never replaces a success; among successes the lower cost wins
            if best is None or (candidate.success and (not best.success or candidate.cost < best.cost)):
                best = candidate
            if not candidate.success:  # failed, or on the reach boundary: reachability holds the light there
                break
            new_mask = self.search.visibility(candidate.position)
            if np.array_equal(new_mask, mask):
                break
            theta, mask = solved.x, new_mask
        assert best is not None  # VISIBILITY_ROUNDS ≥ 1
        if best.on_boundary:
            best, more = self._step_inside(best, best.azimuth if azimuth is None else phi, beam)
            iterations += more
        return dataclasses.replace(best, iterations=iterations, time_s=time.perf_counter() - t0)

    def _run(
        self, theta0: Array, p: Array, lbg: Array, ubg: Array, *, relax: bool = True, beam: bool = False
    ) -> Solve:
        """The NLP from ``theta0`` with the bounds ``lbg``, ``ubg`` of its first :data:`ZENITH_ROW` + 1
        rows and the clearance rows that can bind (:func:`~optlight.planning.trajectory.solve_active_rows`,
        one posture: those below :data:`~optlight.planning.trajectory.ACTIVE_DISTANCE` at ``theta0``,
        more when the solution breaks one left out, all in the last solve), with the iterations of
        every solve. IPOPT's time per iteration grows with the rows (L-BFGS over ~230 of them on the
        scaling benchmark's obstacles, of which ~26 are near a posture). Each solve is
        :meth:`_margined`'s (``relax``: with its fallbacks; ``beam``: with the beam's rows)."""
        solves: list[Solve] = []

        def attempt(active: NDArray[np.bool_] | None, start: Array) -> tuple[Solve, Array | None]:
            nlp, rows = self._solver(active, beam)
            full_lbg = np.r_[lbg, np.full(rows, CAPTURE_SLACK)]
            full_ubg = np.r_[ubg, np.full(rows, np.inf)]
            solves.append(self._margined(nlp, start[0], p, full_lbg, full_ubg, relax))
            return solves[-1], solves[-1].x[None] if solves[-1].success else None

        last = solve_active_rows(self.cell, theta0[None], attempt, bound=CAPTURE_SLACK)
        return dataclasses.replace(last, iterations=sum(s.iterations for s in solves))

    def _margined(self, nlp: ca.Function, theta0: Array, p: Array, lbg: Array, ubg: Array, relax: bool) -> Solve:
        """``nlp`` from ``theta0`` with the capture margins (joints :data:`~optlight.planning.nlp.LIMIT_MARGIN`
        inside their limits, environment rows ≥ ``CAPTURE_SLACK``). Where IPOPT fails from ``theta0``
        (and ``relax``), the NLP without the margins, whose feasible set is larger, then the one with
        them from its solution; where the margins leave no light on the azimuth (the relaxed optimum
        sits where a row meets a joint limit: point_light's landmark 1), the relaxed solution, on its
        rows' bounds, which the trajectory NLP (rows ≥ 0) still accepts."""
        margined = {"p": p, "lbx": self._lower, "ubx": self._upper, "lbg": lbg, "ubg": ubg}
        solved = run(nlp, {"x0": theta0, **margined})
        if solved.success or not relax:
            return solved
        relaxed_lbg = lbg.copy()
        relaxed_lbg[ZENITH_ROW + 1 :] = np.minimum(relaxed_lbg[ZENITH_ROW + 1 :], 0.0)
        relaxed = {"p": p, "lbx": self.robot.lower, "ubx": self.robot.upper, "lbg": relaxed_lbg, "ubg": ubg}
        first = run(nlp, {"x0": theta0, **relaxed})
        if not first.success:
            return dataclasses.replace(solved, iterations=solved.iterations + first.iterations)
        second = run(nlp, {"x0": first.x, **margined})
        kept = second if second.success else first
        return dataclasses.replace(kept, iterations=solved.iterations + first.iterations + second.iterations)

    def conditioning(self, theta: ArrayLike) -> float:
        """σ_min/σ_max of the 5-D light task Jacobian at θ (the generalized IK's: rows 0–4 of
        pinocchio's LOCAL Jacobian of the light, the two optical-axis rows times b, so every row is
        in m/rad) over the joints farther than :data:`AT_LIMIT` from their limits; 0 when fewer than
        5 are. Near 0 on the boundary of the reachable set."""
        theta = np.asarray(theta, float)
        free = (theta > self._lower + AT_LIMIT) & (theta < self._upper - AT_LIMIT)
        if free.sum() < 5:
            return 0.0
        jacobian = KinematicState.compute(self.robot, theta).local_jacobian[:5, free]
        sigma = np.linalg.svd(
            jacobian * np.array([1.0, 1.0, 1.0, self.sphere.radius, self.sphere.radius])[:, None]
        )[1]
        return float(sigma[-1] / sigma[0])

    def _on_sphere(self, position: Array) -> Array:
        """The point of the sphere in the direction of ``position`` from O (the warm start's light may
        be off the sphere)."""
        d = position - self.sphere.center
        return self.sphere.center + self.sphere.radius * d / np.linalg.norm(d)

    def _result(self, theta: Array, converged: bool, status: str) -> PlacementResult:
        """The placement at ``theta``, checked and scored independently of the NLP (``iterations`` and
        ``time_s`` are the caller's to fill). IPOPT relaxes the joint bounds (by ~1e-8 relative, its
        ``bound_relax_factor``; 1e-10 rad seen with active clearance rows): θ is projected into the
        limits first, and everything is checked there."""
        theta = np.clip(theta, self._lower, self._upper)
        position, rotation = self.robot.light_pose(theta)
        h = float(np.abs(h_residual(position, rotation, self.sphere.center, self.sphere.radius)).max())
        zenith, azimuth = self.sphere.angles(position)
        conditioning = self.conditioning(theta)
        clearance, row = (
            self.environment.worst_sphere_row(self.robot, theta)
            if self.environment is not None
            else (math.inf, "")
        )
        clear = clearance >= -CLEARANCE_TOL
        feasible = h <= H_TOL and clear
        # IPOPT rarely certifies a point of the reach boundary (no constraint qualification there, so no
        # multipliers): a feasible singular iterate is on it whether IPOPT converged or stopped
        on_boundary = feasible and conditioning < SINGULAR_TOL
        if on_boundary:
            message = f"on the reach boundary (σ_min/σ_max = {conditioning:.1e}, IPOPT: {status})"
        elif not converged:
            # a feasible iterate is still a light the robot holds clear (PlacementResult.clear)
            message = f"IPOPT: {status}, |h| = {h:.1e} m" + (", its light clear" if feasible else "")
        elif not clear:
            message = f"IPOPT: {status}, but {row} is {-clearance * 1e3:.1f} mm too close"
        elif not feasible:
            message = f"IPOPT: {status}, but |h| = {h:.1e} m"
        else:
            message = f"IPOPT: {status}"
        return PlacementResult(
            theta=theta,
            position=position,
            zenith=float(zenith),
            azimuth=float(azimuth),
            cost=exact_cost(self.scene, self.objective, position),
            success=converged and feasible and not on_boundary,
            status=status,
            message=message,
            on_boundary=on_boundary,
            iterations=0,
            max_h_residual=h,
            conditioning=conditioning,
            min_clearance_m=clearance,
            clearance_row=row,
            time_s=0.0,
        )

    def _step_inside(self, boundary: PlacementResult, azimuth: float, beam: bool) -> tuple[PlacementResult, int]:
        """The light :data:`BOUNDARY_MARGIN` from ``boundary`` along the meridian of ``azimuth`` (rad),
        on the side where the generalized IK (the problem's settings, from ``boundary.theta``, no
        restarts) reaches it and the NLP, with the zenith pinned there through its row's bounds and
        warm-started from the IK, converges to a non-singular configuration; the cheaper side when
        both do. ``boundary`` itself, not a success, when neither does. Also returns the IPOPT
        iterations spent."""
        lbg, ubg = (b.copy() for b in self._bounds["fixed"])
        lit = np.ones(self.search.gbuffer.size)  # the light is pinned: the mask changes nothing
        inside, iterations = [], 0
        for zenith in (boundary.zenith - BOUNDARY_MARGIN, boundary.zenith + BOUNDARY_MARGIN):
            if not self.sphere.zenith_min <= zenith <= self.sphere.zenith_max:
                continue
            ik = generalized_ik(
                self.robot, self.sphere, (zenith, azimuth), boundary.theta, **self._ik, restarts=False
            )
            if not ik.success:
                continue
            lbg[ZENITH_ROW] = ubg[ZENITH_ROW] = math.cos(zenith)
            solved = self._run(ik.theta, np.r_[azimuth, lit], lbg, ubg, relax=False, beam=beam)
            iterations += solved.iterations
            inside.append(self._result(solved.x, solved.success, solved.status))
        inside = [r for r in inside if r.success]
        margin = math.degrees(BOUNDARY_MARGIN)
        if not inside:
            message = f"{boundary.message}, and no reachable light {margin:g}° inside it"
            return dataclasses.replace(boundary, message=message), iterations
        best = min(inside, key=lambda r: r.cost)
        message = f"{boundary.message}: moved {margin:g}° inside it"
        return dataclasses.replace(best, on_boundary=True, message=message), iterations


def _objective_scale(scene: Scene, objective: Objective) -> float:
    """IPOPT's objective scaling factor: 1 / the median cost over a coarse grid of the allowed cap
    (:data:`SCALE_ZENITHS` × :data:`SCALE_AZIMUTHS` lights, NumPy renderer with shadow rays); 1 when
    that median is 0.

    Histogram distances are ~1e-4–1e-1 on the cap, so unscaled the Lagrangian's curvature is the
    constraints' and L-BFGS creeps along the reachable set: from the IK solutions of the 22 landmarks
    the panda reaches (default face, 8 landmarks, 3 bases) IPOPT needed median 10, max 291 iterations
    unscaled, and median 7, max 14 with this scale (115 there; the median is 4e-3–6e-2 on the built-in
    problems). A fixed 1e2–1e4 did as well on the default face, but the scale follows the objective.
    """
    sphere = scene.sphere
    zenith, azimuth = np.meshgrid(
        np.linspace(sphere.zenith_min, sphere.zenith_max, SCALE_ZENITHS),
        np.linspace(0.0, 2 * np.pi, SCALE_AZIMUTHS, endpoint=False),
    )
    positions = sphere.position(zenith.ravel(), azimuth.ravel())
    median = float(np.median(objective.numpy_batch(np.stack([scene.pixels(a) for a in positions]))))
    return 1.0 / median if median > 0.0 else 1.0
