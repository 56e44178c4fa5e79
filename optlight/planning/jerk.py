"""Jerk-limited timing of the path through the landmarks: continuous acceleration, bounded jerk.

TOPPRA's constant-acceleration parametrization (:mod:`optlight.planning.timing`) is time-optimal but
its acceleration steps between gridpoints: unbounded jerk, which a Franka controller refuses
(``joint_motion_generator_acceleration_discontinuity``) and which ROS 2's quintic interpolation
cannot follow. Here every landmark-to-landmark segment, which starts and ends at rest, is timed by a
jerk-limited profile of its path parameter, computed by ruckig (its free version plans state to state,
which is all a rest-to-rest segment needs; docs/design.md §7).

**Path.** The same geometric path as TOPPRA's: the not-a-knot cubic spline q(s) through the
waypoints over the cumulative chord length s ∈ [0, L] (:func:`optlight.planning.chord.chord_path`).
It is C²: q″ is continuous, q‴ is constant between knots.

**Profile.** s(t) rest to rest from 0 to L with 0 ≤ ṡ ≤ V, |s̈| ≤ A, |s⃛| ≤ J (ruckig's time-optimal
seven-phase profile; s̈ is continuous and piecewise linear). Then

    q̇ = q′ ṡ,   q̈ = q″ ṡ² + q′ s̈,   q⃛ = q‴ ṡ³ + 3 q″ ṡ s̈ + q′ s⃛,

so q̈ is continuous (q″ and s̈ are) and, with D_k,j = max over the segment of |q_j^(k)(s)|, every
joint keeps its limits everywhere (not only at samples) when

    D1_j V ≤ v_j,    D2_j V² + D1_j A ≤ a_j,    D3_j V³ + 3 D2_j V A + D1_j J ≤ j_j.

The maxima are exact: on each spline interval q′ is a quadratic (its extremum is at an end or at its
vertex), q″ is linear (at an end) and q‴ constant.

**Choosing V, A, J.** The conditions leave two degrees of freedom: the speed V and how the acceleration
budget a_j − D2_j V² is split between A and the jerk budget. For each V on a grid of
:data:`GRID` values in (0, V_max] and each A = f·A_max(V), f on a grid of :data:`GRID` fractions of
the largest A the second condition allows, J is the largest the third allows; the triple whose
rest-to-rest duration (:func:`rest_to_rest_duration`, closed form) is shortest is kept. Every triple on
the grid satisfies the three conditions, so the choice is sound whatever the grid; the grid only
decides how close to the best single profile it gets.

**Cost.** One profile per segment is conservative where the path's curvature varies: V is limited by
the sharpest point of the segment everywhere along it. The benchmark (``benchmarks/bench_timing.py``)
reports the motion time next to TOPPRA's. A profile of ṡ that varies along s (third-order TOPP) would
be faster and is not attempted here: no maintained Python library solves it, and the single profile is
sound by construction, which a smoothed TOPPRA profile is not.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import ruckig
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline

from optlight.errors import SolverError
from optlight.motion import Trajectory, assemble_trajectory, positive_limits
from optlight.planning.chord import as_bounds, chord_path

Array = NDArray[np.float64]

#: Grid size per parameter (V and the split of the acceleration budget) when choosing the bounds.
GRID = 48


def derivative_maxima(path: CubicSpline) -> tuple[Array, Array, Array]:
    """(D1, D2, D3), each (n,): the exact maxima over the spline's whole domain of |q′_j|, |q″_j|,
    |q‴_j| of a cubic spline q(s) (module docstring)."""
    c = np.asarray(path.c, float)  # (4, m, n): q = c0 τ³ + c1 τ² + c2 τ + c3, τ = s − s_i
    h = np.diff(path.x)[:, None]
    d1_ends = np.maximum(np.abs(c[2]), np.abs(3 * c[0] * h**2 + 2 * c[1] * h + c[2]))
    with np.errstate(divide="ignore", invalid="ignore"):
        vertex = np.where(c[0] != 0, -c[1] / (3 * c[0]), -1.0)
    inside = (vertex > 0) & (vertex < h)
    d1_vertex = np.where(inside, np.abs(c[2] - c[1] ** 2 / np.where(c[0] != 0, 3 * c[0], 1.0)), 0.0)
    d1 = np.maximum(d1_ends, d1_vertex).max(axis=0)
    d2 = np.maximum(np.abs(2 * c[1]), np.abs(6 * c[0] * h + 2 * c[1])).max(axis=0)
    d3 = np.abs(6 * c[0]).max(axis=0)
    return d1, d2, d3


def rest_to_rest_duration(length: ArrayLike, v: ArrayLike, a: ArrayLike, j: ArrayLike) -> Array:
    """Shortest time (s) to move a distance ``length`` from rest to rest with |ṡ| ≤ v, |s̈| ≤ a,
    |s⃛| ≤ j (the double-S profile; arrays broadcast).

    Reaching speed w from rest takes T_a(w) = w/a + a/j over w T_a/2 when w ≥ a²/j (the acceleration
    limit is reached), else 2√(w/j) over w√(w/j). When 2 d(v) ≤ length the profile cruises at v:
    T = 2 T_a(v) + (length − 2 d(v))/v; else it peaks at the w with 2 d(w) = length and T = 2 T_a(w).
    """
    length, v, a, j = np.broadcast_arrays(*(np.asarray(x, float) for x in (length, v, a, j)))

    def ramp(w: Array) -> tuple[Array, Array]:
        full = w >= a**2 / j
        t_a = np.where(full, w / a + a / j, 2 * np.sqrt(w / j))
        return t_a, 0.5 * w * t_a

    t_v, d_v = ramp(v)
    cruise = 2 * d_v <= length
    # peak speed without cruise: with the acceleration limit reached, w²/a + w a/j = length
    w_full = 0.5 * (-(a**2) / j + np.sqrt(a**4 / j**2 + 4 * a * length))
    w_tri = (0.5 * length * np.sqrt(j)) ** (2.0 / 3.0)
    w = np.where(w_full >= a**2 / j, w_full, w_tri)
    t_w, _ = ramp(np.minimum(w, v))
    return np.where(cruise, 2 * t_v + (length - 2 * d_v) / v, 2 * t_w)


def rest_to_rest_moves(
    postures: ArrayLike, velocity_limit: ArrayLike, acceleration_limit: ArrayLike, jerk_limit: ArrayLike
) -> Array:
    """(P − 1,) the shortest times (s) of the moves between consecutive postures (P, n) (rad), each
    from rest to rest under |q̇_j| ≤ v_j, |q̈_j| ≤ a_j, |q⃛_j| ≤ j_j: ruckig's time-optimal multi-joint
    state-to-state trajectory, which from rest to rest takes the slowest joint's double-S time.

    A lower bound on any motion through the same postures in the same order that stops at each of
    them, whatever its path: a path between two postures is at least as long in every joint as the
    straight one, and a joint's double-S profile is the fastest way over a distance."""
    q = np.asarray(postures, float)
    if q.ndim != 2 or q.shape[0] < 1:
        raise ValueError(f"postures must be a (P, n) array, got shape {q.shape}")
    n = q.shape[1]
    vmax, amax, jmax = (
        positive_limits(x, n, name)
        for x, name in ((velocity_limit, "velocity_limit"), (acceleration_limit, "acceleration_limit"), (jerk_limit, "jerk_limit"))
    )
    otg = ruckig.Ruckig(n)
    inp = ruckig.InputParameter(n)
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = vmax.tolist(), amax.tolist(), jmax.tolist()
    inp.current_velocity = inp.current_acceleration = inp.target_velocity = inp.target_acceleration = [0.0] * n
    out = np.zeros(max(q.shape[0] - 1, 0))
    for k in range(out.size):
        inp.current_position, inp.target_position = q[k].tolist(), q[k + 1].tolist()
        trajectory = ruckig.Trajectory(n)
        result = otg.calculate(inp, trajectory)
        if result not in (ruckig.Result.Working, ruckig.Result.Finished):
            raise SolverError(f"move {k}: ruckig returned {result}")
        out[k] = trajectory.duration
    return out


