"""The transfer NLP (docs/design.md §6): the joint-space knots of a move between two postures
(start → first landmark, last landmark → start) that keeps the environment's clearances.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from optlight.errors import SolverError
from optlight.planning.nlp import (
    environment_rows,
    knot_bounds,
    knot_derivatives,
    knot_nlp_options,
    selected_rows,
)
from optlight.planning.trajectory.active_rows import rows_of, solve_active_rows
from optlight.planning.trajectory.between import too_close_between
from optlight.planning.trajectory.optimizer import Array
from optlight.spec import SolverSpec
from optlight.workcell import Workcell

#: Knots of a transfer (start → first landmark, last landmark → start) at most this far apart (rad).
TRANSFER_STEP = 0.1

#: Rounds of transfers planned with their knots' step halved where the arm comes too close between
#: two knots (:func:`plan_transfer`).
TRANSFER_ROUNDS = 4

#: Clearance (m) a transfer keeps at its interior knots beyond the environment's margins: the arm
#: moves between knots, and its ends may sit exactly at a margin (a capture planned against it).
TRANSFER_PADDING = 0.002


def plan_transfer(
    cell: Workcell, solver: SolverSpec, start: Array, goal: Array, *, detour: Array | None = None
) -> Array:
    """Joint angles (K, n) of ``cell``'s robot from ``start`` to ``goal`` (rad), both included: the
    light is off the sphere here, moving to or from the captures (IPOPT's settings from ``solver``).

    The knots of :func:`_transfer_knots`, at most :data:`TRANSFER_STEP` apart per joint, then checked
    where the timing takes the arm between them (the spline through them, exactly, as the
    verification: :func:`~optlight.planning.trajectory.between.too_close_between`): where it comes
    too close between two knots, the step halves and the transfer is planned again (denser knots
    carry the clearance rows closer together), at most :data:`TRANSFER_ROUNDS` times. Raises
    :class:`SolverError` naming the link and the obstacle when no transfer clears."""
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    environment = cell.environment
    if environment is None or not (environment.collisions or environment.view_mode == "path"):
        return _line(start, goal, TRANSFER_STEP)
    step, worst = TRANSFER_STEP, None
    for _ in range(TRANSFER_ROUNDS):
        knots = _transfer_knots(cell, solver, start, goal, detour, step)
        broken, worst = too_close_between(cell, knots, [slice(0, len(knots))])
        if not broken.any():
            return knots
        step /= 2
    assert worst is not None
    raise SolverError(
        f"no transfer clear of the environment between the start configuration and the captures: "
        f"{worst.first} comes {worst.min_distance_m * 1e3:.1f} mm from {worst.second} (allowed "
        f"{worst.threshold_m * 1e3:.1f} mm) between its knots, {TRANSFER_ROUNDS} times denser; choose "
        "another [robot] start"
    )


def _line(start: Array, goal: Array, step: float) -> Array:
    """The straight line in joint space from ``start`` to ``goal`` (rad), both included, its knots at
    most ``step`` apart per joint."""
    count = max(2, int(np.ceil(np.max(np.abs(goal - start)) / step)) + 1)
    return start + np.linspace(0.0, 1.0, count)[:, None] * (goal - start)


def _transfer_knots(
    cell: Workcell, solver: SolverSpec, start: Array, goal: Array, detour: Array | None, step: float
) -> Array:
    """The knots (K, n) of :func:`plan_transfer` at most ``step`` apart per joint, clear at each knot.

    The straight line in joint space when it keeps clear of the environment (collisions; and the
    view, ``[view] mode = "path"``, not the beam: the light is not aimed at the object here) at
    every knot, by the NLPs' sphere model; otherwise the transfer NLP from that line: min Σ_k Σ_j W_j
    (θ_{k+1,j} − θ_{k,j})² (W = 1/v_max², the squared time at the velocity limits) s.t. the rows ≥
    :data:`TRANSFER_PADDING` at the interior knots, joint limits and the end points fixed, with the
    clearance rows that can bind (:func:`solve_active_rows`, as the trajectory NLP: with all 229 rows
    per knot the exact Hessian made table_wall's two transfers 2.1 s). When the NLP fails from the line (a line deep in an obstacle can leave IPOPT in a local infeasibility), it
    starts again from ``detour`` (K', n), a known clear way from ``start`` to ``goal`` (the way back
    along the plan), which it shortens. Raises :class:`SolverError` when that fails too."""
    line = _line(start, goal, step)
    environment = cell.environment
    assert environment is not None
    view = environment.view_mode == "path"
    robot = cell.robot

    def rows(theta: Array) -> Array:
        clearance, view_rows = environment.sphere_clearance(robot, theta, beam=False)
        return np.concatenate([clearance, view_rows if view else np.zeros(0)])

    if all(rows(theta).min(initial=np.inf) >= TRANSFER_PADDING for theta in line[1:-1]):
        return line

    def solve(
        active: NDArray[np.bool_] | None, initial: Array
    ) -> tuple[tuple[Array | None, str], Array | None]:
        rows = None if active is None else rows_of(active)
        q = ca.MX.sym("q", robot.n)
        row_function = ca.Function(
            "transfer_rows",
            [q],
            [environment_rows(environment, robot, q, view=view, beam=False, clearance_rows=rows)],
        )
        if active is not None and rows is not None:  # the view rows, after the clearance rows, at every knot
            views = row_function.size1_out(0) - len(rows)
            active = np.hstack([active[:, rows], np.ones((len(initial), views), bool)])
        knots, status = _transfer_nlp(cell, solver, row_function, start, goal, initial, active)
        return (knots, status), knots

    status = ""
    for initial in (line, None if detour is None else _thinned(np.asarray(detour, float), step)):
        if initial is None or len(initial) < 3:
            continue
        knots, status = solve_active_rows(cell, initial[1:-1], solve, bound=TRANSFER_PADDING - 1e-8)
        if knots is not None and all(rows(t).min(initial=np.inf) >= TRANSFER_PADDING - 1e-8 for t in knots):
            return np.vstack([start, knots, goal])
    raise SolverError(
        f"no transfer clear of the environment between the start configuration and the captures "
        f"({status}); choose another [robot] start"
    )


def _transfer_nlp(
    cell: Workcell,
    solver_spec: SolverSpec,
    row_function: ca.Function,
    start: Array,
    goal: Array,
    initial: Array,
    active: NDArray[np.bool_] | None = None,
) -> tuple[Array | None, str]:
    """The transfer NLP of :func:`plan_transfer` over ``len(initial)`` interior knots from ``initial``
    (rad), the rows of ``row_function`` at every interior knot, or where ``active`` (len(initial), m)
    is True: the interior knots (None when IPOPT fails) and IPOPT's status."""
    n, inner = cell.robot.n, len(initial)
    x = ca.MX.sym("theta", n, inner)
    ends = ca.MX.sym("ends", n, 2)
    knots = ca.horzcat(ends[:, 0], x, ends[:, 1])
    steps = knots[:, 1:] - knots[:, :-1]
    weights = ca.DM(1.0 / cell.limits.velocity)
    g, rows = selected_rows(row_function, x, range(inner), 0, active)
    cost = ca.sumsqr(ca.repmat(weights, 1, inner + 1) * steps)
    options = knot_nlp_options(solver_spec)
    options.update(knot_derivatives(x, ca.vec(ends), cost, g, [rows]))
    solver = ca.nlpsol("transfer", "ipopt", {"x": ca.vec(x), "p": ca.vec(ends), "f": cost, "g": g}, options)
    lower, upper = (np.tile(bound, inner) for bound in knot_bounds(cell.robot))
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
