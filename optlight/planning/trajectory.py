"""The trajectory NLP (docs/design.md §6): joint angles at every path knot, built once, solved many times.

Variables θ_0 … θ_{K−1} (joint angles, rad). Constraints per knot k, with a_k, R_k the light
position and rotation from the symbolic forward kinematics:

- h(θ_k) = R_kᵀ (O − a_k) − [0, 0, b] = 0 (on the sphere, aimed at O; docs/design.md §3);
- path = "arc": the light stays on its segment's great circle, n_sᵀ (a_k − O) = 0, and between
  the segment's end points (two linear inequalities in a_k); path = "free": on the sphere only;
- landmark knots: the light exactly at the landmark (the two tangent components of a_k − a*);
- the interior knots of a transfer segment (:attr:`LightPath.transfers`) are off the sphere: instead
  of h, the one row (|a_k − O|² − b²) / 2b ≥ 0 (to first order the light's distance outside the
  sphere, m), so the light never comes nearer the object than the captures do;
- joint bounds (minus :data:`~optlight.planning.nlp.LIMIT_MARGIN`), and |θ_{k+1} − θ_k| ≤ max_step per joint;
- with an environment (:mod:`optlight.environment`): clearance c(θ_k) ≥ 0 at every knot (robot
  spheres to obstacles and to each other, margins included) and the view cone kept clear,
  v(θ_k) ≥ 0, at the landmark knots (view "capture") or at every knot (view "path").

Cost Σ_k Σ_j W_j (θ_{k+1,j} − θ_{k,j})² + w Σ_k |θ_k − θ_ref|². With W_j ∝ 1/v_max,j² (the
pipeline's choice, scaled to mean order 1) the first term is the squared time each step takes at the
velocity limits, a smooth stand-in for the motion time TOPPRA will find; the small posture term
settles the null space.
The per-knot constraints are one SX function mapped over the knots, so the graph stays small.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

import casadi as ca
import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import CubicSpline

from optlight.errors import IPOPT_ITERATION_LIMIT, SolverError, iteration_limit_error
from optlight.geometry import LightSphere
from optlight.planning.nlp import (
    KnotRows,
    Symbolic,
    arc_rows,
    environment_rows,
    knot_bounds,
    knot_derivatives,
    knot_map,
    knot_nlp_options,
    light_rows,
    pin_rows,
    selected_rows,
    tangent_basis,
)
from optlight.planning.path import LightPath
from optlight.planning.timing import chord_path
from optlight.robot import light_residual
from optlight.robot.ik import generalized_ik, ik_settings
from optlight.setup import Setup
from optlight.spec import SolverSpec

Array = NDArray[np.float64]


#: IPOPT's initial barrier parameter of the trajectory NLP's second try (:func:`optimize_knots`).
WARM_MU_INIT = 1e-4
#: Most IPOPT iterations of the trajectory NLP's first try when a second try or the caller's fallback
#: can follow it (:func:`optimize_knots`; fewer when ``[solver] max_iter`` is smaller).
FIRST_TRY_ITER = 120

#: Weight w of the posture term w Σ_k |θ_k − θ_ref|² (1/rad²): small, it only settles the null space.
POSTURE_WEIGHT = 1e-6


@dataclass(frozen=True)
class TrajectoryNLPResult:
    """Knot configurations (K, n) and the solver's account of them."""

    theta: Array
    success: bool
    status: str
    cost: float
    max_h_residual: float
    iterations: int
    time_s: float


@functools.lru_cache(maxsize=16)
def knot_function(light_pose: ca.Function) -> ca.Function:
    """Per-knot constraints g(θ, O, b, n, u_start, u_end, t1, t2, a*) as one SX function:
    [h (3); plane (1); wedge (2); pin (2); outside (1)], from the robot's symbolic ``light_pose``
    θ → (a, R). Built once per robot (every window's solver, and its Hessian, use it)."""
    theta = ca.SX.sym("theta", light_pose.size1_in(0))
    center, normal, u0, u1, t1, t2, target = (
        ca.SX.sym(s, 3) for s in ("O", "n", "u0", "u1", "t1", "t2", "a_star")
    )
    radius = ca.SX.sym("b")
    a, rot = light_pose(theta)
    h = light_rows(a, rot, center, radius)
    plane, wedge = arc_rows(a, center, normal, u0, u1)
    pin = pin_rows(a, target, t1, t2)
    outside = (ca.sumsqr(a - center) - radius**2) / (2.0 * radius)
    return ca.Function(
        "knot_constraints",
        [theta, center, radius, normal, u0, u1, t1, t2, target],
        [ca.vertcat(h, plane, wedge, pin, outside)],
    )


def _knot_row_index(
    blocks: list[tuple[Symbolic, list[int], list[int]]], outputs: int, n_knots: int
) -> NDArray[np.int64]:
    """(outputs, n_knots): the row of g that each output of the knot function is at each knot, −1
    where it is not a row. ``blocks`` are g's blocks in order: the rows (a matrix, stacked column by
    column into g), the free knots whose columns they are, and which outputs they hold; a block's
    column of a fixed knot (the first, off the sphere) comes before the free ones."""
    index = np.full((outputs, n_knots), -1)
    offset = 0
    for rows, knots, held in blocks:
        if knots:
            fixed = len(held) * (rows.size2() - len(knots))
            stacked = np.arange(len(held) * len(knots)).reshape(len(knots), len(held)).T
            index[np.ix_(held, knots)] = offset + fixed + stacked
        offset += rows.numel()
    return index


