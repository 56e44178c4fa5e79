"""Export: .lp direction convention, the results folder, refusal of a failing plan."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np
import pytest

from optlight.errors import OutputError, UsageError, VerificationError
from optlight.export import (
    MANIFEST,
    check_output_folder,
    joint_trajectory_text,
    lp_direction,
    lp_text,
    write_file,
    write_folder,
    write_results,
)
from optlight.export.files import _yaml_float, _yaml_rows
from optlight.geometry import LightSphere, aim_rotation, sphere_frame
from optlight.jsondata import json_safe
from optlight.motion import Trajectory
from optlight.planning.timing import time_parameterize
from optlight.planning.waypoints import controller_waypoints
from optlight.scene.camera import Camera
from optlight.spec.sizing import image_names
from optlight.verify import VerificationReport, verify_trajectory
from optlight.viz.drawing import FigureJob
from optlight.viz.trajectory_figures import save_trajectory_figure, trajectory_figure

CENTER = np.array([0.45, -0.25, 0.35])
CAMERA = Camera.look_at([0.45, -1.05, 0.35], CENTER, 64, 48)
SPHERE = LightSphere(CENTER, 0.4, sphere_frame(CENTER, CAMERA.position))
LOWER, UPPER = np.array([0.0, -4.0]), np.array([1.3, 4.0])
VMAX, AMAX = np.array([0.8, 1.2]), np.array([2.0, 3.0])
LANDMARKS_Q = np.array([[0.4, 0.0], [0.6, 1.0], [0.5, 2.0]])
NAMES = ["zenith", "azimuth"]


def light_pose(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = SPHERE.position(q[0], q[1])
    return a, aim_rotation(a, CENTER, SPHERE.rotation[:, 0])


def plan(scale: float = 1.0) -> tuple[Trajectory, VerificationReport]:
    s = np.linspace(0, 1, 6)[:, None]
    segments = [a + (b - a) * s for a, b in zip(LANDMARKS_Q[:-1], LANDMARKS_Q[1:], strict=True)]
    traj = time_parameterize(segments, VMAX, AMAX, 0.3, joint_names=NAMES).time_scaled(scale)
    report = verify_trajectory(
        traj,
        light_pose=light_pose,
        lower=LOWER,
        upper=UPPER,
        velocity_limit=VMAX,
        acceleration_limit=AMAX,
        sphere=SPHERE,
        landmark_positions=SPHERE.position(LANDMARKS_Q[:, 0], LANDMARKS_Q[:, 1]),
        planned_path=None,
    )
    return traj, report


def directions() -> np.ndarray:
    return CAMERA.to_camera_frame(SPHERE.direction(LANDMARKS_Q[:, 0], LANDMARKS_Q[:, 1]))


def test_lp_text_writes_a_residue_as_zero() -> None:
    """The default plan's first light lies straight to the right: its y component in the camera frame
    is a residue (−8e-17), which .lp files once gave as −0.000000000."""
    text = lp_text(["a.png", "b.png"], [[0.293204483, -7.9e-17, 0.956049754], [-0.5, 2e-10, -4e-10]])
    assert text.splitlines() == ["2", "a.png 0.293204483 0.000000000 0.956049754", "b.png -0.500000000 0.000000000 0.000000000"]


def test_lp_direction_hand_worked() -> None:
    # frontal light, between object and camera: in the camera frame it points back along -z
    np.testing.assert_allclose(lp_direction([0.0, 0.0, -1.0]), [0.0, 0.0, 1.0])
    # light above the object: image y points down, so the camera-frame direction has y < 0
    up = lp_direction(np.array([0.0, -1.0, -1.0]) / np.sqrt(2))
    assert up[1] > 0 and up[2] > 0
    np.testing.assert_allclose(up, [0.0, 1 / np.sqrt(2), 1 / np.sqrt(2)])
    # light to the right of the image stays on the right
    np.testing.assert_allclose(lp_direction([[1.0, 0.0, 0.0]]), [[1.0, 0.0, 0.0]])
    with pytest.raises(ValueError):
        lp_direction([1.0, 0.0])


def test_lp_direction_from_the_world_through_the_camera() -> None:
    # camera on -y looking at O along +y, world z up: a light straight above O is at the image top,
    # a light at zenith 0 sits between object and camera
    above = lp_direction(CAMERA.to_camera_frame([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(above, [0.0, 1.0, 0.0], atol=1e-12)
    frontal = lp_direction(CAMERA.to_camera_frame(SPHERE.direction(0.0, 0.0)))
    np.testing.assert_allclose(frontal, [0.0, 0.0, 1.0], atol=1e-12)
    # zenith 90°, azimuth 90°: along the sphere's y axis, which is up in the image
    np.testing.assert_allclose(
        lp_direction(CAMERA.to_camera_frame(SPHERE.direction(np.pi / 2, np.pi / 2))), [0, 1, 0], atol=1e-12
    )


def test_write_results(tmp_path) -> None:
    traj, report = plan()
    assert report.passed, report.summary()
    fig = trajectory_figure(traj, lower=LOWER, upper=UPPER, velocity_limit=VMAX, acceleration_limit=AMAX)
    out = tmp_path / "results" / "run"
    files = write_results(
        out,
        trajectory=traj,
        report=report,
        plan_dict={"problem": "test", "landmarks_q": LANDMARKS_Q, "solve_s": np.float64(1.5)},
        joint_names=NAMES,
        light_directions_camera=directions(),
        image_pattern="img_{index:03d}.png",
        figures={"trajectory": FigureJob.of(fig, 120).png},
    )
    assert [f.name for f in files] == ["trajectory.csv", "plan.json", "lights.lp", "trajectory.png"]
    assert all(f.is_file() and f.stat().st_size > 0 for f in files)
    assert sorted(p.name for p in (tmp_path / "results").iterdir()) == ["run"]  # no staging left

    lines = (out / "lights.lp").read_text().splitlines()
    assert lines[0] == "3"
    names = [line.split()[0] for line in lines[1:]]
    assert names == ["img_000.png", "img_001.png", "img_002.png"]
    xyz = np.array([[float(x) for x in line.split()[1:]] for line in lines[1:]])
    np.testing.assert_allclose(xyz, lp_direction(directions()), atol=1e-8)
    assert np.all(xyz[:, 2] > 0)  # lights on the camera side of the object

    data = json.loads((out / "plan.json").read_text())
    assert data["problem"] == "test" and data["landmarks_q"] == LANDMARKS_Q.tolist()
    assert data["verification"]["passed"] is True
    assert data["versions"]["toppra"] == "0.6.10" and data["versions"]["numpy"]
    assert data["timing"]["capture_times_s"] == pytest.approx(traj.capture_times.tolist())
    assert data["timing"]["joint_names"] == NAMES

    with (out / "trajectory.csv").open() as f:
        assert next(csv.reader(f))[:3] == ["t", "q_zenith", "q_azimuth"]
    back = Trajectory.from_csv(
        out / "trajectory.csv", landmark_intervals=data["timing"]["landmark_intervals_s"]
    )
    np.testing.assert_allclose(back.capture_times, traj.capture_times)


def test_refuses_a_failing_report_and_leaves_nothing(tmp_path) -> None:
    traj, report = plan(scale=0.5)
    assert not report.passed
    out = tmp_path / "sub" / "run"
    with pytest.raises(VerificationError, match="refusing") as err:
        write_results(
            out,
            trajectory=traj,
            report=report,
            plan_dict={},
            joint_names=NAMES,
            light_directions_camera=directions(),
            image_pattern="img_{index:03d}.png",
        )
    assert err.value.report is report
    assert "velocity" in str(err.value)
    assert list(tmp_path.iterdir()) == []


def test_a_failure_while_writing_leaves_nothing(tmp_path) -> None:
    traj, report = plan()

    def broken() -> bytes:
        raise OSError("disk full")

    with pytest.raises(OutputError, match=r"cannot write .*run: disk full; nothing was written"):
        write_results(
            tmp_path / "run",
            trajectory=traj,
            report=report,
            plan_dict={},
            joint_names=NAMES,
            light_directions_camera=directions(),
            image_pattern="img_{index:03d}.png",
            figures={"broken": broken},
        )
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(TypeError, match="plan_dict.thing"):
        write_results(
            tmp_path / "run",
            trajectory=traj,
            report=report,
            plan_dict={"plan_dict": {"thing": object()}},
            joint_names=NAMES,
            light_directions_camera=directions(),
            image_pattern="img_{index:03d}.png",
        )
    assert list(tmp_path.iterdir()) == []


def tree(folder: Path) -> dict[str, bytes]:
    """Every file below ``folder`` (hidden ones too) and its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def results_kwargs() -> dict:
    traj, report = plan()
    return dict(
        trajectory=traj,
        report=report,
        plan_dict={},
        joint_names=NAMES,
        light_directions_camera=directions(),
        image_pattern="img_{index:03d}.png",
    )


