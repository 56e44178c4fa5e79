"""Reachability map of the light cap."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from conftest import REACH_ONLY, reacher_of, reduced_problem
from matplotlib.backends.backend_agg import FigureCanvasAgg

from optlight.geometry import LightSphere, direction_in_sphere_frame
from optlight.planning.placement import CLEARANCE_TOL, POSE_TOL
from optlight.planning.reach import ClearField, ReachabilityMap, reachability_map
from optlight.robot import load_robot
from optlight.setup import Setup
from optlight.spec import load_problem, problem_from_dict


def test_the_paper_layout_cap_is_fully_reachable_by_the_panda(tmp_path: Path) -> None:
    problem = reduced_problem(**REACH_ONLY)
    reach = reachability_map(
        reacher_of(Setup.from_problem(problem)), zenith_step_deg=10.0, azimuth_step_deg=30.0
    )
    assert reach.zenith.shape == (7,) and reach.azimuth.shape == (12,)
    assert np.isclose(np.rad2deg(reach.zenith[-1]), problem.light_sphere.zenith_max_deg)
    assert reach.success.all() and reach.reachable_fraction == 1.0 and reach.unreachable == []
    assert np.all(reach.manipulability > 0)
    robot = load_robot(problem)
    sphere = LightSphere.from_problem(problem)
    for i, j in [(0, 0), (3, 5), (6, 11)]:
        theta = reach.theta[i, j]
        assert robot.within_limits(theta, tol=0.0)
        zenith, azimuth = sphere.angles(robot.light_pose(theta)[0])
        assert np.isclose(zenith, reach.zenith[i], atol=1e-4)
        if i > 0:
            assert np.isclose(azimuth, reach.azimuth[j], atol=1e-4)

    png, js = reach.save(tmp_path / "out")
    assert png.name == "reachability.png" and png.stat().st_size > 10_000
    data = json.loads(js.read_text())
    assert data["robot"] == "panda" and data["reachable_fraction"] == 1.0
    assert np.allclose(data["zenith_deg"], np.arange(0, 61, 10))
    assert (
        len(data["theta_rad"]) == 7 and len(data["theta_rad"][0]) == 12 and len(data["theta_rad"][0][0]) == 7
    )


def test_unreachable_cells_are_reported(tmp_path: Path) -> None:
    """An object 1.2 m from the base: the near side of the cap is within reach, the far side is not."""
    problem = problem_from_dict(
        {
            "object": {"center_m": [1.2, 0.0, 0.5]},
            "camera": {"position_m": [0.4, 0.0, 0.5]},
            "solver": {"ik_max_iter": 60},
        }
    )
    reach = reachability_map(
        reacher_of(Setup.from_problem(problem)), zenith_step_deg=30.0, azimuth_step_deg=60.0
    )
    assert 0.0 < reach.reachable_fraction < 1.0
    failed = ~reach.success
    assert np.isnan(reach.manipulability[failed]).all() and np.isnan(reach.theta[failed]).all()
    assert len(reach.unreachable) == failed.sum()
    _, js = reach.save(tmp_path)
    data = json.loads(js.read_text())
    i, j = np.argwhere(failed)[0]
    assert data["theta_rad"][i][j] is None and data["manipulability"][i][j] is None


def test_the_environment_takes_cells_away(tmp_path: Path) -> None:
    """table_wall: the arm reaches the far side of the cap only over the camera's view cone. Every
    cell stays reachable by the IK; the taken ones have no clear joint angles, the others have them."""
    problem = load_problem("table_wall")
    setup = Setup.from_problem(problem)
    robot, env, sphere = setup.robot, setup.environment, setup.sphere
    assert env is not None
    reach = reachability_map(reacher_of(setup), zenith_step_deg=6.0, azimuth_step_deg=30.0)
    assert reach.environment and reach.success.all()
    assert reach.taken.any() and reach.clear.any()
    assert 0.0 < reach.taken_fraction < 0.5 and reach.clear_fraction == 1.0 - reach.taken_fraction
    assert 150.0 in {azimuth for _, azimuth in reach.taken_cells}
    assert set(reach.status[reach.taken]) == {"taken"} and set(reach.status[reach.clear]) == {"reachable"}
    for i, j in np.argwhere(reach.success):
        row, _ = env.worst_sphere_row(robot, reach.theta[i, j])
        assert row == pytest.approx(reach.clearance[i, j], abs=1e-12)
        # clear cells keep clear joint angles (the IK's, or found near them by ClearPosture)
        assert (row < -CLEARANCE_TOL) == reach.taken[i, j]
        light = robot.light_pose(reach.theta[i, j])[0]
        target = sphere.position(reach.zenith[i], reach.azimuth[j])
        assert np.linalg.norm(light - target) <= max(reach.residual[i, j], POSE_TOL) + 1e-12

    free = problem_from_dict({**problem.to_dict(), "environment": {"enabled": False}}, source=problem.source)
    bare = dataclasses.replace(setup, problem=free, environment=None)
    without = reachability_map(reacher_of(bare), zenith_step_deg=6.0, azimuth_step_deg=30.0)
    assert not without.environment and not without.taken.any() and np.isnan(without.clearance).all()
    np.testing.assert_array_equal(without.success, reach.success)  # the IK part does not change

    png, js = reach.save(tmp_path)
    assert png.stat().st_size > 10_000
    data = json.loads(js.read_text())
    assert data["environment"] is True and data["taken_fraction"] == reach.taken_fraction
    # the legend (taken cells) lies below the polar plot and its labels: it once covered the 270° one
    figure = reach.figure()
    canvas = FigureCanvasAgg(figure)
    canvas.draw()
    renderer = canvas.get_renderer()
    (legend,) = figure.legends
    polar = figure.axes[0].get_tightbbox(renderer)
    assert legend.get_window_extent(renderer).y1 <= polar.y0
    i, j = np.argwhere(reach.taken)[0]
    assert data["status"][i][j] == "taken" and data["success"][i][j] is True and data["clearance_m"][i][j] < 0


def test_no_blocked_cell_is_clear_from_a_clear_neighbours_posture() -> None:
    """rti_dome: the panda crosses the camera's view cone on part of the cap, and which posture a cell
    is started from decides whether the arm is clear there. At the map's end no blocked cell (taken
    or unreached) is reached clear from the posture of a clear neighbour (the grow pass's fixed
    point; the azimuth-chained pass alone leaves such cells), and every clear cell's posture holds the
    light at the cell (pinocchio) clear of every environment row."""
    setup = Setup.from_problem(reduced_problem("rti_dome", camera_px=32))
    robot, env, sphere = setup.robot, setup.environment, setup.sphere
    assert env is not None
    reach = reachability_map(reacher_of(setup), zenith_step_deg=6.0, azimuth_step_deg=20.0)
    assert reach.taken.any() and reach.clear_fraction > 0.5
    reacher = reacher_of(setup)
    n_z, n_a = reach.taken.shape
    for i, j in np.argwhere(~reach.clear):
        target = sphere.position(reach.zenith[i], reach.azimuth[j])
        for ni, nj in ((i, (j - 1) % n_a), (i, (j + 1) % n_a), (i - 1, j), (i + 1, j)):
            if 0 <= ni < n_z and reach.clear[ni, nj]:
                assert reacher.attempt(target, reach.theta[ni, nj]).theta is None, (i, j, ni, nj)
    for i, j in np.argwhere(reach.clear):
        light = robot.light_pose(reach.theta[i, j])[0]
        target = sphere.position(reach.zenith[i], reach.azimuth[j])
        assert np.linalg.norm(light - target) <= max(reach.residual[i, j], POSE_TOL) + 1e-12
        assert env.worst_sphere_row(robot, reach.theta[i, j])[0] >= -CLEARANCE_TOL


def _half_clear_map() -> ReachabilityMap:
    """A synthetic map of 4 zenith rings × 36 azimuths, clear for azimuths 0–170°, taken for 180–350°."""
    zenith, azimuth = np.deg2rad([20.0, 25.0, 30.0, 35.0]), np.deg2rad(np.arange(36) * 10.0)
    shape = (len(zenith), len(azimuth))
    taken = np.zeros(shape, bool)
    taken[:, 18:] = True
    nan = np.full(shape, np.nan)
    return ReachabilityMap(
        "synthetic", zenith, azimuth, np.ones(shape, bool), nan, np.full((*shape, 7), np.nan), nan, 0.0,
        environment=True, taken=taken, clearance=nan,
    )


def test_clear_field_casadi_form_and_gradient() -> None:
    """The CasADi form equals the NumPy form, and its gradient the NumPy form's central differences."""
    field = ClearField.from_map(_half_clear_map())
    rng = np.random.default_rng(3)
    d = direction_in_sphere_frame(rng.uniform(0.3, 0.6, 6), rng.uniform(0.0, 2 * np.pi, 6))
    x = ca.MX.sym("d", 6, 3)
    f = ca.Function("f", [x], [field.casadi(x)])
    g = ca.Function("g", [x], [ca.jacobian(ca.sum1(field.casadi(x)), x)])
    np.testing.assert_allclose(f(d).full().ravel(), field.numpy(d), rtol=0, atol=1e-12)
    grad = np.reshape(np.asarray(g(d)), (3, 6)).T  # CasADi vectorises column-major
    h = 1e-6
    numeric = np.zeros_like(d)
    for k in range(6):
        for c in range(3):
            e = np.zeros_like(d)
            e[k, c] = h
            numeric[k, c] = (field.numpy(d[k] + e[k]) - field.numpy(d[k] - e[k])) / (2 * h)
    np.testing.assert_allclose(grad, numeric, rtol=1e-5, atol=1e-6)


def test_clear_field_sign_follows_the_map() -> None:
    """Positive at clear cells, negative at taken ones; zero on the plane through azimuths 175° and
    355°, which the reflection φ → 350° − φ maps onto itself while it swaps the clear and the taken
    cells (the field is odd under it)."""
    reach = _half_clear_map()
    field = ClearField.from_map(reach)
    zenith, azimuth = np.meshgrid(reach.zenith, reach.azimuth, indexing="ij")
    values = field.numpy(direction_in_sphere_frame(zenith, azimuth))
    assert np.all(values[reach.clear] > 0.5) and np.all(values[reach.taken] < -0.5)
    on_plane = direction_in_sphere_frame(np.deg2rad([18.0, 27.0, 37.0]), np.deg2rad([175.0, 355.0, 175.0]))
    np.testing.assert_allclose(field.numpy(on_plane), 0.0, atol=1e-12)
