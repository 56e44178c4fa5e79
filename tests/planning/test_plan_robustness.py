"""Cells the shipped problems do not cover plan and verify, or say why: the light's beam onto the
object is planned around where the camera's view is (placement, set design, the trajectory NLP's
captures); a set designed over the reachable lights is designed on the lights the reachability map
found clear, or says how many fit."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest
from conftest import reacher_of, reduced_problem

import optlight
from optlight.environment.view import view_check_for
from optlight.errors import UnreachableError
from optlight.pipeline import wanted_lights
from optlight.planning.landmarks import LandmarkSet
from optlight.planning.set_landmarks import (
    CLEAR_MARGIN,
    SetDesign,
    allowed_cap,
    clear_lights,
    directions_of,
    fitting_count,
    landmarks_of_set,
)
from optlight.setup import Setup


def _sphere_stereo(zenith_max_deg: float = 50.0) -> optlight.Problem:
    """A photometric-stereo set of 10 lights on a matte sphere, panda, a 50° cap."""
    return reduced_problem(
        "photometric_stereo",
        camera_px=64,
        object={"kind": "sphere", "radius_m": 0.08},
        light_sphere={"zenith_max_deg": zenith_max_deg},
        lightset={"count": 10, "starts": 1},
    )


@pytest.fixture(scope="module")
def stereo_setup() -> Setup:
    return Setup.from_problem(_sphere_stereo())


def test_beam_rows_casadi_and_numpy_agree(stereo_setup: Setup) -> None:
    env, robot = stereo_setup.environment, stereo_setup.robot
    assert env is not None and env.beam is not None
    function = env.view_cone_function(robot)
    labels = env.view_labels(robot)
    assert function.size1_out(0) == len(labels) and any(label.endswith("↔ beam") for label in labels)
    rng = np.random.default_rng(3)
    for theta in robot.random_configuration(rng, 5):
        numpy_rows = env.sphere_clearance(robot, theta)[1]
        np.testing.assert_allclose(np.asarray(function(theta)).ravel(), numpy_rows, atol=1e-9)


def test_beam_cone_holds_every_ray_the_exact_check_casts(stereo_setup: Setup) -> None:
    """Points on the rays from the light to the object's bounding sphere, beyond the housing's radius
    where the ray caster starts, are inside the beam cone (sd < 0); points off every such ray by more
    than the smoothing are outside (sd > 0): brute force by the cone's definition."""
    env = stereo_setup.environment
    assert env is not None and env.beam is not None
    beam, rng = env.beam, np.random.default_rng(0)
    apex = beam.center + np.array([0.1, -0.2, 0.3])
    targets = beam.center + beam.radius * rng.normal(size=(500, 3)) / np.sqrt(3.0) * rng.uniform(0, 1, (500, 1))
    targets = targets[np.linalg.norm(targets - beam.center, axis=1) < beam.radius]
    rays = targets - apex
    length = np.linalg.norm(rays, axis=1)
    s = rng.uniform(beam.skip, length)
    on_rays = apex + (s / length)[:, None] * rays
    on_rays = on_rays[(on_rays - apex) @ (beam.center - apex) / np.linalg.norm(beam.center - apex)
                      <= np.linalg.norm(beam.center - apex)]
    assert (beam.signed_distance(on_rays, apex) < 0).all()
    # far to the side of the beam, and behind the light
    side = apex + np.cross(beam.center - apex, [0.0, 0.0, 1.0]) + rng.normal(scale=0.01, size=(50, 3))
    behind = apex - 0.5 * (beam.center - apex) + rng.normal(scale=0.01, size=(50, 3))
    assert (beam.signed_distance(np.vstack([side, behind]), apex) > 0).all()


@pytest.mark.slow
def test_a_stereo_set_on_a_sphere_keeps_the_arm_out_of_the_beam() -> None:
    """A photometric-stereo set on a sphere with a 50° cap on the panda: the arm stood in the light's
    beam at some lights (verification failed on the beam) when the beam was only verified."""
    plan = optlight.solve(_sphere_stereo())
    assert plan.verification.passed, plan.verification
    view = view_check_for(plan.setup.robot, plan.setup.scene, plan.setup.problem.light)
    captures = plan.trajectory.capture_times
    report = view.check(plan.trajectory.sample(captures)[0], captures)
    assert len(report.captures) >= 8 and all(c.beam_blocked == 0.0 for c in report.captures)


