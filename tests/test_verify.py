"""Independent verification, on an analytic 2-joint "arm": q = (zenith θ, azimuth φ) of the light.

light_pose(q) puts the light at a(θ, φ) on the sphere with its z axis aimed at O, so every
configuration satisfies h = 0 and the tests do not depend on the robot code.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from optlight.errors import VerificationError
from optlight.geometry import LightSphere, aim_rotation, sphere_frame
from optlight.planning.timing import time_parameterize
from optlight.verify import Tolerances, distance_to_polyline, ensure_verified, verify_trajectory

SPHERE = LightSphere(
    center=np.array([0.4, -0.2, 0.3]), radius=0.4, rotation=sphere_frame([0.4, -0.2, 0.3], [0.4, -1.2, 0.3])
)
LOWER = np.array([0.05, -np.pi])
UPPER = np.array([1.2, np.pi])
VMAX = np.array([0.8, 1.2])
AMAX = np.array([2.0, 3.0])
NAMES = ("zenith", "azimuth")
LANDMARKS_Q = np.array([[0.5, 0.0], [0.7, 0.8], [0.4, 1.6], [0.8, 2.4], [0.6, 3.0]])


def light_pose(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Light at zenith q[0], azimuth q[1], aimed at O (roll from the sphere's x axis)."""
    a = SPHERE.position(q[0], q[1])
    return a, aim_rotation(a, SPHERE.center, SPHERE.rotation[:, 0])


def segments(k: int = 9) -> list[np.ndarray]:
    s = np.linspace(0.0, 1.0, k)[:, None]
    out = []
    for a, b in zip(LANDMARKS_Q[:-1], LANDMARKS_Q[1:], strict=True):
        w = a + (b - a) * s
        w[:, 0] += 0.1 * np.sin(np.pi * s[:, 0])
        out.append(w)
    return out


def planned_path(k: int = 41) -> np.ndarray:
    """Light positions along the planned joint path, densely (the arcs the planner meant)."""
    s = np.linspace(0.0, 1.0, k)[:, None]
    q = np.vstack(
        [
            a + (b - a) * s + [[0.1, 0.0]] * np.sin(np.pi * s)
            for a, b in zip(LANDMARKS_Q[:-1], LANDMARKS_Q[1:], strict=True)
        ]
    )
    return SPHERE.position(q[:, 0], q[:, 1])


def check(trajectory, **kw):  # noqa: ANN001, ANN201 - test helper
    args = dict(
        light_pose=light_pose,
        lower=LOWER,
        upper=UPPER,
        velocity_limit=VMAX,
        acceleration_limit=AMAX,
        sphere=SPHERE,
        landmark_positions=SPHERE.position(LANDMARKS_Q[:, 0], LANDMARKS_Q[:, 1]),
        planned_path=planned_path(),
    )
    args.update(kw)
    return verify_trajectory(trajectory, **args)


@pytest.fixture(scope="module")
def trajectory():  # noqa: ANN201
    return time_parameterize(segments(), VMAX, AMAX, 0.2, joint_names=NAMES)


def test_a_timed_plan_passes_and_stays_within_the_limits(trajectory) -> None:
    report = check(trajectory)
    assert report.passed, report.summary()
    ensure_verified(report)
    assert report.violations == ()
    assert report.samples >= trajectory.duration * 1000
    assert set(report.checks) == {
        "position",
        "velocity",
        "acceleration",
        "h",
        "aim",
        "landmark",
        "path",
    }
    worst_rate = max(report.checks["velocity"].max_value, report.checks["acceleration"].max_value)
    assert 0.99 < worst_rate <= 1 + 1e-3  # time-optimal: a limit is reached, none exceeded
    assert report.checks["h"].max_value < 1e-12
    assert report.checks["path"].max_value < 2e-3
    # independent of the report: dense resampling stays within the limits
    _, qd, qdd = trajectory.sample(np.linspace(0, trajectory.duration, 200_001))
    assert np.max(np.abs(qd) / VMAX) <= 1 + 1e-3
    assert np.max(np.abs(qdd) / AMAX) <= 1 + 1e-3
    assert "PASSED" in report.summary()


