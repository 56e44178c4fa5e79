"""Flying captures (docs/design.md §6): the path through all the landmarks timed as one motion that
never stops at a capture, passing each landmark slowly enough that the light's motion during the
camera's exposure stays within the blur tolerances.

**Path.** One not-a-knot cubic spline q(s) through the knots of every segment over the cumulative
chord parameter s (rad), the landmarks among its knots (each segment's waypoints first merged and
kept within the joint bounds by :func:`~optlight.planning.chord.chord_path`, the whole spline then
kept within them the same way). Unlike the stop mode's spline per segment, it is C² through the
landmarks: q′ and q″ have no corner there, so the robot can pass a landmark at a non-zero speed with
continuous q̇ and q̈. Where the joint path turns sharply at a landmark (:data:`CORNER_DEG`) the path
is split into two such splines and the arm passes that landmark at rest.

**Speed at a capture.** With p(q) the light's position and O the object's centre, the light moves at
v = |p′(s)| ṡ (m/s) and turns about O at ω = |(I − d dᵀ) p′(s)| ṡ / |p − O| (rad/s),
d = (p − O)/|p − O|; p′ = dp/ds by a central difference of the forward kinematics. During an exposure
of T s the light moves about v T and turns about ω T, so the path speed at landmark k is capped at

    c_k = :data:`SPEED_MARGIN` · min(blur_rad / (T |ω′|), blur_m / (T |p′|)),

ω′ = ω/ṡ; the margin covers the speed and direction changing within the exposure (ṡ changes by at
most J T²/8 around a landmark, where s̈ = 0). The first and the last capture are taken at rest (the
approach ends and the retreat starts there).

**Timing.** The path is cut at its knots, each knot interval in :data:`SUBDIVISIONS` pieces. Each
piece k gets its own bounds (V_k, A_k, J_k) from its derivative maxima
(:func:`~optlight.planning.jerk.path_bounds`, so every joint keeps its limits wherever ṡ ≤ V_k on
it) and is timed by ruckig's time-optimal jerk-limited profile from (ṡ, s̈) = (c_k, 0) to
(c_{k+1}, 0), ṡ ≥ 0. At a cut both pieces have ṡ = c_k and s̈ = 0, so q̇ = q′ṡ and q̈ = q″ṡ² + q′s̈
are continuous. The cut speeds: c_k at most the V of both pieces around it, 0 at the ends, at most
the blur cap at a landmark, then lowered by a forward and a backward pass until every piece can
change from one end speed to the other within :data:`LENGTH_MARGIN` of its length
(:func:`speed_change_distance`). Where ruckig still finds no profile, both end speeds of the piece
are halved and the path timed again. A piece's bounds are the shortest rest-to-rest profile over
:data:`REFERENCE_LENGTHS` lengths of its segment: a choice, sound whatever it is, that favours speed
over acceleration; the bounds follow the path's curvature piece by piece, which is what makes the
motion faster than stopping (one profile per segment, as the stop mode times it, is limited
everywhere by the segment's sharpest point, and a corner of the joint path sits at every landmark).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline

from optlight.errors import SolverError
from optlight.motion import Exposure, Piece, Trajectory, assemble_trajectory, positive_limits
from optlight.planning.chord import (
    MAX_BULGE_REFINEMENTS,
    as_bounds,
    chord_parameter,
    chord_path,
    spline_position_range,
)
from optlight.planning.jerk import JerkLimitedMotion, derivative_maxima, path_bounds
from optlight.spec.trajectory import TrajectorySpec

__all__ = ["CORNER_DEG", "SPEED_MARGIN", "capture_speed_caps", "corner_runs", "exposure_of", "flying_path", "flying_timing", "speed_change_distance"]

Array = NDArray[np.float64]
LightPositions = Callable[[Array], Array]

#: Fraction of the blur-limited path speed planned at a capture (module docstring).
SPEED_MARGIN = 0.9
#: Largest number of times the end speeds of a piece are halved when ruckig finds no profile.
MAX_SPEED_HALVINGS = 30
#: Pieces each knot interval of the capture path is timed in: the derivative maxima of a shorter
#: piece are smaller, so the path speed follows the curvature more closely.
SUBDIVISIONS = 4
#: Length, in lengths of its segment, over which a piece's bounds are chosen for the shortest
#: rest-to-rest duration (:func:`~optlight.planning.jerk.path_bounds`): longer favours speed over
#: acceleration, as passing through a landmark does.
REFERENCE_LENGTHS = 4.0
#: Landmarks where the joint path turns by more than this (deg) are passed at rest
#: (:func:`corner_runs`): a C² spline through a sharp corner bends over whole knot intervals around
#: it and would slow the motion there more than a stop does.
CORNER_DEG = 60.0
#: Fraction of a path piece's length its speed change is planned within (ruckig's profile then
#: exists with room to spare).
LENGTH_MARGIN = 0.95
#: Step (rad of chord parameter) of the central difference of the light's position along the path.
FK_STEP = 1e-6


def exposure_of(spec: TrajectorySpec) -> Exposure:
    """The exposure and blur tolerances of a problem's ``[trajectory]`` (in s, rad and m)."""
    return Exposure(spec.exposure_s, np.deg2rad(spec.blur_deg), spec.blur_mm * 1e-3)


