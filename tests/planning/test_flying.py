"""Flying captures: one motion through the landmarks without stopping, slow enough at each capture
for the blur tolerances. The blur is re-measured here by dense sampling of the timed trajectory and
pinocchio's forward kinematics (not by the planner's speed cap), the light's position at each trigger
against its landmark, the limits and the continuity of the motion by dense resampling."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import ruckig
from conftest import reduced_problem

import optlight
from optlight.motion import Exposure
from optlight.planning.flying import corner_runs, flying_timing, speed_change_distance
from optlight.planning.jerk import nonstop_bound, rest_to_rest_moves
from optlight.planning.policy import tour_costs
from optlight.verify import verify_trajectory

EXPOSURE_S = 0.005
BLUR_DEG = 0.2
BLUR_MM = 2.0


@pytest.fixture(scope="module")
def flying_plan() -> optlight.Plan:
    """The default problem, reduced to 8 landmarks and a 96² camera, with flying captures."""
    return optlight.solve(reduced_problem(camera_px=96, landmarks={"count": 8}, trajectory={"capture": "flying"}))


@pytest.fixture(scope="module")
def stop_plan() -> optlight.Plan:
    """The same problem stopping at every capture (the default)."""
    return optlight.solve(reduced_problem(camera_px=96, landmarks={"count": 8}))


def _light_positions(robot: optlight.Robot, thetas: np.ndarray) -> np.ndarray:
    """Light positions (T, 3) by pinocchio's forward kinematics, called here directly."""
    model, data = robot.model, robot.model.createData()
    frame = robot.light_frame_id
    out = []
    for theta in thetas:
        pin.framesForwardKinematics(model, data, robot.to_pin(theta))
        out.append(data.oMf[frame].translation.copy())
    return np.array(out)


def _dense_blur(plan: optlight.Plan, samples: int = 401) -> tuple[np.ndarray, np.ndarray]:
    """Per capture, the largest angle (rad) between two of the light's directions from the sphere's
    centre and the largest distance (m) between two of its positions during the exposure centred on
    the capture, over ``samples`` instants."""
    trajectory, center = plan.trajectory, plan.setup.sphere.center
    angles, distances = [], []
    for t in trajectory.capture_times:
        times = np.clip(np.linspace(t - EXPOSURE_S / 2, t + EXPOSURE_S / 2, samples), 0.0, trajectory.duration)
        p = _light_positions(plan.robot, trajectory.sample(times)[0])
        u = (p - center) / np.linalg.norm(p - center, axis=1, keepdims=True)
        angles.append(np.arccos(np.clip(u @ u.T, -1.0, 1.0)).max())
        distances.append(np.linalg.norm(p[:, None] - p[None], axis=2).max())
    return np.array(angles), np.array(distances)


def test_flying_plan_verifies_without_stopping(flying_plan: optlight.Plan) -> None:
    trajectory, report = flying_plan.trajectory, flying_plan.verification
    assert report.passed, report.summary()
    assert {"blur_angle", "blur_distance"} <= report.checks.keys()
    assert report.checks["blur_angle"].samples == len(flying_plan.visited)
    intervals = trajectory.landmark_intervals
    assert np.all(intervals[:, 1] == intervals[:, 0])  # no dwell
    qd = trajectory.sample(trajectory.capture_times)[1]
    speed = np.linalg.norm(qd, axis=1)
    assert speed[0] == speed[-1] == 0.0  # the approach ends and the retreat starts at rest
    inner = speed[1:-1]
    assert np.all((inner > 0.05) | (inner == 0.0))  # passed at speed, or at rest at a sharp corner
    assert np.count_nonzero(inner) >= inner.size / 2


def test_blur_by_dense_resampling_within_tolerance(flying_plan: optlight.Plan) -> None:
    angles, distances = _dense_blur(flying_plan)
    assert np.rad2deg(angles.max()) <= BLUR_DEG
    assert distances.max() <= BLUR_MM * 1e-3
    assert angles[1:-1].min() > 0.0  # the light moves during the interior exposures