def test_a_compressed_time_axis_fails_naming_joint_and_time(trajectory) -> None:
    fast = trajectory.time_scaled(0.5)  # velocities ×2, accelerations ×4
    report = check(fast)
    assert not report.passed
    assert not report.checks["velocity"].passed and not report.checks["acceleration"].passed
    assert report.checks["velocity"].max_value == pytest.approx(
        2 * check(trajectory).checks["velocity"].max_value, rel=1e-3
    )
    v = next(v for v in report.violations if v.check == "velocity")
    assert v.joint in NAMES
    assert 0 < v.time_s < fast.duration
    assert v.value > v.limit == pytest.approx(VMAX[NAMES.index(v.joint)] * (1 + 1e-3))
    assert v.joint in v.message and f"{v.time_s:.4f}" in v.message
    # the recorded time really is a violation of that joint
    _, qd, _ = fast.sample([v.time_s])
    assert abs(qd[0, NAMES.index(v.joint)]) == pytest.approx(v.value)
    # the light constraints still hold: only the rate checks fail
    assert report.checks["h"].passed and report.checks["landmark"].passed and report.checks["path"].passed
    with pytest.raises(VerificationError, match="velocity") as err:
        ensure_verified(report)
    assert err.value.report is report
    assert "FAILED" in report.summary() and v.message in report.summary()
    assert len([x for x in report.violations if x.check == "velocity"]) <= 5


def test_a_spline_that_bulges_past_a_joint_limit_is_caught() -> None:
    # waypoints within [0.05, 1.2]; the cubic through them overshoots the upper limit of the zenith
    w = np.array([[0.3, 0.0], [1.1, 0.2], [1.2, 0.4], [0.4, 0.6]])
    traj = time_parameterize([w], VMAX, AMAX, 0.1, joint_names=NAMES)
    report = check(
        traj,
        landmark_positions=SPHERE.position(w[[0, -1], 0], w[[0, -1], 1]),
        planned_path=None,
    )
    assert not report.passed
    assert report.checks["position"].max_value > 1e-3
    v = next(v for v in report.violations if v.check == "position")
    assert v.joint == "zenith" and v.limit == UPPER[0] and v.value > UPPER[0]
    assert "path" in report.skipped and "path" not in report.checks


def test_light_off_the_sphere_or_off_the_landmark_fails(trajectory) -> None:
    def off_sphere(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a, r = light_pose(q)
        return a + 1e-4 * r[:, 2], r  # 0.1 mm along the optical axis

    report = check(trajectory, light_pose=off_sphere)
    assert not report.checks["h"].passed
    assert report.checks["h"].max_value == pytest.approx(1e-4, rel=1e-6)
    assert report.checks["aim"].passed

    def tilted(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a, r = light_pose(q)
        c, s = np.cos(1e-3), np.sin(1e-3)
        return a, r @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]])

    report = check(trajectory, light_pose=tilted)
    assert not report.checks["aim"].passed
    assert report.checks["aim"].max_value == pytest.approx(1e-3, rel=1e-6)

    moved = SPHERE.position(LANDMARKS_Q[:, 0], LANDMARKS_Q[:, 1])
    moved[2] += [0.0, 0.0, 1e-3]
    report = check(trajectory, landmark_positions=moved)
    assert [v.check for v in report.violations] == ["landmark"]
    assert "landmark 2" in report.violations[0].message
    assert report.checks["landmark"].episodes == 1
    moved[3] += [0.0, 0.0, 1e-3]  # two consecutive dwells: two episodes, not one
    assert check(trajectory, landmark_positions=moved).checks["landmark"].episodes == 2