class TrajectoryOptimizer:
    """IPOPT over all knots of a path; the solver is built once per (knot count, landmark knots,
    transfer knots, first knot fixed or not).

    ``robot`` provides ``symbolic_light_pose`` (CasADi θ → (a, R)), ``lower``, ``upper``,
    ``theta_ref`` and ``n``; ``joint_weights`` W (n,) weigh the joint steps (default 1);
    ``clearance`` and ``view`` are CasADi functions θ → distances (≥ 0 is safe) from
    :class:`optlight.environment.Environment`; ``active`` (K, m), when given, the clearance rows that
    are rows of the NLP at each knot of the paths it solves (K knots, m the rows of ``clearance``;
    None: all, at every knot); ``retry``: the settings of :func:`optimize_knots`' second try, IPOPT's
    initial barrier parameter :data:`WARM_MU_INIT` (instead of its default 0.1) and an infeasible
    problem expected; ``max_iter``: at most that many IPOPT iterations (None: ``[solver] max_iter``;
    never more). Solvers are cached, so solving many paths of the same size reuses one.
    """

    def __init__(
        self,
        robot: Any,
        *,
        path_mode: str = "arc",
        max_step: float = 0.25,
        posture_weight: float = POSTURE_WEIGHT,
        joint_weights: NDArray[np.float64] | None = None,
        clearance: ca.Function | None = None,
        active: NDArray[np.bool_] | None = None,
        view: ca.Function | None = None,
        view_mode: str = "capture",
        solver: SolverSpec | None = None,
        retry: bool = False,
        max_iter: int | None = None,
    ) -> None:
        self.robot = robot
        self.path_mode = path_mode
        self.max_step = float(max_step)
        self.posture_weight = float(posture_weight)
        self.joint_weights = np.ones(robot.n) if joint_weights is None else np.asarray(joint_weights, float)
        self.clearance = clearance
        self.active = active
        self.view = view
        self.view_mode = view_mode
        # the exact Hessian and the Jacobian, knot by knot (knot_derivatives): the knot rows are
        # small SX graphs
        self.options = knot_nlp_options(solver or SolverSpec(), ipopt__constr_viol_tol=1e-9)
        if retry:  # why these two: optimize_knots
            self.options["ipopt.mu_init"] = WARM_MU_INIT
            self.options["ipopt.expect_infeasible_problem"] = "yes"
        if max_iter is not None:
            self.options["ipopt.max_iter"] = min(self.options["ipopt.max_iter"], max_iter)
        self._solvers: dict[tuple[int, tuple[int, ...], tuple[int, ...], bool], ca.Function] = {}
        self._knot_fn = knot_function(robot.symbolic_light_pose)

    def _solver(
        self, n_knots: int, landmark_knots: tuple[int, ...], off_sphere: tuple[int, ...], fixed_start: bool
    ) -> ca.Function:
        key = (n_knots, landmark_knots, off_sphere, fixed_start)
        if key not in self._solvers:
            self._solvers[key] = self._build_solver(*key)
        return self._solvers[key]

    def _build_solver(
        self, n_knots: int, landmark_knots: tuple[int, ...], off_sphere: tuple[int, ...], fixed_start: bool
    ) -> ca.Function:
        n = self.robot.n
        free = list(range(int(fixed_start), n_knots))
        variables = ca.MX.sym("theta", n, len(free))
        # parameters: O (3), b (1), θ_ref (n), per knot n, u0, u1, t1, t2, a* (18 × K), then the
        # first knot's angles (n), used when it is fixed
        p = ca.MX.sym("p", 4 + n + 18 * n_knots + n)
        center, radius, theta_ref = p[0:3], p[3], p[4 : 4 + n]
        per_knot = ca.reshape(p[4 + n : 4 + n + 18 * n_knots], 18, n_knots)
        theta = ca.horzcat(p[4 + n + 18 * n_knots :], variables) if fixed_start else variables
        mapped = knot_map(self._knot_fn, n_knots)
        g_all = mapped(
            theta,
            ca.repmat(center, 1, n_knots),
            ca.repmat(radius, 1, n_knots),
            per_knot[0:3, :],
            per_knot[3:6, :],
            per_knot[6:9, :],
            per_knot[9:12, :],
            per_knot[12:15, :],
            per_knot[15:18, :],
        )
        # a fixed knot's rows are constants: only the free knots carry rows
        on_sphere = [k for k in free if k not in set(off_sphere)]
        landmarks = [k for k in landmark_knots if k in set(free)]
        interior = [k for k in on_sphere if k not in set(landmark_knots)] if self.path_mode == "arc" else []
        view_knots = (free if self.view_mode == "path" else landmarks) if self.view is not None else []
        # g: per block its rows and, for the knot function's rows, which of its outputs they are
        blocks: list[tuple[Symbolic, list[int], list[int]]] = [
            (g_all[0:3, on_sphere], on_sphere, [0, 1, 2]),
            (g_all[6:8, landmarks], landmarks, [6, 7]),
            (theta[:, 1:] - theta[:, :-1], [], []),
            (g_all[8, list(off_sphere)], [k for k in off_sphere if k in set(free)], [8]),
        ]
        if self.path_mode == "arc":
            blocks += [(g_all[3, interior], interior, [3]), (g_all[4:6, interior], interior, [4, 5])]
        knot_index = _knot_row_index(blocks, self._knot_fn.size1_out(0), n_knots)
        constraints: list[Symbolic] = [ca.vec(rows) for rows, _, _ in blocks]
        offset = sum(c.size1() for c in constraints)
        environment: list[KnotRows] = []
        for function, knots, active in (
            (self.clearance, range(len(free)), self._active_at(n_knots, free)),
            (self.view, [k - int(fixed_start) for k in view_knots], None),
        ):
            if function is not None:
                block, rows = selected_rows(function, variables, knots, offset, active)
                constraints.append(block)
                environment.append(rows)
                offset += block.size1()
        dtheta = theta[:, 1:] - theta[:, :-1]
        posture = theta - ca.repmat(theta_ref, 1, n_knots)
        w = ca.DM(np.sqrt(self.joint_weights))
        cost = ca.sumsqr(ca.repmat(w, 1, n_knots - 1) * dtheta) + self.posture_weight * ca.sumsqr(posture)
        g = ca.vertcat(*constraints)
        knot_rows = KnotRows(
            self._knot_fn,
            list(range(len(free))),
            [
                ca.repmat(center, 1, len(free)),
                ca.repmat(radius, 1, len(free)),
                *(per_knot[i : i + 3, free] for i in range(0, 18, 3)),
            ],
            knot_index[:, free],
        )
        derivatives = knot_derivatives(variables, p, cost, g, [knot_rows, *environment])
        nlp = {"x": ca.vec(variables), "p": p, "f": cost, "g": g}
        return ca.nlpsol("trajectory_nlp", "ipopt", nlp, {**self.options, **derivatives})

    def _active_at(self, n_knots: int, knots: list[int]) -> NDArray[np.bool_] | None:
        """The rows of :attr:`active` at ``knots`` of a path of ``n_knots`` knots (None: all)."""
        if self.active is None:
            return None
        if self.active.shape[0] != n_knots:
            raise ValueError(f"active clearance rows for {self.active.shape[0]} knots, the path has {n_knots}")
        return self.active[knots]

    def bounds(
        self, n_knots: int, n_landmarks: int, n_off_sphere: int = 0, n_fixed: int = 0
    ) -> tuple[Array, Array]:
        """lbg, ubg in the order the constraints are stacked in the solver (``n_fixed`` of the
        landmark knots fixed)."""
        n = self.robot.n
        eq = np.zeros(3 * (n_knots - n_off_sphere - n_fixed) + 2 * (n_landmarks - n_fixed))
        step = np.full(n * (n_knots - 1), self.max_step)
        lbg, ubg = [eq, -step, np.zeros(n_off_sphere)], [eq, step, np.full(n_off_sphere, np.inf)]
        if self.path_mode == "arc":
            n_int = n_knots - n_landmarks - n_off_sphere
            lbg += [np.zeros(n_int), np.zeros(2 * n_int)]
            ubg += [np.zeros(n_int), np.full(2 * n_int, np.inf)]
        rows = 0
        if self.clearance is not None:
            active = self._active_at(n_knots, list(range(n_fixed, n_knots)))
            rows += self.clearance.size1_out(0) * (n_knots - n_fixed) if active is None else int(active.sum())
        if self.view is not None:
            rows += self.view.size1_out(0) * (
                (n_knots if self.view_mode == "path" else n_landmarks) - n_fixed
            )
        lbg.append(np.zeros(rows))
        ubg.append(np.full(rows, np.inf))
        return np.concatenate(lbg), np.concatenate(ubg)

    def solve(
        self, path: LightPath, sphere: LightSphere, theta0: Array, fixed_start: bool = False
    ) -> TrajectoryNLPResult:
        """Optimise the knot configurations of ``path``, warm-started at ``theta0`` (K, n); with
        ``fixed_start``, the first knot keeps its angles from ``theta0``."""
        n_knots, n = path.n_knots, self.robot.n
        if n_knots < 2 and fixed_start:
            raise ValueError("a path of one knot with that knot fixed has nothing to optimise")
        landmark_knots = tuple(int(k) for k in path.landmark_knots)
        off_sphere = tuple(int(k) for k in np.flatnonzero(~path.on_sphere()))
        free = list(range(int(fixed_start), n_knots))
        solver = self._solver(n_knots, landmark_knots, off_sphere, fixed_start)
        per_knot = np.zeros((n_knots, 18))
        for seg in path.segments():
            u0, u1 = path.directions[seg.start], path.directions[seg.stop - 1]
            normal = np.cross(u0, u1)
            norm = np.linalg.norm(normal)
            normal = normal / norm if norm > 1e-12 else tangent_basis(u0)[0]
            per_knot[seg, 0:3], per_knot[seg, 3:6], per_knot[seg, 6:9] = normal, u0, u1
        for k in range(n_knots):
            per_knot[k, 9:12], per_knot[k, 12:15] = tangent_basis(path.directions[k])
        per_knot[:, 15:18] = path.positions
        theta0 = np.asarray(theta0, float)
        p = np.concatenate(
            [sphere.center, [sphere.radius], self.robot.theta_ref, per_knot.ravel(), theta0[0]]
        )
        lbg, ubg = self.bounds(n_knots, len(landmark_knots), len(off_sphere), int(fixed_start))
        lower, upper = knot_bounds(self.robot)
        lbx, ubx = np.tile(lower, len(free)), np.tile(upper, len(free))
        x0 = np.clip(theta0[free].ravel(), lbx, ubx)
        start = time.perf_counter()
        out = solver(x0=x0, p=p, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
        elapsed = time.perf_counter() - start
        stats = solver.stats()
        theta = theta0.copy()
        theta[free] = np.asarray(out["x"]).reshape(len(free), n)
        g = np.asarray(out["g"]).ravel()
        n_h = 3 * (len(free) - len(off_sphere))  # the h rows come first, free on-sphere knots only
        max_h = float(np.max(np.abs(g[:n_h]))) if n_h else 0.0
        if not np.all(np.isfinite(theta)):
            raise SolverError(f"trajectory NLP returned non-finite joint angles ({stats['return_status']})")
        return TrajectoryNLPResult(
            theta=theta,
            success=bool(stats["success"]),
            status=str(stats["return_status"]),
            cost=float(out["f"]),
            max_h_residual=max_h,
            iterations=int(stats["iter_count"]),
            time_s=elapsed,
        )


def knot_cost(setup: Setup, theta: Array) -> float:
    """The cost :func:`optimize_knots` minimises, at the knots ``theta`` (K, n) (rad), in NumPy:
    Σ_k Σ_j (θ_{k+1,j} − θ_{k,j})² / v_max,j² + :data:`POSTURE_WEIGHT` Σ_k |θ_k − θ_ref|² (s²)."""
    steps = np.diff(theta, axis=0) / setup.limits.velocity
    return float(np.sum(steps**2) + POSTURE_WEIGHT * np.sum((theta - setup.robot.theta_ref) ** 2))


#: What an NLP solve of :func:`solve_active_rows` returns.
_Result = TypeVar("_Result")

#: Clearance rows below this (m) at a knot (or at one next to it) join the trajectory NLP
#: (:func:`optimize_knots`) and the transfer NLP (:func:`plan_transfer`) there. Chosen knot by knot,
#: 0.1 m halves the NLP time on the obstacle problems against 0.15 m; a row left out that the
#: solution breaks still joins (:data:`ACTIVE_ROUNDS`).
ACTIVE_DISTANCE = 0.1
#: Solves of the trajectory NLP with the near rows before the last, which has them all.
ACTIVE_ROUNDS = 2


def optimize_knots(
    setup: Setup, path: LightPath, warm: Array, fixed_start: bool = False, *, fallback: bool = False
) -> TrajectoryNLPResult:
    """The trajectory NLP over the path's knots, warm-started at the per-knot IK ``warm`` (K, n),
    the first knot kept at its ``warm`` angles with ``fixed_start``; ``fallback``: the caller has
    another way to go when this one fails (:func:`~optlight.pipeline.optimize_window`'s transfers,
    for a warm start with segments the per-knot IK did not follow).

    Joint steps are weighed by 1/v_max,j² (the squared time at the velocity limits); with an
    environment its view-cone rows join, and of its clearance rows those that can bind, knot by
    knot: each row at the knots of ``warm`` where it is below :data:`ACTIVE_DISTANCE`, and at their
    neighbours (:func:`solve_active_rows`; on the collision problem's second window 817 of its
    57 × 210 (knot, row) pairs). A row left out that the solution breaks joins, with the rows near
    the solution, and the NLP is solved again from there; after :data:`ACTIVE_ROUNDS` such solves,
    the last has every row at every knot.
    Why: the exact Hessian of the clearance rows was ~80 % of the NLP's time with all rows, and
    L-BFGS did not converge in 300 iterations on the collision problem.

    One solve, from the per-knot IK: its capture postures are the placement's, clear with a margin.
    (Not a continuation through the optimum without the environment: that optimum moves the capture
    postures into the view cone or the obstacles, and the constrained solve from it fails on half of
    the built-in problems — default, collision, face_ur5, sphere_xarm7, rti_dome — where the one
    from the per-knot IK succeeds on all of them, in less time.)

    When those solves fail, they run again with IPOPT's initial barrier parameter
    :data:`WARM_MU_INIT` instead of its default 0.1: the warm start is feasible or nearly, with rows a
    few mm from their bounds, and the large barrier first pushes the iterate away from it (a window of
    the scaling benchmark's 576 captures among 3 obstacles ended "infeasible" after 84 iterations
    although its warm start met every row; from 1e-4 it converged in 17). Not the first try: from
    1e-4 the NLP also settles nearer the warm start's local optimum, which on the loop benchmark's
    bowl put a capture's arm across the light's beam. Nor when the warm start is far from feasible
    (a knot on the sphere the per-knot IK missed: |h| above :data:`WARM_H_TOL`): there the small
    barrier has nothing to keep, and a path the arm cannot follow on the sphere took as long again
    to be found infeasible (photometric_stereo: 245 more iterations, 4 s). The retry also tells
    IPOPT to expect an infeasible problem (restoration sooner, left only on a real reduction): most
    retries that fail are windows the fallbacks of :func:`~optlight.pipeline.optimize_window` then
    solve, and so those retries give up in about half the iterations, while every solve that
    succeeds takes the same iterations to the same plan. Not the first try: there it sends
    face_ur5's first solve to knots that hold a capture's light at the antipode of its landmark
    (0.8 m away: the pin rows' other root on the sphere), which verification refuses.

    Nor with a ``fallback``: a warm start whose IK jumped branches between two knots (a step beyond
    ``max_step_rad``) or put the arm into an obstacle at one is not near the feasible set either, and
    the segment it did not follow becomes a transfer. On the ten built-in problems and the scaling
    benchmark's obstacle cells no such retry ever succeeded: each failed (after 32–134 iterations,
    2.5 s of one window of 576 / 3) before the transfers solved.

    Where the retry or the fallback can follow, the first try stops after :data:`FIRST_TRY_ITER`
    iterations: on the ten built-in problems and the scaling benchmark's 576 captures among 3
    obstacles every first try that succeeded did so within 83 iterations, while the five of 576 / 3
    that failed ran 181–300 (four of them; 905 iterations, ~9 s) before IPOPT gave up and the retry
    or a fallback took over (photometric_stereo's, 273 before the transfers). One that the cap cuts
    short: an 82-knot window of the photometric-stereo set designed on the cap (the ``lightset_plans``
    benchmark's baseline) had converged in 141 iterations; its transfer solves it in 25, with 21 %
    less motion per capture. Where neither can follow, the first try has all ``[solver] max_iter``
    iterations: it is the last.
    Raises :class:`SolverError` when the solves fail.
    """
    can_retry = not fallback and _warm_start_on_sphere(setup, path, warm)
    first_budget = FIRST_TRY_ITER if can_retry or fallback else None
    first = _active_rounds(setup, path, warm, fixed_start, retry=False, max_iter=first_budget)
    retry = not first.success and can_retry
    nlp = _active_rounds(setup, path, warm, fixed_start, retry=True) if retry else first
    iterations = first.iterations + (0 if nlp is first else nlp.iterations)
    time_s = first.time_s + (0.0 if nlp is first else nlp.time_s)
    nlp = dataclasses.replace(nlp, iterations=iterations, time_s=time_s)
    if not nlp.success and nlp.status == IPOPT_ITERATION_LIMIT:
        raise iteration_limit_error("the trajectory NLP", setup.solver.max_iter)
    if not nlp.success:
        raise SolverError(
            f"the trajectory NLP failed ({nlp.status} after {nlp.iterations} iterations, "
            f"max |h| = {nlp.max_h_residual:.2e} m); try a smaller [trajectory] knot_spacing_deg, a "
            'larger max_step_rad or path = "free"'
        )
    return nlp


#: Largest |h| (m) of a warm start at its knots on the sphere for the small-barrier retry of
#: :func:`optimize_knots`: the per-knot IK's converged knots are within √ik_tol ≈ 3e-5 m.
WARM_H_TOL = 1e-4


def _warm_start_on_sphere(setup: Setup, path: LightPath, warm: Array) -> bool:
    """Whether ``warm`` (K, n) holds the light on the sphere, pointing at O, to :data:`WARM_H_TOL`
    at every knot of ``path`` that the NLP keeps there (:meth:`LightPath.on_sphere`)."""
    return all(
        np.abs(light_residual(setup.robot, setup.sphere, theta)).max() <= WARM_H_TOL
        for theta in warm[path.on_sphere()]
    )


def _active_rounds(
    setup: Setup, path: LightPath, warm: Array, fixed_start: bool, retry: bool, max_iter: int | None = None
) -> TrajectoryNLPResult:
    """The solves of :func:`optimize_knots` with the active clearance rows (:func:`solve_active_rows`),
    from ``warm``, with the ``retry`` settings of :class:`TrajectoryOptimizer` or not and at most
    ``max_iter`` iterations each (None: ``[solver] max_iter``); the last solve, with the iterations
    and time of all."""
    env = setup.environment
    solves: list[TrajectoryNLPResult] = []

    def solve(active: NDArray[np.bool_] | None, start: Array) -> tuple[TrajectoryNLPResult, Array | None]:
        rows = None if active is None else _rows_of(active)
        optimizer = TrajectoryOptimizer(
            setup.robot,
            path_mode=setup.trajectory_spec.path,
            max_step=setup.trajectory_spec.max_step_rad,
            joint_weights=1.0 / setup.limits.velocity**2,
            clearance=env.clearance_function(setup.robot, rows) if env and env.collisions else None,
            active=None if active is None else active[:, rows],
            view=env.view_cone_function(setup.robot) if env and env.view_cone else None,
            view_mode=env.view_mode if env else "capture",
            solver=setup.solver,
            retry=retry,
            max_iter=max_iter,
        )
        solves.append(optimizer.solve(path, setup.sphere, start, fixed_start))
        return solves[-1], solves[-1].theta if solves[-1].success else None

    nlp = solve_active_rows(setup, warm, solve)
    return dataclasses.replace(
        nlp, iterations=sum(s.iterations for s in solves), time_s=sum(s.time_s for s in solves)
    )


def solve_active_rows(
    setup: Setup,
    warm: Array,
    solve: Callable[[NDArray[np.bool_] | None, Array], tuple[_Result, Array | None]],
    bound: float = 0.0,
) -> _Result:
    """An NLP over knots solved with only the clearance rows that can bind, knot by knot:
    ``solve(active, start)`` solves it from the knots ``start`` (K, n) with the clearance row i at
    knot k where ``active[k, i]`` ((K, m) over :meth:`Environment.clearance_function`'s rows; None:
    every row at every knot) and returns its result and its knots (None when it failed). First the
    rows below :data:`ACTIVE_DISTANCE` at a knot of ``warm`` or at a neighbour of it
    (:func:`near_rows`); when the solution breaks a row left out (below ``bound``, m, at some
    knot), those and the rows near the solution join, and the NLP is solved again from the
    solution; after :data:`ACTIVE_ROUNDS` such solves, the last has every row at every knot.
    Without clearance rows (no environment, or no collisions modelled): one solve with None.

    Knot by knot, not one row set for all knots: a row near at some knot is far at most others (on
    the collision problem's second window, 817 (knot, row) pairs instead of the 42 rows near
    somewhere at each of its 57 knots, 2,394), and IPOPT's linear algebra grows with the pairs."""
    env, robot = setup.environment, setup.robot
    if env is None or not env.collisions:
        return solve(None, warm)[0]
    active: NDArray[np.bool_] | None = near_rows(env.clearance_values(robot, warm), ACTIVE_DISTANCE)
    for round_ in range(ACTIVE_ROUNDS + 1):
        result, theta = solve(active, warm)
        if active is None or theta is None:
            break
        values = env.clearance_values(robot, theta)
        broken = (values < bound) & ~active
        if not broken.any():
            break
        active = active | broken | near_rows(values, ACTIVE_DISTANCE) if round_ + 1 < ACTIVE_ROUNDS else None
        warm = theta
    return result


def _rows_of(active: NDArray[np.bool_]) -> list[int]:
    """The clearance rows (columns of ``active`` (K, m)) that are rows of the NLP at some knot."""
    return [int(i) for i in np.flatnonzero(active.any(axis=0))]


def near_rows(values: Array, distance: float) -> NDArray[np.bool_]:
    """(K, m): the clearance rows (``values`` (K, m), m) below ``distance`` at each knot or at a
    knot next to it: the knots move in a solve, a row's nearest approach with them."""
    near = values < distance
    spread = near.copy()
    spread[1:] |= near[:-1]
    spread[:-1] |= near[1:]
    return spread


#: Knots of a transfer (start → first landmark, last landmark → start) at most this far apart (rad).
TRANSFER_STEP = 0.1

#: Clearance (m) a transfer keeps at its interior knots beyond the environment's margins: the arm
#: moves between knots, and its ends may sit exactly at a margin (a capture planned against it).
TRANSFER_PADDING = 0.002


def plan_transfer(setup: Setup, start: Array, goal: Array, *, detour: Array | None = None) -> Array:
    """Joint angles (K, n) from ``start`` to ``goal`` (rad), both included: the light is off the
    sphere here, moving to or from the captures.

    The straight line in joint space, knots at most :data:`TRANSFER_STEP` apart per joint, when it
    keeps clear of the environment (collisions; and the view, ``[view] mode = "path"``, not the beam:
    the light is not aimed at the object here) at every knot,
    by the NLPs' sphere model; otherwise the transfer NLP from that line: min Σ_k Σ_j W_j
    (θ_{k+1,j} − θ_{k,j})² (W = 1/v_max², the squared time at the velocity limits) s.t. the rows ≥
    :data:`TRANSFER_PADDING` at the interior knots, joint limits and the end points fixed, with the
    clearance rows that can bind (:func:`solve_active_rows`, as the trajectory NLP: with all 229 rows
    per knot the exact Hessian made table_wall's two transfers 2.1 s). When the NLP fails from the line (a line deep in an obstacle can leave IPOPT in a local infeasibility), it
    starts again from ``detour`` (K', n), a known clear way from ``start`` to ``goal`` (the way back
    along the plan), which it shortens. Raises :class:`SolverError` when that fails too."""
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    count = max(2, int(np.ceil(np.max(np.abs(goal - start)) / TRANSFER_STEP)) + 1)
    line = start + np.linspace(0.0, 1.0, count)[:, None] * (goal - start)
    environment = setup.environment
    view = environment is not None and environment.view_mode == "path"
    if environment is None or not (environment.collisions or view):
        return line
    robot = setup.robot

    def rows(theta: Array) -> Array:
        clearance, view_rows = environment.sphere_clearance(robot, theta, beam=False)
        return np.concatenate([clearance, view_rows if view else np.zeros(0)])

    if all(rows(theta).min(initial=np.inf) >= TRANSFER_PADDING for theta in line[1:-1]):
        return line

    def solve(
        active: NDArray[np.bool_] | None, initial: Array
    ) -> tuple[tuple[Array | None, str], Array | None]:
        rows = None if active is None else _rows_of(active)
        q = ca.MX.sym("q", robot.n)
        row_function = ca.Function(
            "transfer_rows", [q], [environment_rows(environment, robot, q, view=view, beam=False, clearance_rows=rows)]
        )
        if active is not None and rows is not None:  # the view rows, after the clearance rows, at every knot
            views = row_function.size1_out(0) - len(rows)
            active = np.hstack([active[:, rows], np.ones((len(initial), views), bool)])
        knots, status = _transfer_nlp(setup, row_function, start, goal, initial, active)
        return (knots, status), knots

    status = ""
    for initial in (line, None if detour is None else _thinned(np.asarray(detour, float), TRANSFER_STEP)):
        if initial is None or len(initial) < 3:
            continue
        knots, status = solve_active_rows(setup, initial[1:-1], solve, bound=TRANSFER_PADDING - 1e-8)
        if knots is not None and all(rows(t).min(initial=np.inf) >= TRANSFER_PADDING - 1e-8 for t in knots):
            return np.vstack([start, knots, goal])
    raise SolverError(
        f"no transfer clear of the environment between the start configuration and the captures "
        f"({status}); choose another [robot] start"
    )


def _transfer_nlp(
    setup: Setup,
    row_function: ca.Function,
    start: Array,
    goal: Array,
    initial: Array,
    active: NDArray[np.bool_] | None = None,
) -> tuple[Array | None, str]:
    """The transfer NLP of :func:`plan_transfer` over ``len(initial)`` interior knots from ``initial``
    (rad), the rows of ``row_function`` at every interior knot, or where ``active`` (len(initial), m)
    is True: the interior knots (None when IPOPT fails) and IPOPT's status."""
    n, inner = setup.robot.n, len(initial)
    x = ca.MX.sym("theta", n, inner)
    ends = ca.MX.sym("ends", n, 2)
    knots = ca.horzcat(ends[:, 0], x, ends[:, 1])
    steps = knots[:, 1:] - knots[:, :-1]
    weights = ca.DM(1.0 / setup.limits.velocity)
    g, rows = selected_rows(row_function, x, range(inner), 0, active)
    cost = ca.sumsqr(ca.repmat(weights, 1, inner + 1) * steps)
    options = knot_nlp_options(setup.solver)
    options.update(knot_derivatives(x, ca.vec(ends), cost, g, [rows]))
    solver = ca.nlpsol("transfer", "ipopt", {"x": ca.vec(x), "p": ca.vec(ends), "f": cost, "g": g}, options)
    lower, upper = (np.tile(bound, inner) for bound in knot_bounds(setup.robot))
    x0 = np.clip(initial.ravel(), lower, upper)  # knot by knot, as ca.vec(x) stacks them
    out = solver(
        x0=x0, p=np.c_[start, goal].T.ravel(), lbx=lower, ubx=upper, lbg=TRANSFER_PADDING, ubg=np.inf
    )
    status = str(solver.stats()["return_status"])
    if not solver.stats()["success"]:
        return None, status
    return np.asarray(out["x"]).reshape(inner, n), status


def _thinned(knots: Array, step: float) -> Array:
    """The knots (K, n) (rad) thinned to fewer whose neighbours are at most ``step`` apart per joint
    where the original's are (greedy: from each kept knot, the farthest knot still within ``step``);
    the first and last are kept."""
    kept, last = [0], 0
    for k in range(1, len(knots)):
        if np.max(np.abs(knots[k] - knots[last])) > step and k - 1 > last:
            kept.append(k - 1)
            last = k - 1
    if kept[-1] != len(knots) - 1:
        kept.append(len(knots) - 1)
    return knots[kept]


#: Largest distance (m) the timed path's light may stray from the planned path (the polyline of the
#: knots' lights) between two knots of a segment on the sphere before a knot is added there: half the
#: verification's tolerance (:attr:`optlight.verify.Tolerances.path_m`, 5 mm; the planner does not
#: import the verifier).
PATH_DEVIATION_M = 2.5e-3
#: Points per knot interval at which the spline's light is measured against the planned path.
DEVIATION_SAMPLES = 8
#: Rounds of knot insertion (each halves the intervals that still stray).
MAX_PATH_REFINEMENTS = 6


def follow_planned_path(setup: Setup, knots: Array) -> Array:
    """The knots (K, n) (rad) of one segment on the sphere, with knots added where the path the
    timing will follow strays from the planned one.

    The timing follows the not-a-knot cubic spline through the knots in joint space
    (:func:`~optlight.planning.timing.chord_path`); between two knots the light follows that
    spline's forward kinematics, not the chord between the knots' lights, and where the joints move
    a long way for a short light step it leaves the planned path; where the spline leaves the joint
    bounds, chord_path adds the joint-space midpoint of two knots, whose light is off the path too.
    So, per round: every waypoint whose light is more than :data:`PATH_DEVIATION_M` from the
    polyline of the knots' lights is put back on it, and the spline is sampled at
    :data:`DEVIATION_SAMPLES` points per interval; where its light is more than that from the
    polyline, a waypoint is added at the interval's middle, put on it the same way. "Put on it":
    the generalized IK (no restarts) from those joint angles to the light at the polyline's point
    nearest their light, carried radially onto the sphere (within the sag ρ(1 − cos(Δ/2)) of the
    chord between two knots Δ apart, 0.06 mm at 2°), aimed at O; kept when it converges within the
    joint bounds. Halving an interval shrinks the spline's bulge about fourfold; at most
    :data:`MAX_PATH_REFINEMENTS` rounds. What cannot be put back is left as it is (the verification
    reports it)."""
    planned = setup.robot.light_positions(knots)
    if len(planned) < 2:
        return knots
    bounds = (setup.limits.lower, setup.limits.upper)
    w = knots
    for _ in range(MAX_PATH_REFINEMENTS):
        chord = chord_path(w, bounds)
        if chord is None:
            return w
        w = chord[1].copy()
        changed = False
        for i in np.flatnonzero(_polyline_distance(setup.robot.light_positions(w), planned) > PATH_DEVIATION_M):
            on_path = _onto_path(setup, w[i], planned)
            if on_path is not None:
                w[i], changed = on_path, True
        chord = chord_path(w)  # the parameter of the corrected waypoints
        if chord is None:
            return w
        s, w = chord
        spline = CubicSpline(s, w, bc_type="not-a-knot")
        tau = (np.arange(DEVIATION_SAMPLES) + 0.5) / DEVIATION_SAMPLES
        between = s[:-1, None] + tau[None, :] * np.diff(s)[:, None]
        lights = setup.robot.light_positions(spline(between.ravel()))
        stray = _polyline_distance(lights, planned).reshape(between.shape).max(axis=1) > PATH_DEVIATION_M
        for i in np.flatnonzero(stray)[::-1]:  # from the end: the indices before stay valid
            middle = _onto_path(setup, spline(0.5 * (s[i] + s[i + 1])), planned)
            if middle is not None:
                w, changed = np.insert(w, i + 1, middle, axis=0), True
        if not changed:
            return w
    return w


def _onto_path(setup: Setup, theta: Array, planned: Array) -> Array | None:
    """Joint angles near ``theta`` (rad) whose light is on the planned path (the polyline through
    ``planned`` (K, 3), m, carried onto the sphere), aimed at O, within the joint bounds
    (:func:`follow_planned_path`); None when the IK does not converge there."""
    sphere = setup.sphere
    target = _nearest_on_polyline(setup.robot.light_positions(theta)[0], planned)
    return _light_at(setup, sphere.center + sphere.radius * _unit(target - sphere.center), theta)


def _light_at(setup: Setup, target: Array, theta: Array) -> Array | None:
    """The generalized IK (no restarts, the joint-limit task) from ``theta`` (rad) to the light at
    ``target`` (m, on the sphere) aimed at O: its joint angles when it converges within the joint
    bounds, else None."""
    settings = {**ik_settings(setup.solver), "secondary": ("joint_limits",)}
    ik = generalized_ik(setup.robot, setup.sphere, target, theta, restarts=False, **settings)
    inside = np.all((ik.theta >= setup.limits.lower) & (ik.theta <= setup.limits.upper))
    return ik.theta if ik.success and inside else None


def _unit(v: Array) -> Array:
    return v / np.linalg.norm(v)


#: Largest sag (m) of the chord between two knots' lights on the sphere below the great-circle arc
#: between them (ρ(1 − cos(Δ/2)) for lights Δ apart) before a knot is added on the arc: half the
#: spline's allowance. The planned path is the polyline of the knots' lights; the
#: light, on the sphere, follows the arc.
ARC_SAG_M = 0.5 * PATH_DEVIATION_M


def knots_on_arcs(setup: Setup, knots: Array) -> Array:
    """The knots (K, n) (rad) of one segment on the sphere, with knots added on the great-circle
    arc between two consecutive knots whose lights are so far apart that the chord between them
    sags more than :data:`ARC_SAG_M` below the arc (the free path's NLP bounds the joints' steps,
    not the light's: lights 50° apart sag 37 mm at ρ = 0.4 m, and the light on the sphere is that
    far from the planned path). A knot goes at the arc's midpoint, by the generalized IK from the
    joint-space midpoint (:func:`_light_at`), and the halves are split again, at most
    :data:`MAX_PATH_REFINEMENTS` deep; where the IK fails, the interval is left as it is."""
    out = [knots[0]]
    for q0, q1 in zip(knots[:-1], knots[1:], strict=True):
        out += _arc_knots(setup, q0, q1, MAX_PATH_REFINEMENTS)
        out.append(q1)
    return np.array(out)


def _arc_knots(setup: Setup, q0: Array, q1: Array, depth: int) -> list[Array]:
    """Knots strictly between ``q0`` and ``q1`` on their lights' arc (:func:`knots_on_arcs`)."""
    sphere = setup.sphere
    u0, u1 = (_unit(a - sphere.center) for a in setup.robot.light_positions(np.array([q0, q1])))
    half = 0.5 * float(np.arctan2(np.linalg.norm(np.cross(u0, u1)), u0 @ u1))
    if depth == 0 or sphere.radius * (1.0 - np.cos(half)) <= ARC_SAG_M or np.linalg.norm(u0 + u1) < 1e-9:
        return []
    middle = _light_at(setup, sphere.center + sphere.radius * _unit(u0 + u1), 0.5 * (q0 + q1))
    if middle is None:
        return []
    return [*_arc_knots(setup, q0, middle, depth - 1), middle, *_arc_knots(setup, middle, q1, depth - 1)]


def _polyline_distance(points: Array, polyline: Array) -> Array:
    """Distance (m) from each point (P, 3) to the polyline through the vertices (K ≥ 2, 3):
    min over segments of |p − (v_i + c d_i)|, c = clip((p − v_i)·d_i / |d_i|², 0, 1)."""
    a, d = polyline[:-1], np.diff(polyline, axis=0)
    rel = points[:, None, :] - a[None, :, :]
    c = np.clip(np.einsum("pkj,kj->pk", rel, d) / np.maximum(np.einsum("kj,kj->k", d, d), 1e-300), 0.0, 1.0)
    return np.linalg.norm(rel - c[:, :, None] * d[None, :, :], axis=2).min(axis=1)


def _nearest_on_polyline(point: Array, polyline: Array) -> Array:
    """The point (3,) of the polyline through the vertices (K, 3) nearest ``point`` (3,) (m)."""
    a, d = polyline[:-1], np.diff(polyline, axis=0)
    c = np.clip(np.einsum("ij,ij->i", point - a, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-300), 0.0, 1.0)
    nearest = a + c[:, None] * d
    return nearest[np.argmin(np.linalg.norm(nearest - point, axis=1))]