def nonstop_bound(postures: ArrayLike, velocity_limit: ArrayLike, acceleration_limit: ArrayLike) -> float:
    """A lower bound (s) on the time of any motion through the postures (P, n) (rad) in their order,
    from rest at the first to rest at the last, whatever its path and its speeds at the postures in
    between, under |q̇_j| ≤ v_j and |q̈_j| ≤ a_j: the larger of

    - Σ_k max_j |q_{k+1,j} − q_{k,j}| / v_j: no joint moves faster than its limit on any move;
    - max_j Σ_r T_j(D_r): where the sequence of joint j's positions turns, the joint reaches an
      extremum at least as far, with zero velocity, so its motion holds rest-to-rest moves over at
      least the distances D_r between consecutive turns (the first and last posture included), one
      after the other, each taking at least T_j(D) = D/v_j + v_j/a_j when D ≥ v_j²/a_j, else 2√(D/a_j)
      (bang-bang; the jerk limit is left out, since at a turn the acceleration need not be zero).
    """
    q = np.asarray(postures, float)
    if q.ndim != 2 or q.shape[0] < 1:
        raise ValueError(f"postures must be a (P, n) array, got shape {q.shape}")
    vmax = positive_limits(velocity_limit, q.shape[1], "velocity_limit")
    amax = positive_limits(acceleration_limit, q.shape[1], "acceleration_limit")
    steps = np.diff(q, axis=0)
    cruise = float(np.sum(np.max(np.abs(steps) / vmax, axis=1, initial=0.0)))
    stops = 0.0
    for j in range(q.shape[1]):
        d = steps[:, j][steps[:, j] != 0.0]
        if d.size == 0:
            continue
        run = np.concatenate([[0], np.cumsum(np.sign(d[1:]) != np.sign(d[:-1]))])  # run index per step
        distance = np.abs(np.bincount(run, weights=d))
        v, a = vmax[j], amax[j]
        time = np.where(distance >= v * v / a, distance / v + v / a, 2.0 * np.sqrt(distance / a))
        stops = max(stops, float(time.sum()))
    return max(cruise, stops)