def corner_runs(segments: Sequence[Array]) -> list[tuple[int, int]]:
    """The segments as runs [first, last) split at every landmark where the joint path turns by more
    than :data:`CORNER_DEG` (the angle between the last chord of the segment ending there and the
    first chord of the next): there the arm stops, each run gets its own spline."""
    cuts = [0]
    for k in range(1, len(segments)):
        before, after = segments[k - 1][-1] - segments[k - 1][-2], segments[k][1] - segments[k][0]
        norms = np.linalg.norm(before) * np.linalg.norm(after)
        if norms > 0 and np.dot(before, after) < np.cos(np.deg2rad(CORNER_DEG)) * norms:
            cuts.append(k)
    cuts.append(len(segments))
    return list(zip(cuts[:-1], cuts[1:], strict=True))


def flying_path(
    segments: Sequence[Array], position_bounds: tuple[Array, Array] | None
) -> tuple[CubicSpline, NDArray[np.intp]] | None:
    """The spline q(s) through every segment's knots (module docstring) and the knot index of each of
    the M landmarks; None when all the landmarks coincide."""
    knots: list[Array] = [segments[0][:1]]
    landmark = [0]
    for w in segments:
        chord = chord_path(w, position_bounds)
        if chord is not None:
            knots.append(chord[1][1:])
        landmark.append(landmark[-1] + (0 if chord is None else len(chord[1]) - 1))
    w_all = np.vstack(knots)
    if len(w_all) < 2:
        return None
    index = np.asarray(landmark, np.intp)
    lower, upper = position_bounds if position_bounds is not None else (-np.inf, np.inf)
    for _ in range(MAX_BULGE_REFINEMENTS if position_bounds is not None else 0):
        low, high = spline_position_range(chord_parameter(w_all), w_all)
        outside = np.flatnonzero(((low < lower) | (high > upper)).any(axis=1))
        if outside.size == 0:
            break
        w_all = np.insert(w_all, outside + 1, 0.5 * (w_all[outside] + w_all[outside + 1]), axis=0)
        index = index + np.searchsorted(outside, index, side="left")
    return CubicSpline(chord_parameter(w_all), w_all, bc_type="not-a-knot"), index


def _subdivided(knots: Array, parts: int) -> Array:
    """The knots with every interval cut into ``parts`` equal intervals."""
    fractions = np.arange(parts) / parts
    inner = knots[:-1, None] + np.diff(knots)[:, None] * fractions[None]
    return np.append(inner.ravel(), knots[-1])


def _between(path: CubicSpline, a: float, b: float) -> CubicSpline:
    """The spline on [a, b] (inside one of its intervals) as a one-interval spline on [0, b − a]:
    the cubic's Taylor coefficients at a."""
    d = [np.asarray(path(a, nu), float) for nu in range(4)]
    c = np.stack([d[3] / 6.0, d[2] / 2.0, d[1], d[0]])[:, None, :]
    return CubicSpline.construct_fast(c, np.array([0.0, b - a]))