def test_tight_blur_is_kept_and_slows_the_plan(flying_plan: optlight.Plan) -> None:
    """A tolerance 10× tighter binds at the captures: measured blur within it, some capture close to
    it (the cap is active), and the plan slower."""
    tight = optlight.solve(
        reduced_problem(camera_px=96, landmarks={"count": 8}, trajectory={"capture": "flying", "blur_deg": 0.02})
    )
    assert tight.verification.passed, tight.verification.summary()
    angles, _ = _dense_blur(tight)
    assert np.rad2deg(angles.max()) <= 0.02
    assert np.rad2deg(angles.max()) > 0.5 * 0.02
    assert tight.trajectory.duration > flying_plan.trajectory.duration


def test_triggers_put_the_light_on_its_landmark(flying_plan: optlight.Plan) -> None:
    triggers = flying_plan.trajectory.trigger_times(flying_plan.problem.trajectory.settle_s)
    p = _light_positions(flying_plan.robot, flying_plan.trajectory.sample(triggers)[0])
    landmarks = np.array([lm.position for lm in flying_plan.visited])
    assert np.linalg.norm(p - landmarks, axis=1).max() < 1e-3


def test_motion_is_continuous_and_within_limits(flying_plan: optlight.Plan) -> None:
    trajectory, limits = flying_plan.trajectory, flying_plan.setup.limits
    t = np.linspace(0.0, trajectory.duration, 200_001)
    q, qd, qdd = trajectory.sample(t)
    assert np.all(np.abs(qd) <= limits.velocity * (1 + 1e-6))
    assert np.all(np.abs(qdd) <= limits.acceleration * (1 + 1e-6))
    for tc in trajectory.capture_times[1:-1]:  # no step of q̇ or q̈ where the light passes a landmark
        _, before_d, before_dd = trajectory.sample(tc - 1e-7)
        _, after_d, after_dd = trajectory.sample(tc + 1e-7)
        assert np.abs(after_d - before_d).max() < 1e-3
        assert np.abs(after_dd - before_dd).max() < 1e-2


def test_flying_is_faster_than_stopping(flying_plan: optlight.Plan, stop_plan: optlight.Plan) -> None:
    assert flying_plan.trajectory.duration < stop_plan.motion_time  # faster than the stop plan's moves alone


def test_stop_plan_has_its_dwells_and_no_blur(stop_plan: optlight.Plan) -> None:
    trajectory, spec = stop_plan.trajectory, stop_plan.problem.trajectory
    assert spec.capture == "stop"
    intervals = trajectory.landmark_intervals
    assert np.allclose(intervals[:, 1] - intervals[:, 0], spec.dwell_s)
    windows = trajectory.exposure_windows(spec.settle_s, spec.exposure_s)
    assert np.allclose(windows[:, 0], intervals[:, 0] + spec.settle_s)
    assert stop_plan.verification.checks["blur_angle"].max_value == 0.0


