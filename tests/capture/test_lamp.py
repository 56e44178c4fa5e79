"""The lamp's calibration (optlight/capture/lamp.py): its gradient against finite differences, a known
offset on the flange recovered from captures rendered with it (the NumPy renderer and Mitsuba), zero
read as zero, and the lamp's frame the re-plan uses."""

from __future__ import annotations

import csv
import dataclasses
import json
import re
import shlex
from pathlib import Path

import mitsuba  # noqa: F401 - a missing Mitsuba must fail these tests, never skip them
import numpy as np
import pinocchio as pin
import pytest

from optlight import cli, load_problem
from optlight.acquisition import acquire
from optlight.acquisition.loop import trigger_joints
from optlight.capture import ModelCamera, real_lamp, write_capture_png
from optlight.capture.calibration import calibrate, lamp_robot
from optlight.capture.lamp import LampGeometry, lamp_shading
from optlight.capture.mitsuba import MitsubaCamera
from optlight.errors import ProblemError
from optlight.jsondata import json_safe
from optlight.robot import load_robot
from optlight.robot.loading import placement
from optlight.scene import Scene
from optlight.setup import Setup
from optlight.spec import LoopSpec, RobotSpec, WorldSpec, problem_from_dict

#: Lights (zenith, azimuth in degrees) of the captures.
LIGHTS_DEG = [(15, 0), (25, 45), (35, 90), (45, 135), (55, 180), (30, 225), (40, 270), (50, 315), (20, 200), (60, 100)]


#: A tiny problem in the layout where the panda reaches the whole cap (conftest.REACH_ONLY), its lamp
#: 3 cm off on the flange, two rounds.
LAMP_PROBLEM = (
    "[object]\ncenter_m = [0.35, 0.0, 0.45]\n[camera]\nposition_m = [-0.343, -0.4, 0.45]\n"
    'width = 64\nheight = 64\n[view]\nmode = "off"\n[landmarks]\ncount = 4\nresolution = 32\n'
    "[world]\nlamp_offset_m = [0.03, 0.0, 0.0]\ngamma = 2.2\nambient = 0.1\n[loop]\niterations = 2\n"
)


@pytest.fixture(scope="module")
def face_scene() -> Scene:
    return Scene.from_problem(
        problem_from_dict(
            {"light": {"model": "point"}, "object": {"face": {"resolution": 64}}, "camera": {"width": 96, "height": 96}}
        )
    )


def light_frames(scene: Scene, lights=LIGHTS_DEG) -> list[tuple[np.ndarray, np.ndarray]]:
    """Nominal light frames on the sphere aimed at O (+z towards it), rolled arbitrarily about the axis."""
    sphere = scene.sphere
    frames = []
    for z, a in lights:
        position = sphere.position(np.deg2rad(z), np.deg2rad(a))
        axis = (sphere.center - position) / np.linalg.norm(sphere.center - position)
        x = np.cross([0.3, 0.5, 0.8], axis)
        x /= np.linalg.norm(x)
        frames.append((position, np.column_stack([x, np.cross(axis, x), axis])))
    return frames


def test_lamp_shading_gradient_agrees_with_finite_differences(face_scene: Scene) -> None:
    gb = face_scene.gbuffer
    pixels = np.arange(0, gb.size, 40)
    frames = light_frames(face_scene)
    offset = np.array([0.01, -0.02, 0.005])
    for model in ("point", "directional"):
        geometry = LampGeometry(
            gb.points[pixels],
            gb.normals[pixels],
            np.array([p for p, _ in frames]),
            np.array([r for _, r in frames]),
            np.ones((len(frames), pixels.size)),
            model,
            np.asarray(face_scene.sphere.center, float),
            float(face_scene.sphere.radius),
        )
        _, analytic = lamp_shading(offset, geometry)
        for j in range(3):
            step = np.zeros(3)
            step[j] = 1e-6
            numeric = (lamp_shading(offset + step, geometry)[0] - lamp_shading(offset - step, geometry)[0]) / 2e-6
            assert np.abs(numeric).max() > 0.1  # the offset changes the shading
            np.testing.assert_allclose(analytic[..., j], numeric, atol=1e-6 * np.abs(numeric).max())


