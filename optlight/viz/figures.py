"""Figures (matplotlib, PNG, headless): small functions that take results and return a figure.

Landmark figures: :func:`landmarks_polar_figure` (the paper's Fig. 1), :func:`histograms_figure`,
:func:`contact_sheet_figure`, :func:`cost_map_figure`; :func:`landmark_figures` gives all four as
:class:`~optlight.viz.drawing.FigureJob` s (drawn here or in a worker process), and
:func:`save_landmark_figures` writes them. A plan's captures are its landmarks but for those the
placement moved (status "placed": the robot cannot hold the light clear at the landmark): the polar
plots draw those where they are captured, joined to their landmark, and the contact sheet shows
their camera image there.
Figures are drawn on :class:`matplotlib.figure.Figure` objects, never through pyplot, so nothing
depends on a display or on global backend state. Angles are shown in degrees.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np
from matplotlib.colors import LogNorm

from optlight.planning.landmarks import Landmark, LandmarkSet
from optlight.scene import Scene
from optlight.viz.drawing import FigureJob
from optlight.viz.layout import set_margins

if TYPE_CHECKING:  # imported where a figure is made: see optlight.viz.layout
    from matplotlib.figure import Figure
    from matplotlib.projections.polar import PolarAxes

#: Floor of the logarithmic colour scale of cost maps (costs can be exactly 0 at the reference).
COST_FLOOR = 1e-12
#: Decades of the cost map's logarithmic colour scale below the largest cost.
COST_DECADES = 5.0
#: Contact sheet: width and height (in) of a cell; side (in) of the image in it, 0.05 in above the
#: cell's bottom edge, centred across, its label above.
CONTACT_SHEET_CELL_IN = (1.4, 1.55)
CONTACT_SHEET_TILE_IN = 1.3
#: Contact sheet: cells per row.
CONTACT_SHEET_COLUMNS = 6
#: The colour of the captures the placement moved, in the polar plot and the contact sheet.
MOVED_COLOR = "tab:purple"
#: Resolution (dots per inch) of the landmark figures' PNGs.
LANDMARK_FIGURE_DPI = 110


def _polar_axes(fig: Figure, r_max: float) -> PolarAxes:
    ax = cast("PolarAxes", fig.add_subplot(projection="polar"))
    ax.set_rlim(0.0, math.degrees(r_max))
    ax.set_rlabel_position(135)
    ax.grid(True, alpha=0.4)
    return ax


def _zenith_edges(zenith: np.ndarray) -> np.ndarray:
    """Cell edges (n + 1,) around sorted zeniths (n ≥ 2): midpoints, ends mirrored, clipped at 0."""
    mid = 0.5 * (zenith[1:] + zenith[:-1])
    return np.maximum(np.r_[2 * zenith[0] - mid[0], mid, 2 * zenith[-1] - mid[-1]], 0.0)


def _azimuth_edges(azimuth: np.ndarray) -> np.ndarray:
    """Cell edges (n + 1,) around n equally spaced azimuths covering the circle (2πj/n)."""
    step = 2 * np.pi / azimuth.size
    return np.r_[azimuth - step / 2, azimuth[-1] + step / 2]


def radial_limit(
    landmarks: LandmarkSet, zenith_max: float, fixed_zenith: float | None = None, moved: Sequence[Landmark] = ()
) -> float:
    """A radial limit (rad) for polar plots: 1.4 × the largest landmark, moved capture's (or fixed)
    zenith, rounded up to 5°, at most ``zenith_max``."""
    zeniths = [float(landmarks.zeniths.max(initial=0.0)), *(c.zenith for c in moved)]
    largest = max(zeniths + ([fixed_zenith] if fixed_zenith else []))
    return min(zenith_max, math.radians(5 * math.ceil(max(math.degrees(1.4 * largest), 1e-9) / 5)))


def moved_captures(captures: Sequence[Landmark]) -> list[Landmark]:
    """The captures the placement moved off their landmark (status "placed"), by landmark index."""
    return sorted((c for c in captures if c.status == "placed"), key=lambda c: c.index)


def _draw_moved(ax: PolarAxes, landmarks: LandmarkSet, moved: Sequence[Landmark], color: str) -> None:
    """Each moved capture where it is captured (a filled diamond), joined to its landmark."""
    origin = {lm.index: lm for lm in landmarks.landmarks}
    for k, capture in enumerate(moved):
        landmark = origin[capture.index]
        ax.plot(
            [landmark.azimuth, capture.azimuth],
            np.degrees([landmark.zenith, capture.zenith]),
            color=color,
            lw=0.8,
        )
        ax.plot(
            capture.azimuth,
            math.degrees(capture.zenith),
            "D",
            color=color,
            ms=5,
            label="captured elsewhere (moved by the placement)" if k == 0 else None,
        )


def landmarks_polar_figure(
    landmarks: LandmarkSet, r_max: float, fixed_zenith: float | None = None, moved: Sequence[Landmark] = ()
) -> Figure:
    """The landmarks projected on the plane (the paper's Fig. 1): radius = zenith (deg), angle =
    azimuth; circles for the landmarks, stars for the fixed-zenith circle at the same azimuths
    (``fixed_zenith``, rad; the paper's 10° trajectory), diamonds for the ``moved`` captures
    (:func:`moved_captures`) where they are captured. ``r_max`` (rad) is the radial limit."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(5.2, 5.2))
    ax = _polar_axes(fig, r_max)
    az, zen = landmarks.azimuths, np.degrees(landmarks.zeniths)
    _shade_view(ax, landmarks.view_zenith)
    if fixed_zenith is not None:
        circle = np.linspace(0, 2 * np.pi, 361)
        ax.plot(circle, np.full_like(circle, math.degrees(fixed_zenith)), color="0.6", lw=0.8)
        ax.plot(
            az,
            np.full_like(az, math.degrees(fixed_zenith)),
            "*",
            color="tab:orange",
            ms=8,
            label=f"the paper's fixed zenith ({math.degrees(fixed_zenith):.0f}°)",
        )
    order = np.argsort(az) if landmarks.mode == "azimuth" else np.arange(len(az))
    if landmarks.mode == "azimuth":
        ax.plot(np.r_[az[order], az[order][:1]], np.r_[zen[order], zen[order][:1]], color="tab:blue", lw=0.8)
    ax.plot(az, zen, "o", mfc="none", color="tab:blue", ms=7, label="landmarks")
    _draw_moved(ax, landmarks, moved, MOVED_COLOR)
    ax.set_title(f"Landmarks ({len(landmarks)}, {landmarks.mode} mode): radius = zenith (deg)", fontsize=10)
    ax.legend(loc="lower left", bbox_to_anchor=(-0.1, -0.12), fontsize=8, frameon=False)
    return fig


def _shade_view(ax: PolarAxes, view_zenith: float) -> None:
    """Hatch the lights the camera's view takes away (zenith < ``view_zenith``, rad): there the
    light's housing would stand in front of the lens."""
    if view_zenith <= 0:
        return
    circle = np.linspace(0, 2 * np.pi, 361)
    ax.fill_between(
        circle,
        0.0,
        math.degrees(view_zenith),
        facecolor="0.85",
        edgecolor="0.5",
        hatch="//",
        lw=0.0,
        label=f"in the camera's view (< {math.degrees(view_zenith):.1f}°)",
    )


def histograms_figure(landmarks: LandmarkSet, indices: Sequence[int] | None = None) -> Figure:
    """Reference against achieved soft histograms at a few landmarks (default: four spread over the
    set), bins on normalised luminance [0, 1]."""
    from matplotlib.figure import Figure

    n = len(landmarks)
    if indices is None:
        indices = sorted(set(np.linspace(0, n - 1, min(4, n)).round().astype(int).tolist()))
    k = landmarks.reference_histogram.size
    centres = (np.arange(k) + 0.5) / k
    fig = Figure(figsize=(3.2 * len(indices), 2.8))
    axes = fig.subplots(1, len(indices), sharey=True, squeeze=False)[0]
    for ax, i in zip(axes, indices, strict=True):
        lm = landmarks.landmarks[i]
        ax.bar(centres, landmarks.histograms[i], width=1.0 / k, color="tab:blue", alpha=0.6, label="achieved")
        ax.step(centres, landmarks.reference_histogram, where="mid", color="k", lw=1.2, label="reference")
        ax.set_title(
            f"#{lm.index}: θ {math.degrees(lm.zenith):.1f}°, φ {math.degrees(lm.azimuth):.0f}°\ncost {lm.cost:.2e}",
            fontsize=9,
        )
        ax.set_xlabel("normalised luminance")
        ax.set_xlim(0, 1)
    axes[0].set_ylabel("fraction of pixels")
    axes[0].legend(fontsize=8, frameon=False)
    # two-line titles on top
    set_margins(fig, left=0.7, right=0.15, top=0.55, bottom=0.5, columns=len(fig.axes), gap_x=0.3)
    return fig


def contact_sheet_images(landmarks: LandmarkSet, scene: Scene, moved: Sequence[Landmark] = ()) -> np.ndarray:
    """The camera image (NumPy renderer, shadow rays) at every landmark, or where it is captured when
    the placement ``moved`` it (:func:`moved_captures`), (M, H, W) float32: with the visibility the
    landmark search kept (:meth:`~optlight.planning.landmarks.LandmarkSet.visibility`), else every
    light's shadow rays in one ray-caster call; a moved capture's cast afresh."""
    captured = {c.index: c for c in moved}
    lights = [captured.get(lm.index, lm) for lm in landmarks.landmarks]
    positions = np.array([lm.position for lm in lights]).reshape(-1, 3)
    visibility = landmarks.visibility(scene.gbuffer.size)
    if visibility is None:
        visibility = scene.visibility(positions)
    elif captured:
        rows = [k for k, lm in enumerate(landmarks.landmarks) if lm.index in captured]
        visibility = visibility.copy()
        visibility[rows] = scene.visibility(positions[rows])
    images = [scene.to_image(scene.pixels(p, v)) for p, v in zip(positions, visibility, strict=True)]
    return np.array(images, np.float32).reshape(len(positions), scene.camera.height, scene.camera.width)


def contact_sheet_figure(
    landmarks: LandmarkSet,
    images: np.ndarray,
    saturation: float,
    columns: int = CONTACT_SHEET_COLUMNS,
    moved: Sequence[Landmark] = (),
) -> Figure:
    """The camera images at the landmarks (:func:`contact_sheet_images`; grey levels 0 to
    ``saturation``) in a grid, each labelled with its index, zenith and azimuth; where the placement
    ``moved`` the capture, the image is the capture's and the label (in :data:`MOVED_COLOR`) gives the
    landmark's zenith, an arrow and the capture's.

    Drawn as images and labels on one axes spanning the figure, laid out in inches
    (:data:`CONTACT_SHEET_CELL_IN`): an axes per image, each with its title, would take about five
    times as long to draw for 36 landmarks (axes, ticks, titles and the tight bounding box of each)."""
    from matplotlib.figure import Figure

    n = len(landmarks)
    cols = max(1, min(columns, n))
    rows = math.ceil(n / cols)
    (cell_w, cell_h), tile = CONTACT_SHEET_CELL_IN, CONTACT_SHEET_TILE_IN
    fig = Figure(figsize=(cell_w * cols, cell_h * rows))
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_xlim(0.0, cell_w * cols)
    ax.set_ylim(cell_h * rows, 0.0)  # inches from the top left corner
    ax.axis("off")
    captured = {c.index: c for c in moved}
    for k, (lm, image) in enumerate(zip(landmarks.landmarks, images, strict=True)):
        x = cell_w * (k % cols) + 0.5 * (cell_w - tile)
        y = cell_h * (k // cols) + cell_h - tile - 0.05
        ax.imshow(image, cmap="gray", vmin=0.0, vmax=saturation, extent=(x, x + tile, y + tile, y))
        zenith = f"{math.degrees(lm.zenith):.1f}°"
        if lm.index in captured:  # from the landmark's zenith to the capture's, along its azimuth
            zenith = f"{math.degrees(lm.zenith):.1f}→{math.degrees(captured[lm.index].zenith):.1f}°"
        ax.text(
            x + 0.5 * tile,
            y - 0.04,
            f"#{lm.index} θ {zenith} φ {math.degrees(lm.azimuth):.0f}°",
            color=MOVED_COLOR if lm.index in captured else "black",
            fontsize=7,
            ha="center",
            va="bottom",
        )
    return fig


def log_color_limits(values: np.ndarray, decades: float = COST_DECADES) -> tuple[float, float]:
    """Limits (vmin, vmax) of a logarithmic colour scale for ``values``: their largest finite value
    and ``decades`` below it, not below :data:`COST_FLOOR`. Values all at or below the floor (a
    term of weight 0, an all-black image), empty or non-finite give one decade above the floor, so
    the map is drawn in its lowest colour rather than refused by the scale (it needs
    0 < vmin < vmax)."""
    finite = values[np.isfinite(values)]
    vmax = float(finite.max(initial=0.0))
    if vmax <= COST_FLOOR:
        return COST_FLOOR, 10.0 * COST_FLOOR
    return max(COST_FLOOR, vmax * 10.0**-decades), vmax


def cost_map_figure(landmarks: LandmarkSet, r_max: float, moved: Sequence[Landmark] = ()) -> Figure:
    """The coarse sweep's cost over (zenith, azimuth) as a polar heat map (radius = zenith in deg up
    to ``r_max`` (rad), logarithmic colours over five decades below the largest cost), the landmarks
    on top and the ``moved`` captures (:func:`moved_captures`) where they are captured."""
    from matplotlib.figure import Figure

    grid = landmarks.sweep
    fig = Figure(figsize=(5.8, 5.0))
    ax = _polar_axes(fig, r_max)
    vmin, vmax = log_color_limits(grid.cost[:, grid.zenith <= r_max + 1e-12])
    cost = np.ma.masked_invalid(np.maximum(grid.cost, COST_FLOOR))
    mesh = ax.pcolormesh(
        _azimuth_edges(grid.azimuth),
        np.degrees(_zenith_edges(grid.zenith)),
        cost.T,
        shading="flat",
        norm=LogNorm(vmin=vmin, vmax=vmax),
        cmap="viridis_r",
    )
    ax.plot(landmarks.azimuths, np.degrees(landmarks.zeniths), "o", mfc="none", color="tab:red", ms=6)
    _draw_moved(ax, landmarks, moved, "tab:red")
    if landmarks.view_zenith > 0:
        circle = np.linspace(0, 2 * np.pi, 361)
        ax.plot(circle, np.full_like(circle, math.degrees(landmarks.view_zenith)), "--", color="white", lw=1.0)
    width, height = landmarks.resolution
    moved_note = "\nfilled: captured elsewhere (moved by the placement)" if moved else ""
    ax.set_title(f"Sweep cost (search renders {width}×{height}), landmarks in red{moved_note}", fontsize=10)
    fig.colorbar(mesh, ax=ax, pad=0.1, shrink=0.8, label="cost")
    return fig


#: The file stems of :func:`landmark_figures`, in its order.
LANDMARK_FIGURES = ("landmarks_polar", "landmarks_histograms", "landmarks_images", "landmarks_cost")


def landmark_figures(
    landmarks: LandmarkSet, scene: Scene, captures: Sequence[Landmark] = ()
) -> dict[str, FigureJob]:
    """The landmark figures by file stem (:data:`LANDMARK_FIGURES`), with the plan's ``captures``
    the placement moved (:func:`moved_captures`; none when ``captures`` is empty). The fixed-zenith
    circle is the reference light's zenith when the reference is a light; the polar plots zoom to
    :func:`radial_limit`. The contact sheet's images are rendered here, from the visibility the
    search kept, so that its job carries images (10 MB for the default's 36 landmarks) rather than
    the scene (26 MB, its ray caster built again and every shadow ray cast again where it is drawn)."""
    moved = moved_captures(captures)
    ref = scene.problem.objective.reference
    fixed = math.radians(ref.zenith_deg) if ref.kind == "light" else None
    r_max = radial_limit(landmarks, scene.sphere.zenith_max, fixed, moved)
    dpi = LANDMARK_FIGURE_DPI
    images = contact_sheet_images(landmarks, scene, moved)
    saturation = scene.light.saturation
    jobs = (
        FigureJob(landmarks_polar_figure, (landmarks, r_max, fixed, moved), dpi),
        FigureJob(histograms_figure, (landmarks,), dpi),
        FigureJob(contact_sheet_figure, (landmarks, images, saturation, CONTACT_SHEET_COLUMNS, moved), dpi),
        FigureJob(cost_map_figure, (landmarks, r_max, moved), dpi),
    )
    return dict(zip(LANDMARK_FIGURES, jobs, strict=True))


def save_landmark_figures(
    landmarks: LandmarkSet, scene: Scene, folder: str | Path, captures: Sequence[Landmark] = ()
) -> list[Path]:
    """All :func:`landmark_figures` written into ``folder`` as ``<name>.png``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    jobs = landmark_figures(landmarks, scene, captures)
    return [job.save(folder / f"{name}.png") for name, job in jobs.items()]
