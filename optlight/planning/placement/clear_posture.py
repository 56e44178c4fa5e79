"""Clear postures (docs/design.md §5, §8): :class:`ClearPosture`, joint angles for a given light
clear of the environment (clearance, view cone, beam) near given joint angles.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.environment import CAPTURE_SLACK, Environment
from optlight.geometry import h_residual
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
from optlight.planning.placement.light import CLEARANCE_TOL, SOLVERS_KEPT, Array
from optlight.planning.trajectory import WARM_MU_INIT, solve_active_rows
from optlight.spec import SolverSpec
from optlight.workcell import Workcell

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


class ClearPosture:
    """Joint angles clear of the environment for a given light, near given joint angles: the arm's
    redundancy used where the generalized IK, which does not see the environment, found a posture
    that collides or blocks the camera.

    Variables θ (n, rad); parameters θ₀ (n), the light position a* (m, on the sphere) and two unit
    vectors t₁, t₂ tangent to the sphere at a*:

        min |θ − θ₀|²   s.t.  h(θ) = R(θ)ᵀ (O − a(θ)) − [0, 0, b]ᵀ = 0,  t_iᵀ (a(θ) − a*) = 0 (i = 1, 2),
                              c(θ) ≥ s,  v(θ) ≥ s,  lower + m ≤ θ ≤ upper − m

    (the trajectory NLP's landmark pin; c, v the environment's clearance and view rows, v only when
    its view cone is on; s = :data:`~optlight.environment.CAPTURE_SLACK`). The robot and sphere are
    the work cell's, ``environment`` its environment; IPOPT's iteration limit and tolerance come from
    ``solver`` (``[solver]``). :meth:`solve` checks its
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

    def __init__(self, cell: Workcell, environment: Environment, solver: SolverSpec) -> None:
        self.cell = cell
        self.robot = robot = cell.robot
        self._lower, self._upper = knot_bounds(robot)
        self.environment = environment
        self.sphere = sphere = cell.sphere
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
            solver, ipopt__hessian_approximation="exact", ipopt__expect_infeasible_problem="yes"
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

        solved = solve_active_rows(self.cell, warm[None], attempt, bound=CAPTURE_SLACK)
        if not solved.success:
            return None
        theta = np.clip(solved.x, self._lower, self._upper)
        position, rotation = self.robot.light_pose(theta)
        h = float(np.abs(h_residual(position, rotation, self.sphere.center, self.sphere.radius)).max())
        clearance, row = self.environment.worst_sphere_row(self.robot, theta)
        ok = h <= POSE_TOL and np.linalg.norm(position - target) <= POSE_TOL and clearance >= -CLEARANCE_TOL
        return (theta, clearance, row) if ok else None