@pytest.mark.parametrize(
    ("offset", "tolerance_mm"),
    [((0.03, 0.0, 0.0), 5.0), ((0.0, -0.03, 0.0), 5.0), ((0.0, 0.0, 0.0), 1.0)],
)
def test_a_known_offset_on_the_flange_is_recovered(face_scene: Scene, offset, tolerance_mm: float) -> None:
    """The NumPy renderer with the lamp off on the flange, γ 2.2, ambient and noise: the lateral offset
    comes back within the tolerance, every component identifiable, and the photometric fit with it."""
    world = WorldSpec(lamp_offset_m=offset, gamma=2.2, ambient=0.1, noise_std=0.005)
    camera = ModelCamera(face_scene, world)
    captures = [camera.capture(p, k, r) for k, (p, r) in enumerate(light_frames(face_scene))]
    calibration = calibrate(face_scene, captures, LoopSpec())
    lamp = calibration.lamp
    assert lamp is not None and all(lamp.identifiable)
    error_mm = 1e3 * np.abs(np.array(lamp.estimate_m) - np.array(offset[:2]))
    assert error_mm.max() <= tolerance_mm, lamp.summary()
    assert calibration.gamma == pytest.approx(2.2, rel=0.03)
    positions = lamp.positions(np.array([c.light_position for c in captures]), np.array([c.light_rotation for c in captures]))
    truth = np.array([real_lamp(c.light_position, c.light_rotation, world)[0] for c in captures])
    assert np.abs(positions - truth).max() <= 1e-3 * tolerance_mm


def test_the_nominal_lamp_is_kept_when_asked_or_without_rotations(face_scene: Scene) -> None:
    camera = ModelCamera(face_scene, WorldSpec(lamp_offset_m=(0.03, 0.0, 0.0)))
    frames = light_frames(face_scene)
    with_rotation = [camera.capture(p, k, r) for k, (p, r) in enumerate(frames)]
    assert calibrate(face_scene, with_rotation, LoopSpec(lamp="nominal")).lamp is None
    without = [dataclasses.replace(c, light_rotation=None) for c in with_rotation]
    assert calibrate(face_scene, without, LoopSpec()).lamp is None


def test_the_lamp_offset_turns_with_the_flange() -> None:
    """The world's lamp offset is in the light frame: a' = a + R δ_L (+ the world-frame offset)."""
    rotation = np.asarray(pin.rpy.rpyToMatrix(0.3, -0.4, 1.1), float)
    world = WorldSpec(lamp_offset_m=(0.01, 0.02, -0.03), light_offset_m=(0.0, 0.0, 0.005), lamp_rpy_deg=(10.0, 0.0, 0.0))
    position, axis = real_lamp(np.zeros(3), rotation, world)
    np.testing.assert_allclose(position, rotation @ [0.01, 0.02, -0.03] + [0.0, 0.0, 0.005], atol=1e-15)
    np.testing.assert_allclose(axis, rotation @ [0.0, -np.sin(np.deg2rad(10)), np.cos(np.deg2rad(10))], atol=1e-12)
    assert real_lamp(np.zeros(3), None, world)[1] is None


def test_the_replanned_robot_puts_the_calibrated_lamp_where_the_real_one_is(face_scene: Scene) -> None:
    """lamp_robot moves [robot]'s light frame by R_o δ: forward kinematics of the new frame (pinocchio)
    is the nominal frame's position plus R δ at any joint angles."""
    camera = ModelCamera(face_scene, WorldSpec(lamp_offset_m=(0.0, 0.03, 0.0)))
    captures = [camera.capture(p, k, r) for k, (p, r) in enumerate(light_frames(face_scene))]
    lamp = calibrate(face_scene, captures, LoopSpec()).lamp
    assert lamp is not None
    spec = RobotSpec(name="panda", light_offset_m=(0.0, 0.0, 0.05), light_rpy_deg=(0.0, 20.0, 0.0))
    nominal, moved = load_robot(spec), load_robot(lamp_robot(spec, lamp))
    q = nominal.theta_ref + 0.2
    a, rotation = nominal.light_pose(q)
    expected = a + rotation @ lamp.offset_m
    np.testing.assert_allclose(moved.light_pose(q)[0], expected, atol=1e-12)
    np.testing.assert_allclose(moved.light_pose(q)[0], a + rotation @ [0.0, 0.03, 0.0], atol=5e-3)
    offset_frame = placement(spec.light_offset_m, spec.light_rpy_deg)
    assert np.linalg.norm(offset_frame.translation - np.asarray(lamp_robot(spec, lamp).light_offset_m)) > 0.02


