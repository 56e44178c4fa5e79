"""The geometric path of a segment, shared by the timing laws (docs/design.md §6): the not-a-knot
cubic spline q(s) through the joint waypoints over the cumulative chord parameter
s_0 = 0, s_k = s_{k-1} + |q_k − q_{k-1}|₂ (rad).

The spline interpolates the waypoints but may bulge beyond them between knots: two consecutive
waypoints on the trajectory NLP's bound, 5 mrad inside a joint limit, with the path turning on both
sides, bulged 6 mrad past the limit (a re-plan of the camera loop). Given the joint position bounds,
the path gets more waypoints where its spline leaves them (:func:`chord_path`);
:func:`optlight.verify.verify_trajectory` checks the limits again, independently.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

#: Waypoints closer than this (rad, Euclidean in joint space) are merged; a segment whose waypoints
#: all coincide has no motion.
MERGE_DISTANCE = 1e-9
#: Largest number of times the waypoints of a segment are refined where its spline leaves the joint
#: position bounds (:func:`chord_path`).
MAX_BULGE_REFINEMENTS = 8


def chord_path(
    waypoints: Array, position_bounds: tuple[Array, Array] | None = None
) -> tuple[Array, Array] | None:
    """Waypoints with near-duplicates merged and their cumulative chord parameter s (rad), or None
    when all waypoints coincide. The last waypoint is kept exactly.

    With ``position_bounds`` (lower, upper), each (n,) rad: where the not-a-knot cubic spline through
    the waypoints leaves the bounds between two waypoints, the midpoint of the joint-space chord
    between them (inside the bounds when both are) becomes a waypoint too, and the spline is fitted
    again, at most :data:`MAX_BULGE_REFINEMENTS` times; every waypoint given is kept. Halving an
    interval shrinks its bulge about fourfold (the bulge of a cubic interpolant grows as h²)."""
    kept = [waypoints[0]]
    for q in waypoints[1:]:
        if np.linalg.norm(q - kept[-1]) > MERGE_DISTANCE:
            kept.append(q)
    if len(kept) == 1:
        return None
    kept[-1] = waypoints[-1]
    w = np.array(kept)
    if position_bounds is not None:
        w = _within_bounds(w, *position_bounds)
    return chord_parameter(w), w


def _within_bounds(w: Array, lower: Array, upper: Array) -> Array:
    """The waypoints ``w`` (K, n) with the chord midpoints :func:`chord_path` adds where the spline
    through them leaves [``lower``, ``upper``]."""
    for _ in range(MAX_BULGE_REFINEMENTS):
        low, high = spline_position_range(chord_parameter(w), w)
        outside = np.flatnonzero(((low < lower) | (high > upper)).any(axis=1))
        if outside.size == 0:
            break
        w = np.insert(w, outside + 1, 0.5 * (w[outside] + w[outside + 1]), axis=0)
    return w


def chord_parameter(w: Array) -> Array:
    """The cumulative chord parameter (K,) of waypoints (K, n): s_0 = 0, s_k = s_{k−1} + |q_k − q_{k−1}|₂."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(w, axis=0), axis=1))])


def spline_position_range(s: Array, w: Array) -> tuple[Array, Array]:
    """(lowest, highest), each (K − 1, n): the exact range of each joint of the not-a-knot cubic
    spline through waypoints ``w`` (K, n) at ``s`` (K,) on each interval: the cubic's values at the
    interval's ends and where its derivative, a quadratic, vanishes inside."""
    from scipy.interpolate import CubicSpline

    c = np.asarray(CubicSpline(s, w, bc_type="not-a-knot").c, float)  # q = c0 τ³ + c1 τ² + c2 τ + c3
    h = np.diff(s)[:, None]
    qa, qb, qc = 3 * c[0], 2 * c[1], c[2]  # q′ = qa τ² + qb τ + qc
    with np.errstate(divide="ignore", invalid="ignore"):
        root = np.sqrt(qb**2 - 4 * qa * qc)
        quadratic = [(-qb + root) / (2 * qa), (-qb - root) / (2 * qa)]
        linear = -qc / qb
    candidates = [np.zeros_like(c[0]), np.broadcast_to(h, c[0].shape)]
    for tau in (*quadratic, linear):
        valid = np.isfinite(tau) & (tau > 0) & (tau < h)
        candidates.append(np.where(valid, tau, 0.0))
    values = np.stack([((c[0] * t + c[1]) * t + c[2]) * t + c[3] for t in candidates])
    return values.min(axis=0), values.max(axis=0)


def as_bounds(position_bounds: tuple[ArrayLike, ArrayLike]) -> tuple[Array, Array]:
    """``position_bounds`` (lower, upper) as two float arrays."""
    return np.asarray(position_bounds[0], float), np.asarray(position_bounds[1], float)