def _rti_ur10(**lightset: object) -> optlight.Problem:
    """An RTI set of 12 lights on a face, UR10, a 65° cap on a 0.31 m sphere, designed over the
    reachable lights (the default): the clear lights are a band of the cap."""
    return optlight.problem_from_dict(
        {
            "object": {"kind": "face", "center_m": [0.599, -0.193, 0.243]},
            "camera": {"position_m": [0.084, -0.688, 0.365], "width": 64, "height": 64, "fov_deg": 25.0},
            "light_sphere": {"radius_m": 0.306, "zenith_max_deg": 64.8},
            "robot": {"name": "ur10"},
            "objective": {
                "terms": [{"kind": "histogram", "distance": "emd2"}],
                "reference": {"kind": "light", "zenith_deg": 30.0, "azimuth_deg": 90.0},
            },
            "lightset": {"kind": "rti", "count": 12, "starts": 2, **lightset},
            "trajectory": {"order": "tour", "path": "free"},
        }
    )


@pytest.fixture(scope="module")
def rti_design() -> tuple[Setup, LandmarkSet, SetDesign]:
    setup = Setup.from_problem(_rti_ur10())
    wanted = wanted_lights(setup)
    return (setup, *landmarks_of_set(reacher_of(setup), setup.lightset_spec, setup.landmark_spec, wanted))


@pytest.mark.slow
def test_a_set_over_the_reachable_lights_is_designed_on_the_clear_cells(
    rti_design: tuple[Setup, LandmarkSet, SetDesign],
) -> None:
    """From uniform starts IPOPT called the band infeasible and 3 of the 12 lights were designed where
    the map found nothing clear (the placement then dropped them)."""
    setup, found, design = rti_design
    assert design.reach is not None and design.field is not None
    directions = directions_of(setup.sphere, found.landmarks)
    assert len(directions) == 12
    assert (design.field.numpy(directions) >= CLEAR_MARGIN - 1e-6).all()
    # each light is within a map step of a cell the map found clear (the field only smooths them)
    cells = design.reach.directions[design.reach.clear.ravel()]
    nearest = np.degrees(np.arccos(np.clip((directions @ cells.T).max(axis=1), -1.0, 1.0)))
    assert nearest.max() <= 2.0 * setup.problem.lightset.reach_step_deg


@pytest.mark.slow
def test_too_few_clear_lights_for_the_set_says_how_many_fit(
    rti_design: tuple[Setup, LandmarkSet, SetDesign],
) -> None:
    setup, _, design = rti_design
    assert design.reach is not None and design.field is not None
    pool = clear_lights(design.reach, design.field, allowed_cap(setup.workcell))
    assert 12 <= len(pool) < 400
    many = Setup.from_problem(_rti_ur10(count=400))
    with pytest.raises(UnreachableError, match=rf"set \[lightset\] count = {len(pool)} \(or less\)"):
        fitting_count(many.robot, many.lightset_spec, many.landmark_spec, pool, design.reach)
    partial = optlight.problem_from_dict(
        {**_rti_ur10(count=400).to_dict(), "landmarks": {"allow_partial": True}}
    )
    fits = Setup.from_problem(partial)
    assert fitting_count(fits.robot, fits.lightset_spec, fits.landmark_spec, pool, design.reach) == len(pool)


def _zigzag_knots(setup: Setup, amplitude: float) -> np.ndarray:
    """Knots of one segment on the sphere, lights 2° apart along a zenith-30° ring, whose postures
    swing the panda's elbow back and forth in its self-motion (±``amplitude`` rad along the null
    space of the light's 6-D Jacobian, then back onto the light by IK): every knot is exact, but the
    joints move a long way between lights 2° apart, as they do where a plan turns the arm about the
    light."""
    robot, sphere = setup.robot, setup.sphere
    knots: list[np.ndarray] = []
    for k, azimuth in enumerate(range(0, 12, 2)):
        start = robot.theta_ref
        if knots:
            null = np.linalg.svd(robot.light_jacobian(knots[-1]))[2][-1]
            start = knots[-1] + (amplitude if k % 2 else -amplitude) * np.sign(null[0]) * null
        target = sphere.position(np.radians(30.0), np.radians(azimuth))
        ik = optlight.generalized_ik(robot, sphere, target, start, restarts=False, secondary=())
        assert ik.success
        knots.append(ik.theta)
    return np.array(knots)