def test_a_folder_optlight_did_not_write_is_refused_even_with_overwrite(tmp_path) -> None:
    out = tmp_path / "run"
    out.mkdir()
    (out / "thesis.tex").write_text("old")
    for overwrite in (False, True):
        with pytest.raises(UsageError, match="optlight did not write"):
            write_results(out, overwrite=overwrite, **results_kwargs())
    assert tree(tmp_path) == {"run/thesis.tex": b"old"}
    (tmp_path / "file.txt").write_text("mine")
    with pytest.raises(UsageError, match="existing file"):
        write_results(tmp_path / "file.txt", overwrite=True, **results_kwargs())
    assert (tmp_path / "file.txt").read_text() == "mine"


def test_an_earlier_output_is_replaced_only_with_overwrite_and_user_files_stay(tmp_path) -> None:
    out = tmp_path / "run"
    out.mkdir()  # an existing empty folder receives the output
    first = write_results(out, **results_kwargs())
    manifest = json.loads((out / MANIFEST).read_text())
    assert sorted(manifest["files"]) == sorted(f.name for f in first)
    (out / "notes.md").write_text("mine")
    (out / "old_figure.png").write_bytes(b"stale")  # as if an earlier run had written it
    manifest["files"].append("old_figure.png")
    (out / MANIFEST).write_text(json.dumps(manifest))
    before = tree(out)
    with pytest.raises(UsageError, match="earlier optlight run"):
        write_results(out, **results_kwargs())
    assert tree(out) == before
    write_results(out, overwrite=True, **results_kwargs())
    names = {p.name for p in out.iterdir()}
    assert names == {*(f.name for f in first), MANIFEST, "notes.md"}  # the stale file is gone
    assert (out / "notes.md").read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no staging left