def capture_speed_caps(
    path: CubicSpline, s: Array, light_positions: LightPositions, center: ArrayLike, exposure: Exposure
) -> Array:
    """Largest path speeds ṡ (rad/s) at the path parameters ``s`` (P,) that keep the blur of an
    exposure within its tolerances, :data:`SPEED_MARGIN` included (module docstring)."""
    s = np.asarray(s, float)
    if s.size == 0:
        return np.zeros(0)
    lo, hi = float(path.x[0]), float(path.x[-1])
    ahead, behind = np.minimum(s + FK_STEP, hi), np.maximum(s - FK_STEP, lo)
    p_plus, p_minus, p = (light_positions(path(x)) for x in (ahead, behind, s))
    dp = (p_plus - p_minus) / (ahead - behind)[:, None]  # dp/ds (m/rad)
    r = p - np.asarray(center, float)
    dist = np.linalg.norm(r, axis=1)
    d = r / dist[:, None]
    turn = np.linalg.norm(dp - d * np.sum(dp * d, axis=1, keepdims=True), axis=1) / dist  # dω/dṡ
    move = np.linalg.norm(dp, axis=1)
    with np.errstate(divide="ignore"):
        cap = np.minimum(exposure.blur_rad / (exposure.seconds * turn), exposure.blur_m / (exposure.seconds * move))
    return SPEED_MARGIN * cap


def flying_timing(
    segments: Sequence[ArrayLike],
    velocity_limit: ArrayLike,
    acceleration_limit: ArrayLike,
    jerk_limit: ArrayLike,
    *,
    light_positions: LightPositions,
    center: ArrayLike,
    exposure: Exposure,
    joint_names: Sequence[str] | None = None,
    approach: ArrayLike | None = None,
    retreat: ArrayLike | None = None,
    position_bounds: tuple[ArrayLike, ArrayLike] | None = None,
) -> Trajectory:
    """Time the path through the landmarks without stopping at them (module docstring): rest at the
    first and the last landmark only, each other landmark passed at most at its blur-limited speed,
    |q̇_j| ≤ velocity_limit_j, |q̈_j| ≤ acceleration_limit_j, |q⃛_j| ≤ jerk_limit_j everywhere.
    Every landmark's dwell has zero length: the trajectory's capture time is when the light is there.

    Args:
        segments, approach, retreat, position_bounds, joint_names: as for
            :func:`optlight.planning.jerk.jerk_limited_timing` (the approach and the retreat are
            timed rest to rest, as there).
        light_positions: joint angles (P, n) (rad) -> the light's positions (P, 3) (m, world).
        center: the object's centre O (3,) (m, world), which the blur angle is measured about.
        exposure: the exposure time and the blur tolerances.

    Raises ValueError for bad inputs and :class:`SolverError` when ruckig fails on a segment.
    """
    waypoints = [np.asarray(w, float) for w in segments]
    n = waypoints[0].shape[1] if waypoints and waypoints[0].ndim == 2 else 0
    vmax = positive_limits(velocity_limit, n, "velocity_limit")
    amax = positive_limits(acceleration_limit, n, "acceleration_limit")
    jmax = positive_limits(jerk_limit, n, "jerk_limit")
    bounds = None if position_bounds is None else as_bounds(position_bounds)
    lone = len(waypoints) == 1 and waypoints[0].shape[0] == 1
    motions: dict[int, Piece] = {}
    for first, last in [] if lone else corner_runs(waypoints):
        built = flying_path(waypoints[first:last], bounds)
        if built is not None:
            timed = _capture_motions(*built, (vmax, amax, jmax), light_positions, center, exposure)
            motions |= {first + i: motion for i, motion in timed.items()}

    def segment(index: int, w: Array, n: int) -> Piece | None:
        if 0 <= index < len(waypoints) and not lone:
            return motions.get(index)
        chord = chord_path(w, bounds)  # the approach or the retreat, rest to rest
        if chord is None:
            return None
        path = CubicSpline(chord[0], chord[1], bc_type="not-a-knot")
        return JerkLimitedMotion(path, path_bounds(derivative_maxima(path), float(chord[0][-1]), vmax, amax, jmax), index)

    return assemble_trajectory(waypoints, 0.0, segment, joint_names, approach=approach, retreat=retreat)


