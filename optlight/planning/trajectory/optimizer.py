"""The trajectory NLP's optimizer (docs/design.md §6): :class:`TrajectoryOptimizer` builds the NLP
over the knots once per shape (the per-knot constraints one SX function mapped over the knots) and
solves it many times; :func:`knot_cost` is its cost in NumPy.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from optlight.errors import SolverError
from optlight.geometry import LightSphere
from optlight.planning.nlp import (
    KnotRows,
    Symbolic,
    arc_rows,
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
from optlight.spec import SolverSpec
from optlight.workcell import Workcell

Array = NDArray[np.float64]


#: IPOPT's initial barrier parameter of the trajectory NLP's second try (:func:`optimize_knots`).
WARM_MU_INIT = 1e-4


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
        self,
        path: LightPath,
        sphere: LightSphere,
        theta0: Array,
        fixed_start: bool = False,
        fixed_end: bool = False,
    ) -> TrajectoryNLPResult:
        """Optimise the knot configurations of ``path``, warm-started at ``theta0`` (K, n); with
        ``fixed_start``, the first knot keeps its angles from ``theta0``; with ``fixed_end``, the
        last (its bounds lower = upper = ``theta0[-1]``: the rest of the plan goes on from there)."""
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
        if fixed_end:
            lbx[-n:] = ubx[-n:] = np.asarray(theta0, float)[-1]
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


def knot_cost(cell: Workcell, theta: Array) -> float:
    """The cost :func:`optimize_knots` minimises for ``cell``'s robot and limits, at the knots
    ``theta`` (K, n) (rad), in NumPy:
    Σ_k Σ_j (θ_{k+1,j} − θ_{k,j})² / v_max,j² + :data:`POSTURE_WEIGHT` Σ_k |θ_k − θ_ref|² (s²)."""
    steps = np.diff(theta, axis=0) / cell.limits.velocity
    return float(np.sum(steps**2) + POSTURE_WEIGHT * np.sum((theta - cell.robot.theta_ref) ** 2))


def joined_results(results: Sequence[TrajectoryNLPResult], theta: Array, cost: float) -> TrajectoryNLPResult:
    """One result for several solves ``results`` of parts of one path (windows, or segments solved
    again) at its knots ``theta`` (K, n) of ``cost``: iterations and times added, the largest |h|, the
    statuses that occurred."""
    return TrajectoryNLPResult(
        theta=theta,
        success=all(r.success for r in results),
        status=", ".join(dict.fromkeys(r.status for r in results)),
        cost=cost,
        max_h_residual=max(r.max_h_residual for r in results),
        iterations=sum(r.iterations for r in results),
        time_s=sum(r.time_s for r in results),
    )
