"""The waypoints a trajectory controller interpolates: the few points of a timed trajectory that
quintic interpolation reproduces within a tolerance (docs/design.md §12).

ROS 2's joint_trajectory_controller, given positions, velocities and accelerations at every point,
joins consecutive points (t_k, q_k, q̇_k, q̈_k) and (t_{k+1}, …) by the quintic Hermite polynomial: the
one polynomial of degree 5 per joint with those q, q̇, q̈ at both ends. It needs no dense samples: a
dwell is one polynomial (at rest at both ends, it is constant), and a jerk-limited motion (smooth
between its profile's phase changes) needs a point every few tens of milliseconds.

**Choice.** The points are :attr:`Trajectory.boundaries` (every dwell and motion start and end) plus,
on each span between two boundaries, points picked greedily on a grid G (the times of
:meth:`Trajectory.sample_times` at ``rate_hz``, rounded to the nanosecond a ``time_from_start`` holds,
so the file's points are the trajectory's at exactly the times written): from the last point t_a, the
next is the furthest grid time t_b found by doubling then bisecting the number of grid steps, such
that the quintic on [t_a, t_b] is within ``margin · tolerance_rad`` of the trajectory's q at every grid
time between them and every midpoint of two consecutive ones. The deviation is not monotone in t_b,
so the bisection may stop short of the furthest such t_b (one more point than needed), never past one
that fails: every span it keeps was checked. ``margin`` < 1 leaves room for the times between the
checked ones, which :func:`optlight.verify.verify_trajectory` samples independently.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from optlight.motion import Trajectory

Array = NDArray[np.float64]

#: Largest deviation (rad) of the quintic interpolation of the waypoints from the planned q.
TOLERANCE_RAD = 1e-4
#: The fraction of the tolerance the choice of waypoints allows itself on its grid.
MARGIN = 0.5


@dataclass(frozen=True)
class Waypoints:
    """Points (t_k, q_k, q̇_k, q̈_k) of a trajectory for a controller that interpolates quintically.

    ``nanoseconds`` (K,) the times from the start (int, ns; 0 first, the duration last); ``q``, ``qd``,
    ``qdd`` (K, n) the trajectory's positions (rad), velocities (rad/s) and accelerations (rad/s²) at
    those times; ``tolerance_rad`` the deviation the points were chosen for; ``max_deviation_rad`` the
    largest deviation found on the choice's grid."""

    nanoseconds: NDArray[np.int64]
    q: Array
    qd: Array
    qdd: Array
    tolerance_rad: float
    max_deviation_rad: float

    @property
    def t(self) -> Array:
        """(K,) the times (s)."""
        return self.nanoseconds / 1e9

    def __len__(self) -> int:
        return int(self.nanoseconds.size)


def quintic_positions(
    t0: float, t1: float, p0: tuple[Array, Array, Array], p1: tuple[Array, Array, Array], t: Array
) -> Array:
    """q(t) (T, n) of the quintic Hermite polynomial between the states p0 = (q, q̇, q̈) at t0 and p1 at
    t1 (each a triple of (n,) arrays), at times t (T,) with t0 ≤ t ≤ t1: with h = t1 − t0,
    x = (t − t0)/h, Δ = q1 − q0, v = h q̇, a = h² q̈,

        q = q0 + v0 x + a0 x²/2 + c3 x³ + c4 x⁴ + c5 x⁵,
        c3 = 10 Δ − 6 v0 − 4 v1 − (3 a0 − a1)/2,  c4 = −15 Δ + 8 v0 + 7 v1 + (3 a0 − 2 a1)/2,
        c5 = 6 Δ − 3 (v0 + v1) − (a0 − a1)/2."""
    h = t1 - t0
    x = ((t - t0)[:, None]) / h
    (q0, v0, a0), (q1, v1, a1) = ((p[0], p[1] * h, p[2] * h**2) for p in (p0, p1))
    d = q1 - q0
    c3 = 10 * d - 6 * v0 - 4 * v1 - 0.5 * (3 * a0 - a1)
    c4 = -15 * d + 8 * v0 + 7 * v1 + 0.5 * (3 * a0 - 2 * a1)
    c5 = 6 * d - 3 * (v0 + v1) - 0.5 * (a0 - a1)
    return q0 + x * (v0 + x * (0.5 * a0 + x * (c3 + x * (c4 + x * c5))))


def controller_waypoints(
    trajectory: Trajectory,
    *,
    tolerance_rad: float = TOLERANCE_RAD,
    rate_hz: float = 1000.0,
    margin: float = MARGIN,
) -> Waypoints:
    """The waypoints of ``trajectory`` (module docstring): its boundaries plus the points the greedy
    choice on the grid at ``rate_hz`` (Hz) adds, so that quintic interpolation stays within
    ``margin · tolerance_rad`` (rad) of q on the grid and its midpoints."""
    if not (tolerance_rad > 0 and 0 < margin <= 1):
        raise ValueError(f"tolerance_rad must be positive and margin in (0, 1], got {tolerance_rad}, {margin}")
    ns = np.unique(np.round(trajectory.sample_times(rate_hz) * 1e9).astype(np.int64))
    grid = ns / 1e9
    mid = 0.5 * (grid[1:] + grid[:-1])
    q, qd, qdd = trajectory.sample(grid)
    q_mid = trajectory.sample(mid)[0]
    if not (np.isfinite(q).all() and np.isfinite(qd).all() and np.isfinite(qdd).all()):
        raise ValueError("the trajectory has non-finite samples")
    bound = margin * tolerance_rad
    boundary = np.searchsorted(ns, np.round(trajectory.boundaries * 1e9).astype(np.int64))
    boundary = np.unique(np.clip(boundary, 0, ns.size - 1))

    def deviation(a: int, b: int) -> float:
        """Largest |quintic − q| on the grid times strictly inside [a, b] and the midpoints in it."""
        times = np.concatenate([grid[a + 1 : b], mid[a:b]])
        truth = np.concatenate([q[a + 1 : b], q_mid[a:b]])
        if times.size == 0:
            return 0.0
        start, end = (q[a], qd[a], qdd[a]), (q[b], qd[b], qdd[b])
        fit = quintic_positions(float(grid[a]), float(grid[b]), start, end, times)
        return float(np.abs(fit - truth).max())

    chosen = [int(boundary[0])]
    worst = 0.0
    for a, b in zip(boundary[:-1].tolist(), boundary[1:].tolist(), strict=True):
        start = a
        while start < b:
            step = 1
            while start + 2 * step <= b and deviation(start, start + 2 * step) <= bound:
                step *= 2
            if start + 2 * step > b and deviation(start, b) <= bound:
                step = b - start
            else:  # the largest passing step lies in [step, 2 step): bisect
                lo, hi = step, min(2 * step, b - start)
                while hi - lo > 1:
                    m = (lo + hi) // 2
                    lo, hi = (m, hi) if deviation(start, start + m) <= bound else (lo, m)
                step = lo
            worst = max(worst, deviation(start, start + step))
            start += step
            chosen.append(start)
    index = np.array(chosen)
    return Waypoints(ns[index], q[index], qd[index], qdd[index], float(tolerance_rad), worst)