def _capture_motions(
    path: CubicSpline,
    landmark: NDArray[np.intp],
    limits: tuple[Array, Array, Array],
    light_positions: LightPositions,
    center: ArrayLike,
    exposure: Exposure,
) -> dict[int, Piece]:
    """The timed motion of each segment with motion, by segment index (module docstring)."""
    knots = np.asarray(path.x, float)
    x = _subdivided(knots, SUBDIVISIONS)
    landmark = landmark * SUBDIVISIONS
    pieces = [_between(path, a, b) for a, b in zip(x[:-1], x[1:], strict=True)]
    segment_of = np.searchsorted(landmark, np.arange(x.size - 1), side="right") - 1
    reference = REFERENCE_LENGTHS * (x[landmark[1:]] - x[landmark[:-1]])
    bounds = np.array(
        [path_bounds(derivative_maxima(p), float(reference[segment_of[k]]), *limits) for k, p in enumerate(pieces)]
    )  # (P, 3): V, A, J of each piece
    speed = np.minimum(np.r_[0.0, bounds[:, 0]], np.r_[bounds[:, 0], 0.0])  # the ends at rest
    caps = capture_speed_caps(path, x[landmark[1:-1]], light_positions, center, exposure)
    speed[landmark[1:-1]] = np.minimum(speed[landmark[1:-1]], caps)
    speed = _reachable(speed, np.diff(x), bounds)
    for _ in range(MAX_SPEED_HALVINGS + 1):
        motions: list[JerkLimitedMotion] = []
        failed = []
        for k, p in enumerate(pieces):
            try:
                motions.append(JerkLimitedMotion(p, tuple(bounds[k]), k, speeds=(float(speed[k]), float(speed[k + 1]))))
            except SolverError:
                failed.append(k)
        if not failed:
            return {
                i: _Chain(motions[a:b]) for i, (a, b) in enumerate(zip(landmark[:-1], landmark[1:], strict=True)) if b > a
            }
        for k in failed:  # a changed end speed also changes the neighbour's: all are timed again
            speed[k : k + 2] *= 0.5
    raise SolverError(
        f"path pieces {failed}: no jerk-limited profile between the path speeds, even "
        f"{2**MAX_SPEED_HALVINGS}× slower (ruckig)"
    )


def _reachable(speed: Array, length: Array, bounds: Array) -> Array:
    """The largest path speeds at the knots, at most ``speed`` (K,), such that every piece k
    (``length`` (K − 1,), ``bounds`` (K − 1, 3)) can change from one end speed to the other within
    :data:`LENGTH_MARGIN` of its length (:func:`speed_change_distance`): a forward pass, then a
    backward one."""
    c = speed.copy()
    for k in range(c.size - 1):
        c[k + 1] = min(c[k + 1], _fastest(c[k], LENGTH_MARGIN * length[k], *bounds[k, 1:]))
    for k in range(c.size - 2, -1, -1):
        c[k] = min(c[k], _fastest(c[k + 1], LENGTH_MARGIN * length[k], *bounds[k, 1:]))
    return c


def speed_change_distance(u: float, w: float, a: float, j: float) -> float:
    """Distance (rad) the path covers while its speed changes from u to w (rad/s) as fast as
    |s̈| ≤ a and |s⃛| ≤ j allow, s̈ = 0 at both ends: (u + w)/2 · T, the profile being symmetric, with
    T = Δ/a + a/j when Δ = |w − u| ≥ a²/j (a is reached), else 2 √(Δ/j)."""
    d = abs(w - u)
    t = d / a + a / j if d >= a * a / j else 2.0 * np.sqrt(d / j)
    return 0.5 * (u + w) * t


def _fastest(u: float, length: float, a: float, j: float) -> float:
    """The largest speed w ≥ u reachable from u within ``length`` (:func:`speed_change_distance`,
    increasing in w), by bisection."""
    lo, hi = u, u + 1.0
    while speed_change_distance(u, hi, a, j) <= length:
        lo, hi = hi, 2.0 * hi
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if speed_change_distance(u, mid, a, j) <= length else (lo, mid)
    return lo


class _Chain:
    """Pieces one after another, as one piece (a segment timed piece by piece)."""

    def __init__(self, pieces: Sequence[Piece]) -> None:
        self._trajectory = Trajectory(pieces, np.zeros((0, 2)), np.zeros((0, 2)))

    @property
    def duration(self) -> float:
        return self._trajectory.duration

    def evaluate(self, t: Array) -> tuple[Array, Array, Array]:
        return self._trajectory.sample(t)

    def jerk(self, t: Array) -> Array:
        return self._trajectory.jerk(t)
