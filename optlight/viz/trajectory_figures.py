"""Figures of a timed trajectory: q, q̇, q̈ of every joint against its limits, dwells shaded; the
light's path on the sphere.

Built on :class:`matplotlib.figure.Figure` (no pyplot, no global backend state); ``savefig`` to a
PNG renders with Agg, so this works headless.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np
from numpy.typing import ArrayLike

from optlight.geometry import LightSphere
from optlight.motion import Trajectory
from optlight.viz.layout import set_margins

if TYPE_CHECKING:  # imported where a figure is made: see optlight.viz.layout
    from matplotlib.figure import Figure
    from matplotlib.projections.polar import PolarAxes


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
    ``rate_hz`` plus the boundaries; limits dashed red, dwells (exposures) shaded, captures dotted.

    Fixed margins (in inches) rather than a layout engine, and the dwells and captures of each axes
    as one collection each rather than an artist per dwell: for 7 joints and 36 dwells a constrained
    layout measuring 21 axes and 1,500 artists would take most of the figure's time. Every axes spans
    exactly the trajectory's time and only the bottom row has time ticks: matplotlib makes a tick
    object for every tick of every axes, drawn or not, and the rows above would hold a third of the
    figure's ticks."""
    from matplotlib.collections import LineCollection, PolyCollection
    from matplotlib.figure import Figure
    from matplotlib.ticker import NullLocator

    n = trajectory.dof
    lo, hi = (np.broadcast_to(np.asarray(x, float), (n,)) for x in (lower, upper))
    vmax, amax = (np.broadcast_to(np.asarray(x, float), (n,)) for x in (velocity_limit, acceleration_limit))
    names = trajectory.joint_names or tuple(f"j{i}" for i in range(n))
    t = trajectory.sample_times(rate_hz)
    series = trajectory.sample(t)
    bounds = ((lo, hi), (-vmax, vmax), (-amax, amax))
    titles = ("q [rad]", "q̇ [rad/s]", "q̈ [rad/s²]")

    width, height = 13.0, 1.7 * n + 0.8
    fig = Figure(figsize=(width, height))
    # margins (in): the joint names and tick labels on the left, the titles on top, t below
    set_margins(fig, left=0.85, right=0.15, top=0.75, bottom=0.5, rows=n, columns=3, gap_x=0.55, gap_y=0.2)
    axes = fig.subplots(n, 3, squeeze=False)
    dwells = [[(a, 0.0), (b, 0.0), (b, 1.0), (a, 1.0)] for a, b in trajectory.landmark_intervals]
    captures = [[(tc, 0.0), (tc, 1.0)] for tc in trajectory.capture_times]
    for j in range(n):
        for c in range(3):
            ax = axes[j, c]
            # x in data, y in axes coordinates: full height whatever the limits; not autoscaled
            across = ax.get_xaxis_transform()
            ax.add_collection(PolyCollection(dwells, facecolor="0.85", lw=0, transform=across), autolim=False)
            ax.add_collection(
                LineCollection(captures, colors="0.6", lw=0.5, linestyles=":", transform=across), autolim=False
            )
            ax.plot(t, series[c][:, j], lw=1.0, color="C0")
            for limit in bounds[c]:
                if np.isfinite(limit[j]):
                    ax.axhline(limit[j], color="C3", lw=0.8, ls="--")
            if j == 0:
                ax.set_title(titles[c])
            if c == 0:
                ax.set_ylabel(names[j])
            ax.set_xlim(t[0], t[-1])
            if j == n - 1:
                ax.set_xlabel("t [s]")
            else:
                ax.xaxis.set_major_locator(NullLocator())
    fig.suptitle(
        f"Timed trajectory: {trajectory.duration:.2f} s, {trajectory.capture_times.size} captures "
        "(grey: dwells, red: limits)",
        y=1 - 0.12 / height,
        va="top",
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


#: Most tick intervals per axis of the path figure's 3-D view.
PATH_3D_TICKS = 4


def path_figure(
    sphere: LightSphere,
    planned: ArrayLike,
    timed: ArrayLike,
    landmarks: ArrayLike,
) -> Figure:
    """The light's path on the sphere: planned knots, the timed trajectory's light positions and the
    landmarks (world frame, m), as a polar projection (radius = zenith in degrees, angle = azimuth) and
    a 3-D view around O."""
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    fig = Figure(figsize=(10.5, 5.0))
    polar = cast("PolarAxes", fig.add_subplot(1, 2, 1, projection="polar"))
    points = {"planned knots": planned, "timed trajectory": timed, "landmarks": landmarks}
    styles = {
        "planned knots": {"marker": ".", "linestyle": "none", "color": "tab:blue", "markersize": 4},
        "timed trajectory": {"linestyle": "-", "color": "tab:orange", "linewidth": 1.0},
        "landmarks": {"marker": "o", "linestyle": "none", "color": "tab:red", "markersize": 6, "mfc": "none"},
    }
    for label, pts in points.items():
        zen, az = sphere.angles(np.asarray(pts, float).reshape(-1, 3))
        polar.plot(az, np.rad2deg(zen), label=label, **styles[label])  # type: ignore[arg-type]
    polar.set_rlim(0.0, float(np.rad2deg(sphere.zenith_max)))
    polar.set_title("zenith (radius, °) and azimuth of the light", fontsize=10)
    polar.legend(loc="lower left", bbox_to_anchor=(-0.15, -0.15), fontsize=8)

    ax3 = fig.add_subplot(1, 2, 2, projection="3d")
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 37), np.linspace(0, np.pi, 19))
    c, b = sphere.center, sphere.radius
    ax3.plot_wireframe(
        c[0] + b * np.cos(u) * np.sin(v),
        c[1] + b * np.sin(u) * np.sin(v),
        c[2] + b * np.cos(v),
        color="0.85",
        linewidth=0.4,
    )
    for label, pts in points.items():
        p = np.asarray(pts, float).reshape(-1, 3)
        ax3.plot(p[:, 0], p[:, 1], p[:, 2], **styles[label])
    for axis, name in ((ax3.xaxis, "x"), (ax3.yaxis, "y"), (ax3.zaxis, "z")):
        axis.set_major_locator(MaxNLocator(PATH_3D_TICKS))  # the default's 9 x labels ran together
        axis.set_label_text(f"{name} (m)")
    ax3.set_box_aspect((1, 1, 1))
    ax3.set_title("world frame", fontsize=10)
    # fixed margins: tight_layout measured every label of both axes first (a third of the time)
    fig.subplots_adjust(left=0.06, right=0.92, top=0.88, bottom=0.13, wspace=0.2)
    return fig
