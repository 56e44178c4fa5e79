"""Joint-space light placement (docs/design.md §5, the design's NLP): the best light the robot can reach.

Variables: the joint angles θ (n, rad). With a(θ), R(θ) the light's position (m) and rotation from the
symbolic forward kinematics (:attr:`Robot.symbolic_light_pose`) and u(θ) = R_WSᵀ (a(θ) − O) / b the
light's direction in the sphere frame (unit when h = 0):

    min_θ  D̃(a(θ), v)
    s.t.   h(θ) = R(θ)ᵀ (O − a(θ)) − [0, 0, b]ᵀ = 0              on the sphere, aimed at O (docs/design.md §3)
           −sin φ u_x + cos φ u_y = 0,   cos φ u_x + sin φ u_y ≥ 0   in the half-plane of azimuth φ
           cos θ_max ≤ u_z ≤ cos θ_min                             the allowed zenith range
           c(θ) ≥ s,   v(θ) ≥ s                                     clearance, view (environment on)
           lower + m ≤ θ ≤ upper − m                               joint limits less m = LIMIT_MARGIN

``D̃`` is the differentiable objective (:attr:`Objective.function`: smooth max and clip) at the
landmark search's resolution (:func:`optlight.planning.landmarks.search_scene`), so a sphere-space
landmark the robot reaches is a solution of this NLP too. The two azimuth rows are linear in u: the
equality puts the light in the plane through the pole at azimuth φ, the inequality keeps it on the
φ side of the pole (not at φ + π). At the pole (u_x = u_y = 0) every azimuth holds, as on the sphere.

Environment. When the problem's ``[environment] enabled`` is set, the rows of the trajectory NLP's
environment (:class:`~optlight.environment.Environment`) join: the clearance c(θ) (m; robot spheres to
the obstacles minus ``margin``, sphere pairs of the self pairs minus ``self_margin``) and, unless the
view cone is off, the view rows v(θ) (m; signed distance of the robot's spheres to the camera's view
cone minus their radii) — a landmark is a capture, so the view cone is kept clear in both of its
modes (the light's beam onto the object, the view rows' second part, is checked on the placement's
result and held by the clear posture, :class:`ClearPosture`); each row at least s = :data:`~optlight.environment.CAPTURE_SLACK`, so that the trajectory NLP
(rows ≥ 0) starts inside its feasible set (where no light of the azimuth keeps s: on the rows'
bounds, :meth:`LightPlacement._margined`). A landmark whose light the robot only reaches by
colliding or blocking the camera then moves along its azimuth to the best light it reaches clear of
both, exactly as an unreachable one does; the trajectory NLP, which pins its landmark knots, could
not do that itself. The clearance rows are those that can bind, as the trajectory NLP takes them
(:func:`~optlight.planning.trajectory.solve_active_rows`, one posture): those below
:data:`~optlight.planning.trajectory.ACTIVE_DISTANCE` at the warm start, more when the solution
breaks one left out, all in the last solve. With L-BFGS, IPOPT's time per iteration grows with the
rows: of the scaling benchmark's 206 clearance rows among its obstacles, ~26 are near a posture,
so taking only those makes each placement solve markedly cheaper for the same solutions.

Azimuth free. The same solver with both azimuth rows switched off through their bounds
(−∞ ≤ g ≤ ∞): one graph and one ``nlpsol`` per row set, as
:class:`~optlight.planning.landmarks.CapRefiner` switches off its unused separation rows. A second solver would only drop two cheap rows, at the
price of building, and keeping consistent, a second NLP.

Parameters p = (φ, v): the azimuth (rad) and the cast-shadow visibility mask v (P,) at the search
resolution. The mask is fixed during a solve: shadow rays at the warm start's light direction, and
when the mask at the solution differs the NLP is solved once more from the solution with the mask
there (:data:`VISIBILITY_ROUNDS`). The NLP is built once per set of clearance rows (the
objective's graph once for all) and reused for every solve.

Reach boundary. When the light the objective wants is out of reach, the NLP's optimum lies on the
boundary of the reachable set, which is a fold of the kinematics: there the 5-D light task Jacobian
(position and optical axis, over the joints not at a limit) loses rank, the light cannot move outwards,
and a trajectory NLP that pins a landmark there fails (IPOPT: Error_In_Step_Computation, seen on the
default face with a low base; pinned 0.02° inside it converged). So a solution whose Jacobian is
singular (σ_min/σ_max < :data:`SINGULAR_TOL`) is moved :data:`BOUNDARY_MARGIN` back along its meridian,
to the side the generalized IK reaches from the solution, then solved again with the zenith pinned there
(the zenith row's bounds) from the IK's angles, to the NLP's accuracy and with a non-singular Jacobian;
the lower cost wins when both sides qualify. A solution with no such side is not a success.

Reported numbers: ``cost`` is the objective of the NumPy render with shadow rays at the camera's
resolution (as :func:`~optlight.planning.landmarks.exact_cost`), of the light where pinocchio's forward
kinematics puts it; ``max_h_residual`` is |h|∞ (m) from pinocchio, independent of the CasADi mirror.

Angles are radians, lengths metres.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.environment import CAPTURE_SLACK, Environment
from optlight.geometry import h_residual
from optlight.objectives import Objective
from optlight.planning.landmarks import exact_cost
from optlight.planning.nlp import (
    KnotRows,
    Solve,
    environment_rows,
    ipopt_options,
    knot_bounds,
    knot_derivatives,
    light_rows,
    pin_rows,
    run,
    selected_rows,
    tangent_basis,
)
from optlight.planning.trajectory import WARM_MU_INIT, solve_active_rows
from optlight.robot import KinematicState, generalized_ik
from optlight.scene import Scene
from optlight.setup import Setup

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
#: Largest |h|∞ (m) and light position error (m) of a posture found by :class:`ClearPosture`, at θ
#: projected back into the limits: IPOPT relaxes them by ~1e-8 relative (``bound_relax_factor``),
#: ~3e-8 rad at the Panda's, and the projection moves the light by up to ~2e-8 m. At 1e-8 m,
#: clear postures IPOPT had found were refused (22 of the 178 solves of the 144-capture chain; on
#: the default face, landmark 31's, which then went to the placement NLP, 0.4 s, to end at the
#: same light). The trajectory NLP re-solves the pose (|h| ≤ 1e-9) and verification allows 1e-6.
POSE_TOL = 1e-7
#: Largest step (rad, max over the joints) from a clear-posture solve's anchor to its warm start for
#: which IPOPT starts from the small barrier :data:`~optlight.planning.trajectory.WARM_MU_INIT` (see
#: :meth:`ClearPosture.solve`).
NEAR_STEP = 0.5
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


class LightPlacement:
    """The joint-space placement NLP of a built setup (see the module docstring): its objective
    built once, one ``nlpsol`` per set of clearance rows on first use (:data:`SOLVERS_KEPT` kept).

    The NLP renders the setup's search scene with its search objective; reported costs use the
    camera-resolution scene and objective. The setup's environment (None when ``[environment]`` is
    not enabled) adds its clearance and view rows.
    """

    def __init__(self, setup: Setup) -> None:
        self.setup = setup
        self.scene = setup.scene
        self.robot = robot = setup.robot
        self._lower, self._upper = knot_bounds(robot)
        self.sphere = sphere = setup.sphere
        self.objective = setup.objective
        self.search = setup.search_scene
        self.search_objective = setup.search_objective
        #: The environment whose rows are constraints, or None.
        self.environment = setup.environment
        self._ik = dict(setup.ik)

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
            setup.solver,
            ipopt__obj_scaling_factor=self.objective_scale,
            ipopt__constr_viol_tol=CONSTRAINT_TOL,
            ipopt__acceptable_constr_viol_tol=CONSTRAINT_TOL,
            ipopt__expect_infeasible_problem="yes",
        )
        self._theta, self._p = theta, p
        self._cost = self.cost_function(theta, p[1:])
        self._light = [light_rows(a, rot, sphere.center, sphere.radius), plane, side, u[2]]
        self._solvers: OrderedDict[tuple[int, ...] | None, tuple[ca.Function, int]] = OrderedDict()
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

    def _solver(self, active: NDArray[np.bool_] | None) -> tuple[ca.Function, int]:
        """The NLP with the clearance rows ``active`` ((1, m) over the environment's clearance rows;
        None: all of them) and the view rows, and its number of environment rows: built on first
        use (~5 ms, the objective's graph shared), the :data:`SOLVERS_KEPT` last used kept."""
        key = None if active is None else tuple(int(i) for i in np.flatnonzero(active[0]))
        if key not in self._solvers:
            rows, env, theta = list(self._light), self.environment, self._theta
            if env is not None and env.collisions:
                clearance = env.clearance_function(self.robot)
                rows.append(clearance(theta) if active is None else selected_rows(clearance, theta, [0], 0, active)[0])
            if env is not None and env.view_cone is not None:
                # the beam's rows are left to the check of the result (worst_sphere_row) and the
                # clear posture: started from the IK's posture of a light out of reach, the arm
                # stretched through the beam, IPOPT reported the placement infeasible (point_light)
                rows.append(env.view_cone_function(self.robot, beam=False)(theta))
            g = ca.vertcat(*rows)
            nlp = ca.nlpsol("light_placement", "ipopt", {"x": theta, "p": self._p, "f": self._cost, "g": g}, self._options)
            self._solvers[key] = (nlp, g.size1() - (ZENITH_ROW + 1))
            if len(self._solvers) > SOLVERS_KEPT:
                self._solvers.popitem(last=False)
        self._solvers.move_to_end(key)
        return self._solvers[key]

    def solve(self, azimuth: float | None, theta0: ArrayLike) -> PlacementResult:
        """The best light on the half-plane of ``azimuth`` (rad; None: anywhere on the allowed cap)
        that the robot reaches, IPOPT warm-started at ``theta0`` (n, rad): a local optimum, the one
        ``theta0`` leads to, kept off the reach boundary. Never raises for an unreachable azimuth:
        returns ``success=False`` and says why in ``message``."""
        t0 = time.perf_counter()
        lbg, ubg = self._bounds["free" if azimuth is None else "fixed"]
        phi = 0.0 if azimuth is None else float(azimuth)
        theta = np.asarray(theta0, float)
        mask = self.search.visibility(self._on_sphere(self.robot.light_pose(theta)[0]))
        best: PlacementResult | None = None
        iterations = 0
        for _ in range(VISIBILITY_ROUNDS):
            solved = self._run(theta, np.r_[phi, mask], lbg, ubg)
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
            best, more = self._step_inside(best, best.azimuth if azimuth is None else phi)
            iterations += more
        return dataclasses.replace(best, iterations=iterations, time_s=time.perf_counter() - t0)

    def _run(self, theta0: Array, p: Array, lbg: Array, ubg: Array, *, relax: bool = True) -> Solve:
        """The NLP from ``theta0`` with the bounds ``lbg``, ``ubg`` of its first :data:`ZENITH_ROW` + 1
        rows and the clearance rows that can bind (:func:`~optlight.planning.trajectory.solve_active_rows`,
        one posture: those below :data:`~optlight.planning.trajectory.ACTIVE_DISTANCE` at ``theta0``,
        more when the solution breaks one left out, all in the last solve), with the iterations of
        every solve. IPOPT's time per iteration grows with the rows (L-BFGS over ~230 of them on the
        scaling benchmark's obstacles, of which ~26 are near a posture). Each solve is
        :meth:`_margined`'s (``relax``: with its fallbacks)."""
        solves: list[Solve] = []

        def attempt(active: NDArray[np.bool_] | None, start: Array) -> tuple[Solve, Array | None]:
            nlp, rows = self._solver(active)
            full_lbg = np.r_[lbg, np.full(rows, CAPTURE_SLACK)]
            full_ubg = np.r_[ubg, np.full(rows, np.inf)]
            solves.append(self._margined(nlp, start[0], p, full_lbg, full_ubg, relax))
            return solves[-1], solves[-1].x[None] if solves[-1].success else None

        last = solve_active_rows(self.setup, theta0[None], attempt, bound=CAPTURE_SLACK)
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
            message = f"IPOPT: {status}, |h| = {h:.1e} m"
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

    def _step_inside(self, boundary: PlacementResult, azimuth: float) -> tuple[PlacementResult, int]:
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
            solved = self._run(ik.theta, np.r_[azimuth, lit], lbg, ubg, relax=False)
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


class ClearPosture:
    """Joint angles clear of the environment for a given light, near given joint angles: the arm's
    redundancy used where the generalized IK, which does not see the environment, found a posture
    that collides or blocks the camera.

    Variables θ (n, rad); parameters θ₀ (n), the light position a* (m, on the sphere) and two unit
    vectors t₁, t₂ tangent to the sphere at a*:

        min |θ − θ₀|²   s.t.  h(θ) = R(θ)ᵀ (O − a(θ)) − [0, 0, b]ᵀ = 0,  t_iᵀ (a(θ) − a*) = 0 (i = 1, 2),
                              c(θ) ≥ s,  v(θ) ≥ s,  lower + m ≤ θ ≤ upper − m

    (the trajectory NLP's landmark pin; c, v the environment's clearance and view rows, v only when
    its view cone is on; s = :data:`~optlight.environment.CAPTURE_SLACK`). The sphere is the
    problem's; IPOPT's iteration limit and tolerance come from ``[solver]``. :meth:`solve` checks its
    answer with pinocchio.

    Clearance rows as the trajectory NLP takes them (:func:`~optlight.planning.trajectory.solve_active_rows`,
    one knot): only those below :data:`~optlight.planning.trajectory.ACTIVE_DISTANCE` at θ₀, more
    when the solution breaks one left out, all in the last solve. IPOPT's time per iteration grows
    with the rows: among the scaling benchmark's 3 obstacles ~26 of its 206 clearance rows are near
    a posture, so a solve with those alone costs well under two thirds of one with all of them.
    One NLP per row set, built on first use and kept
    (:data:`SOLVERS_KEPT`), with the exact Hessian and the Jacobian of
    :func:`~optlight.planning.nlp.knot_derivatives`: MX graphs over the environment's functions,
    ~9 ms to build on collision where CasADi generating the Jacobian took ~23 ms and its own expanded
    Hessian of a row set ~25 ms. Without clearance rows (the view cone alone, as on the default face)
    the one NLP has every row, expanded to SX as before.
    """

    def __init__(self, setup: Setup, environment: Environment) -> None:
        self.setup = setup
        self.robot = robot = setup.robot
        self._lower, self._upper = knot_bounds(robot)
        self.environment = environment
        self.sphere = sphere = setup.sphere
        theta = ca.SX.sym("theta", robot.n)
        target, t1, t2 = (ca.SX.sym(name, 3) for name in ("a_star", "t1", "t2"))
        a, rot = robot.symbolic_light_pose(theta)
        self._pose = ca.Function(
            "posture_pose",
            [theta, target, t1, t2],
            [ca.vertcat(light_rows(a, rot, sphere.center, sphere.radius), pin_rows(a, target, t1, t2))],
        )
        # Most solves of a light the arm cannot hold clear are infeasible (rti_dome: 320 of 338):
        # IPOPT told to expect that gives up about three times sooner, and the solves that succeed
        # succeed all the same.
        self._options = ipopt_options(
            setup.solver, ipopt__hessian_approximation="exact", ipopt__expect_infeasible_problem="yes"
        )
        #: (clearance row set or None, small barrier) -> (nlp, lbg, ubg)
        self._solvers: OrderedDict[tuple[tuple[int, ...] | None, bool], tuple[ca.Function, Array, Array]]
        self._solvers = OrderedDict()

    def _solver(self, active: NDArray[np.bool_] | None, small_barrier: bool) -> tuple[ca.Function, Array, Array]:
        """The NLP with the clearance rows ``active`` ((1, m) over the environment's clearance rows;
        None: all of them) and the view rows, IPOPT starting from the barrier parameter
        :data:`~optlight.planning.trajectory.WARM_MU_INIT` when ``small_barrier`` (else from its
        default), and its constraint bounds (lbg, ubg): built on first use, the
        :data:`SOLVERS_KEPT` last used kept."""
        key = (None if active is None else tuple(int(i) for i in np.flatnonzero(active[0])), small_barrier)
        if key not in self._solvers:
            theta = ca.MX.sym("theta", self.robot.n)
            p = ca.MX.sym("p", self.robot.n + 9)
            options = {**self._options, "ipopt.mu_init": WARM_MU_INIT} if small_barrier else self._options
            nlp, rows = (
                self._all_rows(theta, p, options) if active is None else self._row_set(theta, p, active, options)
            )
            lbg = np.r_[np.zeros(5), np.full(rows, CAPTURE_SLACK)]  # 5 equalities, then the rows
            ubg = np.r_[np.zeros(5), np.full(rows, np.inf)]
            self._solvers[key] = (nlp, lbg, ubg)
            if len(self._solvers) > SOLVERS_KEPT:
                self._solvers.popitem(last=False)
        self._solvers.move_to_end(key)
        return self._solvers[key]

    def _all_rows(self, theta: ca.MX, p: ca.MX, options: dict[str, Any]) -> tuple[ca.Function, int]:
        """The NLP with every row, expanded to SX with CasADi's Hessian (one build, many solves:
        10–40 % less per solve than as MX); its
        number of environment rows."""
        n = self.robot.n
        theta0, target, t1, t2 = p[:n], p[n : n + 3], p[n + 3 : n + 6], p[n + 6 : n + 9]
        environment = environment_rows(self.environment, self.robot, theta)
        g = ca.vertcat(self._pose(theta, target, t1, t2), environment)
        nlp = {"x": theta, "p": p, "f": ca.sumsqr(theta - theta0), "g": g}
        return ca.nlpsol(
            "clear_posture", "ipopt", nlp, {**options, "expand": True}
        ), environment.size1()

    def _row_set(
        self, theta: ca.MX, p: ca.MX, active: NDArray[np.bool_], options: dict[str, Any]
    ) -> tuple[ca.Function, int]:
        """The NLP with the clearance rows ``active`` (1, m) and the view rows, as MX over the
        environment's functions with :func:`~optlight.planning.nlp.knot_derivatives` (many builds,
        one per row set: ~9 ms each, against ~25 ms expanded with CasADi's Hessian); its number of
        environment rows."""
        robot, environment = self.robot, self.environment
        n = robot.n
        theta0, target, t1, t2 = p[:n], p[n : n + 3], p[n + 3 : n + 6], p[n + 6 : n + 9]
        blocks = [self._pose(theta, target, t1, t2)]
        parts = [KnotRows(self._pose, [0], [target, t1, t2], np.arange(5)[:, None])]
        functions: list[tuple[ca.Function, NDArray[np.bool_] | None]] = [
            (environment.clearance_function(robot), active)
        ]
        if environment.view_cone is not None:
            functions.append((environment.view_cone_function(robot), None))
        for function, rows in functions:
            block, part = selected_rows(function, theta, [0], sum(b.size1() for b in blocks), rows)
            blocks.append(block)
            parts.append(part)
        g = ca.vertcat(*blocks)
        cost = ca.sumsqr(theta - theta0)
        nlp = {"x": theta, "p": p, "f": cost, "g": g}
        derivatives = knot_derivatives(theta, p, cost, g, parts)
        return ca.nlpsol("clear_posture", "ipopt", nlp, {**options, **derivatives}), g.size1() - 5

    def solve(
        self, target: ArrayLike, theta0: ArrayLike, warm: ArrayLike | None = None
    ) -> tuple[Array, float, str] | None:
        """Clear joint angles for the light at ``target`` (m, on the sphere) nearest ``theta0`` (rad)
        that IPOPT finds from ``warm`` (rad; default ``theta0``), their smallest environment row (m)
        and its label; None when it finds none (checked with pinocchio at θ projected into the
        limits, IPOPT relaxing its bounds: |h|∞ and the light's distance to ``target`` ≤
        :data:`POSE_TOL`, every row ≥ −:data:`CLEARANCE_TOL`).

        A ``warm`` start that already holds the light at ``target`` (the generalized IK's angles,
        :class:`~optlight.planning.policy.Reacher`) leaves IPOPT only the clearance to restore, not
        the pose as well. Where that is only the camera's view (``warm`` breaks no clearance row) and
        ``warm`` is within :data:`NEAR_STEP` of ``theta0`` (a chain's next landmark), IPOPT starts from
        the small barrier :data:`~optlight.planning.trajectory.WARM_MU_INIT` instead of its default
        0.1, which first pushes the iterate away from the rows it nearly meets: about a third fewer
        iterations, with every built-in problem's plan the same. Not farther (yale_grid's 1.4-rad
        step then goes to another posture, and its plan's motion grows 4 %), nor where ``warm``
        breaks a clearance row (with every solve among the scaling benchmark's obstacles from the
        small barrier, the 36-capture cell loses a capture and the 144-capture one's mean cost grows
        20 %): there it settles in the warm start's local optimum, not the anchor's."""
        target = np.asarray(target, float)
        t1, t2 = tangent_basis((target - self.sphere.center) / self.sphere.radius)
        theta0 = np.asarray(theta0, float)
        warm = theta0 if warm is None else np.asarray(warm, float)
        parameters = np.r_[theta0, target, t1, t2]
        env = self.environment
        # only the view to restore: the warm start's arm clear of the obstacles (and of itself)
        nearest = env.clearance_values(self.robot, warm).min(initial=np.inf) if env.collisions else np.inf
        only_view = float(nearest) >= CAPTURE_SLACK
        small_barrier = only_view and float(np.abs(warm - theta0).max()) <= NEAR_STEP

        def attempt(active: NDArray[np.bool_] | None, start: Array) -> tuple[Solve, Array | None]:
            nlp, lbg, ubg = self._solver(active, small_barrier)
            bounds = {"lbx": self._lower, "ubx": self._upper, "lbg": lbg, "ubg": ubg}
            solved = run(nlp, {"x0": start[0], "p": parameters, **bounds})
            return solved, solved.x[None] if solved.success else None

        solved = solve_active_rows(self.setup, warm[None], attempt, bound=CAPTURE_SLACK)
        if not solved.success:
            return None
        theta = np.clip(solved.x, self._lower, self._upper)
        position, rotation = self.robot.light_pose(theta)
        h = float(np.abs(h_residual(position, rotation, self.sphere.center, self.sphere.radius)).max())
        clearance, row = self.environment.worst_sphere_row(self.robot, theta)
        ok = h <= POSE_TOL and np.linalg.norm(position - target) <= POSE_TOL and clearance >= -CLEARANCE_TOL
        return (theta, clearance, row) if ok else None


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