def test_a_dwell_that_drifts_is_checked_at_every_sample(trajectory) -> None:
    # The verifier computes one pose per run of equal configurations: a dwell whose configuration
    # creeps (zenith + 2e-3 rad/s) must still be measured at each sample, its worst distance to
    # the landmark the one at the dwell's end.
    start, end = trajectory.landmark_intervals[2]

    class Drifting:
        def __getattr__(self, name: str):  # noqa: ANN204 - the wrapped trajectory's other members
            return getattr(trajectory, name)

        def sample(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            q, qd, qdd = trajectory.sample(t)
            inside = (t >= start) & (t <= end)
            q = q.copy()
            q[inside, 0] += 2e-3 * (t[inside] - start)
            return q, qd, qdd

    report = check(Drifting())
    drift = 2e-3 * (end - start)
    q_end = LANDMARKS_Q[2] + [drift, 0.0]
    expected = np.linalg.norm(light_pose(q_end)[0] - light_pose(LANDMARKS_Q[2])[0])
    assert report.checks["landmark"].max_value == pytest.approx(expected, rel=1e-6)
    assert report.checks["landmark"].time_s == pytest.approx(end, abs=2e-3)


def test_deviation_from_the_planned_path_is_reported_and_has_a_tolerance(trajectory) -> None:
    shifted = planned_path() + [0.0, 0.0, 0.01]
    report = check(trajectory, planned_path=shifted)
    assert not report.checks["path"].passed
    assert report.checks["path"].max_value > 0.009
    loose = check(trajectory, planned_path=shifted, tol=Tolerances(path_m=0.05))
    assert loose.checks["path"].passed and loose.checks["path"].max_value == report.checks["path"].max_value


def test_nan_from_the_kinematics_fails_instead_of_passing(trajectory) -> None:
    def broken(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a, r = light_pose(q)
        return (a * np.nan, r) if q[1] > 2.0 else (a, r)

    report = check(trajectory, light_pose=broken)
    assert not report.passed
    assert not report.checks["h"].passed and not report.checks["path"].passed
    assert np.isnan(report.checks["h"].max_value)
    json.dumps(report.to_dict(), allow_nan=False)


def test_report_to_dict_is_json_and_complete(trajectory) -> None:
    report = check(trajectory.time_scaled(0.7))
    d = json.loads(json.dumps(report.to_dict(), allow_nan=False))
    assert d["passed"] is False
    assert d["checks"]["velocity"]["passed"] is False
    assert d["counts"]["velocity"] == report.checks["velocity"].failing_samples > 0
    assert d["violations"][0]["check"] in d["checks"]
    assert d["tolerances"]["limit_rel"] == 1e-3


def test_inputs_are_checked(trajectory) -> None:
    with pytest.raises(ValueError, match="landmark positions"):
        check(trajectory, landmark_positions=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="1000"):
        check(trajectory, rate_hz=100.0)


def test_distance_to_polyline() -> None:
    poly = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0]])
    pts = np.array([[0.5, 0.2, 0], [2, 0, 0], [1, 0.5, 0.3], [-1, 0, 0], [0.5, 0, 0]])
    np.testing.assert_allclose(distance_to_polyline(pts, poly), [0.2, 1.0, 0.3, 1.0, 0.0])
    np.testing.assert_allclose(distance_to_polyline(pts[:1], poly[:1]), [np.hypot(0.5, 0.2)])


def brute_force_distance(points: np.ndarray, polyline: np.ndarray) -> np.ndarray:
    """Distance to the nearest of all the segments, each measured (the definition, O(P K))."""
    best = np.full(len(points), np.inf)
    for a, b in zip(polyline[:-1], polyline[1:], strict=True):
        d = b - a
        c = np.clip((points - a) @ d / max(d @ d, 1e-300), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(points - a - c[:, None] * d, axis=1))
    return best


@pytest.mark.parametrize("seed", range(4))
def test_distance_to_polyline_matches_every_segment_measured(seed: int) -> None:
    rng = np.random.default_rng(seed)
    # a wiggly path of short steps with a few long jumps (a transfer's knots), repeated vertices
    steps = rng.normal(scale=0.01, size=(400, 3))
    steps[rng.choice(400, 5, replace=False)] *= 30.0
    steps[rng.choice(400, 5, replace=False)] = 0.0
    polyline = np.cumsum(steps, axis=0)
    near = polyline[rng.integers(0, 400, 3000)] + rng.normal(scale=0.02, size=(3000, 3))
    far = rng.uniform(polyline.min(0) - 1.0, polyline.max(0) + 1.0, size=(500, 3))
    points = np.vstack([near, far])
    # runs of equal points (a dwell's samples), one of them interrupted by a NaN sample
    points = np.repeat(points, rng.integers(1, 4, len(points)), axis=0)
    points[rng.choice(len(points), 20, replace=False)] = np.nan
    expected = brute_force_distance(points, polyline)
    np.testing.assert_allclose(distance_to_polyline(points, polyline), expected, atol=1e-12)