def test_mitsuba_lamp_off_on_the_flange_is_recovered() -> None:
    """The physically based camera (a 1.5 cm disk lamp 3 cm off on the flange, γ 2.2, noise) on a
    small face: the calibration recovers the lateral offset within 5 mm."""
    problem = problem_from_dict(
        {
            "light": {"model": "point"},
            "object": {"face": {"resolution": 48}},
            "camera": {"width": 64, "height": 64},
            "world": {
                "lamp_offset_m": [0.03, 0.0, 0.0],
                "light_radius_m": 0.015,
                "light_profile": "lambertian",
                "gamma": 2.2,
                "noise_std": 0.003,
                "spp": 32,
            },
        }
    )
    scene = Scene.from_problem(problem)
    camera = MitsubaCamera(scene, problem.world)
    captures = [camera.capture(p, k, r) for k, (p, r) in enumerate(light_frames(scene, LIGHTS_DEG[:8]))]
    lamp = calibrate(scene, captures, problem.loop).lamp
    assert lamp is not None and all(lamp.identifiable)
    assert 1e3 * np.linalg.norm(np.array(lamp.estimate_m) - [0.03, 0.0]) <= 5.0, lamp.summary()


@pytest.mark.slow
def test_the_loop_replans_with_the_calibrated_lamp(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A lamp 3 cm off on the flange: the open-loop plan's lamp lands 3 cm from where the plan believes;
    the re-plan (robot light frame moved by the calibration) puts the real lamp within 5 mm of it, and
    acquisition.json and the CLI report the offset."""
    problem = tmp_path / "lamp.toml"
    problem.write_text(LAMP_PROBLEM)
    result = acquire(problem, "model")
    world = result.setup.problem.world
    assert len(result.iterations) == 2
    misses = []
    for it in result.iterations:
        believed = it.plan.robot.light_positions(trigger_joints(it.plan))
        real = np.array([real_lamp(c.light_position, c.light_rotation, world)[0] for c in it.captures])
        misses.append(np.linalg.norm(real - believed, axis=1).max())
    assert misses[0] == pytest.approx(0.03, abs=1e-9)
    assert misses[1] <= 5e-3
    lamp = result.iterations[0].calibration.lamp
    reported = json.loads(json.dumps(json_safe(result.iterations[0].to_dict())))["calibration"]["lamp"]
    assert reported["applied_offset_m"] == pytest.approx(lamp.offset_m.tolist())
    out = tmp_path / "out"
    assert cli.main(["acquire", str(problem), "--camera", "model", "--out", str(out)]) == 0
    assert "lamp offset on the flange (light frame): x +" in capsys.readouterr().out
    assert json.loads((out / "calibration.json").read_text())["lamp"]["applied_offset_m"][0] == pytest.approx(0.03, abs=5e-3)


@pytest.mark.slow
def test_folder_camera_rounds_with_a_lamp_off_on_the_flange(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The round protocol with a lamp 3 cm off: the lab (the model camera) puts the real lamp where the
    row's joint angles put the nominal light frame, moved by the true offset; the second round's
    captures.csv, written with the calibrated light frame, still finds its images, and the calibration
    recovers the offset within 5 mm."""
    problem = tmp_path / "lamp.toml"
    problem.write_text(LAMP_PROBLEM)
    loaded = load_problem(problem)
    setup = Setup.from_problem(loaded)
    camera = ModelCamera(setup.scene, loaded.world)
    out = tmp_path / "acquisition"
    assert cli.main(["acquire", str(problem), "--camera", "folder", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    rounds = 0
    while "the dataset is in" not in text:
        folder = Path(re.search(r"^  3\. save each image .* in (\S+)/: ", text, re.M).group(1))
        with (folder / "captures.csv").open(newline="") as f:
            for row in csv.DictReader(f):
                q = [float(row[f"q_{n}"]) for n in setup.robot.joint_names]
                position, rotation = setup.robot.light_pose(q)
                image = camera.capture(position, 0, rotation).image
                write_capture_png(folder / row["image"], image, loaded.light.saturation)
        rounds += 1
        assert cli.main(shlex.split(text.strip().splitlines()[-1])[1:]) == 0
        text = capsys.readouterr().out
    assert rounds == 2
    lamp = json.loads((out / "calibration.json").read_text())["lamp"]
    assert lamp["applied_offset_m"] == pytest.approx([0.03, 0.0, 0.0], abs=5e-3)


def test_a_lamp_offset_beyond_the_light_sphere_is_refused() -> None:
    with pytest.raises(ProblemError, match=r"world\.lamp_offset_m: expected an offset shorter than the light sphere's radius"):
        problem_from_dict({"world": {"lamp_offset_m": [0.0, 0.0, 0.5]}})
    with pytest.raises(ProblemError, match=r"loop\.lamp"):
        problem_from_dict({"loop": {"lamp": "guess"}})
