"""The camera's view at the planning stage: the lights whose housing would stand in front of the lens
are taken away before the search (checked with coal against the exact cone), landmarks that coincide
are one capture, and the plan starts and ends at the robot's start configuration."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import REACH_ONLY, reduced_problem, search_landmarks

import optlight
from optlight.environment import CAPTURE_SLACK
from optlight.errors import ProblemError
from optlight.planning.landmarks import Landmark, distinct_landmarks
from optlight.setup import Setup, housing_clearance, housing_sphere_clearance


def _housing_points_in_view(setup: Setup, zenith: float, azimuth: float = 0.0, count: int = 4000) -> int:
    """How many of ``count`` points spread over the housing (cylinder of [light], behind the emitting
    point, axis away from O) lie inside the view cone, tested with the cone's definition (angle to
    the axis ≤ α, between the camera and the plane through O): brute force, no distances."""
    light, sphere, cone = setup.problem.light, setup.sphere, setup.environment.view_cone
    rng = np.random.default_rng(0)
    d = sphere.direction(zenith, azimuth)
    x = np.cross([1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0], d)
    x /= np.linalg.norm(x)
    y = np.cross(d, x)
    t = rng.uniform(0.0, light.housing_length_m, count)
    phi = rng.uniform(0.0, 2 * np.pi, count)
    rho = light.housing_radius_m * np.sqrt(rng.uniform(0.0, 1.0, count))
    rho[: count // 2] = light.housing_radius_m  # half on the mantle, half through the volume
    points = sphere.center + (sphere.radius + t)[:, None] * d + rho[:, None] * (
        np.cos(phi)[:, None] * x + np.sin(phi)[:, None] * y
    )
    v = points - cone.apex
    along = v @ cone.axis
    angle = np.arccos(np.clip(along / np.linalg.norm(v, axis=1), -1.0, 1.0))
    return int(np.sum((angle <= cone.half_angle) & (along >= 0.0) & (along <= cone.length)))


@pytest.fixture(scope="module")
def setup() -> Setup:
    return Setup.from_problem(reduced_problem(camera_px=48, landmarks={"count": 12, "resolution": 32}))


def test_the_view_takes_away_the_lights_in_front_of_the_lens(setup: Setup) -> None:
    theta_v = setup.view_zenith
    assert theta_v > setup.scene.sphere.zenith_min
    assert setup.sphere.zenith_min == theta_v
    # a degree nearer the axis the housing is in the view at some azimuth, from the boundary on at none
    azimuths = np.radians(np.arange(0.0, 360.0, 15.0))
    assert max(_housing_points_in_view(setup, theta_v - math.radians(1.0), phi) for phi in azimuths) > 0
    assert all(_housing_points_in_view(setup, theta_v, phi) == 0 for phi in azimuths)
    assert all(_housing_points_in_view(setup, theta_v + math.radians(5.0), phi) == 0 for phi in azimuths)
    # the boundary is where the tighter of the two housing models just holds: the exact coal shape
    # touches the cone, or the NLPs' spheres (over every roll) keep CAPTURE_SLACK from it
    exact = housing_clearance(setup.sphere, setup.environment, theta_v)
    spheres = housing_sphere_clearance(setup.sphere, setup.environment, setup.robot, theta_v) - CAPTURE_SLACK
    assert min(exact, spheres) == pytest.approx(0.0, abs=1e-6) and 0.0 <= max(exact, spheres) < 5e-3


def test_landmarks_stay_out_of_the_view_and_say_where_they_moved(setup: Setup) -> None:
    landmarks = search_landmarks(setup)
    assert min(lm.zenith for lm in landmarks.landmarks) >= setup.view_zenith - 1e-12
    # the default's reference light (zenith 10°) is in the view: the azimuths whose best light was
    # there are named, with the clear landmark that replaces it
    assert landmarks.notes
    assert len(landmarks.notes) == 1 and "is in the camera's view" in landmarks.notes[0]
    assert landmarks.sweep.zenith.min() == pytest.approx(setup.scene.sphere.zenith_min)


def test_coincident_landmarks_are_one_capture() -> None:
    def lm(index: int, zenith_deg: float, azimuth_deg: float, cost: float) -> Landmark:
        return Landmark(index, math.radians(zenith_deg), math.radians(azimuth_deg), np.zeros(3), cost, "refined", "", 0, 0.0)

    landmarks = [lm(0, 0.0, 0.0, 0.3), lm(1, 0.0, 90.0, 0.1), lm(2, 0.2, 180.0, 0.2), lm(3, 20.0, 0.0, 0.5)]
    kept, notes = distinct_landmarks(landmarks, math.radians(0.5))
    # 0, 1, 2 are within 0.2° of the pole: one capture, the cheapest (1) kept, the order kept
    assert [k.index for k in kept] == [1, 3]
    assert notes == ["landmarks 0, 1, 2 are one capture (within 0.5° of each other): landmark 1 is kept"]
    # the same direction is the same light at any tolerance (the pole at two azimuths)
    assert [k.index for k in distinct_landmarks(landmarks, 0.0)[0]] == [1, 2, 3]


@pytest.mark.parametrize(
    ("start", "fragment"),
    [
        ([0.0, 0.0, 0.0], "7 joint angles"),
        ([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 9.0], "within the limits"),
        ("no_such_pose", "a configuration of panda (default)"),
    ],
)
def test_bad_start_configurations_name_the_key(start, fragment: str) -> None:
    with pytest.raises(ProblemError) as err:
        Setup.from_problem(reduced_problem(camera_px=32, robot={"start": start}))
    assert err.value.key == "robot.start" and fragment in str(err.value)


def test_a_start_in_collision_names_the_key() -> None:
    problem = reduced_problem(
        "collision", camera_px=32, robot={"start": [0.0, 0.6, 0.0, -0.5, 0.0, 1.2, 0.785]}
    )
    with pytest.raises(ProblemError, match="robot.start: expected a configuration clear of the environment"):
        Setup.from_problem(problem)


def test_the_default_plan_starts_and_ends_at_the_start_and_keeps_the_view_clear() -> None:
    """The whole default job at a small size: the trajectory leaves from and returns to [robot] start,
    and the verification's exact ray cast (robot meshes + housing, placed by pinocchio) finds the view
    and the beam clear at every capture."""
    problem = reduced_problem(camera_px=48, landmarks={"count": 12, "resolution": 32})
    plan = optlight.solve(problem)
    start = plan.setup.start
    q, qd, _ = plan.trajectory.sample(np.array([0.0, plan.trajectory.duration]))
    np.testing.assert_allclose(q, [start, start], atol=1e-9)
    np.testing.assert_allclose(qd, 0.0, atol=1e-9)  # at rest where it leaves and where it arrives
    assert plan.verification.passed, plan.verification.summary()
    report = plan.verification
    assert {"view", "beam"} <= set(report.checks) and not {"view", "beam"} & set(report.skipped)
    assert report.checks["view"].passed and report.checks["beam"].passed
    zeniths = [lm.zenith for lm in plan.visited]
    assert min(zeniths) >= plan.setup.view_zenith - 1e-9


def test_a_plan_without_view_protection_says_so_first(tmp_path) -> None:
    """[view] mode = "off": the view and beam checks are skipped, and report.md says so before
    anything else; protected, its first lines say how."""
    plan = optlight.solve(reduced_problem(camera_px=32, landmarks={"count": 2, "resolution": 32}, **REACH_ONLY))
    assert {"view", "beam"} <= set(plan.verification.skipped)
    plan.save(tmp_path / "off", preview=False)
    head = (tmp_path / "off" / "report.md").read_text().splitlines()[:4]
    assert any("The camera's view is not protected" in line for line in head)