def test_an_output_in_rounds_is_continued_by_its_kind_only_and_user_files_stay(tmp_path) -> None:
    """An output written with ``resumable`` (the folder camera's rounds) is updated without
    ``overwrite`` by a writer continuing that kind, which replaces only the files the manifest lists;
    another kind, a plain writer and a finished output are refused as any earlier output."""
    out = tmp_path / "run"

    def writer(names: list[str]):
        def write(staging: Path) -> list[Path]:
            for name in names:
                (staging / name).parent.mkdir(parents=True, exist_ok=True)
                (staging / name).write_text("optlight")
            return [staging / name for name in names]

        return write

    write_folder(out, writer(["state.json", "round_00/plan.json"]), resumable="rounds")
    assert json.loads((out / MANIFEST).read_text())["resume"] == "rounds"
    (out / "round_00" / "r00_000.png").write_text("the user's image")
    before = tree(out)
    for kwargs in ({}, {"resume": "other"}):
        with pytest.raises(UsageError, match="earlier optlight run"):
            write_folder(out, writer(["state.json"]), **kwargs)
        assert tree(out) == before
    write_folder(out, writer(["state.json", "round_00/plan.json", "round_01/plan.json"]), resume="rounds")
    assert (out / "round_00" / "r00_000.png").read_text() == "the user's image"
    assert "resume" not in json.loads((out / MANIFEST).read_text())  # finished
    with pytest.raises(UsageError, match="earlier optlight run"):
        check_output_folder(out, resume="rounds")


@pytest.mark.parametrize(
    "manifest",
    ['{"files": ["../outside.txt"]}', '{"files": ["/etc/passwd"]}', "not json", '{"files": "a"}', "[]"],
)
def test_a_manifest_that_could_reach_outside_the_folder_is_not_trusted(tmp_path, manifest: str) -> None:
    out = tmp_path / "run"
    out.mkdir()
    (out / MANIFEST).write_text(manifest)
    (tmp_path / "outside.txt").write_text("keep")
    with pytest.raises(UsageError, match="optlight did not write"):
        write_results(out, overwrite=True, **results_kwargs())
    assert (tmp_path / "outside.txt").read_text() == "keep"


