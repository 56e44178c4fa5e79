"""Clearance between the knots (docs/design.md §6, §8): the trajectory NLP's clearance rows hold at
its knots, the timing then moves the arm between them and the verification checks it densely. Where
the exact check (coal, the verification's model) finds the arm too close between two knots, the
segment's knots are doubled and it is solved again between its two captures' postures
(:func:`clear_between_knots`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import CubicSpline

from optlight.environment.check import EnvironmentReport, PairClearance
from optlight.errors import CaptureSolverError, SolverError
from optlight.planning.chord import chord_path
from optlight.planning.path import LightPath
from optlight.planning.trajectory.knots import optimize_knots
from optlight.planning.trajectory.optimizer import Array, TrajectoryNLPResult, joined_results, knot_cost
from optlight.spec import SolverSpec, TrajectorySpec
from optlight.workcell import Workcell

#: Most configurations per interval of the timed spline at which the exact check looks between two
#: knots (:func:`timed_between`).
BETWEEN_SAMPLES = 8
#: Largest joint step (rad) between two configurations the check looks at (fewer on short intervals).
BETWEEN_STEP_RAD = 0.04
#: Rounds of knot insertion and segment re-solves (each halves the intervals still too close).
BETWEEN_ROUNDS = 4
#: A segment solved again takes joint steps of at most this many times its knots' mean step (the
#: largest joint's): the NLP cannot leap over an obstacle between two clear knots, as the steps halve
#: with each round of added knots.
STEP_SHRINK = 3.0
#: An interval is too close when an exact distance on it is below its threshold plus this (m): the
#: verification samples the timed spline more densely than the check.
BETWEEN_PADDING_M = 1e-3
#: A sphere row this far below 0 (m) sends an interval to the exact check (the NLP's knots hold the
#: rows to IPOPT's tolerance, ~1e-9 m below).
SPHERE_TOL_M = 1e-6
#: Within the padding, an interval is too close only where it comes this much closer than its knots (m).
DIP_M = 1e-4

#: The knots the timing follows: the path and its knots with knots added on the arcs
#: (:func:`optlight.pipeline.knots_on_path`).
TimedKnots = Callable[[Workcell, LightPath, Array], tuple[LightPath, Array]]


@dataclasses.dataclass(frozen=True)
class ClearPath:
    """The trajectory NLP's path ``path``, warm start ``warm`` (K, n) and result ``nlp`` with knots
    added where the arm came too close between two knots, and what the timing follows: ``timed_path``
    and its knots ``timed_knots`` (K', n), rad."""

    path: LightPath
    warm: Array
    nlp: TrajectoryNLPResult
    timed_path: LightPath
    timed_knots: Array


def clear_between_knots(
    cell: Workcell,
    spec: TrajectorySpec,
    solver: SolverSpec,
    path: LightPath,
    warm: Array,
    nlp: TrajectoryNLPResult,
    timed: TimedKnots,
) -> ClearPath:
    """The plan's knots of ``cell``'s robot with the environment's clearance held between them, not
    only at them (``spec``, ``solver``: ``[trajectory]`` and ``[solver]``, for the segments' re-solves).

    Per round: the knots the timing follows (``timed``: the NLP's and those added on the arcs) are
    checked on the timed spline (:func:`timed_between`) between each two knots, at configurations at most
    :data:`BETWEEN_STEP_RAD` apart (:func:`too_close_between`): where the NLPs' sphere model breaks a row,
    with the exact distances of the verification (:meth:`Environment.check`, coal): below the
    threshold (margin, self margin, and the view cone with ``[view] mode = "path"``), or within
    :data:`BETWEEN_PADDING_M` of it and closer than at the knots, is too close.
    Each segment with such an interval has every interval halved (a knot at its middle) and is solved
    again by the trajectory NLP from those knots, its two captures' postures kept
    (``optimize_knots(fixed_start=True, fixed_end=True)``), each joint's step at most
    :data:`STEP_SHRINK` times the segment's mean step: the new knots carry the clearance rows, the
    step bound keeps the NLP from leaping over the obstacle again between two of them, and the rest
    of the plan is unchanged. When that NLP fails on the sphere, the segment becomes a transfer (the
    light leaves the sphere outwards, :attr:`LightPath.transfers`) solved the same way. At most
    :data:`BETWEEN_ROUNDS` rounds. Without obstacles, or when every interval clears, the path is
    returned as it is.

    Why not halve only the intervals too close: the NLP's knots are free to slide, and a knot added
    in one interval let it leap over the obstacle in the next (a Kinova's link_5 past the camera body:
    12 mm inside it after every round).

    Raises :class:`CaptureSolverError` naming the segment's captures, the link and the obstacle when
    the segment's NLP fails or the rounds run out."""
    environment, theta, results = cell.environment, nlp.theta, [nlp]
    timed_path, timed_knots = timed(cell, path, theta)
    if environment is None or not (environment.collisions or environment.view_mode == "path"):
        return ClearPath(path, warm, nlp, timed_path, timed_knots)
    rounds = 0
    while True:
        broken, worst = too_close_between(cell, timed_knots, timed_path.segments())
        if not broken.any():
            joined = nlp if len(results) == 1 else joined_results(results, theta, knot_cost(cell, theta))
            return ClearPath(path, warm, joined, timed_path, timed_knots)
        segments = np.unique(_segment_of(timed_path)[broken])
        if rounds == BETWEEN_ROUNDS:
            s = int(segments[0])
            raise CaptureSolverError(
                _message(s, worst, f"after {BETWEEN_ROUNDS} rounds of added knots"), s, s + 1
            )
        rounds += 1
        warm = _with_new_knots(timed_knots, theta, warm)
        within = np.isin(_segment_of(timed_path), segments)  # every interval of those segments
        path, theta, warm = _split(cell, timed_path, timed_knots, warm, within)
        for s in (int(s) for s in segments):
            knots = path.knots_between(s, s + 1)
            step = min(
                STEP_SHRINK * float(np.abs(np.diff(theta[knots], axis=0)).max(axis=1).mean()),
                spec.max_step_rad,
            )
            path, result = _solve_segment(cell, spec, solver, path, theta[knots], s, step, worst)
            theta = theta.copy()
            theta[knots] = result.theta
            results.append(result)
        timed_path, timed_knots = timed(cell, path, theta)


def _solve_segment(
    cell: Workcell,
    spec: TrajectorySpec,
    solver: SolverSpec,
    path: LightPath, knots: Array, segment: int, step: float, worst: PairClearance | None
) -> tuple[LightPath, TrajectoryNLPResult]:
    """The trajectory NLP over ``segment`` of ``path`` from its ``knots`` (K, n), its two captures'
    postures kept, joint steps at most ``step`` (rad): on the sphere (or off it, as the segment is);
    when that fails on the sphere, as a transfer (the light leaves the sphere outwards between the
    two captures, :attr:`LightPath.transfers`). The path (with that transfer) and the result; raises
    :class:`CaptureSolverError` (:func:`_message`) when both fail."""
    window = path.window(segment, segment + 1)
    try:
        return path, optimize_knots(cell, spec, solver, window, knots, True, fixed_end=True, max_step=step)
    except SolverError as error:
        if window.transfers[0]:
            raise CaptureSolverError(_message(segment, worst, error), segment, segment + 1) from error
    transfers = path.transfers.copy()
    transfers[segment] = True
    try:
        window = window.with_transfers([True])
        return path.with_transfers(transfers), optimize_knots(
            cell, spec, solver, window, knots, True, fixed_end=True, max_step=step
        )
    except SolverError as error:
        raise CaptureSolverError(_message(segment, worst, error), segment, segment + 1) from error


def too_close_between(
    cell: Workcell, knots: Array, segments: list[slice]
) -> tuple[NDArray[np.bool_], PairClearance | None]:
    """(K − 1,) the intervals between the ``knots`` (K, n) of ``cell``'s robot that are too close,
    and the worst such pair (None when there is none); ``segments`` the slices of the knots the
    timing follows as one spline each. A pair of bodies is too close on an interval when its exact
    distance between the two knots (where the timing takes the arm: :func:`timed_between`) is below
    its threshold, or below the threshold plus
    :data:`BETWEEN_PADDING_M` and below its distance at both knots by more than :data:`DIP_M` (the
    motion between them comes closer than the knots: between the samples it may come closer still; a pair as close at the knots, a light carried 0.7 mm beyond the self
    margin from a link by a joint that does not change it, is not).

    Only the intervals where the NLPs' sphere model (:meth:`Environment.sphere_clearance`, whose
    spheres contain the bodies) breaks a row, at a knot or between, are checked exactly (coal, two
    checks: between the knots, at them): elsewhere every sphere keeps its margin. The exact check of
    every interval of the shipped obstacle problems took 0.16–0.44 s of a 10 s solve, the spheres
    ~0.05 s."""
    if len(knots) < 2:
        return np.zeros(0, bool), None
    bounds = (cell.limits.lower, cell.limits.upper)
    between = [b for segment in segments for b in timed_between(knots[segment], bounds)]
    at_knots = _sphere_minima(cell, knots)
    inside = np.split(_sphere_minima(cell, np.vstack(between)), np.cumsum([len(b) for b in between])[:-1])
    worst = [
        _closer_between(_check(cell, b), _check(cell, knots[i : i + 2]))
        if min(at_knots[i], at_knots[i + 1], inside[i].min()) < -SPHERE_TOL_M
        else None
        for i, b in enumerate(between)
    ]
    broken = np.array([w is not None for w in worst])
    close = [w for w in worst if w is not None]
    return broken, min(close, key=lambda w: w.min_distance_m - w.threshold_m) if close else None


def _sphere_minima(cell: Workcell, thetas: Array) -> Array:
    """(T,) the smallest row of the NLPs' sphere model (clearance, and the view cone with ``[view]
    mode = "path"``; m) at each of the configurations ``thetas`` (T, n): their CasADi functions, the
    NLPs' own, mapped over the configurations."""
    environment = cell.environment
    assert environment is not None
    functions = [environment.clearance_function(cell.robot)] if environment.collisions else []
    if environment.view_mode == "path":
        functions.append(environment.view_cone_function(cell.robot, beam=False))
    values = [np.asarray(f.map(len(thetas))(thetas.T)) for f in functions if f.size1_out(0)]
    return np.min(np.vstack(values), axis=0) if values else np.full(len(thetas), np.inf)


def timed_between(knots: Array, bounds: tuple[Array, Array], step: float = BETWEEN_STEP_RAD) -> list[Array]:
    """Per interval between the waypoints ``knots`` (K, n) (rad) of one timed segment, the
    configurations (c, n) the timing passes strictly between its two knots: its geometric path, the
    not-a-knot cubic spline q(s) over the chord parameter through the knots and the midpoints
    :func:`~optlight.planning.chord.chord_path` adds where it would leave the joint ``bounds``
    (both timings follow it, docs/design.md §6), at c evenly spaced s, c = ⌈Δ / ``step``⌉ (Δ the
    largest joint's step), at least 1, at most :data:`BETWEEN_SAMPLES` per spline interval. Not
    the straight line: the spline swings past it between knots (a Kinova's finger 2.3 mm closer to
    the object than at a transfer's knots)."""
    chord = chord_path(knots, bounds)
    if chord is None:  # no motion: the knot itself
        return [knots[:1] for _ in range(len(knots) - 1)]
    s, w = chord
    spline = CubicSpline(s, w, bc_type="not-a-knot") if len(w) > 2 else None
    counts = np.clip(np.ceil(np.abs(np.diff(w, axis=0)).max(axis=1) / step).astype(int), 1, BETWEEN_SAMPLES)
    samples = [s[i] + (np.arange(1, c + 1) / (c + 1)) * (s[i + 1] - s[i]) for i, c in enumerate(counts)]
    at = _waypoint_of(knots, w)
    out = []
    for i in range(len(knots) - 1):
        where = np.concatenate(samples[at[i] : at[i + 1]] + [s[at[i] + 1 : at[i + 1]]])
        if where.size == 0:  # a knot merged with its neighbour
            out.append(knots[i : i + 1])
        elif spline is None:
            out.append(w[0] + (where / s[-1])[:, None] * (w[1] - w[0]))
        else:
            out.append(np.asarray(spline(np.sort(where))))
    return out


def _waypoint_of(knots: Array, w: Array) -> NDArray[np.int64]:
    """(K,) the index in the timed waypoints ``w`` of each of the ``knots`` (K, n): ``w`` holds every
    knot in order, the midpoints chord_path added between them, and not the knots it merged with
    the one before (those get the index of that one); the last knot is the last waypoint."""
    at, j = np.zeros(len(knots), np.int64), 0
    for i, q in enumerate(knots):
        for k in range(j, len(w)):
            if np.array_equal(w[k], q):
                j = k
                break
        at[i] = j
    at[-1] = len(w) - 1
    return at


def _check(cell: Workcell, thetas: Array) -> EnvironmentReport:
    """The verification's exact environment check of the configurations ``thetas`` (T, n), no capture
    among them."""
    assert cell.environment is not None
    return cell.environment.check(cell.robot, thetas, np.arange(len(thetas), dtype=float))


def _padded(pair: PairClearance) -> bool:
    """Whether ``pair`` comes within its threshold plus :data:`BETWEEN_PADDING_M`."""
    return pair.time_s is not None and pair.min_distance_m < pair.threshold_m + BETWEEN_PADDING_M


def _closer_between(between: EnvironmentReport, ends: EnvironmentReport) -> PairClearance | None:
    """The pair of ``between`` (an interval's samples between its knots) farthest below its threshold
    among those too close there (:func:`too_close_between`; ``ends`` the check at the two knots); None when
    no pair is."""
    at_knots = {(p.kind, p.first, p.second): p.min_distance_m for p in ends.pairs if p.time_s is not None}
    close = [
        p
        for p in between.pairs
        if p.time_s is not None
        and (
            p.min_distance_m < p.threshold_m
            or (_padded(p) and p.min_distance_m < at_knots.get((p.kind, p.first, p.second), np.inf) - DIP_M)
        )
    ]
    return min(close, key=lambda p: p.min_distance_m - p.threshold_m) if close else None


def _segment_of(path: LightPath) -> NDArray[np.int64]:
    """(K − 1,) the segment (visiting order: segment s from capture s to s + 1) of each interval
    between ``path``'s K knots."""
    return np.searchsorted(path.landmark_knots, np.arange(path.n_knots - 1), side="right") - 1


def _with_new_knots(timed_knots: Array, theta: Array, warm: Array) -> Array:
    """The warm start (K', n) of the timed knots (K', n): ``warm`` (K, n) at the knots ``theta`` (K, n)
    they hold (in order, the same angles), the timed knot itself at a knot added on an arc (found by
    the generalized IK: a per-knot IK)."""
    out, k = timed_knots.copy(), 0
    for i, q in enumerate(timed_knots):
        if k < len(theta) and np.array_equal(q, theta[k]):
            out[i], k = warm[k], k + 1
    return out


def _split(
    cell: Workcell, path: LightPath, theta: Array, warm: Array, broken: NDArray[np.bool_]
) -> tuple[LightPath, Array, Array]:
    """``path``, its knots ``theta`` and warm start ``warm`` (K, n) with a knot at the middle (in joint
    space) of each interval in ``broken`` (K − 1,): its light's direction, position and rotation (the
    NLP pins only the captures' lights), its warm start the middle itself."""
    at = np.flatnonzero(broken) + 1
    middles = 0.5 * (theta[at - 1] + theta[at])
    poses = [cell.robot.light_pose(q) for q in middles]
    positions = np.array([a for a, _ in poses])
    offsets = positions - cell.sphere.center
    directions = offsets / np.linalg.norm(offsets, axis=1, keepdims=True)
    rotations = np.array([r for _, r in poses])
    shift = np.searchsorted(at, path.landmark_knots, side="right")  # new knots before each capture
    refined = dataclasses.replace(
        path,
        directions=np.insert(path.directions, at, directions, axis=0),
        positions=np.insert(path.positions, at, positions, axis=0),
        rotations=np.insert(path.rotations, at, rotations, axis=0),
        landmark_knots=(path.landmark_knots + shift).astype(np.int64),
    )
    return refined, np.insert(theta, at, middles, axis=0), np.insert(warm, at, middles, axis=0)


def _message(segment: int, worst: PairClearance | None, why: SolverError | str) -> str:
    """The one line of a segment whose clearance between knots could not be made to hold: after
    :data:`BETWEEN_ROUNDS` rounds (``why`` a sentence) or with the NLP failing (``why`` its error)."""
    where = (
        f"{worst.first} comes {worst.min_distance_m * 1e3:.1f} mm from {worst.second} "
        f"(allowed {worst.threshold_m * 1e3:.1f} mm) between knots"
        if worst is not None
        else "the arm comes too close between knots"
    )
    reason = (
        why
        if isinstance(why, str)
        else f"and the trajectory NLP found no way around, on the sphere or off it ({why})"
    )
    return (
        f"between captures {segment} and {segment + 1} (visiting order): {where} {reason}; move the "
        "obstacle, lower [environment] margin_m or choose other captures"
    )
