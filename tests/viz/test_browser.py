"""The offline preview in a real browser: headless Chromium (Debian's, through playwright) renders
the saved HTML with WebGL on SwiftShader; the robot must be visible where its joints project.

Skipped only when /usr/bin/chromium is missing (``.ci/run`` installs it). Flags as docs/design.md §7
says; playwright's own browsers are never downloaded.
"""

from __future__ import annotations

import io
import time
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from PIL import Image
from playwright.sync_api import Page, sync_playwright

from optlight.planning.timing import time_parameterize
from optlight.robot import load_robot
from optlight.scene import Scene
from optlight.spec import problem_from_dict
from optlight.viz.preview import Preview

CHROMIUM = Path("/usr/bin/chromium")
FLAGS = [
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--no-sandbox",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-quic",
]
VIEWPORT = {"width": 800, "height": 600}

pytestmark = pytest.mark.skipif(not CHROMIUM.exists(), reason=f"browser test skipped: {CHROMIUM} is missing")

#: Screen position (px) of meshcat world points, through the viewer's scene graph and camera.
PROJECT_JS = """(points) => {
  const T = MeshCat.THREE;
  const root = viewer.scene_tree.find(["meshcat"]).object;
  root.updateMatrixWorld(true);
  viewer.camera.updateMatrixWorld(true);
  const canvas = viewer.renderer.domElement.getBoundingClientRect();
  return points.map(([x, y, z]) => {
    const p = root.localToWorld(new T.Vector3(x, y, z)).project(viewer.camera);
    return [canvas.left + (p.x + 1) / 2 * canvas.width, canvas.top + (1 - p.y) / 2 * canvas.height];
  });
}"""


#: Seek the animation to t (s); the light node's position (meshcat world frame) and the clip's length.
SEEK_JS = """(t) => {
  viewer.animator.seek(t);
  const light = viewer.scene_tree.find(["meshcat", "light"]).object;
  return [light.position.toArray(), viewer.animator.duration];
}"""


def drawn_fraction(shot: np.ndarray) -> float:
    """Fraction of the pixels that differ from meshcat's background, a vertical gradient (constant
    along each row): pixels away from their row's median. The top rows (meshcat's controls bar) are
    left out."""
    body = shot[40:].astype(np.int32)
    return float((np.abs(body - np.median(body, axis=1, keepdims=True)).sum(axis=2) > 30).mean())


def settled_screenshot(page: Page, timeout_s: float = 20.0) -> np.ndarray:
    """A screenshot (H, W, 3) once the page has drawn a scene and two shots in a row agree."""
    deadline = time.monotonic() + timeout_s
    previous = None
    while time.monotonic() < deadline:
        shot = np.asarray(Image.open(io.BytesIO(page.screenshot())).convert("RGB"), dtype=np.int16)
        if previous is not None and drawn_fraction(shot) > 0.01 and np.array_equal(shot, previous):
            return shot
        previous = shot
        page.wait_for_timeout(250)
    raise AssertionError(f"the preview did not settle within {timeout_s} s")


def open_preview(page: Page, path: Path) -> np.ndarray:
    """Load a saved preview, stop its animation at t = 0 and screenshot it."""
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(path.as_uri())
    page.wait_for_function(
        "typeof viewer !== 'undefined' && viewer.animator.actions.length > 0", timeout=20000
    )
    page.evaluate("viewer.animator.pause(); viewer.animator.seek(0)")
    shot = settled_screenshot(page)
    assert not errors, errors
    return shot


@pytest.mark.slow
def test_offline_preview_draws_the_robot(tmp_path):
    # the paper's layout: the robot at θ_ref stands clear of the face and the sphere on screen
    problem = problem_from_dict(
        {
            "robot": {"name": "panda"},
            "object": {"face": {"resolution": 48}, "center_m": [0.35, 0.0, 0.45]},
            "camera": {"position_m": [-0.343, -0.4, 0.45]},
        }
    )
    scene = Scene.from_problem(problem, width=32, height=32)
    robot = load_robot(problem)
    landmarks = scene.sphere.position(np.full(8, 0.5), np.linspace(0, 2 * np.pi, 8, endpoint=False))
    knots = robot.theta_ref + np.linspace(0.0, 1.0, 3)[:, None] * np.array([0.4, 0.2, 0, -0.2, 0, 0.2, 0.4])
    trajectory = time_parameterize([knots], robot.velocity_limit, robot.acceleration_limit, dwell_s=0.2)
    args = (scene, robot, landmarks, np.arange(8.0), landmarks, trajectory)
    lit = {"light_position": landmarks[0]}  # the face lit from a landmark in front, not from θ_ref
    with_robot = Preview(*args, **lit).save_html(tmp_path / "with_robot.html")
    without_robot = Preview(*args, **lit, show_robot=False).save_html(tmp_path / "without_robot.html")

    # Scrubbing the animation puts the light where the kinematics has it then (keyframes
    # interpolated by three.js itself), and the clip lasts the trajectory's duration.
    scrub_times = [0.37 * trajectory.duration, 0.81 * trajectory.duration]

    # Where the robot is at t = 0: the origins of its frames (links, joints, flange, light).
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.to_pin(trajectory.sample(0.0)[0][0]))
    robot_points = [f.translation.tolist() for f in data.oMf[1:]]

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=FLAGS)
        try:
            page = browser.new_page(viewport=VIEWPORT)
            shot_robot = open_preview(page, with_robot)
            corners = np.array(page.evaluate(PROJECT_JS, robot_points))
            scrubbed = {t: page.evaluate(SEEK_JS, t) for t in scrub_times}
            page = browser.new_page(viewport=VIEWPORT)
            shot_empty = open_preview(page, without_robot)
        finally:
            browser.close()
    for t, (position, duration) in scrubbed.items():
        assert duration == pytest.approx(trajectory.duration, abs=1e-4)
        expected, _ = robot.light_pose(trajectory.sample(t)[0][0])
        np.testing.assert_allclose(position, expected, atol=1e-3)
    Image.fromarray(shot_robot.astype(np.uint8)).save(tmp_path / "with_robot.png")
    Image.fromarray(shot_empty.astype(np.uint8)).save(tmp_path / "without_robot.png")

    # Not blank: object, sphere, landmarks, camera and robot cover a good part of the picture.
    assert drawn_fraction(shot_empty) > 0.03
    assert drawn_fraction(shot_robot) > drawn_fraction(shot_empty)
    # The robot: a substantial difference inside the box around its frames' screen positions, and
    # (apart from the robot) the same picture elsewhere.
    changed = np.abs(shot_robot - shot_empty).sum(axis=2) > 40
    margin = 25
    x0, y0 = np.floor(corners.min(axis=0)).astype(int) - margin
    x1, y1 = np.ceil(corners.max(axis=0)).astype(int) + margin
    assert 0 <= x0 < x1 <= VIEWPORT["width"] and 0 <= y0 < y1 <= VIEWPORT["height"]
    inside = np.zeros_like(changed)
    inside[y0:y1, x0:x1] = True
    assert changed[inside].mean() > 0.15, f"robot covers {changed[inside].mean():.1%} of its box"
    assert changed[~inside].mean() < 0.005, f"{changed[~inside].mean():.2%} changed outside the robot's box"
