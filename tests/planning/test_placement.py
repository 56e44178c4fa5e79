"""Joint-space light placement: it reproduces reachable landmarks, its solutions meet h = 0 (checked with
pinocchio), the azimuth and the limits, the NLP is built once, its gradient is right, and the pipeline
moves a landmark the robot cannot reach along its azimuth, or names it when nothing there is reachable."""

from __future__ import annotations

import dataclasses
import math
import threading
import warnings
from typing import Any

import casadi as ca
import numpy as np
import pytest
from conftest import REACH_ONLY, reacher_of, reduced_problem, search_landmarks

import optlight
from optlight import pipeline as pipeline_module
from optlight.errors import UnreachableError
from optlight.geometry import h_residual
from optlight.pipeline import PlacementAhead
from optlight.planning.landmarks import LandmarkSet, exact_cost
from optlight.planning.placement import LightPlacement, PlacementResult
from optlight.planning.placement import light as placement_module
from optlight.planning.policy import PlacementChain, place_landmarks
from optlight.robot import Robot, generalized_ik
from optlight.setup import Setup
from optlight.spec import Problem

#: A base 0.9 m below the light ring, on the camera side, found by probing with the IK: the light
#: reaches every azimuth near the pole, but not the 45° and 135° landmarks (zenith 7.6°) of the 8.
LOW_BASE = [-0.603, -0.55, -0.45]


def small_problem(count: int = 8, **sections: dict[str, Any]) -> Problem:
    """The default problem in the :data:`REACH_ONLY` layout with a 64² camera searched at its own
    resolution (so the placement NLP and the landmark search share one model) and ``count``
    landmarks."""
    landmarks = {"count": count, "resolution": 64, **sections.pop("landmarks", {})}
    return reduced_problem(camera_px=64, landmarks=landmarks, **{**REACH_ONLY, **sections})


class Case:
    """A problem built once, with its landmarks and placement NLP."""

    def __init__(self, problem: Problem) -> None:
        self.problem = problem
        self.setup = Setup.from_problem(problem)
        self.scene = self.setup.scene
        self.sphere = self.setup.sphere
        self.robot: Robot = self.setup.robot
        self.landmarks: LandmarkSet = search_landmarks(self.setup)
        self.placement = LightPlacement(self.setup.workcell, self.setup.image_costs, self.setup.solver)


@pytest.fixture(scope="module")
def default() -> Case:
    return Case(small_problem())


@pytest.fixture(scope="module")
def low() -> Case:
    return Case(small_problem(robot={"base_position_m": LOW_BASE}))


def assert_feasible(setup: Case, result: PlacementResult, azimuth: float | None) -> None:
    """h = 0 by pinocchio (not the CasADi mirror the NLP used), the azimuth half-plane, the zenith
    range and the joint limits, and the reported position, angles and cost."""
    robot, sphere = setup.robot, setup.sphere
    assert result.success, result.message
    position, rotation = robot.light_pose(result.theta)
    assert np.abs(h_residual(position, rotation, sphere.center, sphere.radius)).max() < 1e-8
    np.testing.assert_allclose(result.position, position, atol=1e-12)
    assert robot.within_limits(result.theta, tol=0.0)
    u = sphere.rotation.T @ (position - sphere.center) / sphere.radius
    assert sphere.zenith_min - 1e-8 <= math.acos(min(1.0, u[2])) <= sphere.zenith_max + 1e-8
    if azimuth is not None:
        assert abs(-math.sin(azimuth) * u[0] + math.cos(azimuth) * u[1]) < 1e-9
        assert math.cos(azimuth) * u[0] + math.sin(azimuth) * u[1] >= -1e-9
    zenith, phi = sphere.angles(position)
    assert result.zenith == pytest.approx(float(zenith), abs=1e-12)
    assert result.azimuth == pytest.approx(float(phi), abs=1e-12)
    assert result.cost == pytest.approx(
        exact_cost(setup.scene, setup.placement.objective, position), rel=1e-12
    )


@pytest.mark.parametrize("offset_deg", [0.0, 3.0])
def test_reachable_landmarks_are_reproduced(default: Case, offset_deg: float) -> None:
    """Warm-started at the IK solution of the landmark (or of a light 3° farther from the pole), the NLP
    on the landmark's azimuth returns to the landmark."""
    for lm in default.landmarks.landmarks:
        start = generalized_ik(
            default.robot,
            default.sphere,
            (lm.zenith + math.radians(offset_deg), lm.azimuth),
            default.robot.theta_ref,
        )
        assert start.success
        result = default.placement.solve(lm.azimuth, start.theta)
        assert_feasible(default, result, lm.azimuth)
        assert math.degrees(abs(result.zenith - lm.zenith)) < 0.2
        assert result.cost <= lm.cost * (1 + 1e-6) + 1e-8
        assert 0 < result.iterations < 60


