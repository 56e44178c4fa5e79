"""Figures drawn without layout engines: the contact sheet puts each landmark's image in its cell,
the trajectory figure shades every dwell across the whole height of every axes."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from PIL import Image

from optlight.geometry import LightSphere, sphere_frame
from optlight.planning.timing import time_parameterize
from optlight.robot import load_robot
from optlight.scene import Scene
from optlight.spec import problem_from_dict
from optlight.viz.drawing import FigureJob
from optlight.viz.figures import (
    CONTACT_SHEET_CELL_IN,
    CONTACT_SHEET_TILE_IN,
    contact_sheet_figure,
    contact_sheet_images,
)
from optlight.viz.trajectory_figures import path_figure, trajectory_figure


def centroid(image: np.ndarray) -> np.ndarray:
    """Brightness-weighted centre (x, y) of an image, as fractions of its width and height."""
    h, w = image.shape
    total = image.sum()
    return np.array([(image.sum(axis=0) @ np.arange(w)) / total / w, (image.sum(axis=1) @ np.arange(h)) / total / h])


def test_contact_sheet_puts_each_image_in_its_cell(tmp_path):
    """A sphere lit from eight azimuths, drawn in rows of three: in the PNG, the brightness centre
    of each cell's tile is where it is in that light's render (the tile is the right image, upright
    and unmirrored)."""
    problem = problem_from_dict({"object": {"kind": "sphere", "radius_m": 0.08}, "light": {"cast_shadows": False}})
    scene = Scene.from_problem(problem, width=48, height=48)
    azimuths = np.linspace(0.0, 2 * np.pi, 8, endpoint=False)
    positions = scene.sphere.position(np.full(8, 0.9), azimuths)
    landmarks = _Sized(
        SimpleNamespace(index=i, zenith=0.9, azimuth=a, position=p)
        for i, (a, p) in enumerate(zip(azimuths, positions, strict=True))
    )
    images = contact_sheet_images(landmarks, scene)  # type: ignore[arg-type]
    figure = contact_sheet_figure(landmarks, images, scene.light.saturation, columns=3)  # type: ignore[arg-type]
    sheet = FigureJob.of(figure, 110).save(tmp_path / "sheet.png")
    png = np.asarray(Image.open(sheet).convert("L"), float)
    dpi = png.shape[1] / (3 * CONTACT_SHEET_CELL_IN[0])
    (cell_w, cell_h), tile = CONTACT_SHEET_CELL_IN, CONTACT_SHEET_TILE_IN
    assert abs(png.shape[0] - math.ceil(8 / 3) * cell_h * dpi) <= 1  # three rows
    for k, position in enumerate(positions):
        x = (cell_w * (k % 3) + 0.5 * (cell_w - tile)) * dpi
        y = (cell_h * (k // 3) + cell_h - tile - 0.05) * dpi
        margin = 2  # pixels at the tile's edge may blend with the white around it
        drawn = png[round(y) + margin : round(y + tile * dpi) - margin, round(x) + margin : round(x + tile * dpi) - margin]
        expected = centroid(scene.render(position))
        np.testing.assert_allclose(centroid(drawn), expected, atol=0.02, err_msg=f"cell {k}")
    # the lights go round: their images' bright sides differ, so the comparison above discriminates
    spread = np.ptp([centroid(scene.render(p)) for p in positions], axis=0)
    assert spread.min() > 0.05


class _Sized(list):
    """Landmarks standing in for a LandmarkSet: what the contact sheet reads (``len``, ``.landmarks``)."""

    @property
    def landmarks(self) -> list:
        return list(self)

    def visibility(self, pixels: int) -> None:
        """No kept visibility: the contact sheet casts its own shadow rays."""


def robot_trajectory_figure(trajectory, robot):
    """The trajectory figure against ``robot``'s own limits."""
    return trajectory_figure(
        trajectory,
        lower=robot.lower,
        upper=robot.upper,
        velocity_limit=robot.velocity_limit,
        acceleration_limit=robot.acceleration_limit,
    )


