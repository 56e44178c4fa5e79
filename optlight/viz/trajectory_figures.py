"""Figures of a timed trajectory: q, q̇, q̈ of every joint against its limits, dwells shaded.

Built on :class:`matplotlib.figure.Figure` (no pyplot, no global backend state); ``savefig`` to a
PNG renders with Agg, so this works headless.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import ArrayLike

from optlight.planning.timing import Trajectory


def trajectory_figure(
    trajectory: Trajectory,
    *,
    lower: ArrayLike,
    upper: ArrayLike,
    velocity_limit: ArrayLike,
    acceleration_limit: ArrayLike,
    rate_hz: float = 200.0,
) -> Figure:
    """One row per joint, columns q (rad), q̇ (rad/s), q̈ (rad/s²) over t (s), sampled at
    ``rate_hz`` plus the boundaries; limits dashed red, dwells (exposures) shaded, captures dotted."""
    n = trajectory.dof
    lo, hi = (np.broadcast_to(np.asarray(x, float), (n,)) for x in (lower, upper))
    vmax, amax = (np.broadcast_to(np.asarray(x, float), (n,)) for x in (velocity_limit, acceleration_limit))
    names = trajectory.joint_names or tuple(f"j{i}" for i in range(n))
    t = trajectory.sample_times(rate_hz)
    series = trajectory.sample(t)
    bounds = ((lo, hi), (-vmax, vmax), (-amax, amax))
    titles = ("q [rad]", "q̇ [rad/s]", "q̈ [rad/s²]")

    fig = Figure(figsize=(13, 1.7 * n + 0.8), layout="constrained")
    axes = fig.subplots(n, 3, sharex=True, squeeze=False)
    for j in range(n):
        for c in range(3):
            ax = axes[j, c]
            for a, b in trajectory.landmark_intervals:
                ax.axvspan(a, b, color="0.85", lw=0)
            for tc in trajectory.capture_times:
                ax.axvline(tc, color="0.6", lw=0.5, ls=":")
            ax.plot(t, series[c][:, j], lw=1.0, color="C0")
            for limit in bounds[c]:
                if np.isfinite(limit[j]):
                    ax.axhline(limit[j], color="C3", lw=0.8, ls="--")
            if j == 0:
                ax.set_title(titles[c])
            if c == 0:
                ax.set_ylabel(names[j])
            if j == n - 1:
                ax.set_xlabel("t [s]")
    fig.suptitle(
        f"Timed trajectory: {trajectory.duration:.2f} s, {trajectory.capture_times.size} captures "
        "(grey: dwells, red: limits)"
    )
    return fig


def save_trajectory_figure(
    path: str | Path,
    trajectory: Trajectory,
    *,
    lower: ArrayLike,
    upper: ArrayLike,
    velocity_limit: ArrayLike,
    acceleration_limit: ArrayLike,
    dpi: int = 120,
) -> Path:
    """:func:`trajectory_figure` written to a PNG file."""
    fig = trajectory_figure(
        trajectory,
        lower=lower,
        upper=upper,
        velocity_limit=velocity_limit,
        acceleration_limit=acceleration_limit,
    )
    path = Path(path)
    fig.savefig(path, dpi=dpi)
    return path