def test_free_azimuth_finds_the_reference_light(default: Case) -> None:
    """With the azimuth free the NLP descends to the reference light (10° zenith) or its mirror image
    (the face is mirror-symmetric), where the cost vanishes."""
    result = default.placement.solve(None, default.robot.theta_ref)
    assert_feasible(default, result, None)
    assert result.cost < 1e-7
    assert math.degrees(result.zenith) == pytest.approx(10.0, abs=0.2)
    assert min(result.azimuth, abs(result.azimuth - math.pi), 2 * math.pi - result.azimuth) < math.radians(
        0.5
    )


def test_nlp_built_once(default: Case, monkeypatch: pytest.MonkeyPatch) -> None:
    built: list[str] = []
    real = ca.nlpsol

    def counting(*args: Any, **kwargs: Any) -> Any:
        built.append(args[0])
        return real(*args, **kwargs)

    monkeypatch.setattr(placement_module.ca, "nlpsol", counting)
    placement = LightPlacement(default.setup.workcell, default.setup.image_costs, default.setup.solver)
    theta = default.robot.theta_ref
    for azimuth in (0.0, math.pi / 2, None, 3 * math.pi / 2):
        result = placement.solve(azimuth, theta)
        assert result.success
        theta = result.theta
    assert built == ["light_placement"]


def test_search_resolution_is_the_landmark_search_one() -> None:
    problem = small_problem(count=1, landmarks={"resolution": 40})
    built = Setup.from_problem(problem)
    placement = LightPlacement(built.workcell, built.image_costs, built.solver)
    assert (placement.search.camera.width, placement.search.camera.height) == (40, 40)
    assert (placement.scene.camera.width, placement.scene.camera.height) == (64, 64)


def test_cost_gradient_matches_finite_differences(default: Case) -> None:
    robot, placement = default.robot, default.placement
    rng = np.random.default_rng(7)
    theta = robot.random_configuration(rng)
    position = robot.light_pose(theta)[0]
    v = placement.search.visibility(position)
    # the NLP's cost is the objective of the light where pinocchio puts it
    expected = float(placement.search_objective.function(position, v))
    assert float(placement.cost_function(theta, v)) == pytest.approx(expected, rel=1e-12)
    x = ca.MX.sym("theta", robot.n)
    gradient = ca.Function("gradient", [x], [ca.gradient(placement.cost_function(x, v), x)])
    analytic = np.asarray(gradient(theta), float).ravel()
    step = 1e-6
    numeric = np.array(
        [
            (
                float(placement.cost_function(theta + step * e, v))
                - float(placement.cost_function(theta - step * e, v))
            )
            / (2 * step)
            for e in np.eye(robot.n)
        ]
    )
    assert np.abs(analytic).max() > 1e-6
    np.testing.assert_allclose(analytic, numeric, rtol=1e-5, atol=1e-6 * np.abs(analytic).max())


def test_out_of_reach_optimum_is_kept_off_the_reach_boundary(low: Case) -> None:
    """The landmark at 45° is out of reach: the NLP's optimum lies on the reach boundary, where the light
    task is singular, and the light ends 0.1° inside it, non-singular and cheaper than any reachable light
    nearer the pole."""
    robot, sphere, lm = low.robot, low.sphere, low.landmarks.landmarks[1]
    start = generalized_ik(robot, sphere, lm.position, robot.theta_ref)
    assert not start.success
    result = low.placement.solve(lm.azimuth, start.theta)
    assert_feasible(low, result, lm.azimuth)
    assert result.on_boundary and result.message.endswith("moved 0.1° inside it")
    assert result.conditioning >= placement_module.SINGULAR_TOL
    # 0.1° on the other side of the boundary the light is out of reach
    beyond = result.zenith + 2 * placement_module.BOUNDARY_MARGIN
    assert not generalized_ik(robot, sphere, (beyond, lm.azimuth), result.theta).success
    nearer = [
        exact_cost(low.scene, low.placement.objective, sphere.position(z, lm.azimuth))
        for z in (0.0, result.zenith / 2)
    ]
    assert result.cost < min(nearer)