def test_trajectory_figure_shades_every_dwell_full_height(tmp_path):
    robot = load_robot("panda")
    knots = robot.theta_ref + np.linspace(0.0, 1.0, 4)[:, None] * np.array([0.4, 0.2, 0, -0.2, 0, 0.2, 0.4])
    trajectory = time_parameterize([knots[:2], knots[1:3], knots[2:]], robot.velocity_limit, robot.acceleration_limit, dwell_s=0.3)
    fig = robot_trajectory_figure(trajectory, robot)
    fig.savefig(tmp_path / "trajectory.png", dpi=fig.dpi)  # the pixels the transforms below give
    png = np.asarray(Image.open(tmp_path / "trajectory.png").convert("L"), float)
    height = png.shape[0]
    assert len(fig.axes) == 3 * trajectory.dof
    for ax in fig.axes:
        bbox = ax.get_window_extent()
        rows = height - np.linspace(bbox.y0 + 0.01 * bbox.height, bbox.y1 - 0.01 * bbox.height, 50)
        for a, b in trajectory.landmark_intervals:
            # a column a fifth into the dwell (off the capture line): grey from bottom to top, but
            # where the curve or a limit line crosses it
            x = round(ax.transData.transform((a + 0.2 * (b - a), 0.0))[0])
            grey = np.abs(png[np.round(rows).astype(int), x] - 0.85 * 255) < 8
            assert grey[:3].any() and grey[-3:].any() and grey.mean() > 0.85


def test_trajectory_figure_spans_the_motion_with_time_ticks_on_its_bottom_row():
    """Every axes spans the trajectory's time exactly; only the bottom row carries time ticks (and
    the label), the rows above none."""
    robot = load_robot("panda")
    knots = robot.theta_ref + np.linspace(0.0, 1.0, 3)[:, None] * 0.3
    trajectory = time_parameterize([knots[:2], knots[1:]], robot.velocity_limit, robot.acceleration_limit, dwell_s=0.2)
    fig = robot_trajectory_figure(trajectory, robot)
    fig.canvas.draw()
    axes = np.array(fig.axes).reshape(trajectory.dof, 3)
    times = trajectory.sample_times(200.0)
    for ax in axes.ravel():
        assert ax.get_xlim() == (times[0], times[-1])
    for ax in axes[-1]:
        assert ax.get_xlabel() == "t [s]" and len(ax.get_xticks()) >= 3
    for ax in axes[:-1].ravel():
        assert len(ax.get_xticks()) == 0


def test_the_path_figures_3d_labels_do_not_run_together():
    """The 3-D view of the default plan's path (a 0.4 m sphere): at most five labelled ticks per axis
    (matplotlib's default gave the x axis nine, whose labels ran into each other), drawn apart."""
    center = np.array([0.5, 0.0, 0.4])
    sphere = LightSphere(center, 0.4, sphere_frame(center, center + np.array([0.0, 0.0, 1.0])))
    ring = sphere.position(np.full(12, 0.3), np.linspace(0.0, 2 * np.pi, 12, endpoint=False))
    figure = path_figure(sphere, ring, ring, ring)
    canvas = FigureCanvasAgg(figure)
    canvas.draw()  # the ticks are laid out as in the PNG
    view, renderer = figure.axes[1], canvas.get_renderer()
    for axis in (view.xaxis, view.yaxis, view.zaxis):
        lo, hi = sorted(axis.get_view_interval())
        shown = zip(axis.get_majorticklocs(), axis.get_ticklabels(), strict=True)
        labels = [label for at, label in shown if lo <= at <= hi and label.get_text()]
        assert 2 <= len(labels) <= 5, [t.get_text() for t in labels]
        boxes = [t.get_window_extent(renderer) for t in labels]
        assert not any(a.overlaps(b) for i, a in enumerate(boxes) for b in boxes[i + 1 :]), labels  # apart