def test_captures_csv_gives_triggers_and_blur(flying_plan: optlight.Plan, tmp_path: Path) -> None:
    flying_plan.save(tmp_path / "out", preview=False)
    with (tmp_path / "out" / "captures.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(flying_plan.visited)
    angles, distances = _dense_blur(flying_plan)
    for row, t, angle, distance in zip(rows, flying_plan.trajectory.capture_times, angles, distances, strict=True):
        assert float(row["trigger_s"]) == pytest.approx(t, abs=1e-9)
        assert float(row["dwell_start_s"]) == float(row["dwell_end_s"]) == float(row["trigger_s"])
        assert float(row["exposure_start_s"]) == pytest.approx(t - EXPOSURE_S / 2, abs=1e-8)
        assert float(row["exposure_end_s"]) - float(row["exposure_start_s"]) == pytest.approx(EXPOSURE_S, abs=1e-8)
        # the file's blur (the path's length during the exposure) is at least the largest angle and
        # distance between two of its instants; at an interior capture close to them (the path is all
        # but straight there; at the first and the last the light arrives or leaves at rest)
        slack = 1.05 if 0 < int(row["capture"]) < len(rows) - 1 else np.inf
        assert angle * (1 - 1e-4) <= np.deg2rad(float(row["blur_deg"])) <= angle * slack + 1e-9
        assert distance * (1 - 1e-4) <= float(row["blur_mm"]) * 1e-3 <= distance * slack + 1e-9
        assert float(row["blur_deg"]) <= BLUR_DEG
        assert float(row["blur_mm"]) <= BLUR_MM


def test_verification_fails_a_blur_above_tolerance(flying_plan: optlight.Plan) -> None:
    setup = flying_plan.setup
    report = verify_trajectory(
        flying_plan.trajectory,
        light_pose=setup.robot.light_pose,
        lower=setup.limits.lower,
        upper=setup.limits.upper,
        velocity_limit=setup.limits.velocity,
        acceleration_limit=setup.limits.acceleration,
        sphere=setup.sphere,
        landmark_positions=[lm.position for lm in flying_plan.visited],
        exposure=Exposure(EXPOSURE_S, np.deg2rad(0.001), 1e-5),
    )
    assert not report.passed
    moving = np.linalg.norm(flying_plan.trajectory.sample(flying_plan.trajectory.capture_times)[1], axis=1) > 0
    assert report.checks["blur_angle"].failing_samples == np.count_nonzero(moving) > 0  # those at rest pass
    assert any(v.check == "blur_distance" for v in report.violations)


def test_motion_bound_reports_the_flying_bound(flying_plan: optlight.Plan, stop_plan: optlight.Plan) -> None:
    bound = flying_plan.motion_bound()
    assert bound["flying_s"] <= bound["rest_to_rest_s"]
    assert bound["flying_ratio"] >= 1.0
    assert "flying_s" not in stop_plan.motion_bound()
    # a bound for any motion through the postures: the stop plan's motion too
    trajectory, limits = stop_plan.trajectory, stop_plan.setup.limits
    postures = trajectory.sample(np.r_[0.0, trajectory.landmark_intervals[:, 0], trajectory.duration])[0]
    assert nonstop_bound(postures, limits.velocity, limits.acceleration) <= stop_plan.motion_time


def test_nonstop_bound_by_hand() -> None:
    """One joint through 0, 1, 0.5, 2 rad (v = a = 1): it stops where it turns, so at least the
    bang-bang times over 1, 0.5 and 1.5 rad, 2 + 2√0.5 + 2.5 s (more than the 3 s at full speed);
    a second joint moving 4 rad on the first move makes the velocity bound 4 + 0.5 + 1.5 s win."""
    q = np.array([[0.0], [1.0], [0.5], [2.0]])
    assert nonstop_bound(q, 1.0, 1.0) == pytest.approx(2.0 + 2.0 * np.sqrt(0.5) + 2.5)
    q2 = np.column_stack([q[:, 0], [0.0, 4.0, 4.0, 4.0]])
    assert nonstop_bound(q2, [1.0, 1.0], [1.0, 100.0]) == pytest.approx(6.0)  # its stops: 4.01 s only


def test_tour_costs_are_ruckig_move_times(flying_plan: optlight.Plan) -> None:
    """With flying captures the tour's costs are the slowest joint's rest-to-rest move times, as
    ruckig plans them (here, not through optlight's closed form)."""
    setup, limits = flying_plan.setup, flying_plan.setup.limits
    thetas = flying_plan.robot.random_configuration(np.random.default_rng(3), 5)
    costs = tour_costs(setup.trajectory_spec, setup.limits, thetas)
    n = setup.robot.n
    otg, inp = ruckig.Ruckig(n), ruckig.InputParameter(n)
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = (x.tolist() for x in (limits.velocity, limits.acceleration, limits.jerk))
    for a in range(5):
        for b in range(5):
            if a == b:
                continue
            inp.current_position, inp.target_position = thetas[a].tolist(), thetas[b].tolist()
            out = ruckig.Trajectory(n)
            otg.calculate(inp, out)
            assert costs[a, b] == pytest.approx(out.duration, rel=1e-6)
    moves = rest_to_rest_moves(thetas, limits.velocity, limits.acceleration, limits.jerk)
    assert np.allclose(moves, costs[np.arange(4), np.arange(1, 5)], rtol=1e-6)


# ---------------------------------------------------------------- the timing law alone


VMAX = np.array([1.0, 1.5, 0.8])
AMAX = np.array([3.0, 2.0, 4.0])
JMAX = np.array([30.0, 20.0, 40.0])
#: Landmarks on a helix: the joint path turns by about 25° at each.
LANDMARKS = np.array([[np.cos(a), np.sin(a), 0.3 * a] for a in np.linspace(0.0, 2.0, 5)])


def _segments(k: int = 8) -> list[np.ndarray]:
    s = np.linspace(0.0, 1.0, k)[:, None]
    return [a + (b - a) * s for a, b in zip(LANDMARKS[:-1], LANDMARKS[1:], strict=True)]


def test_timing_law_caps_the_speed_at_the_landmarks() -> None:
    """Joint angles as the light's position (m) and a far centre: the light's speed at an interior
    landmark times the exposure stays within the linear tolerance, the limits hold everywhere."""
    exposure = Exposure(0.01, np.pi, 2e-3)  # the angle does not bind
    trajectory = flying_timing(
        _segments(),
        VMAX,
        AMAX,
        JMAX,
        light_positions=lambda q: np.asarray(q, float)[:, :3],
        center=np.array([100.0, 0.0, 0.0]),
        exposure=exposure,
    )
    captures = trajectory.capture_times
    assert np.allclose(trajectory.sample(captures)[0], LANDMARKS, atol=1e-12)
    qd = trajectory.sample(captures)[1]
    speed = np.linalg.norm(qd, axis=1)
    assert np.all(speed[1:-1] * exposure.seconds <= exposure.blur_m)
    assert np.all(speed[1:-1] * exposure.seconds > 0.5 * exposure.blur_m)  # the cap binds here
    t = np.linspace(0.0, trajectory.duration, 100_001)
    _, qd, qdd = trajectory.sample(t)
    assert np.all(np.abs(qd) <= VMAX * (1 + 1e-9))
    assert np.all(np.abs(qdd) <= AMAX * (1 + 1e-9))
    dt = np.diff(t)[:, None]
    assert np.all(np.abs(np.diff(qdd, axis=0)) / dt <= JMAX * (1 + 1e-3))


def test_speed_change_distance_matches_ruckig() -> None:
    """The distance a speed change from u to w needs, as ruckig's time-optimal profile (no position
    target: velocity control) covers it."""
    rng = np.random.default_rng(5)
    for _ in range(50):
        u, w, a, j = rng.uniform(0, 2), rng.uniform(0, 2), rng.uniform(0.5, 5), rng.uniform(5, 100)
        otg, inp, out = ruckig.Ruckig(1), ruckig.InputParameter(1), ruckig.Trajectory(1)
        inp.control_interface = ruckig.ControlInterface.Velocity
        inp.current_position, inp.current_velocity, inp.current_acceleration = [0.0], [u], [0.0]
        inp.target_velocity, inp.target_acceleration = [w], [0.0]
        inp.max_velocity, inp.max_acceleration, inp.max_jerk = [10.0], [a], [j]
        otg.calculate(inp, out)
        assert speed_change_distance(u, w, a, j) == pytest.approx(out.at_time(out.duration)[0][0], rel=1e-6, abs=1e-12)


def test_sharp_corner_is_passed_at_rest() -> None:
    """A joint path that turns by 90° at a landmark is split there and the arm stops; a 20° turn is
    passed at speed."""
    s = np.linspace(0.0, 1.0, 6)[:, None]
    points = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [0.5, 0.5, 0.0], [0.5 + 0.5 * np.sin(0.35), 0.5 + 0.5 * np.cos(0.35), 0.0]])
    segments = [a + (b - a) * s for a, b in zip(points[:-1], points[1:], strict=True)]
    assert corner_runs(segments) == [(0, 1), (1, 3)]
    trajectory = flying_timing(
        segments,
        VMAX,
        AMAX,
        JMAX,
        light_positions=lambda q: np.asarray(q, float)[:, :3],
        center=np.array([100.0, 0.0, 0.0]),
        exposure=Exposure(0.01, np.pi, 2e-3),
    )
    speed = np.linalg.norm(trajectory.sample(trajectory.capture_times)[1], axis=1)
    assert speed[1] == 0.0 and speed[2] > 0.0
    t = np.linspace(0.0, trajectory.duration, 50_001)
    _, qd, qdd = trajectory.sample(t)
    assert np.all(np.abs(qd) <= VMAX * (1 + 1e-9)) and np.all(np.abs(qdd) <= AMAX * (1 + 1e-9))