def test_unreachable_landmark_moves_along_its_azimuth(low: Case) -> None:
    robot, sphere, landmarks = low.robot, low.sphere, low.landmarks.landmarks
    moved = [1, 3]
    for j in moved:  # the landmark is out of reach, the light at half its zenith is not
        lm = landmarks[j]
        assert not generalized_ik(robot, sphere, lm.position, robot.theta_ref).success
        assert generalized_ik(robot, sphere, (lm.zenith / 2, lm.azimuth), robot.theta_ref).success
    placed = place_landmarks(reacher_of(low.setup), low.setup.landmark_spec, landmarks)
    kept, thetas, notes = placed.landmarks, placed.thetas, placed.warnings
    assert [lm.index for lm in kept] == list(range(len(landmarks)))
    assert [lm.index for lm in kept if lm.status == "placed"] == moved
    assert len(notes) == len(moved)
    for j, note in zip(moved, notes, strict=True):
        before, after = landmarks[j], kept[j]
        assert note.startswith(
            f"landmark {j} (azimuth {math.degrees(before.azimuth):.1f}°) moved from zenith "
            f"{math.degrees(before.zenith):.1f}° to {math.degrees(after.zenith):.1f}° to be reachable"
        )
        assert after.azimuth == before.azimuth
        assert math.radians(0.5) < before.zenith - after.zenith
        assert after.cost == pytest.approx(
            exact_cost(low.scene, low.placement.objective, after.position), rel=1e-12
        )
        assert after.iterations > before.iterations
        position, rotation = robot.light_pose(thetas[j])
        assert np.abs(h_residual(position, rotation, sphere.center, sphere.radius)).max() < 1e-8
        assert low.placement.conditioning(thetas[j]) >= placement_module.SINGULAR_TOL
    # every landmark kept is where the robot puts the light, to the IK's accuracy (|e|² < ik_tol)
    accuracy = 2 * math.sqrt(low.problem.solver.ik_tol)
    for lm, theta in zip(kept, thetas, strict=True):
        position, rotation = robot.light_pose(theta)
        assert np.abs(h_residual(position, rotation, sphere.center, sphere.radius)).max() < accuracy
        np.testing.assert_allclose(position, lm.position, atol=accuracy)
        assert robot.within_limits(theta, tol=0.0)


def test_the_azimuth_placement_tries_the_previous_capture_last(low: Case) -> None:
    """Where the NLP fails from both IK attempts' angles (the camera loop's strong-ambient re-plan:
    the IK missed the light from both starts, and from its angles, 8 cm off the sphere, IPOPT found
    the azimuth infeasible), it starts from the previous capture's clear angles; those failures are
    imposed here on the first two starts of landmark 1, which is out of reach."""
    reacher = reacher_of(low.setup)
    placement, starts = reacher.placement, []
    solve = placement.solve

    def failing_first_two(azimuth: float | None, theta0: Any) -> PlacementResult:
        starts.append(np.array(theta0, float))
        result = solve(azimuth, theta0)
        return result if len(starts) > 2 else dataclasses.replace(result, success=False, message="imposed")

    placement.solve = failing_first_two  # type: ignore[method-assign]
    first, lm = low.landmarks.landmarks[0], low.landmarks.landmarks[1]
    placed = place_landmarks(reacher, low.setup.landmark_spec, [first, lm])
    assert len(starts) == 3
    # the third start holds the previous capture's light (its angles, before the placement's follow-back)
    np.testing.assert_allclose(low.robot.light_pose(starts[2])[0], first.position, atol=1e-6)
    assert [m.status for m in placed.landmarks][1] == "placed"
    position, rotation = low.robot.light_pose(placed.thetas[1])
    assert np.abs(h_residual(position, rotation, low.sphere.center, low.sphere.radius)).max() < 1e-8
    np.testing.assert_allclose(position, placed.landmarks[1].position, atol=1e-9)