def test_write_file_replaces_only_with_overwrite_and_never_a_folder(tmp_path) -> None:
    path = tmp_path / "a" / "b.png"
    write_file(path, lambda tmp: tmp.write_bytes(b"one"))
    assert path.read_bytes() == b"one"
    with pytest.raises(UsageError, match="exists"):
        write_file(path, lambda tmp: tmp.write_bytes(b"two"))
    write_file(path, lambda tmp: tmp.write_bytes(b"two"), overwrite=True)
    assert path.read_bytes() == b"two"
    with pytest.raises(UsageError, match="is a folder"):
        write_file(tmp_path / "a", lambda tmp: tmp.write_bytes(b"x"), overwrite=True)

    def broken(tmp: Path) -> None:
        tmp.write_bytes(b"half")
        raise OSError("disk full")

    with pytest.raises(OutputError, match=r"cannot write .*b.png: disk full; nothing was written"):
        write_file(path, broken, overwrite=True)
    assert path.read_bytes() == b"two" and sorted(p.name for p in path.parent.iterdir()) == ["b.png"]


def test_bad_inputs_are_rejected_before_writing(tmp_path) -> None:
    traj, report = plan()
    base = dict(trajectory=traj, report=report, plan_dict={}, joint_names=NAMES, image_pattern="i{index}.png")
    with pytest.raises(ValueError, match="unit vectors"):
        write_results(tmp_path / "a", light_directions_camera=2 * directions(), **base)
    with pytest.raises(ValueError, match="one per capture"):
        write_results(tmp_path / "a", light_directions_camera=directions()[:2], **base)
    with pytest.raises(ValueError, match="keys"):
        write_results(
            tmp_path / "a", light_directions_camera=directions(), **{**base, "plan_dict": {"versions": 1}}
        )
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError, match="repeated"):
        image_names("img.png", 3)
    with pytest.raises(ValueError, match="whitespace"):
        image_names("img {index}.png", 2)


def test_json_safe() -> None:
    out = json_safe({"a": np.arange(3), "b": (np.float32(0.5), np.nan), "c": {1: np.bool_(True)}})
    assert out == {"a": [0, 1, 2], "b": [0.5, None], "c": {"1": True}}
    json.dumps(out, allow_nan=False)


def test_trajectory_figure_file(tmp_path) -> None:
    traj, _ = plan()
    path = save_trajectory_figure(
        tmp_path / "t.png", traj, lower=LOWER, upper=UPPER, velocity_limit=VMAX, acceleration_limit=AMAX
    )
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# ---------------------------------------------------------------- joint_trajectory.yaml, captures.csv

JMAX = np.array([20.0, 30.0])


def jerk_plan() -> Trajectory:
    from optlight.planning.jerk import jerk_limited_timing

    s = np.linspace(0, 1, 6)[:, None]
    segments = [a + (b - a) * s for a, b in zip(LANDMARKS_Q[:-1], LANDMARKS_Q[1:], strict=True)]
    return jerk_limited_timing(segments, VMAX, AMAX, JMAX, 0.3, joint_names=NAMES)


def hermite_solve(t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, times: np.ndarray) -> np.ndarray:
    """q at ``times`` of the quintic through points (t, q, q̇, q̈), each interval's six coefficients
    solved from the 6×6 system of its end values (numpy.linalg.solve), in absolute time: an
    implementation of its own, not optlight's closed forms."""
    out = np.full((times.size, q.shape[1]), np.nan)
    for k in range(t.size - 1):
        inside = (times >= t[k]) & (times <= t[k + 1])
        if not inside.any():
            continue
        rows = []
        for tau in (t[k], t[k + 1]):
            rows += [[tau**i for i in range(6)], [i * tau ** (i - 1) if i else 0.0 for i in range(6)]]
            rows += [[i * (i - 1) * tau ** (i - 2) if i > 1 else 0.0 for i in range(6)]]
        rhs = np.array([q[k], qd[k], qdd[k], q[k + 1], qd[k + 1], qdd[k + 1]])
        coefficients = np.linalg.solve(np.array(rows), rhs)  # (6, n)
        out[inside] = np.vander(times[inside], 6, increasing=True) @ coefficients
    return out