def path_bounds(
    maxima: tuple[Array, Array, Array], length: float, vmax: Array, amax: Array, jmax: Array
) -> tuple[float, float, float]:
    """(V, A, J) for the path parameter: the shortest rest-to-rest profile over ``length`` on the
    grid of feasible bounds (module docstring). ``maxima`` from :func:`derivative_maxima`."""
    d1, d2, d3 = maxima
    moving = d1 > 0
    d1, d2, d3 = d1[moving], d2[moving], d3[moving]
    vmax, amax, jmax = vmax[moving], amax[moving], jmax[moving]
    # V below each condition's own cap (the last two strictly: A and J must stay positive)
    with np.errstate(divide="ignore"):
        caps = [
            np.min(vmax / d1),
            np.min(np.sqrt(amax / np.where(d2 > 0, d2, 0.0))),
            np.min(np.cbrt(jmax / np.where(d3 > 0, d3, 0.0))),
        ]
    v_grid = min(caps[0], 0.999 * caps[1], 0.999 * caps[2]) * np.linspace(1.0 / GRID, 1.0, GRID)
    a_room = np.min((amax[None] - d2[None] * v_grid[:, None] ** 2) / d1[None], axis=1)  # (GV,)
    a_grid = a_room[:, None] * np.linspace(1.0 / GRID, 1.0, GRID)[None]  # (GV, GA)
    vv = v_grid[:, None, None]
    j_room = (jmax - d3 * vv**3 - 3 * d2 * vv * a_grid[..., None]) / d1  # (GV, GA, n)
    j_grid = j_room.min(axis=2)
    v_all = np.broadcast_to(v_grid[:, None], a_grid.shape)
    feasible = (a_grid > 0) & (j_grid > 0)
    if not feasible.any():
        raise SolverError("no jerk-limited profile fits the joint limits on this segment")
    duration = np.where(
        feasible, rest_to_rest_duration(length, v_all, a_grid, np.where(feasible, j_grid, 1.0)), np.inf
    )
    k = np.unravel_index(np.argmin(duration), duration.shape)
    return float(v_all[k]), float(a_grid[k]), float(j_grid[k])