def test_a_placement_on_the_reach_boundary_is_tried_from_every_start(low: Case) -> None:
    """Landmark 1 is out of reach and its placement NLP ends on the reach boundary: the optimum
    where the first start's branch runs out of reach may be a local one (a camera-loop re-plan: 51.9°
    from one start, its arm in the light's beam; 26.4° and a 3.5× lower cost from another). The
    azimuth placement then solves from every start and keeps the cheapest success."""
    reacher = reacher_of(low.setup)
    placement, results = reacher.placement, []
    solve = placement.solve

    def recorded(azimuth: float | None, theta0: Any) -> PlacementResult:
        results.append(solve(azimuth, theta0))
        return results[-1]

    placement.solve = recorded  # type: ignore[method-assign]
    first, lm = low.landmarks.landmarks[0], low.landmarks.landmarks[1]
    placed = place_landmarks(reacher, low.setup.landmark_spec, [first, lm])
    assert results[0].success and results[0].on_boundary
    assert len(results) == 3  # both IK attempts' angles, then the previous capture's
    cheapest = min((r for r in results if r.success), key=lambda r: r.cost)
    assert placed.landmarks[1].status == "placed"
    assert placed.landmarks[1].cost == cheapest.cost
    np.testing.assert_allclose(placed.thetas[1], cheapest.theta)


