"""``interpolation``: the plan against what a controller makes of its waypoints, the quintic Hermite
interpolation ROS 2's joint_trajectory_controller evaluates between them."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.verify.collector import Collector
from optlight.verify.report import Tolerances

Array = NDArray[np.float64]

#: Points a controller interpolates quintically (duck-typed, as
#: :class:`optlight.planning.waypoints.Waypoints`): ``t`` (K,) s, ``q``, ``qd``, ``qdd`` (K, n).
ControllerPoints = Any


def interpolation_check(collector: Collector, waypoints: ControllerPoints, q: Array, tol: Tolerances) -> None:
    """``interpolation``: |q̂_j(t) − q_j(t)| ≤ interpolation_rad at every sample, q̂ the quintic
    Hermite interpolation of the waypoints (:func:`quintic_hermite`)."""
    names, t = collector.names, collector.t
    interpolated = quintic_hermite(waypoints.t, waypoints.q, waypoints.qd, waypoints.qdd, t)
    gap = np.abs(interpolated - q)
    collector.joint_check(
        "interpolation",
        "largest |q̂_j − q_j|, q̂ the quintic interpolation of the controller waypoints",
        "rad",
        gap,
        np.full(q.shape[1], tol.interpolation_rad),
        lambda j, k: (
            f"joint {names[j]}: the waypoints' quintic interpolation is {gap[k, j]:.3g} rad from the plan "
            f"at t = {t[k]:.4f} s (> {tol.interpolation_rad:.3g} rad)"
        ),
    )


def quintic_hermite(t_points: ArrayLike, q: ArrayLike, qd: ArrayLike, qdd: ArrayLike, t: ArrayLike) -> Array:
    """Positions (T, n) at times t (T,) of the quintic Hermite interpolation of points
    (t_k, q_k, q̇_k, q̈_k) (K,) and (K, n) each: on [t_k, t_{k+1}], h = t_{k+1} − t_k, x = (t − t_k)/h,

        q̂ = H₀ q_k + H₁ h q̇_k + H₂ h² q̈_k + H₃ q_{k+1} + H₄ h q̇_{k+1} + H₅ h² q̈_{k+1},
        H₀ = 1 − 10x³ + 15x⁴ − 6x⁵,  H₁ = x − 6x³ + 8x⁴ − 3x⁵,  H₂ = (x² − 3x³ + 3x⁴ − x⁵)/2,
        H₃ = 10x³ − 15x⁴ + 6x⁵,      H₄ = −4x³ + 7x⁴ − 3x⁵,     H₅ = (x³ − 2x⁴ + x⁵)/2,

    the basis whose values and first two derivatives at x = 0 and 1 pick out one of the six end
    values each. NaN outside [t_0, t_K] (a time the points do not cover)."""
    tp = np.asarray(t_points, float)
    q, qd, qdd = (np.asarray(a, float) for a in (q, qd, qdd))
    times = np.asarray(t, float)
    k = np.clip(np.searchsorted(tp, times, side="right") - 1, 0, tp.size - 2)
    h = (tp[k + 1] - tp[k])[:, None]
    x = (times - tp[k])[:, None] / h
    x2, x3 = x * x, x * x * x
    x4, x5 = x3 * x, x3 * x2
    basis = (
        1 - 10 * x3 + 15 * x4 - 6 * x5,
        x - 6 * x3 + 8 * x4 - 3 * x5,
        0.5 * (x2 - 3 * x3 + 3 * x4 - x5),
        10 * x3 - 15 * x4 + 6 * x5,
        -4 * x3 + 7 * x4 - 3 * x5,
        0.5 * (x3 - 2 * x4 + x5),
    )
    ends = (q[k], h * qd[k], h**2 * qdd[k], q[k + 1], h * qd[k + 1], h**2 * qdd[k + 1])
    out = sum(b * e for b, e in zip(basis, ends, strict=True))
    outside = (times < tp[0] - 1e-9) | (times > tp[-1] + 1e-9)
    return np.where(outside[:, None], np.nan, out)