class JerkLimitedMotion:
    """One segment: the path q(s) (cubic spline, s ∈ [0, L]) and ruckig's profile s(t), evaluated
    vectorised from the profile's seven phases (duration t_k, jerk j_k, and s, ṡ, s̈ at each phase start):
    on phase k, with τ the time since its start, s = p_k + v_k τ + a_k τ²/2 + j_k τ³/6.

    The profile starts and ends with s̈ = 0 and path speeds ṡ = ``speeds`` (0 ≤ each ≤ V; rest to rest
    by default), never moving backwards (ṡ ≥ 0; ruckig fails when the distance is too short to change
    from one speed to the other without reversing)."""

    def __init__(
        self,
        path: CubicSpline,
        bounds: tuple[float, float, float],
        index: int,
        speeds: tuple[float, float] = (0.0, 0.0),
    ) -> None:
        self.path = path
        self.length = float(path.x[-1])
        self.bounds = bounds
        self._d = [path.derivative(k) for k in (1, 2, 3)]
        v, a, j = bounds
        otg = ruckig.Ruckig(1)
        inp = ruckig.InputParameter(1)
        inp.current_position, inp.current_velocity, inp.current_acceleration = [0.0], [speeds[0]], [0.0]
        inp.target_position, inp.target_velocity, inp.target_acceleration = [self.length], [speeds[1]], [0.0]
        inp.max_velocity, inp.max_acceleration, inp.max_jerk = [v], [a], [j]
        if any(speeds):
            inp.min_velocity = [0.0]
        reference = ruckig.Trajectory(1)
        result = otg.calculate(inp, reference)
        if result not in (ruckig.Result.Working, ruckig.Result.Finished):
            raise SolverError(
                f"segment {index}: ruckig returned {result} for bounds V={v}, A={a}, J={j}, "
                f"path speeds {speeds[0]:.6g} → {speeds[1]:.6g}"
            )
        self.reference: ruckig.Trajectory | None = reference  # ruckig's own, which the tests compare
        profile = reference.profiles[0][0]
        if profile.brake.duration > 0 or profile.accel.duration > 0:
            raise SolverError(f"segment {index}: ruckig planned a braking phase from rest (ruckig changed?)")
        self._phase_t = np.asarray(profile.t, float)
        self._start = np.concatenate([[0.0], np.cumsum(self._phase_t)])
        self._j = np.asarray(profile.j, float)
        self._a = np.asarray(profile.a, float)[:7]
        self._v = np.asarray(profile.v, float)[:7]
        self._p = np.asarray(profile.p, float)[:7]

    def __getstate__(self) -> dict[str, Any]:
        """ruckig's trajectory does not pickle, and the evaluation needs only its phases: a copy
        (a figure drawn in a worker process) holds None in its place."""
        return {**self.__dict__, "reference": None}

    @property
    def duration(self) -> float:
        return float(self._start[-1])

    def profile(self, t: Array) -> tuple[Array, Array, Array, Array]:
        """s, ṡ, s̈, s⃛ at local times t, each (T,)."""
        k = np.clip(np.searchsorted(self._start, t, side="right") - 1, 0, 6)
        tau = t - self._start[k]
        j, a, v, p = self._j[k], self._a[k], self._v[k], self._p[k]
        s = p + tau * (v + tau * (a / 2 + tau * j / 6))
        return np.clip(s, 0.0, self.length), v + tau * (a + tau * j / 2), a + tau * j, j

    def evaluate(self, t: Array) -> tuple[Array, Array, Array]:
        s, sd, sdd, _ = self.profile(t)
        d1, d2 = self._d[0](s), self._d[1](s)
        return self.path(s), d1 * sd[:, None], d2 * (sd**2)[:, None] + d1 * sdd[:, None]

    def jerk(self, t: Array) -> Array:
        s, sd, sdd, sddd = self.profile(t)
        d1, d2, d3 = (d(s) for d in self._d)
        return d3 * (sd**3)[:, None] + 3 * d2 * (sd * sdd)[:, None] + d1 * sddd[:, None]


def jerk_limited_timing(
    segments: Sequence[ArrayLike],
    velocity_limit: ArrayLike,
    acceleration_limit: ArrayLike,
    jerk_limit: ArrayLike,
    dwell_s: float,
    *,
    joint_names: Sequence[str] | None = None,
    approach: ArrayLike | None = None,
    retreat: ArrayLike | None = None,
    position_bounds: tuple[ArrayLike, ArrayLike] | None = None,
) -> Trajectory:
    """Time the path through the landmarks with continuous acceleration: rest at every landmark for
    ``dwell_s`` (s), and move along each segment by the jerk-limited profile of the module docstring,
    so that |q̇_j| ≤ velocity_limit_j, |q̈_j| ≤ acceleration_limit_j and |q⃛_j| ≤ jerk_limit_j
    everywhere (rad/s, rad/s², rad/s³). ``segments``, ``approach``, ``retreat`` and
    ``position_bounds`` as for :func:`optlight.planning.timing.time_parameterize`.

    Raises ValueError for bad inputs and :class:`SolverError` when ruckig fails on a segment.
    """
    joint_bounds = None if position_bounds is None else as_bounds(position_bounds)

    def segment(index: int, waypoints: Array, n: int) -> JerkLimitedMotion | None:
        chord = chord_path(waypoints, joint_bounds)
        if chord is None:
            return None
        s, w = chord
        path = CubicSpline(s, w, bc_type="not-a-knot")
        bounds = path_bounds(derivative_maxima(path), float(s[-1]), vmax, amax, jmax)
        return JerkLimitedMotion(path, bounds, index)

    probe = np.asarray(segments[0], float) if len(segments) else np.zeros((0, 0))
    n = probe.shape[1] if probe.ndim == 2 else 0
    vmax = positive_limits(velocity_limit, n, "velocity_limit")
    amax = positive_limits(acceleration_limit, n, "acceleration_limit")
    jmax = positive_limits(jerk_limit, n, "jerk_limit")
    return assemble_trajectory(segments, dwell_s, segment, joint_names, approach=approach, retreat=retreat)
