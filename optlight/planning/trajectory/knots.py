"""Solving the trajectory NLP over a path (docs/design.md §6): :func:`optimize_knots` with its
active clearance rows, a first try on a budget and a retry from a small barrier when the warm start
is on the sphere.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from optlight.errors import IPOPT_ITERATION_LIMIT, SolverError, iteration_limit_error
from optlight.planning.path import LightPath
from optlight.planning.trajectory.active_rows import rows_of, solve_active_rows
from optlight.planning.trajectory.optimizer import Array, TrajectoryNLPResult, TrajectoryOptimizer
from optlight.robot import light_residual
from optlight.spec import SolverSpec, TrajectorySpec
from optlight.workcell import Workcell

#: Most IPOPT iterations of the trajectory NLP's first try when a second try or the caller's fallback
#: can follow it (:func:`optimize_knots`; fewer when ``[solver] max_iter`` is smaller).
FIRST_TRY_ITER = 120


def optimize_knots(
    cell: Workcell,
    spec: TrajectorySpec,
    solver: SolverSpec,
    path: LightPath,
    warm: Array,
    fixed_start: bool = False,
    *,
    fallback: bool = False,
    fixed_end: bool = False,
    max_step: float | None = None,
) -> TrajectoryNLPResult:
    """The trajectory NLP (``spec``: ``[trajectory]``'s path mode and step; ``solver``: IPOPT's
    settings) of ``cell``'s robot over the path's knots, warm-started at the per-knot IK ``warm`` (K, n),
    the first knot kept at its ``warm`` angles with ``fixed_start``, the last with ``fixed_end``,
    each joint's step between two knots at most ``max_step`` (rad; None: ``[trajectory]
    max_step_rad``) (the last two: a segment solved again between two postures the plan keeps,
    :func:`~optlight.planning.trajectory.clear_between_knots`); ``fallback``: the caller has
    another way to go when this one fails (:func:`~optlight.planning.trajectory.windows.optimize_window`'s transfers,
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
    retries that fail are windows the fallbacks of :func:`~optlight.planning.trajectory.windows.optimize_window` then
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
    can_retry = not fallback and _warm_start_on_sphere(cell, path, warm)
    first_budget = FIRST_TRY_ITER if can_retry or fallback else None
    first = _active_rounds(
        cell, spec, solver, path, warm, fixed_start, retry=False, max_iter=first_budget, fixed_end=fixed_end,
        max_step=max_step,
    )
    retry = not first.success and can_retry
    nlp = (
        _active_rounds(cell, spec, solver, path, warm, fixed_start, retry=True, fixed_end=fixed_end, max_step=max_step)
        if retry
        else first
    )
    iterations = first.iterations + (0 if nlp is first else nlp.iterations)
    time_s = first.time_s + (0.0 if nlp is first else nlp.time_s)
    nlp = dataclasses.replace(nlp, iterations=iterations, time_s=time_s)
    if not nlp.success and nlp.status == IPOPT_ITERATION_LIMIT:
        raise iteration_limit_error("the trajectory NLP", solver.max_iter)
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


def _warm_start_on_sphere(cell: Workcell, path: LightPath, warm: Array) -> bool:
    """Whether ``warm`` (K, n) holds the light on the sphere, pointing at O, to :data:`WARM_H_TOL`
    at every knot of ``path`` that the NLP keeps there (:meth:`LightPath.on_sphere`)."""
    return all(
        np.abs(light_residual(cell.robot, cell.sphere, theta)).max() <= WARM_H_TOL
        for theta in warm[path.on_sphere()]
    )


def _active_rounds(
    cell: Workcell,
    spec: TrajectorySpec,
    solver: SolverSpec,
    path: LightPath,
    warm: Array,
    fixed_start: bool,
    retry: bool,
    max_iter: int | None = None,
    fixed_end: bool = False,
    max_step: float | None = None,
) -> TrajectoryNLPResult:
    """The solves of :func:`optimize_knots` with the active clearance rows (:func:`solve_active_rows`),
    from ``warm``, with the ``retry`` settings of :class:`TrajectoryOptimizer` or not and at most
    ``max_iter`` iterations each (None: ``[solver] max_iter``), the last knot kept with ``fixed_end``, joint steps at most ``max_step`` (None: ``[trajectory]
    max_step_rad``); the last solve, with the iterations
    and time of all."""
    env = cell.environment
    solves: list[TrajectoryNLPResult] = []

    def solve(active: NDArray[np.bool_] | None, start: Array) -> tuple[TrajectoryNLPResult, Array | None]:
        rows = None if active is None else rows_of(active)
        optimizer = TrajectoryOptimizer(
            cell.robot,
            path_mode=spec.path,
            max_step=spec.max_step_rad if max_step is None else max_step,
            joint_weights=1.0 / cell.limits.velocity**2,
            clearance=env.clearance_function(cell.robot, rows) if env and env.collisions else None,
            active=None if active is None else active[:, rows],
            view=env.view_cone_function(cell.robot) if env and env.view_cone else None,
            view_mode=env.view_mode if env else "capture",
            solver=solver,
            retry=retry,
            max_iter=max_iter,
        )
        solves.append(optimizer.solve(path, cell.sphere, start, fixed_start, fixed_end))
        return solves[-1], solves[-1].theta if solves[-1].success else None

    nlp = solve_active_rows(cell, warm, solve)
    return dataclasses.replace(
        nlp, iterations=sum(s.iterations for s in solves), time_s=sum(s.time_s for s in solves)
    )