def test_joint_trajectory_yaml_holds_few_waypoints_the_quintic_follows_within_1e_4(tmp_path) -> None:
    """joint_trajectory.yaml is a plain ROS message of waypoints, not samples: every dwell and motion
    boundary, exact values of the plan at the times written, far fewer points than the controller
    rate would give, and their quintic interpolation (solved here independently) stays within 1e-4
    rad of the plan on a dense grid. The goal file holds the same trajectory."""
    import yaml

    from optlight.export import read_joint_trajectory, write_joint_trajectory
    traj = jerk_plan()
    waypoints = controller_waypoints(traj, rate_hz=1000.0)
    path, goal = write_joint_trajectory(tmp_path, waypoints, NAMES)
    assert (path.name, goal.name) == ("joint_trajectory.yaml", "follow_joint_trajectory_goal.yaml")
    doc = yaml.safe_load(path.read_text())  # a plain YAML reader, no optlight involved
    assert doc["joint_names"] == NAMES and doc["header"]["stamp"] == {"sec": 0, "nanosec": 0}
    points = doc["points"]
    assert all(set(p) == {"positions", "velocities", "accelerations", "effort", "time_from_start"} for p in points)
    assert all(isinstance(p["time_from_start"]["nanosec"], int) for p in points)
    t = np.array([p["time_from_start"]["sec"] * 10**9 + p["time_from_start"]["nanosec"] for p in points]) / 1e9
    assert t[0] == 0.0 and np.all(np.diff(t) > 0) and t[-1] == pytest.approx(traj.duration, abs=1e-9)
    assert np.all(np.isin(np.round(traj.boundaries, 9), np.round(t, 9)))  # every dwell start and end
    assert len(points) < 0.1 * traj.sample_times(1000.0).size  # waypoints, not 1 kHz samples
    q, qd, qdd = (np.array([p[key] for p in points]) for key in ("positions", "velocities", "accelerations"))
    for value, original in zip((q, qd, qdd), traj.sample(t), strict=True):
        np.testing.assert_array_equal(value, original)  # exact floats

    dense = np.linspace(0.0, t[-1], 20_001)
    gap = np.abs(hermite_solve(t, q, qd, qdd, dense) - traj.sample(dense)[0])
    assert gap.max() <= 1e-4
    assert gap.max() > 1e-7  # the points are few enough for the interpolation to differ from the plan
    back = read_joint_trajectory(path, landmark_intervals=traj.landmark_intervals)
    np.testing.assert_allclose(back.sample(dense)[0], traj.sample(dense)[0], rtol=0, atol=1e-4)

    document = yaml.safe_load(goal.read_text())
    assert set(document) == {"trajectory", "goal_time_tolerance"}
    assert document["trajectory"] == doc and document["goal_time_tolerance"] == {"sec": 0, "nanosec": 500_000_000}


def test_interpolation_check_fails_waypoints_too_far_apart() -> None:
    """The verification interpolates the waypoints on its own: the chosen ones pass; every other one
    of them dropped (the boundaries kept) leaves the quintic too far from the plan, and the check
    names a joint and a time."""
    from dataclasses import replace

    traj = jerk_plan()
    args = dict(
        light_pose=light_pose,
        lower=LOWER,
        upper=UPPER,
        velocity_limit=VMAX,
        acceleration_limit=AMAX,
        sphere=SPHERE,
        landmark_positions=SPHERE.position(LANDMARKS_Q[:, 0], LANDMARKS_Q[:, 1]),
    )
    waypoints = controller_waypoints(traj)
    report = verify_trajectory(traj, waypoints=waypoints, **args)
    assert report.passed and 0 < report.checks["interpolation"].max_value <= 1e-4
    assert "interpolation" in verify_trajectory(traj, **args).skipped
    keep = np.isin(np.round(waypoints.t, 9), np.round(traj.boundaries, 9))
    keep[::2] = True
    sparse = replace(
        waypoints,
        nanoseconds=waypoints.nanoseconds[keep],
        q=waypoints.q[keep],
        qd=waypoints.qd[keep],
        qdd=waypoints.qdd[keep],
    )
    bad = verify_trajectory(traj, waypoints=sparse, **args)
    assert not bad.passed and bad.checks["interpolation"].max_value > 1e-4
    v = next(v for v in bad.violations if v.check == "interpolation")
    assert v.joint in NAMES and "quintic interpolation" in v.message