def test_the_timed_path_keeps_to_the_planned_path_between_far_apart_postures(small_setup: Setup) -> None:
    """The timing's joint-space spline between knots whose postures are far apart (and the joint-space
    midpoints it adds to keep within the joint bounds) took the light 6 mm from the planned path:
    the plan failed its own verification. Knots are now added on the path where it strays."""
    from optlight.pipeline import time_knots, verify_knots
    from optlight.planning.path import LightPath

    theta = _zigzag_knots(small_setup, 1.3)
    positions = small_setup.robot.light_positions(theta)
    rotations = np.array([small_setup.robot.light_pose(q)[1] for q in theta])
    directions = (positions - small_setup.sphere.center) / small_setup.sphere.radius
    path = LightPath(directions, positions, rotations, np.arange(2), np.array([0, len(theta) - 1]), np.zeros(1, bool))
    trajectory = time_knots(small_setup, path, theta)
    report = verify_knots(small_setup, trajectory, positions[[0, -1]], theta, path.transfers)
    check = report.checks["path"]
    assert check.samples > 1000 and check.max_value <= 0.5 * check.limit


def test_hardest_capture_is_the_one_farthest_from_its_neighbours() -> None:
    from optlight.planning.trajectory.windows import hardest_capture

    thetas = np.array([[0.0, 0.0], [0.1, 0.0], [0.1, 1.5], [0.2, 0.1], [0.3, 0.1]])
    assert hardest_capture(thetas, 0, 4) == 2  # 1.5 rad before it, 1.4 after: a posture off its way
    assert hardest_capture(thetas, 3, 4) == 3  # within the window only
    assert hardest_capture(thetas[:1], 0, 0) == 0


