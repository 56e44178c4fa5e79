"""The whole pipeline on a reduced default problem: solve, verify, export, refuse, unreachable."""

from __future__ import annotations

import dataclasses
import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import REACH_ONLY, reduced_problem

import optlight
from optlight.errors import UnreachableError, VerificationError
from optlight.export import MANIFEST
from optlight.geometry import h_residual
from optlight.motion import Trajectory
from optlight.pipeline import STAGES
from optlight.plan import joint_path_length
from optlight.planning.jerk import rest_to_rest_duration
from optlight.planning.policy import LandmarkPlacement
from optlight.stages import OptimizedPath, Route
from optlight.verify import verify_trajectory


def small_problem(**overrides: dict) -> optlight.Problem:
    """The default problem with 8 landmarks and a 96² camera, so the whole pipeline runs in seconds."""
    landmarks = {"count": 8, **overrides.pop("landmarks", {})}
    return reduced_problem(camera_px=96, landmarks=landmarks, **overrides)


@pytest.fixture(scope="module")
def solved() -> tuple[optlight.Plan, list[tuple[str, object]]]:
    """The small problem's plan, and what its stage listener heard: (stage, result) in order."""
    heard: list[tuple[str, object]] = []
    plan = optlight.solve(small_problem(), on_stage=lambda stage, result: heard.append((stage, result)))
    return plan, heard


@pytest.fixture(scope="module")
def plan(solved: tuple[optlight.Plan, list[tuple[str, object]]]) -> optlight.Plan:
    return solved[0]


def test_the_listener_hears_every_stage_with_its_result(
    solved: tuple[optlight.Plan, list[tuple[str, object]]],
) -> None:
    """Each stage, in order, once, with the typed result the plan is made of (optlight.stages)."""
    plan, heard = solved
    assert [stage for stage, _ in heard] == list(STAGES)
    results = dict(heard)
    assert results["scene"] is plan.setup and results["landmarks"] is plan.landmarks
    placement = results["placement"]
    route, optimized = results["path"], results["nlp"]
    assert isinstance(placement, LandmarkPlacement) and isinstance(route, Route)
    assert route.visited is plan.visited
    assert all(placement.landmarks[i] is v for i, v in zip(route.order, plan.visited, strict=True))
    np.testing.assert_array_equal(route.landmark_thetas, plan.landmark_thetas)
    np.testing.assert_array_equal(placement.thetas[route.order], plan.landmark_thetas)
    assert isinstance(optimized, OptimizedPath) and optimized.visited is plan.visited
    assert optimized.nlp is plan.nlp and optimized.path is plan.path and optimized.knot_ik is plan.knot_ik
    assert results["timing"] is plan.trajectory and results["verify"] is plan.verification


def test_plan_meets_the_light_constraints_and_limits(plan: optlight.Plan) -> None:
    robot, sphere = plan.robot, plan.scene.sphere
    assert plan.nlp.success and plan.verification.passed
    assert all(robot.within_limits(theta) for theta in plan.landmark_thetas)
    for k, theta in zip(plan.path.landmark_knots, plan.nlp.theta[plan.path.landmark_knots], strict=True):
        p, r = robot.light_pose(theta)  # pinocchio, independent of the CasADi mirror the NLP used
        assert np.abs(h_residual(p, r, sphere.center, sphere.radius)).max() < 1e-8
        np.testing.assert_allclose(p, plan.path.positions[k], atol=1e-8)
    # the NLP never lengthens the joint path of the per-knot IK it starts from
    assert joint_path_length(plan.nlp.theta) <= joint_path_length(plan.knot_ik) + 1e-9
    # one capture per landmark, the light still during each dwell
    traj = plan.trajectory
    assert traj.capture_times.size == len(plan.visited)
    _, qd, _ = traj.sample(traj.capture_times)
    np.testing.assert_allclose(qd, 0.0, atol=1e-9)