def test_quintic_points_reproduce_a_quintic_exactly() -> None:
    rng = np.random.default_rng(5)
    c = rng.normal(size=(6, 2))  # q(t) = Σ c_k t^k on [0, 2]

    def poly(t: np.ndarray, d: int) -> np.ndarray:
        k = np.arange(6)
        coef = np.array([np.prod(np.arange(i - d + 1, i + 1)) if i >= d else 0.0 for i in k])
        powers = np.where(k >= d, t[:, None] ** np.maximum(k - d, 0), 0.0)
        return (powers * coef) @ c

    t = np.array([0.0, 0.3, 1.1, 2.0])
    traj = Trajectory.from_points(t, poly(t, 0), poly(t, 1), poly(t, 2))
    dense = np.linspace(0.0, 2.0, 301)
    for value, d in zip(traj.sample(dense), (0, 1, 2), strict=True):
        np.testing.assert_allclose(value, poly(dense, d), atol=1e-10)
    np.testing.assert_allclose(traj.jerk(dense), poly(dense, 3), atol=1e-8)


def test_unreadable_joint_trajectories_are_named(tmp_path) -> None:
    from optlight.export import read_joint_trajectory

    path = tmp_path / "bad.yaml"
    path.write_text("joint_names: [a]\npoints:\n  - {positions: [0.0]}\n  - {positions: [1.0]}\n")
    with pytest.raises(ValueError, match="time_from_start"):
        read_joint_trajectory(path)
    path.write_text("points: []\n")
    with pytest.raises(ValueError, match="joint_names and points"):
        read_joint_trajectory(path)


def test_every_trigger_lies_in_a_dwell_at_rest_and_names_match_lights_lp(tmp_path) -> None:
    from optlight.export import write_captures

    traj = jerk_plan()
    positions = SPHERE.position(LANDMARKS_Q[:, 0], LANDMARKS_Q[:, 1])
    path = write_captures(
        tmp_path / "captures.csv",
        traj,
        settle_s=0.2,
        image_pattern="cap_{index:02d}.png",
        light_directions_camera=directions(),
        light_positions=positions,
        light_angles_deg=np.rad2deg(LANDMARKS_Q[:, :2]),
        joint_names=NAMES,
    )
    with path.open() as f:
        rows = list(csv.DictReader(f))
    assert [int(r["capture"]) for r in rows] == list(range(len(LANDMARKS_Q)))
    assert [r["image"] for r in rows] == image_names("cap_{index:02d}.png", len(LANDMARKS_Q))
    for row, (a, b), p, q in zip(rows, traj.landmark_intervals, positions, LANDMARKS_Q, strict=True):
        trigger = float(row["trigger_s"])
        assert float(row["dwell_start_s"]) == pytest.approx(a, abs=1e-9)
        assert trigger == pytest.approx(a + 0.2, abs=1e-9) and a < trigger < b
        # the joints are still around the trigger, and the file's joint angles are the landmark's
        _, qd, _ = traj.sample(np.linspace(trigger - 1e-3, trigger + 1e-3, 11))
        assert np.abs(qd).max() < 1e-9
        np.testing.assert_allclose([float(row[f"q_{n}"]) for n in NAMES], q, atol=1e-9)
        np.testing.assert_allclose([float(row[f"light_position_{x}_m"]) for x in "xyz"], p, atol=1e-9)
    with pytest.raises(ValueError, match="settle_s"):
        write_captures(
            tmp_path / "again.csv",
            traj,
            settle_s=0.3,
            image_pattern="x{index}",
            light_directions_camera=directions(),
            light_positions=positions,
            light_angles_deg=np.rad2deg(LANDMARKS_Q[:, :2]),
            joint_names=NAMES,
        )