@pytest.mark.slow
def test_a_capture_the_trajectory_nlp_finds_no_way_through_is_named_and_dropped_with_allow_partial(
    small_default: optlight.Problem, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Where the trajectory NLP finds no way (here: whenever the path holds all the placed captures),
    the plan says between which captures and why; with [landmarks] allow_partial it drops the
    capture that needs the largest reconfiguration and plans the rest."""
    import optlight.pipeline as pipeline
    import optlight.planning.trajectory.windows as windows
    from optlight.errors import CaptureSolverError, SolverError

    real_path, real_knots = pipeline.capture_path, windows.optimize_knots
    paths: list[int] = []  # captures of each path the pipeline plans

    def counted_path(sphere, spec, positions, thetas):  # type: ignore[no-untyped-def]
        paths.append(len(positions))
        return real_path(sphere, spec, positions, thetas)

    def fails_with_every_capture(cell, spec, solver, path, warm, fixed_start, **kwargs):  # type: ignore[no-untyped-def]
        if len(paths) == 1:  # the first path, through every placed capture
            raise SolverError("the trajectory NLP failed (Infeasible_Problem_Detected)")
        return real_knots(cell, spec, solver, path, warm, fixed_start, **kwargs)

    monkeypatch.setattr(pipeline, "capture_path", counted_path)
    monkeypatch.setattr(windows, "optimize_knots", fails_with_every_capture)
    with pytest.raises(CaptureSolverError, match=r"between captures 0 and \d+ \(visiting order\).*Infeasible"):
        optlight.solve(small_default)
    paths.clear()
    partial = optlight.problem_from_dict(
        {
            **small_default.to_dict(),
            "landmarks": {**small_default.to_dict()["landmarks"], "allow_partial": True},
        }
    )
    with pytest.warns(UserWarning, match=r"dropped landmark \d+ .*capture \d+ of the visiting order: the "):
        plan = optlight.solve(partial)
    assert plan.verification.passed
    assert len(paths) == 2 and paths[1] == paths[0] - 1 == len(plan.visited)


def test_knots_far_apart_on_the_sphere_get_knots_on_their_arc(small_setup: Setup) -> None:
    """The free path's NLP bounds the joints' steps, not the light's: two knots whose lights are 40°
    apart leave a chord 24 mm inside the sphere, which the light (on the sphere) cannot follow, and
    the plan failed its own verification on the path. Knots are added on the arc between them."""
    from optlight.pipeline import knots_on_path, time_knots, verify_knots
    from optlight.planning.path import LightPath

    robot, sphere = small_setup.robot, small_setup.sphere
    theta = [robot.theta_ref]
    for azimuth in (60.0, 100.0):
        target = sphere.position(np.radians(30.0), np.radians(azimuth))
        ik = optlight.generalized_ik(robot, sphere, target, theta[-1], restarts=False)
        assert ik.success
        theta.append(ik.theta)
    knots = np.array(theta[1:])
    positions = robot.light_positions(knots)
    rotations = np.array([robot.light_pose(q)[1] for q in knots])
    directions = (positions - sphere.center) / sphere.radius
    path = LightPath(directions, positions, rotations, np.arange(2), np.array([0, 1]), np.zeros(1, bool))
    planned_path, planned = knots_on_path(small_setup.workcell, path, knots)
    assert len(planned) > 2 and planned_path.landmark_knots.tolist() == [0, len(planned) - 1]
    np.testing.assert_array_equal(planned[[0, -1]], knots)
    lights = robot.light_positions(planned)
    np.testing.assert_allclose(np.linalg.norm(lights - sphere.center, axis=1), sphere.radius, atol=1e-5)  # IK tol
    trajectory = time_knots(small_setup, planned_path, planned)
    report = verify_knots(small_setup, trajectory, positions, planned, planned_path.transfers)
    assert report.checks["path"].max_value <= 0.5 * report.checks["path"].limit


def test_the_planners_path_allowance_is_within_the_verifications_tolerance() -> None:
    """The planner keeps the spline within half the verification's tolerance of the planned path and
    measures it with its own polyline distance, which agrees with the verifier's (k-d tree pruned)."""
    from optlight.planning import trajectory
    from optlight.planning.trajectory import following
    from optlight.verify import Tolerances, distance_to_polyline

    assert trajectory.PATH_DEVIATION_M <= 0.5 * Tolerances().path_m
    assert trajectory.ARC_SAG_M <= trajectory.PATH_DEVIATION_M
    rng = np.random.default_rng(1)
    polyline = np.cumsum(rng.normal(scale=0.02, size=(40, 3)), axis=0)
    points = polyline[rng.integers(0, 40, 300)] + rng.normal(scale=0.01, size=(300, 3))
    np.testing.assert_allclose(
        following._polyline_distance(points, polyline), distance_to_polyline(points, polyline), atol=1e-12
    )


def _turned(robot: object, thetas: np.ndarray, every: int = 2) -> np.ndarray:
    """``thetas`` (M, n) with each joint of range above 2π turned by a whole turn (+2π where its
    limits allow, else −2π) at every ``every``-th capture from the second: the same light poses."""
    from optlight.robot.kinematics import PRISMATIC_JOINTS

    lower, upper = robot.lower, robot.upper  # type: ignore[attr-defined]
    wraps = np.array([k not in PRISMATIC_JOINTS for k in robot.joint_kinds]) & (upper - lower > 2 * np.pi)  # type: ignore[attr-defined]
    out = np.array(thetas, float, copy=True)
    for k in range(1, len(out), every):
        up = out[k] + 2 * np.pi
        out[k, wraps] = np.where(up <= upper, up, out[k] - 2 * np.pi)[wraps]
    return out


@pytest.mark.parametrize("name", ["face_ur5", "default"])
def test_unwrapped_postures_keep_the_light_pose_and_turn_least(name: str) -> None:
    """Turned by whole turns, capture postures give the same light pose (pinocchio's kinematics);
    unwrapped along the visiting order they are back at the postures of least travel (here the
    untouched ones, each step under 1 rad) in every joint of range above 2π (the UR5's five; none
    of the Panda's, which are left as they are)."""
    from optlight.planning.turns import unwrapped_postures

    robot = Setup.from_problem(optlight.load_problem(name)).workcell.robot
    rng = np.random.default_rng(3)
    steps = rng.uniform(-1.0, 1.0, size=(6, robot.n))  # neighbours within 1 rad: nothing to unwrap
    thetas = np.clip(np.cumsum(steps, axis=0), np.maximum(robot.lower, -2.5), np.minimum(robot.upper, 2.5))
    turned = _turned(robot, thetas)
    unwrapped = unwrapped_postures(robot, turned, thetas[0])
    for a, b in zip(turned, unwrapped, strict=True):
        (pa, ra), (pb, rb) = robot.light_pose(a), robot.light_pose(b)
        assert np.allclose(pa, pb, atol=1e-12) and np.allclose(ra, rb, atol=1e-12)
    assert np.all((unwrapped >= robot.lower) & (unwrapped <= robot.upper))
    wraps = robot.upper - robot.lower > 2 * np.pi
    if wraps.any():
        assert not np.allclose(turned, thetas)  # the test turns something
        np.testing.assert_allclose(unwrapped[:, wraps], thetas[:, wraps], atol=1e-12)
    else:
        np.testing.assert_array_equal(unwrapped, turned)


def test_unwrapped_postures_travel_least_of_every_choice_of_turns() -> None:
    """Against every choice of whole turns within the limits (enumerated, joint by joint): the
    unwrapped postures' travel Σ_k |θ_k − θ_{k−1}| from the start is the least, on a UR5 whose
    postures are drawn anywhere in its limits."""
    import itertools

    from optlight.planning.turns import unwrapped_postures

    robot = Setup.from_problem(optlight.load_problem("face_ur5")).workcell.robot
    rng = np.random.default_rng(7)
    for _ in range(5):
        start = rng.uniform(robot.lower, robot.upper)
        thetas = rng.uniform(robot.lower, robot.upper, size=(4, robot.n))
        unwrapped = unwrapped_postures(robot, thetas, start)
        for j in range(robot.n):
            options = [
                [t + 2 * np.pi * m for m in range(-2, 3) if robot.lower[j] <= t + 2 * np.pi * m <= robot.upper[j]]
                for t in thetas[:, j]
            ]
            least = min(np.abs(np.diff([start[j], *path])).sum() for path in itertools.product(*options))
            travel = np.abs(np.diff([start[j], *unwrapped[:, j]])).sum()
            assert travel == pytest.approx(least, abs=1e-12)


@pytest.mark.slow
def test_captures_placed_a_turn_apart_are_all_delivered(monkeypatch: pytest.MonkeyPatch) -> None:
    """A UR5 on a table whose placement gives every other capture a whole turn of each joint (the
    same light pose, as a placement that solves each capture on its own can): the plan unwraps them
    and captures every placed landmark, verified, none dropped by the trajectory NLP; the dense
    trajectory is clear by coal's exact distances. (Turning the shoulder by 2π sweeps the arm through
    the table: there is no way through those postures as placed, and allow_partial dropped captures.)"""
    import optlight.pipeline as pipeline
    from optlight.environment.check import check_configurations

    real = pipeline.PlacementAhead.placement
    placed: list[int] = []

    def turned(self, captures):  # type: ignore[no-untyped-def]
        placement = real(self, captures)
        placed.append(len(placement.landmarks))
        return replace(placement, thetas=_turned(self.reacher.cell.robot, placement.thetas))

    monkeypatch.setattr(pipeline.PlacementAhead, "placement", turned)
    problem = reduced_problem(
        "face_ur5",
        camera_px=64,
        landmarks={"count": 6, "allow_partial": True},
        environment={"enabled": True, "table_height_m": -0.02},
        view={"mode": "off"},  # more of the ring clear: more captures to turn
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        plan = optlight.solve(problem)
    assert not [w for w in caught if "the trajectory NLP found no way" in str(w.message)]
    assert placed[-1] >= 2 and len(plan.visited) == placed[-1]
    assert plan.verification.passed
    cell, trajectory = plan.setup.workcell, plan.trajectory
    times = np.union1d(trajectory.sample_times(500.0), trajectory.capture_times)
    q, _, _ = trajectory.sample(times)
    model = cell.environment.collision_model(cell.robot)
    report = check_configurations(model, q, times, view="off")
    assert report.passed, report.summary()
    assert report.min_clearance_m > 0.0