def test_the_nlp_in_windows_plans_what_one_nlp_plans(plan: optlight.Plan, monkeypatch) -> None:
    import optlight.planning.trajectory.windows as windows

    size = plan.path.n_knots // 3
    monkeypatch.setattr(windows, "NLP_WINDOW_KNOTS", size)
    assert len(plan.path.windows(size)) >= 2
    events: list[tuple[str, int, int]] = []
    windowed = optlight.solve(small_problem(), progress=lambda *e: events.append(e))
    assert windowed.verification.passed  # the captures two windows share hold the light to 1e-6 m
    np.testing.assert_array_equal(windowed.path.positions, plan.path.positions)  # the same captures and knots
    assert not windowed.path.transfers.any()
    windows = len(windowed.path.windows(size))
    windowed_events = [("nlp", d, windows) for d in range(1, windows + 1)]
    assert [e for e in events if e[0] == "nlp"] == [("nlp", 0, 1), *windowed_events, ("nlp", 1, 1)]
    # a window's end fixed for the next costs little: motion and the NLP's cost (the squared joint
    # steps at the velocity limits, over all knots) within 5 % of the one NLP's (windows of a third
    # of the path here; measured equal to 1e-7)
    assert windowed.trajectory.duration <= 1.05 * plan.trajectory.duration
    assert windowed.nlp.cost <= 1.05 * plan.nlp.cost


def test_save_writes_the_results_folder(plan: optlight.Plan, tmp_path: Path) -> None:
    folder = tmp_path / "out"
    plan.save(folder, preview=False)
    names = {p.name for p in folder.iterdir()}
    assert {"trajectory.csv", "plan.json", "lights.lp", "trajectory.png", "path.png", "report.md"} <= names
    assert "landmarks_polar.png" in names
    doc = json.loads((folder / "plan.json").read_text())
    assert doc["verification"]["passed"] is True
    assert len(doc["landmarks"]) == len(plan.visited)
    assert set(doc["files"]) == names - {MANIFEST}
    assert sorted(json.loads((folder / MANIFEST).read_text())["files"]) == sorted(doc["files"])
    lp = (folder / "lights.lp").read_text().splitlines()
    assert int(lp[0]) == len(plan.visited) and len(lp) == len(plan.visited) + 1
    # the .lp direction of each capture is the landmark's direction, in the PTM camera convention
    for line, lm in zip(lp[1:], plan.visited, strict=True):
        d = np.array(line.split()[1:], float)
        u = plan.scene.camera.to_camera_frame(
            (lm.position - plan.scene.sphere.center) / plan.scene.sphere.radius
        )
        np.testing.assert_allclose(d, u * [1, -1, -1], atol=1e-6)
    # CSV round trip: the file reproduces the trajectory at its samples
    back = Trajectory.from_csv(folder / "trajectory.csv")
    t = np.linspace(0, plan.trajectory.duration, 57)
    np.testing.assert_allclose(back.sample(t)[0], plan.trajectory.sample(t)[0], atol=2e-3)
    report = (folder / "report.md").read_text()
    assert "verification | passed" in report and "![path](path.png)" in report
    assert "## Files and frames" in report and "x to the right of the image, y towards its top" in report


def test_a_compressed_trajectory_is_refused(plan: optlight.Plan, tmp_path: Path) -> None:
    robot = plan.robot
    fast = plan.trajectory.time_scaled(0.5)
    report = verify_trajectory(
        fast,
        light_pose=robot.light_pose,
        lower=robot.lower,
        upper=robot.upper,
        velocity_limit=robot.velocity_limit,
        acceleration_limit=robot.acceleration_limit,
        sphere=plan.scene.sphere,
        landmark_positions=np.array([lm.position for lm in plan.visited]),
    )
    assert not report.passed
    assert "acceleration" in report.counts and report.counts["acceleration"] > 0
    bad = dataclasses.replace(plan, trajectory=fast, verification=report)
    with pytest.raises(VerificationError, match="failed verification"):
        bad.save(tmp_path / "bad", preview=False)
    assert not any(tmp_path.iterdir()), "nothing may be written for a failing plan"