def test_verification_flags_acceleration_steps_and_names_joint_and_time() -> None:
    traj = jerk_plan()
    args = dict(
        light_pose=light_pose,
        lower=LOWER,
        upper=UPPER,
        velocity_limit=VMAX,
        acceleration_limit=AMAX,
        sphere=SPHERE,
        landmark_positions=SPHERE.position(LANDMARKS_Q[:, 0], LANDMARKS_Q[:, 1]),
        jerk_limit=JMAX,
    )
    report = verify_trajectory(traj, **args)
    assert report.passed, report.summary()
    assert report.checks["acceleration_continuity"].max_value <= 1 + 1e-6
    assert report.checks["jerk"].max_value <= 1 + 1e-9
    toppra, _ = plan()  # the same landmarks timed by TOPPRA: q̈ steps at its gridpoints
    bad = verify_trajectory(toppra, **args)
    assert not bad.passed and bad.counts["acceleration_continuity"] > 0
    v = next(v for v in bad.violations if v.check == "acceleration_continuity")
    assert v.joint in NAMES and "q̈ jumps by" in v.message and f"t = {v.time_s - 1e-3:.4f}" in v.message
    # skipped when no jerk limit is given (a TOPPRA plan verified as before)
    assert "acceleration_continuity" in verify_trajectory(toppra, **{**args, "jerk_limit": None}).skipped


def test_trajectory_files_are_the_text_of_value_by_value_formatting(tmp_path) -> None:
    """trajectory.csv and joint_trajectory.yaml are formatted a row (csv) or an array (yaml) at a
    time for speed; their text is the one formatting each value on its own gives (csv.writer with
    f'{v:.12g}' and f'{t:.9f}', and _yaml_float), byte for byte: readers of the files see no change."""
    traj, _ = plan()
    rate = 250.0
    t = traj.sample_times(rate)
    q, qd, qdd = traj.sample(t)
    reference = io.StringIO(newline="")
    writer = csv.writer(reference)
    writer.writerow(["t"] + [f"{p}_{n}" for p in ("q", "qd", "qdd") for n in NAMES])
    for row_t, row in zip(t, np.hstack([q, qd, qdd]), strict=True):
        writer.writerow([f"{row_t:.9f}", *(f"{v:.12g}" for v in row)])
    traj.to_csv(tmp_path / "trajectory.csv", NAMES, rate_hz=rate)
    assert (tmp_path / "trajectory.csv").read_bytes() == reference.getvalue().encode()

    waypoints = controller_waypoints(traj, rate_hz=rate)
    text = joint_trajectory_text(waypoints, NAMES)
    q, qd, qdd = waypoints.q, waypoints.qd, waypoints.qdd
    for k in (0, len(waypoints) // 2, len(waypoints) - 1):
        for name, values in (("positions", q[k]), ("velocities", qd[k]), ("accelerations", qdd[k])):
            assert f"{name}: [" + ", ".join(_yaml_float(v) for v in values) + "]\n" in text
    assert text.count("positions: [") == len(waypoints)
    # every form a float takes: exponent without a point (YAML would read '1e-05' as a string),
    # with one, negative zero, the largest and smallest magnitudes
    odd = np.array([[1e-05, 1.5e-07, -0.0, 0.1, 1e16, 123456789.123, 5e-324, -1.7976931348623157e308]])
    assert _yaml_rows(odd) == ["[" + ", ".join(_yaml_float(v) for v in odd[0]) + "]"]
    assert _yaml_rows(odd)[0].startswith("[1.0e-05, 1.5e-07, -0.0, 0.1, 1.0e+16, ")
    # the digits are orjson's and the notation repr's: on both sides of where their notations part
    # (1e-4, 1e16) and over every magnitude a double takes, each text is _yaml_float's
    rng = np.random.default_rng(7)
    edges = [np.nextafter(1e-4, 0.0), 1e-4, np.nextafter(1e16, 0.0), 1e16]
    many = np.r_[edges, rng.choice([-1.0, 1.0], 60_000) * 10.0 ** rng.uniform(-320, 308, 60_000)].reshape(-1, 4)
    assert _yaml_rows(many) == ["[" + ", ".join(_yaml_float(v) for v in row) + "]" for row in many]
