"""MuJoCo execution of a results folder: the MJCF model against pinocchio, and `optlight simulate` on
a small plan (tracking, the light at the triggers, torques), and on a lamp the arm cannot carry."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import mujoco
import numpy as np
import pytest
from conftest import reduced_problem

import optlight
from optlight.cli import main
from optlight.export import read_joint_trajectory
from optlight.robot import Dynamics, Lamp, load_robot
from optlight.simulation import mjcf_of, simulate, simulate_folder

LAMP = Lamp(0.3, (0.0, 0.0, 0.04), 0.03, 0.06)


@pytest.mark.parametrize("name", ["panda", "kinova"])  # kinova: continuous joints
def test_the_mujoco_model_has_the_dynamics_and_light_frame_of_the_pinocchio_model(name: str) -> None:
    """MuJoCo's inverse dynamics of the MJCF equal pinocchio's RNEA of the model it was written from
    (lamp included), and its light site is the robot's light frame."""
    robot = load_robot(name)
    dynamics = Dynamics(robot, LAMP)
    model = mujoco.MjModel.from_xml_string(mjcf_of(dynamics, 1e-3))
    data = mujoco.MjData(model)
    rng = np.random.default_rng(2)
    for theta in robot.random_configuration(rng, 4):
        v, a = rng.normal(size=robot.n), rng.normal(size=robot.n)
        data.qpos[:], data.qvel[:], data.qacc[:] = theta, v, a
        mujoco.mj_inverse(model, data)
        np.testing.assert_allclose(data.qfrc_inverse, dynamics.torques(theta[None], v[None], a[None])[0], atol=1e-8)
        position, rotation = robot.light_pose(theta)
        site = model.site("light").id
        np.testing.assert_allclose(data.site_xpos[site], position, atol=1e-12)
        np.testing.assert_allclose(data.site_xmat[site].reshape(3, 3), rotation, atol=1e-12)


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> Path:
    plan = optlight.solve(reduced_problem(camera_px=96, landmarks={"count": 3}))
    folder = tmp_path_factory.mktemp("simulate") / "plan"
    plan.save(folder, preview=False)
    return folder


def test_simulate_follows_the_plan_and_puts_the_light_at_each_trigger(
    results: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "simulation.json"
    assert main(["simulate", str(results), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "computed torque at 1000 Hz" in printed and "light at the 3 triggers" in printed
    report = json.loads(out.read_text())
    assert len(report["trigger_position_error_m"]) == 3
    assert max(report["trigger_position_error_m"]) <= 1e-3 and max(report["trigger_axis_error_rad"]) <= 1e-3
    assert max(report["tracking_error_rad"]) <= 1e-3 and report["saturated_steps"] == 0
    assert all(0 < tau < limit for tau, limit in zip(report["peak_torque_nm"], report["torque_limit_nm"], strict=True))
    assert main(["simulate", str(results), "--out", str(out)]) == 2  # not over the earlier file without --force
    assert "--out" in capsys.readouterr().err


def test_a_lamp_the_arm_cannot_carry_saturates_and_misses_the_triggers(results: Path) -> None:
    """The same reference run with a 30 kg lamp: the torques clip at the limits, the arm sags and the
    light is far from its planned place at the triggers."""
    ok = simulate_folder(results)
    plan = json.loads((results / "plan.json").read_text())
    robot = load_robot(plan["problem"]["robot"]["name"])
    heavy = Dynamics(robot, dataclasses.replace(LAMP, mass_kg=30.0))
    reference = read_joint_trajectory(results / "joint_trajectory.yaml")
    sagging = simulate(
        heavy,
        reference,
        rate_hz=1000.0,
        trigger_times=np.array(ok.trigger_times_s),
        planned_positions=np.array([robot.light_pose(q)[0] for q in reference.sample(np.array(ok.trigger_times_s))[0]]),
        planned_axes=np.array([robot.light_pose(q)[1][:, 2] for q in reference.sample(np.array(ok.trigger_times_s))[0]]),
    )
    assert sagging.saturated_steps > 0
    assert max(sagging.trigger_position_error_m) > 10 * max(max(ok.trigger_position_error_m), 1e-4)


def test_simulate_refuses_a_folder_that_is_not_a_results_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "notes.txt").write_text("x")
    assert main(["simulate", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("optlight: error: RESULTS_DIR: ") and "plan.json" in err and len(err.splitlines()) == 1
