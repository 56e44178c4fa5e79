"""The trajectory NLP window by window (docs/design.md §6): a path of many captures is solved in
windows of about :data:`NLP_WINDOW_KNOTS` knots cut at captures, each from the posture the one before
ended at; a window that finds no way is solved again with the one before it, then with its segments
as transfers (the light off the sphere), and only then does the pipeline drop its hardest capture
(:func:`hardest_capture`, ``[landmarks] allow_partial``).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

import numpy as np
from numpy.typing import NDArray

from optlight.errors import CaptureSolverError, SolverError
from optlight.planning.path import LightPath
from optlight.planning.policy import knot_ik
from optlight.planning.trajectory.knots import optimize_knots
from optlight.planning.trajectory.optimizer import Array, TrajectoryNLPResult, joined_results, knot_cost
from optlight.spec import SolverSpec, TrajectorySpec
from optlight.workcell import Workcell

#: Knots per window of the trajectory NLP (:func:`optimize_path`).
NLP_WINDOW_KNOTS = 48


def optimize_path(
    cell: Workcell,
    spec: TrajectorySpec,
    solver: SolverSpec,
    path: LightPath,
    warm: Array,
    failures: NDArray[np.int64],
    landmark_thetas: Array,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[LightPath, Array, TrajectoryNLPResult]:
    """The trajectory NLP of ``cell``'s robot (``spec``: ``[trajectory]``, ``solver``: ``[solver]``),
    window by window along the path (:meth:`LightPath.windows`, about
    :data:`NLP_WINDOW_KNOTS` knots each, cut at captures), warm-started at the per-knot IK ``warm``
    (K, n); a window starts at the posture the window before it ended at (its first knot fixed,
    :func:`optimize_window`), and where it finds no way from there, it is solved again together with
    the window before it. Returns the path (with the transfers the windows needed), its warm start
    and the NLP's result over all knots; raises :class:`SolverError` naming the captures of the
    window that failed (:class:`CaptureSolverError`). ``progress(done, total)`` after each window.

    Why windows: one NLP over all knots needs as many iterations as its hardest stretch needs, for
    every knot; on the scaling benchmark's 576 captures among 3 obstacles it did not converge in
    300 iterations (15 min). The price is that a window's end does not see the next window's path."""
    windows = path.windows(NLP_WINDOW_KNOTS)
    theta, warm, transfers = warm.copy(), warm.copy(), path.transfers.copy()
    results: list[TrajectoryNLPResult] = []
    for done, (first, last) in enumerate(windows):
        attempts = [(first, False)] if done == 0 else [(first, True), (windows[done - 1][0], done > 1)]
        attempts.append((first, done > 0))  # last: every segment of the window a transfer
        for attempt, (start, fixed) in enumerate(attempts):
            knots, window = path.knots_between(start, last), path.window(start, last)
            postures, initial, missed = landmark_thetas[start : last + 1].copy(), warm[knots], failures[start:last]
            if fixed:  # from the posture the window before ended at
                postures[0] = theta[knots.start]
                initial, missed = knot_ik(cell, window, postures)
            try:
                window, warm_window, result = optimize_window(
                    cell, spec, solver, window, initial, missed, postures, fixed, attempt == len(attempts) - 1
                )
                break
            except SolverError as e:
                error = e
        else:
            raise CaptureSolverError(
                f"between captures {first} and {last} (visiting order): {error}", first, last
            ) from error
        warm[knots], theta[knots], transfers[start:last] = warm_window, result.theta, window.transfers
        results.append(result)
        if progress is not None:
            progress(done + 1, len(windows))
    return path.with_transfers(transfers), warm, joined_results(results, theta, knot_cost(cell, theta))


def optimize_window(
    cell: Workcell,
    spec: TrajectorySpec,
    solver: SolverSpec,
    path: LightPath,
    warm: Array,
    failures: NDArray[np.int64],
    landmark_thetas: Array,
    fixed_start: bool = False,
    transfer_all: bool = False,
) -> tuple[LightPath, Array, TrajectoryNLPResult]:
    """The trajectory NLP on the sphere (the paper's path) over the knots of ``path``, warm-started
    at the per-knot IK ``warm`` (K, n) through the capture postures ``landmark_thetas`` (M, n), its
    first knot kept at ``warm`` with ``fixed_start``; when it fails, the segments that IK could not
    follow (:func:`unfollowed_segments`) become transfers: the light leaves the sphere between their
    captures, the arm moving in joint space (:attr:`LightPath.transfers`, warm-started on the
    straight line between the captures' postures), and the NLP runs again. With ``transfer_all``,
    every segment is a transfer, without a try on the sphere. Returns the path, its warm start and
    the NLP's result; raises :class:`SolverError` when the NLP fails with no such segment, or again.
    Where there are such segments, the solve on the sphere is told the transfers can follow
    (``optimize_knots(fallback=True)``: a short first try, no small-barrier retry).

    Why ``transfer_all``: a window whose captures the placement found clear and whose arcs IK
    followed can still have no way on the sphere at the NLP's step bound and sphere rows; off it,
    the arm goes from one clear posture to the next, and the capture that would otherwise be
    dropped is kept."""
    nlp = partial(optimize_knots, cell, spec, solver)
    if transfer_all:
        path = path.with_transfers(np.ones_like(path.transfers))
        warm, _ = knot_ik(cell, path, landmark_thetas)
        return path, warm, nlp(path, warm, fixed_start)
    unfollowed = unfollowed_segments(cell, spec, path, warm, failures)
    try:
        return path, warm, nlp(path, warm, fixed_start, fallback=bool(unfollowed.any()))
    except SolverError:
        if not unfollowed.any():
            raise
    path = path.with_transfers(unfollowed)
    warm, _ = knot_ik(cell, path, landmark_thetas)
    return path, warm, nlp(path, warm, fixed_start)


def hardest_capture(landmark_thetas: Array, first: int, last: int) -> int:
    """Of the captures ``first`` … ``last`` (visiting order) with postures ``landmark_thetas`` (M, n),
    rad, the one whose posture is farthest from its neighbours' (Σ over the segments before and after
    it of the largest joint's change): the capture the trajectory NLP drops first when it finds no way
    through them (``[landmarks] allow_partial``)."""
    steps = np.abs(np.diff(landmark_thetas, axis=0)).max(axis=1, initial=0.0)
    around = np.concatenate([[0.0], steps]) + np.concatenate([steps, [0.0]])
    return first + int(np.argmax(around[first : last + 1]))


def unfollowed_segments(
    cell: Workcell, spec: TrajectorySpec, path: LightPath, warm: Array, failures: NDArray[np.int64]
) -> NDArray[np.bool_]:
    """(M − 1,) the segments whose arc the per-knot IK ``warm`` (K, n) did not follow: where it missed
    a knot (``failures`` (M − 1,)), jumped further than ``spec.max_step_rad`` between two
    knots (to another IK branch) or, with obstacles, put the arm into one at a knot (a clearance row
    of the NLPs' sphere model below 0)."""
    segments, environment = path.segments(), cell.environment
    jumps = np.array([np.abs(np.diff(warm[s], axis=0)).max() for s in segments])
    unfollowed = (failures > 0) | (jumps > spec.max_step_rad)
    if environment is not None and environment.collisions:
        clearance = np.array([environment.sphere_clearance(cell.robot, q)[0].min() for q in warm])
        unfollowed |= np.array([clearance[s].min() < 0.0 for s in segments], dtype=bool)  # none: (0,) bool
    return unfollowed
