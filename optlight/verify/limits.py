"""The joint limits: ``position``, ``velocity``, ``acceleration`` and, with a jerk limit, ``jerk`` and
``acceleration_continuity`` on the controller's grid (docs/design.md §7)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.motion import Trajectory
from optlight.verify.collector import Collector
from optlight.verify.report import Tolerances

Array = NDArray[np.float64]


@dataclass(frozen=True)
class JointLimits:
    """Per joint (n,): position bounds (rad; ±inf for none), velocity and acceleration limits (rad/s,
    rad/s²), and the jerk limit (rad/s³) or None."""

    lower: Array
    upper: Array
    velocity: Array
    acceleration: Array
    jerk: ArrayLike | None


def joint_limits(
    n: int,
    lower: ArrayLike,
    upper: ArrayLike,
    velocity_limit: ArrayLike,
    acceleration_limit: ArrayLike,
    jerk_limit: ArrayLike | None,
) -> JointLimits:
    """The limits as (n,) arrays (a scalar applies to every joint); ValueError for a wrong shape, a
    NaN, or a velocity or acceleration limit that is not positive. The jerk limit is checked where it
    is used (:func:`limit_checks`)."""
    lo, hi = per_joint(lower, n, "lower"), per_joint(upper, n, "upper")
    vmax, amax = (
        per_joint(velocity_limit, n, "velocity_limit"),
        per_joint(acceleration_limit, n, "acceleration_limit"),
    )
    if not ((vmax > 0).all() and (amax > 0).all()):
        raise ValueError("velocity and acceleration limits must be positive")
    return JointLimits(lo, hi, vmax, amax, jerk_limit)


def limit_checks(
    collector: Collector,
    trajectory: Trajectory,
    samples: tuple[Array, Array, Array],
    limits: JointLimits,
    rate_hz: float,
    tol: Tolerances,
) -> tuple[str, ...]:
    """``position``, ``velocity``, ``acceleration`` at the samples (q, q̇, q̈), then ``jerk`` and
    ``acceleration_continuity`` when there is a jerk limit. Returns the names of the checks skipped."""
    q, qd, qdd = samples
    n = q.shape[1]
    position_check(collector, q, limits.lower, limits.upper, tol)
    rate_check(collector, "velocity", "q̇", qd, limits.velocity, "rad/s", tol)
    rate_check(collector, "acceleration", "q̈", qdd, limits.acceleration, "rad/s²", tol)
    if limits.jerk is None:
        return ("jerk", "acceleration_continuity")
    jmax = per_joint(limits.jerk, n, "jerk_limit")
    if not (jmax > 0).all():
        raise ValueError("jerk limits must be positive")
    rate_check(collector, "jerk", "q⃛", trajectory.jerk(collector.t), jmax, "rad/s³", tol)
    continuity_check(collector, trajectory, jmax, rate_hz, tol)
    return ()


def position_check(collector: Collector, q: Array, lo: Array, hi: Array, tol: Tolerances) -> None:
    """``position``: lower_j − tol ≤ q_j ≤ upper_j + tol (rad); the measure is the excess
    max(lower − q, q − upper) (negative: the margin)."""
    names, t = collector.names, collector.t
    excess = np.maximum(lo - q, q - hi)
    collector.joint_check(
        "position",
        "largest excess over [lower, upper] (negative: margin)",
        "rad",
        excess,
        np.full(q.shape[1], tol.position_rad),
        lambda j, k: (
            f"joint {names[j]}: q = {q[k, j]:.6g} rad beyond [{lo[j]:.6g}, {hi[j]:.6g}] at t = {t[k]:.4f} s"
        ),
        value=lambda j, k: q[k, j],
        limit=lambda j, k: hi[j] if q[k, j] > hi[j] else lo[j],
    )


def rate_check(
    collector: Collector, name: str, symbol: str, x: Array, lim: Array, unit: str, tol: Tolerances
) -> None:
    """A derivative's check ``name``: |x_j| / lim_j ≤ 1 + limit_rel at every sample."""
    names, t = collector.names, collector.t
    bound = lim * (1 + tol.limit_rel)
    collector.joint_check(
        name,
        f"largest |{symbol}_j| / limit_j",
        "",
        np.abs(x) / lim,
        np.full(x.shape[1], 1.0 + tol.limit_rel),
        lambda j, k: (
            f"joint {names[j]}: |{symbol}| = {abs(x[k, j]):.6g} {unit} > {bound[j]:.6g} {unit} "
            f"at t = {t[k]:.4f} s"
        ),
        value=lambda j, k: abs(x[k, j]),
        limit=lambda j, k: bound[j],
    )


def continuity_check(
    collector: Collector, trajectory: Trajectory, jmax: Array, rate_hz: float, tol: Tolerances
) -> None:
    """``acceleration_continuity`` on the controller grid t_k = k / rate_hz: the ratio of each jump
    |q̈_j(t_{k+1}) − q̈_j(t_k)| to j_max,j Δt_k (Δt_k = 1 / rate_hz but the last), recorded at t_{k+1}."""
    names = collector.names
    grid = np.arange(int(np.floor(trajectory.duration * rate_hz + 1e-9)) + 1) / rate_hz
    if grid[-1] < trajectory.duration - 1e-12:
        grid = np.append(grid, trajectory.duration)
    if grid.size < 2:
        return
    qdd = trajectory.sample(grid)[2]
    jump = np.abs(np.diff(qdd, axis=0))
    allowed = jmax * np.diff(grid)[:, None]
    ratio = jump / allowed
    sample_times, collector.t = collector.t, grid[1:]  # this check's samples are the controller grid
    collector.joint_check(
        "acceleration_continuity",
        "largest |Δq̈_j| / (jerk_limit_j Δt) between controller samples",
        "",
        ratio,
        np.full(jmax.size, 1.0 + tol.limit_rel),
        lambda j, k: (
            f"joint {names[j]}: q̈ jumps by {jump[k, j]:.6g} rad/s² between t = {grid[k]:.4f} and "
            f"{grid[k + 1]:.4f} s, {ratio[k, j]:.3g}× what jerk_limit {jmax[j]:.6g} rad/s³ allows"
        ),
        value=lambda j, k: jump[k, j],
        limit=lambda j, k: allowed[k, j] * (1 + tol.limit_rel),
    )
    collector.t = sample_times


def per_joint(value: ArrayLike, n: int, name: str) -> Array:
    """``value`` as (n,) numbers (a scalar for every joint); ValueError for another shape or a NaN."""
    x = np.asarray(value, float)
    if x.shape not in ((), (n,)) or np.isnan(x).any():
        raise ValueError(f"{name} must be one or {n} numbers, got {x}")
    return np.broadcast_to(x, (n,)).copy()