def test_the_pipeline_plans_through_moved_landmarks(low: Case) -> None:
    """The whole job with the low base: the two landmarks out of reach are moved, the trajectory NLP pins
    them (kept off the singular reach boundary, where it failed) and the plan passes verification."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        plan = optlight.solve(low.problem)
    assert plan.nlp.success and plan.verification.passed
    assert sorted(lm.index for lm in plan.visited if lm.status == "placed") == [1, 3]
    moved = [w for w in plan.warnings if "to be reachable" in w]
    assert len(moved) == 2 and all(any(m == str(w.message) for w in caught) for m in moved)


def placed_in_threads(monkeypatch: pytest.MonkeyPatch, threads: int) -> set[str]:
    """The names of the threads landmarks are placed in from now on (the chain's forward pass), with
    ``threads`` threads to use."""
    monkeypatch.setattr(pipeline_module, "thread_count", lambda: threads)
    names: set[str] = set()
    real = PlacementChain.add

    def add(self: PlacementChain, lm: Any) -> None:
        names.add(threading.current_thread().name)
        real(self, lm)

    monkeypatch.setattr(PlacementChain, "add", add)
    return names


def offered_and_placed(case: Case, offered: Any, captures: Any) -> Any:
    with PlacementAhead(reacher_of(case.setup), case.setup.landmark_spec) as ahead:
        for lm in offered:
            ahead.offer(lm)
        return ahead.placement(captures)


@pytest.mark.slow
def test_the_placement_ahead_places_in_its_thread_what_place_landmarks_places(
    low: Case, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The chain run ahead of the search (two of the eight landmarks moved along their azimuth by the
    placement NLP there) gives the same angles and notes as place_landmarks; when the captures are
    not the landmarks offered (one merged away) they are placed again in the caller's thread; with
    one thread nothing runs ahead."""
    landmarks = low.landmarks.landmarks
    names = placed_in_threads(monkeypatch, 2)
    expected = place_landmarks(reacher_of(low.setup), low.setup.landmark_spec, landmarks)
    assert sum(lm.status == "placed" for lm in expected.landmarks) == 2
    for offered, captures, threads in [
        (landmarks, landmarks, {"optlight_placement"}),
        (landmarks, landmarks[1:], {"optlight_placement", "MainThread"}),
    ]:
        names.clear()
        got = offered_and_placed(low, offered, captures)
        want = (
            expected
            if len(captures) == len(landmarks)
            else place_landmarks(reacher_of(low.setup), low.setup.landmark_spec, captures)
        )
        assert names == threads
        assert [(lm.index, lm.zenith, lm.status) for lm in got.landmarks] == [
            (lm.index, lm.zenith, lm.status) for lm in want.landmarks
        ]
        np.testing.assert_array_equal(got.thetas, want.thetas)
        assert got.warnings == want.warnings
    names = placed_in_threads(monkeypatch, 1)
    np.testing.assert_array_equal(offered_and_placed(low, landmarks, landmarks).thetas, expected.thetas)
    assert names == {"MainThread"}


@pytest.mark.slow
def test_azimuth_out_of_reach_is_named_or_dropped(monkeypatch: pytest.MonkeyPatch) -> None:
    """From 20° zenith up, the low base reaches only the 270° azimuth of four; the placement run
    ahead of the search raises the same error, once asked for the placement."""
    case = Case(
        small_problem(count=4, robot={"base_position_m": LOW_BASE}, light_sphere={"zenith_min_deg": 20.0})
    )
    landmarks = case.landmarks.landmarks
    with pytest.raises(
        UnreachableError,
        match=r"landmark 0 \(zenith 20\.0°, azimuth 0\.0°\) is out of reach of panda: .*; nor is any light "
        r"on its azimuth within zenith 20\.0–60\.0° \(placement NLP: ",
    ) as sequential:
        place_landmarks(reacher_of(case.setup), case.setup.landmark_spec, landmarks)
    names = placed_in_threads(monkeypatch, 2)
    with pytest.raises(UnreachableError) as ahead:
        offered_and_placed(case, landmarks, landmarks)
    assert str(ahead.value) == str(sequential.value) and names == {"optlight_placement"}
    partial = small_problem(
        count=4,
        robot={"base_position_m": LOW_BASE},
        light_sphere={"zenith_min_deg": 20.0},
        landmarks={"allow_partial": True},
    )
    dropping = Setup.from_problem(partial)
    placed = place_landmarks(reacher_of(dropping), dropping.landmark_spec, landmarks)
    kept, thetas, notes = placed.landmarks, placed.thetas, placed.warnings
    assert [lm.index for lm in kept] == [3] and thetas.shape == (1, case.robot.n)
    assert [note.split(" (")[0] for note in notes] == [
        "dropped landmark 0",
        "dropped landmark 1",
        "dropped landmark 2",
    ]


def test_captures_keep_the_margins_where_they_can_and_the_rows_where_they_cannot(
    small_setup: Setup, monkeypatch: pytest.MonkeyPatch
) -> None:
    """On the default layout (view protected), the placement keeps its capture margin on the view and
    clearance rows; with a margin no light can keep (10 m) it falls back to the NLP without the
    margins and returns that light, on the rows' bounds but feasible, not a failure."""
    setup = small_setup
    assert setup.environment is not None
    azimuth = math.radians(140.0)  # where the forearm comes near the view cone (test_view_plan)
    start = generalized_ik(setup.robot, setup.sphere, (math.radians(30.0), azimuth), setup.robot.theta_ref)
    assert start.success

    def placed(slack: float) -> PlacementResult:
        monkeypatch.setattr(placement_module, "CAPTURE_SLACK", slack)
        result = LightPlacement(setup.workcell, setup.image_costs, setup.solver).solve(azimuth, start.theta)
        assert result.success, result.message
        assert abs(result.azimuth - azimuth) < 1e-6
        return result

    slack = placement_module.CAPTURE_SLACK
    kept, relaxed, unkeepable = placed(slack), placed(0.0), placed(10.0)
    assert kept.min_clearance_m >= slack - 1e-6
    assert relaxed.min_clearance_m < slack - 1e-6  # the margin is active on this azimuth
    assert relaxed.min_clearance_m >= -placement_module.CLEARANCE_TOL
    assert unkeepable.min_clearance_m < 10.0
    # the same light (the roll, the last joint, is free: the solves end at different rolls)
    np.testing.assert_allclose(unkeepable.position, relaxed.position, atol=1e-6)


def test_a_landmark_out_of_reach_is_placed_from_a_clear_posture_found_along_its_azimuth() -> None:
    """The lights of a camera-loop re-plan (default layout, 96² camera): landmark 4 at zenith 60°,
    azimuth 180° is out of reach, and the placement NLP finds its azimuth infeasible from the IK's
    unconverged angles and from the previous capture's (a placement without the scan raises here).
    Scanning the azimuth with the reacher gives it a clear start: the landmark is placed on its
    azimuth, its posture holding the light there (pinocchio) clear of every row."""
    from optlight.planning.landmarks import Landmark

    problem = reduced_problem(
        camera_px=96,
        landmarks={"count": 8, "resolution": 48},
        objective={"reference": {"kind": "light", "zenith_deg": 35.0, "azimuth_deg": 120.0}},
    )
    setup = Setup.from_problem(problem)
    sphere = setup.sphere
    zeniths = np.deg2rad([60.0, 60.0, 58.1, 40.4, 60.0, 60.0, 54.5, 60.0])
    azimuths = np.deg2rad(45.0 * np.arange(8))
    landmarks = [
        Landmark(i, z, a, sphere.position(z, a), 0.01, "refined", "", 0, 0.0)
        for i, (z, a) in enumerate(zip(zeniths, azimuths, strict=True))
    ]
    placed = place_landmarks(reacher_of(setup), setup.landmark_spec, landmarks)
    assert [lm.index for lm in placed.landmarks] == list(range(8))
    fourth = placed.landmarks[4]
    assert fourth.status == "placed" and fourth.azimuth == pytest.approx(np.pi)
    assert any(note.startswith("landmark 4 (azimuth 180.0°)") for note in placed.warnings)
    position = setup.robot.light_pose(placed.thetas[4])[0]
    np.testing.assert_allclose(position, sphere.position(fourth.zenith, fourth.azimuth), atol=1e-6)
    assert setup.environment is not None
    assert setup.environment.worst_sphere_row(setup.robot, placed.thetas[4])[0] >= 0.0


def test_from_a_posture_clear_of_the_beam_the_placement_with_the_beams_rows_keeps_the_arm_out_of_it() -> None:
    """Default layout (view cone and beam on), 96² camera: at azimuth 315° the reacher holds the
    light clear only near zenith 60°. From that posture the placement NLP without the beam's rows
    (they are left to the check of its result) goes to ~54°, with the upper arm 32 mm inside the beam,
    and the check refuses it (a camera-loop re-plan failed there); with them it stays out: a success,
    its light on the sphere and the azimuth (pinocchio), every row of the sphere model ≥ 0."""
    setup = Setup.from_problem(reduced_problem(camera_px=96, landmarks={"count": 8}))
    reacher, sphere, robot = reacher_of(setup), setup.sphere, setup.robot
    azimuth = math.radians(315.0)
    start = reacher.attempt(sphere.position(math.radians(60.0), azimuth), robot.theta_ref).theta
    assert start is not None
    without = reacher.placement.solve(azimuth, start)
    assert not without.success and not without.clear
    assert "beam" in without.clearance_row and without.min_clearance_m < -0.01
    beam = reacher.placement.solve(azimuth, start, beam=True)
    assert beam.success and beam.clear
    position, rotation = robot.light_pose(beam.theta)
    assert np.abs(h_residual(position, rotation, sphere.center, sphere.radius)).max() < 1e-8
    assert sphere.angles(position)[1] == pytest.approx(azimuth, abs=1e-6)
    assert setup.environment is not None
    assert setup.environment.worst_sphere_row(robot, beam.theta)[0] >= 0.0


def test_where_the_placement_nlp_finds_nothing_clear_the_scans_nearest_clear_light_is_kept(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Default layout, 96² camera: a landmark at zenith 30°, azimuth 315° is in the camera's view (the
    upper arm blocks it), and the scan of its azimuth from the previous capture's posture (zenith 28°,
    azimuth 270°) finds clear postures. With every solve of the placement NLP imposed to fail (no
    success, no clear light), the scan's first clear light itself is kept, with a warning: its posture
    holds it on the azimuth (pinocchio), every row ≥ 0."""
    from optlight.planning.landmarks import Landmark, zenith_grid
    from optlight.planning.policy import SCAN_STEP

    setup = Setup.from_problem(reduced_problem(camera_px=96, landmarks={"count": 8}))
    reacher, sphere, robot = reacher_of(setup), setup.sphere, setup.robot
    solve = reacher.placement.solve

    def failing(azimuth: float | None, theta0: Any, **kwargs: Any) -> PlacementResult:
        return dataclasses.replace(solve(azimuth, theta0, **kwargs), success=False, min_clearance_m=-1.0)

    monkeypatch.setattr(reacher.placement, "solve", failing)
    lights = [(math.radians(28.0), math.radians(270.0)), (math.radians(30.0), math.radians(315.0))]
    landmarks = [
        Landmark(i, z, a, sphere.position(z, a), 0.01, "refined", "", 0, 0.0) for i, (z, a) in enumerate(lights)
    ]
    placed = place_landmarks(reacher, setup.landmark_spec, landmarks)
    kept, azimuth = placed.landmarks[1], lights[1][1]
    assert placed.landmarks[0].status == "refined"  # reached as it is: the scan starts from its posture
    assert kept.status == "placed" and kept.zenith != pytest.approx(lights[1][0])
    # a light of the scan's grid (5° apart), not one an NLP solve moved
    assert np.min(np.abs(zenith_grid(sphere, SCAN_STEP) - kept.zenith)) < 1e-6
    assert "nearest clear light on its azimuth" in placed.warnings[0]
    position, rotation = robot.light_pose(placed.thetas[1])
    assert np.abs(h_residual(position, rotation, sphere.center, sphere.radius)).max() < 1e-8
    assert sphere.angles(position)[1] == pytest.approx(azimuth, abs=1e-6)
    np.testing.assert_allclose(position, kept.position, atol=1e-9)
    assert kept.cost == pytest.approx(exact_cost(setup.scene, setup.objective, position))
    assert setup.environment is not None
    assert setup.environment.worst_sphere_row(robot, placed.thetas[1])[0] >= 0.0