#: A base 0.9 m below the light ring, on the camera side: from 10° zenith up it reaches the lower landmarks,
#: and no light at all on the upper azimuths (checked with the IK when this was written; nearer the pole
#: it reaches every azimuth, and the placement NLP would move those landmarks there instead).
LOW_BASE = [-0.603, -0.55, -0.45]
ABOVE_10_DEG = {"zenith_min_deg": 10.0}


def test_unreachable_landmark_is_named() -> None:
    far = small_problem(**REACH_ONLY, robot={"base_position_m": LOW_BASE}, light_sphere=ABOVE_10_DEG)
    with pytest.raises(UnreachableError, match=r"landmark \d+ \(zenith .*°, azimuth .*°\) is out of reach"):
        optlight.solve(far)


@pytest.mark.slow
def test_partial_plans_drop_unreachable_landmarks_with_a_warning() -> None:
    far = small_problem(
        **REACH_ONLY,
        robot={"base_position_m": LOW_BASE},
        light_sphere=ABOVE_10_DEG,
        landmarks={"allow_partial": True},
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        plan = optlight.solve(far)
    dropped = [w for w in plan.warnings if "out of reach" in w]
    assert dropped and 0 < len(plan.visited) == 8 - len(dropped)
    assert any("out of reach" in str(w.message) for w in caught)
    assert plan.verification.passed


def test_a_single_landmark_is_one_dwell(tmp_path: Path) -> None:
    plan = optlight.solve(small_problem(landmarks={"count": 1}))
    assert len(plan.visited) == 1 and plan.verification.passed
    (start, end), = plan.trajectory.landmark_intervals
    assert end - start == pytest.approx(plan.problem.trajectory.dwell_s)
    # from the start configuration to the light and back: motion before and after the one dwell
    assert 0.0 < start and end < plan.trajectory.duration
    plan.save(tmp_path / "one", preview=False)
    assert (tmp_path / "one" / "lights.lp").read_text().splitlines()[0] == "1"


def test_the_view_check_runs_on_every_plan_and_a_blocked_capture_is_refused(
    plan: optlight.Plan, tmp_path: Path
) -> None:
    from optlight.environment.view import view_check_for

    # runs without [environment], enforced: the default plan keeps the view and the beam clear
    assert not plan.problem.environment.enabled
    assert {"view", "beam"} <= set(plan.verification.checks) and not plan.verification.advisory
    assert plan.verification.checks["view"].passed
    # planned with the view off in the paper's layout (the base between camera and face), the arm
    # blocks the view: the check fails the plan, names capture, link and time, and nothing is written
    plan = optlight.solve(small_problem(**REACH_ONLY, landmarks={"count": 4}))
    assert {"view", "beam"} <= set(plan.verification.skipped)
    robot = plan.robot
    report = verify_trajectory(
        plan.trajectory,
        light_pose=robot.light_pose,
        lower=robot.lower,
        upper=robot.upper,
        velocity_limit=robot.velocity_limit,
        acceleration_limit=robot.acceleration_limit,
        sphere=plan.scene.sphere,
        landmark_positions=np.array([lm.position for lm in plan.visited]),
        jerk_limit=robot.jerk_limit,
        view=view_check_for(robot, plan.scene, plan.problem.light).check,
    )
    blocked = [v for v in report.violations if v.check == "view"]
    assert blocked, "the default layout blocks the view at some capture"
    first = blocked[0]
    assert first.joint in {g.name for g in robot.model.frames} | {"light housing"}
    capture = int(first.message.split()[1])
    assert first.time_s == pytest.approx(plan.trajectory.capture_times[capture])
    assert f"at t = {first.time_s:.4f} s" in first.message and f"first by {first.joint}" in first.message
    bad = dataclasses.replace(plan, verification=report)
    with pytest.raises(VerificationError, match=rf"capture {capture} at t = .* first by {first.joint}"):
        bad.save(tmp_path / "blocked", preview=False)
    assert not any(tmp_path.iterdir()), "nothing may be written for a blocked capture"


def test_jerk_limited_plan_exports_for_the_controller(plan: optlight.Plan, tmp_path: Path) -> None:
    from optlight.export import read_joint_trajectory

    checks = plan.verification.checks
    assert checks["jerk"].passed and checks["acceleration_continuity"].passed
    folder = tmp_path / "out"
    plan.save(folder, preview=False)
    written = {p.name for p in folder.iterdir()}
    assert {"joint_trajectory.yaml", "follow_joint_trajectory_goal.yaml", "captures.csv"} <= written
    t = np.loadtxt(folder / "trajectory.csv", delimiter=",", skiprows=1, usecols=0)
    assert np.median(np.diff(t)) == pytest.approx(1.0 / plan.problem.trajectory.rate_hz)
    back = read_joint_trajectory(folder / "joint_trajectory.yaml")
    times = np.linspace(0.0, plan.trajectory.duration, 2001)
    np.testing.assert_allclose(back.sample(times)[0], plan.trajectory.sample(times)[0], atol=1e-4)
    points = (folder / "joint_trajectory.yaml").read_text().count("positions: [")
    assert checks["interpolation"].passed and points == len(plan.waypoints) < 0.1 * t.size
    lp = (folder / "lights.lp").read_text().split("\n")[1:-1]
    captures = (folder / "captures.csv").read_text().splitlines()[1:]
    assert [line.split()[0] for line in lp] == [row.split(",")[4] for row in captures]


def test_moving_time_is_reported_against_its_rest_to_rest_bound(plan: optlight.Plan, tmp_path: Path) -> None:
    """The time-optimal stops at the same postures, under the same limits, bound the moving time from
    below; plan.json and report.md give both, and the peak torques per joint against their limits."""
    bound = plan.summary()["motion_bound"]
    assert bound["motion_time_s"] == pytest.approx(plan.motion_time)
    assert 1.0 <= bound["ratio"] == pytest.approx(plan.motion_time / bound["rest_to_rest_s"])
    assert 0 < bound["between_captures_rest_to_rest_s"] <= bound["between_captures_s"]
    assert bound["between_captures_rest_to_rest_s"] < bound["rest_to_rest_s"]  # the approach and return too
    # every move of the plan takes at least the slowest joint's double-S time between the postures
    # the trajectory holds at its ends (the closed form, not ruckig), and the bound sums those
    limits, segments = plan.setup.limits, plan.trajectory.segment_times
    start, end = (plan.trajectory.sample(segments[:, k])[0] for k in (0, 1))
    shortest = rest_to_rest_duration(np.abs(end - start), limits.velocity, limits.acceleration, limits.jerk).max(axis=1)
    assert np.all(segments[:, 1] - segments[:, 0] >= shortest - 1e-9)
    assert bound["between_captures_rest_to_rest_s"] == pytest.approx(shortest.sum(), rel=1e-9)
    folder = tmp_path / "out"
    plan.save(folder, preview=False)
    saved = json.loads((folder / "plan.json").read_text())
    assert saved["summary"]["motion_bound"] == pytest.approx(bound)
    torques = saved["verification"]["torques"]
    assert torques["joints"] == plan.robot.joint_names and len(torques["fraction"]) == plan.robot.n
    assert saved["summary"]["torque_peak_fraction"] == dict(zip(torques["joints"], torques["fraction"], strict=True))
    report = (folder / "report.md").read_text()
    assert f"{bound['ratio']:.2f}×" in report and "peak joint torque / limit" in report


def test_toppra_timing_stays_available() -> None:
    toppra = optlight.solve(small_problem(trajectory={"timing": "toppra"}, landmarks={"count": 3}))
    assert toppra.verification.passed
    assert {"jerk", "acceleration_continuity"} <= set(toppra.verification.skipped)
