"""Plans in an environment, end to end on the obstacle problems at reduced sizes: the
constrained plan clears every margin by the exact (coal) checks of the verification; the
unconstrained plan of the same problem, checked afterwards, is caught and cannot be saved; a
trajectory through the table and a light in the camera's view cone are caught by the verification."""

from __future__ import annotations

import dataclasses
import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import reacher_of, reduced_problem

import optlight
from optlight.environment import CAPTURE_SLACK, LIGHT, VIEW_CONE, Environment
from optlight.errors import UnreachableError, VerificationError
from optlight.motion import Trajectory
from optlight.planning.landmarks import Landmark
from optlight.planning.nlp import knot_bounds, run, tangent_basis
from optlight.planning.placement import CLEARANCE_TOL, NEAR_STEP, POSE_TOL, ClearPosture, LightPlacement
from optlight.planning.policy import place_landmarks
from optlight.planning.timing import time_parameterize
from optlight.robot import Robot, generalized_ik
from optlight.setup import Setup
from optlight.spec import Problem, SolverSpec
from optlight.verify import ENVIRONMENT_CHECKS, CheckResult, VerificationReport, verify_trajectory
from optlight.workcell import Workcell

#: Landmarks of the reduced collision problem (its file has 12).
COLLISION_LANDMARKS = 8


def reduced(name: str, landmarks: int | None = None, **sections: dict) -> Problem:
    """A built-in problem with a 96² camera (and ``landmarks`` landmarks), sections updated."""
    if landmarks is not None:
        sections["landmarks"] = {**sections.get("landmarks", {}), "count": landmarks}
    return reduced_problem(name, camera_px=96, **sections)


def solve_quietly(problem: Problem) -> optlight.Plan:
    """``optlight.solve`` without the placement's warnings (they are in ``plan.warnings``)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return optlight.solve(problem)


def verify_in(
    plan_robot: Robot, trajectory: Trajectory, problem: Problem, landmarks: np.ndarray
) -> VerificationReport:
    """The pipeline's verification of ``trajectory`` with the exact checks of ``problem``'s environment
    (whether or not the problem enables it for planning)."""
    env = Environment.from_problem(problem)
    sphere = optlight.LightSphere.from_problem(problem)
    return verify_trajectory(
        trajectory,
        light_pose=plan_robot.light_pose,
        lower=plan_robot.lower,
        upper=plan_robot.upper,
        velocity_limit=plan_robot.velocity_limit * problem.robot.velocity_scale,
        acceleration_limit=plan_robot.acceleration_limit,
        sphere=sphere,
        landmark_positions=landmarks,
        environment=lambda q, t, captures: env.check(plan_robot, q, t, capture_times=captures),
    )


def environment_checks(report: VerificationReport) -> dict[str, CheckResult]:
    """The clearance, self-collision and view-cone checks of a report."""
    return {name: c for name, c in report.checks.items() if name in ENVIRONMENT_CHECKS.values()}


@pytest.fixture(scope="module")
def collision() -> Problem:
    return reduced("collision", COLLISION_LANDMARKS)


@pytest.fixture(scope="module")
def constrained(collision: Problem) -> optlight.Plan:
    return solve_quietly(collision)


@pytest.fixture(scope="module")
def unconstrained(collision: Problem) -> optlight.Plan:
    return solve_quietly(reduced("collision", COLLISION_LANDMARKS, environment={"enabled": False}))


def test_the_constrained_plan_clears_every_margin(constrained: optlight.Plan) -> None:
    report = constrained.verification
    assert constrained.nlp.success and report.passed, report.summary()
    checks = environment_checks(report)
    assert set(checks) == {"clearance", "self_collision", "view_cone"}
    for name, check in checks.items():
        # allowed distance minus the smallest coal distance over the dense samples: ≤ 0 means every
        # pair of bodies stays at least its margin apart
        assert check.passed and check.max_value <= 0.0, name
        assert check.samples == report.samples and "↔" in (check.joint or "")
    assert all(v >= 0.0 for v in constrained.summary()["min_clearance_m"].values())
    env = Environment.from_problem(constrained.problem)
    t = constrained.trajectory.sample_times(200.0)
    exact = env.check(constrained.robot, constrained.trajectory.sample(t)[0], t)
    assert exact.passed and exact.min_clearance_m >= env.margin


def test_a_selection_of_clearance_rows_is_those_rows(constrained: optlight.Plan) -> None:
    """The CasADi rows selected by index against the NumPy sphere model (pinocchio) at the plan's
    knots; and the (knot, row) pairs an NLP keeps (selected_rows with an active mask) are the NumPy
    values at those pairs, knot by knot, row by row."""
    import casadi as ca

    from optlight.planning.nlp import selected_rows
    from optlight.planning.trajectory import near_rows

    env, robot = constrained.setup.environment, constrained.robot
    assert env is not None
    knots = constrained.nlp.theta[::7]
    values = env.clearance_values(robot, knots)
    assert values.shape == (len(knots), len(env.clearance_labels(robot)))
    np.testing.assert_array_equal(values[2], env.sphere_clearance(robot, knots[2])[0])
    near = np.flatnonzero(values.min(axis=0) < 0.15)
    assert 0 < len(near) < values.shape[1]
    selected = env.clearance_function(robot, near)
    for theta, row in zip(knots, values, strict=True):
        np.testing.assert_allclose(np.asarray(selected(theta)).ravel(), row[near], atol=1e-9)

    active = near_rows(values[:, near], 0.15)
    assert active.sum() < active.size  # some pairs are left out
    theta = ca.MX.sym("theta", robot.n, len(knots))
    block, rows = selected_rows(selected, theta, range(len(knots)), 5, active)
    g = np.asarray(ca.Function("g", [theta], [block])(knots.T)).ravel()
    np.testing.assert_allclose(g, values[:, near][active], atol=1e-9)
    assert np.array_equal(rows.index.T[active], 5 + np.arange(active.sum())) and (rows.index.T[~active] == -1).all()


def test_near_rows_are_those_below_the_distance_at_a_knot_or_its_neighbours() -> None:
    from optlight.planning.trajectory import near_rows

    values = np.array([[0.5, 0.01], [0.5, 0.5], [0.05, 0.5], [0.5, 0.5], [0.5, 0.5]])
    expected = np.array([[0, 1], [1, 1], [1, 0], [1, 0], [0, 0]], bool)
    np.testing.assert_array_equal(near_rows(values, 0.1), expected)


def env_rows(plan: optlight.Plan) -> int:
    """The number of clearance rows of a plan's environment."""
    env = plan.setup.environment
    assert env is not None
    return int(env.clearance_function(plan.robot).size1_out(0))


def test_rows_left_out_that_the_solution_breaks_join_the_nlp(
    constrained: optlight.Plan, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With no row near enough to start with (a negative distance), the first solve goes through the
    obstacles; the rows it breaks join and the knots come out clear, as with every row."""
    from optlight.planning import trajectory
    from optlight.planning.trajectory import active_rows

    solves: list[int] = []
    real = trajectory.TrajectoryOptimizer.solve

    def counting(self: trajectory.TrajectoryOptimizer, *args: object) -> trajectory.TrajectoryNLPResult:
        solves.append(0 if self.clearance is None else self.clearance.size1_out(0))
        return real(self, *args)

    monkeypatch.setattr(trajectory.TrajectoryOptimizer, "solve", counting)
    monkeypatch.setattr(active_rows, "ACTIVE_DISTANCE", -1.0)
    setup = constrained.setup
    result = trajectory.optimize_knots(
        setup.workcell, setup.trajectory_spec, setup.solver, constrained.path, constrained.knot_ik
    )
    assert len(solves) >= 2 and solves[0] == 0 and 0 < solves[1] < env_rows(constrained)
    env = setup.environment
    assert env is not None
    worst = min(env.sphere_clearance(setup.robot, theta)[0].min() for theta in result.theta)
    assert worst >= -1e-6
    assert result.iterations >= 2


def test_the_transfer_nlp_with_the_rows_that_can_bind_finds_the_all_rows_transfer(
    constrained: optlight.Plan, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The transfer from the last capture back to the start configuration goes round the obstacles (its
    joint-space line does not): solved with the clearance rows near the line, it is the transfer
    solved with every row (ACTIVE_DISTANCE infinite selects them all), clear of every row by the
    padding (the NumPy sphere model, pinocchio), in fewer rows (the same cost to 1e-6)."""
    from optlight.planning import trajectory
    from optlight.planning.trajectory import active_rows, transfer

    sizes: list[int] = []
    real = transfer._transfer_nlp

    def counting(
        cell: Workcell, solver: SolverSpec, rows: object, *args: object
    ) -> tuple[np.ndarray | None, str]:
        sizes.append(rows.size1_out(0))  # type: ignore[attr-defined]
        return real(cell, solver, rows, *args)  # type: ignore[arg-type]

    monkeypatch.setattr(transfer, "_transfer_nlp", counting)
    setup = constrained.setup
    env = setup.environment
    assert env is not None
    last = constrained.nlp.theta[-1]
    active = trajectory.plan_transfer(setup.workcell, setup.solver, last, setup.start)
    assert sizes, "the transfer NLP did not run"
    near_row_count = sizes[-1]
    monkeypatch.setattr(active_rows, "ACTIVE_DISTANCE", np.inf)
    every = trajectory.plan_transfer(setup.workcell, setup.solver, last, setup.start)
    assert near_row_count < sizes[-1]
    line_worst = min(env.sphere_clearance(setup.robot, t)[0].min() for t in np.linspace(last, setup.start, 20))
    assert line_worst < trajectory.TRANSFER_PADDING
    np.testing.assert_allclose(active, every, atol=1e-4)  # IPOPT's tolerance apart
    assert trajectory.knot_cost(setup.workcell, active) == pytest.approx(
        trajectory.knot_cost(setup.workcell, every), rel=1e-6
    )
    worst = min(env.sphere_clearance(setup.robot, theta)[0].min() for theta in active[1:-1])
    assert worst >= trajectory.TRANSFER_PADDING - 1e-6


def test_the_unconstrained_plan_collides_and_is_refused(
    unconstrained: optlight.Plan, collision: Problem, tmp_path: Path
) -> None:
    # planned without the environment (the camera's view still kept), its own verification has
    # nothing to object to …
    assert unconstrained.verification.passed and set(environment_checks(unconstrained.verification)) == {"view_cone"}
    # … checked in the environment afterwards, it hits the object's bounding sphere and itself
    landmarks = np.array([lm.position for lm in unconstrained.visited])
    report = verify_in(unconstrained.robot, unconstrained.trajectory, collision, landmarks)
    assert not report.passed
    assert {name for name, n in report.counts.items() if n} <= {"clearance", "self_collision"}
    found = [v for v in report.violations if v.check in ("clearance", "self_collision")]
    assert found
    for v in found:
        first, second = (v.joint or "").split(" ↔ ")
        assert first and second  # the two bodies
        assert 0.0 <= v.time_s <= unconstrained.trajectory.duration and f"t = {v.time_s:.4f} s" in v.message
        assert v.value < v.limit  # distance (m) below the allowed one
    assert any(v.check == "clearance" and v.joint.endswith("↔ object") for v in found if v.joint)

    bad = dataclasses.replace(unconstrained, verification=report)
    with pytest.raises(VerificationError, match="failed verification"):
        bad.save(tmp_path / "out", preview=False)
    assert not any(tmp_path.iterdir()), "nothing may be written for a plan that fails verification"


def test_a_trajectory_through_the_table_is_caught(constrained: optlight.Plan, collision: Problem) -> None:
    """From the first landmark to the reference posture with the shoulder forward and the elbow open,
    the hand under the table top, and back: a hand-made plan, timed as the pipeline times its plans."""
    robot = constrained.robot
    start = constrained.landmark_thetas[0]
    dip = robot.theta_ref.copy()
    dip[1], dip[3] = 1.7, -0.2
    assert robot.within_limits(dip) and robot.frame_pose("flange", dip).translation[2] < -0.03
    s = np.linspace(0.0, 1.0, 21)[:, None]
    down = (1 - s) * start + s * dip
    trajectory = time_parameterize(
        [np.concatenate([down, down[-2::-1]])],
        robot.velocity_limit,
        robot.acceleration_limit,
        dwell_s=0.5,
        joint_names=robot.joint_names,
    )
    light = robot.light_pose(start)[0]
    report = verify_in(robot, trajectory, collision, np.array([light, light]))

    assert not report.passed and report.counts["clearance"] > 0
    assert all(n == 0 for name, n in report.counts.items() if name not in ENVIRONMENT_CHECKS.values())
    table = [v for v in report.violations if v.check == "clearance" and (v.joint or "").endswith("↔ table")]
    assert table and min(v.value for v in table) < -0.02  # penetration depth (m)
    # the deepest sample is the turning point, halfway through the motion
    (_, leave), (arrive, _) = trajectory.landmark_intervals
    worst = min(table, key=lambda v: v.value)
    assert worst.time_s == pytest.approx(0.5 * (leave + arrive), abs=0.02 * (arrive - leave))


def test_a_light_in_the_view_cone_is_caught() -> None:
    """table_wall: a capture with the light at zenith 0, between the camera and the face."""
    problem = reduced("table_wall")
    robot = optlight.load_robot(problem)
    sphere = optlight.LightSphere.from_problem(problem)
    ik = generalized_ik(robot, sphere, (0.0, 0.0))
    assert ik.success
    trajectory = time_parameterize(
        [np.repeat(ik.theta[None], 2, axis=0)],  # one landmark: its dwell
        robot.velocity_limit,
        robot.acceleration_limit,
        dwell_s=0.5,
        joint_names=robot.joint_names,
    )
    light = robot.light_pose(ik.theta)[0]
    report = verify_in(robot, trajectory, problem, np.array([light] * len(trajectory.landmark_intervals)))
    view = report.checks["view_cone"]
    assert not view.passed and view.max_value > 0.0  # this deep inside the cone (m)
    light = [v for v in report.violations if v.check == "view_cone" and v.joint == f"{LIGHT} ↔ {VIEW_CONE}"]
    assert light and all(v.time_s in trajectory.capture_times for v in light)


@pytest.mark.slow
def test_table_wall_plan_is_clear_where_the_unconstrained_one_is_not() -> None:
    """table_wall: table, camera stand, wall and the view cone at the captures (the
    placement NLP gives the landmarks whose IK solution breaks a row clear joint angles)."""
    problem = reduced("table_wall")
    plan = solve_quietly(problem)
    assert plan.verification.passed, plan.verification.summary()
    assert len(plan.visited) == problem.landmarks.count >= 8
    checks = environment_checks(plan.verification)
    assert set(checks) == {"clearance", "self_collision", "view_cone"}
    assert all(c.max_value <= 0.0 for c in checks.values())

    # unconstrained: neither the obstacles nor the camera's view
    free = solve_quietly(reduced("table_wall", environment={"enabled": False}, view={"mode": "off"}))
    landmarks = np.array([lm.position for lm in free.visited])
    report = verify_in(free.robot, free.trajectory, problem, landmarks)
    assert report.counts["clearance"] > 0 and report.counts["view_cone"] > 0
    assert any(v.check == "clearance" and (v.joint or "").endswith("↔ wall") for v in report.violations)


def test_a_clear_posture_at_a_relaxed_joint_bound_is_kept(small_setup: Setup) -> None:
    """IPOPT relaxes the joint bounds (~1e-8 relative): the clear posture of this light of the
    default face (its landmark 31, from the previous landmark's posture) sits there, and projected
    back into the limits it puts the light 1.5e-8 m from the target. It is a clear posture, kept;
    with a 1e-8 m tolerance it was refused and the landmark went to the placement NLP."""
    light = np.array([0.12452190272325814, 0.12980786560125332, 0.44654155662936695])
    start = np.array([1.0897953090108847, -1.6188833744143365, 0.8533831312972046, -3.071329036573146,
                      -0.5881765127376188, 1.6537322689961658, 0.7788820106584369])
    assert small_setup.environment is not None
    found = ClearPosture(small_setup.workcell, small_setup.environment, small_setup.solver).solve(
        light, start
    )
    assert found is not None
    theta, row, _ = found
    lower, upper = knot_bounds(small_setup.robot)
    assert ((theta >= lower) & (theta <= upper)).all() and row >= CAPTURE_SLACK - CLEARANCE_TOL
    error = float(np.linalg.norm(small_setup.robot.light_pose(theta)[0] - light))
    assert 1e-8 < error <= POSE_TOL


def test_a_clear_posture_warm_started_at_the_ik_angles_is_the_one_from_the_anchor(
    small_setup: Setup, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The light at zenith 25°, azimuth 0° of the default cell, the posture nearest θ_ref: started
    from the IK's angles, which hold the light already, IPOPT ends on the posture it reaches from
    θ_ref itself, in fewer iterations (6 against 41 here), and pinocchio puts the light there."""
    from optlight.planning.placement import clear_posture

    robot, sphere, env = small_setup.robot, small_setup.sphere, small_setup.environment
    assert env is not None
    light = sphere.position(math.radians(25.0), 0.0)
    ik = generalized_ik(robot, sphere, light, robot.theta_ref, restarts=False, **small_setup.ik)
    assert ik.success
    iterations: list[int] = []

    def counted(*args, **kwargs):  # type: ignore[no-untyped-def]
        solved = run(*args, **kwargs)
        iterations.append(solved.iterations)
        return solved

    monkeypatch.setattr(clear_posture, "run", counted)
    posture = ClearPosture(small_setup.workcell, env, small_setup.solver)
    cold = posture.solve(light, robot.theta_ref)
    cold_iterations = sum(iterations)
    iterations.clear()
    warm = posture.solve(light, robot.theta_ref, warm=ik.theta)
    assert cold is not None and warm is not None
    np.testing.assert_allclose(warm[0], cold[0], atol=1e-8)
    assert sum(iterations) < cold_iterations / 2
    assert np.linalg.norm(robot.light_pose(warm[0])[0] - light) <= POSE_TOL
    assert warm[1] >= CAPTURE_SLACK - CLEARANCE_TOL


def test_a_clear_posture_near_its_anchor_starts_from_the_small_barrier(small_setup: Setup) -> None:
    """The default face (the camera's view its only rows), a chain's next light on the view boundary,
    at azimuth 70° after 60°: from the IK's angles, started at the previous light's clear posture, IPOPT
    starts from the small barrier and ends on the posture it reaches from its default barrier, in
    fewer iterations. From a warm start farther than NEAR_STEP from the anchor, the default barrier."""
    robot, sphere, env = small_setup.robot, small_setup.sphere, small_setup.environment
    assert env is not None and not env.collisions
    zenith = sphere.zenith_min
    first = sphere.position(zenith, math.radians(60.0))
    start = generalized_ik(robot, sphere, first, robot.theta_ref, restarts=False, **small_setup.ik)
    previous = ClearPosture(small_setup.workcell, env, small_setup.solver).solve(
        first, robot.theta_ref, warm=start.theta
    )
    assert previous is not None
    light = sphere.position(zenith, math.radians(70.0))
    ik = generalized_ik(robot, sphere, light, previous[0], restarts=False, **small_setup.ik)
    assert ik.success and np.abs(ik.theta - previous[0]).max() <= NEAR_STEP
    assert env.worst_sphere_row(robot, ik.theta)[0] < CAPTURE_SLACK  # the IK's arm in the view

    posture = ClearPosture(small_setup.workcell, env, small_setup.solver)
    found = posture.solve(light, previous[0], warm=ik.theta)
    assert found is not None and list(posture._solvers) == [(None, True)]
    small = posture._solver(None, True)[0].stats()["iter_count"]
    t1, t2 = tangent_basis((light - sphere.center) / sphere.radius)
    nlp, lbg, ubg = posture._solver(None, False)
    lower, upper = knot_bounds(robot)
    args = {"p": np.r_[previous[0], light, t1, t2], "lbx": lower, "ubx": upper, "lbg": lbg, "ubg": ubg}
    default = run(nlp, {"x0": ik.theta, **args})
    assert default.success and small < default.iterations
    # to IPOPT's tolerance: the last joint turns the light about its axis, which only the cost settles
    np.testing.assert_allclose(found[0], np.clip(default.x, lower, upper), atol=1e-5)

    far = ClearPosture(small_setup.workcell, env, small_setup.solver)
    far.solve(light, robot.theta_ref, warm=ik.theta + NEAR_STEP + 0.1)
    assert list(far._solvers) == [(None, False)]


def test_among_obstacles_the_small_barrier_only_restores_the_view() -> None:
    """table_wall, chain steps of 10° along the view's boundary from a clear posture: where the IK's
    arm is clear of the obstacles and only in the camera's view (azimuth 130° after 120°), IPOPT
    starts from the small barrier and ends on the posture it reaches from its default barrier; where
    it is too close to an obstacle (290° after 280°), from the default barrier."""
    setup = Setup.from_problem(reduced("table_wall"))
    robot, sphere, env = setup.robot, setup.sphere, setup.environment
    assert env is not None and env.collisions
    lower, upper = knot_bounds(robot)

    def step(azimuth_deg: float) -> tuple[ClearPosture, np.ndarray, np.ndarray, np.ndarray, tuple]:
        first = sphere.position(sphere.zenith_min, math.radians(azimuth_deg))
        start = generalized_ik(robot, sphere, first, robot.theta_ref, restarts=False, **setup.ik)
        previous = ClearPosture(setup.workcell, env, setup.solver).solve(
            first, robot.theta_ref, warm=start.theta
        )
        assert previous is not None
        light = sphere.position(sphere.zenith_min, math.radians(azimuth_deg + 10.0))
        ik = generalized_ik(robot, sphere, light, previous[0], restarts=False, **setup.ik)
        assert ik.success and np.abs(ik.theta - previous[0]).max() <= NEAR_STEP
        posture = ClearPosture(setup.workcell, env, setup.solver)
        return posture, previous[0], light, ik.theta, posture.solve(light, previous[0], warm=ik.theta)

    posture, anchor, light, warm, found = step(120.0)
    clearance, view = env.sphere_clearance(robot, warm)
    assert clearance.min() >= CAPTURE_SLACK > view.min()  # the case: only the view to restore
    assert found is not None and {small for _, small in posture._solvers} == {True}
    t1, t2 = tangent_basis((light - sphere.center) / sphere.radius)
    default = ClearPosture(setup.workcell, env, setup.solver)
    nlp, lbg, ubg = default._solver(None, False)  # every row, from the default barrier
    args = {"x0": warm, "p": np.r_[anchor, light, t1, t2], "lbx": lower, "ubx": upper, "lbg": lbg, "ubg": ubg}
    every = run(nlp, args)
    assert every.success
    np.testing.assert_allclose(found[0], np.clip(every.x, lower, upper), atol=1e-5)

    posture, _, _, warm, _ = step(280.0)
    assert env.sphere_clearance(robot, warm)[0].min() < CAPTURE_SLACK  # too close to an obstacle
    assert {small for _, small in posture._solvers} == {False}


def test_a_clear_posture_from_the_near_rows_is_the_one_from_every_row() -> None:
    """table_wall, the IK's arm in the wall (zenith 30°, azimuth 0°): ClearPosture solves with the
    clearance rows near θ₀ (and more if its solution breaks one left out); its posture is the one
    the NLP with every row finds, and every row holds there."""
    setup = Setup.from_problem(reduced("table_wall"))
    robot, sphere, env = setup.robot, setup.scene.sphere, setup.environment
    assert env is not None
    ik = generalized_ik(robot, sphere, (math.radians(30.0), 0.0), robot.theta_ref)
    light = sphere.position(math.radians(30.0), 0.0)
    posture = ClearPosture(setup.workcell, env, setup.solver)
    found = posture.solve(light, ik.theta)
    assert found is not None
    row_sets = [key for key, _ in posture._solvers if key is not None]
    rows = len(env.clearance_labels(robot))
    assert row_sets and all(len(key) < rows / 2 for key in row_sets)
    assert not any(small for _, small in posture._solvers)  # the arm in the wall: the default barrier

    t1, t2 = tangent_basis((light - sphere.center) / sphere.radius)
    nlp, lbg, ubg = posture._solver(None, False)
    lower, upper = knot_bounds(robot)
    bounds = {"lbx": lower, "ubx": upper, "lbg": lbg, "ubg": ubg}
    every = run(nlp, {"x0": ik.theta, "p": np.r_[ik.theta, light, t1, t2], **bounds})
    assert every.success
    np.testing.assert_allclose(found[0], np.clip(every.x, lower, upper), atol=1e-6)
    clearance, view = env.sphere_clearance(robot, found[0])
    assert min(clearance.min(), view.min()) >= CAPTURE_SLACK - CLEARANCE_TOL


def test_a_placement_from_the_near_rows_is_the_one_from_every_row() -> None:
    """table_wall, the IK's arm in the wall (zenith 30°, azimuth 0°): the placement NLP solves with
    the clearance rows near θ₀ (and more if its solution breaks one left out); its light is the one
    the NLP with every row finds from θ₀, and every row holds at its joint angles."""
    setup = Setup.from_problem(reduced("table_wall"))
    robot, sphere, env = setup.robot, setup.scene.sphere, setup.environment
    assert env is not None
    ik = generalized_ik(robot, sphere, (math.radians(30.0), 0.0), robot.theta_ref)
    assert env.worst_sphere_row(robot, ik.theta)[0] < -0.02  # the case: the arm in the wall
    placement = LightPlacement(setup.workcell, setup.image_costs, setup.solver)
    p = np.r_[0.0, placement.search.visibility(robot.light_pose(ik.theta)[0])]
    lbg, ubg = placement._bounds["fixed"]
    near = placement._run(ik.theta, p, lbg, ubg)
    assert near.success
    row_sets = [key for key, _ in placement._solvers if key is not None]
    rows = len(env.clearance_labels(robot))
    assert row_sets and all(len(key) < rows / 2 for key in row_sets)

    nlp, n_env = placement._solver(None, False)
    assert n_env == rows + len(env.view_labels(robot, beam=False))  # the beam: checked on the result
    full_lbg, full_ubg = np.r_[lbg, np.full(n_env, CAPTURE_SLACK)], np.r_[ubg, np.full(n_env, np.inf)]
    every = placement._margined(nlp, ik.theta, p, full_lbg, full_ubg, relax=True)
    assert every.success
    # the light, not the angles: the arm's redundancy leaves a family of postures for one light
    np.testing.assert_allclose(robot.light_pose(near.x)[0], robot.light_pose(every.x)[0], atol=1e-6)
    clearance, view = env.sphere_clearance(robot, np.clip(near.x, *knot_bounds(robot)))
    assert min(clearance.min(), view.min()) >= CAPTURE_SLACK - CLEARANCE_TOL


def test_clear_postures_and_placements_or_the_landmark_is_named() -> None:
    """table_wall: the IK's arm for the light at zenith 30°, azimuth 0° runs the elbow into the wall;
    ClearPosture finds a clear posture for the same light, and the placement NLP with the
    environment's rows one for the best light on that azimuth. At 157.5° (the far side of the cap,
    where the arm only reaches over the view cone) no light of the azimuth has a clear arm: the
    landmark is named, with the row that blocks it."""
    setup = Setup.from_problem(reduced("table_wall"))
    robot, scene, env = setup.robot, setup.scene, setup.environment
    assert env is not None
    placement = LightPlacement(setup.workcell, setup.image_costs, setup.solver)
    assert placement.environment is env

    ik = generalized_ik(robot, scene.sphere, (math.radians(30.0), 0.0), robot.theta_ref)
    row, label = env.worst_sphere_row(robot, ik.theta)
    assert ik.success and row < -0.02 and label.endswith("↔ wall")
    light = scene.sphere.position(math.radians(30.0), 0.0)
    found = ClearPosture(setup.workcell, env, setup.solver).solve(light, ik.theta)
    assert found is not None
    theta, row, label = found
    assert row >= -CLEARANCE_TOL and env.worst_sphere_row(robot, theta) == (row, label)
    assert np.linalg.norm(robot.light_pose(theta)[0] - light) <= POSE_TOL
    placed = placement.solve(0.0, ik.theta)
    assert placed.success, placed.message
    assert math.cos(placed.azimuth) == pytest.approx(1.0, abs=1e-9)  # azimuth 0 (or 2π)
    clearance, view = env.sphere_clearance(robot, placed.theta)
    assert min(clearance.min(), view.min()) == pytest.approx(placed.min_clearance_m, abs=1e-12)
    assert placed.min_clearance_m >= -CLEARANCE_TOL

    azimuth = math.radians(157.5)
    zenith = math.radians(30.0)
    blocked = Landmark(0, zenith, azimuth, scene.sphere.position(zenith, azimuth), 0.0, "refined", "", 0, 0.0)
    with pytest.raises(UnreachableError, match="blocked for panda") as error:
        place_landmarks(reacher_of(setup), setup.landmark_spec, [blocked])
    message = str(error.value)
    assert "azimuth 157.5°" in message and f"↔ {VIEW_CONE}" in message
    assert "nor is any light on its azimuth clear of the environment" in message


def test_an_ik_posture_on_the_edge_of_a_row_is_not_a_capture_posture(small_setup: Setup) -> None:
    """The default cell, light at zenith 22°, azimuth 320°: the IK's arm keeps the view cone by
    0.2 mm only. The trajectory NLP pins a capture, and a posture on a row's bound left it no
    interior (a re-plan of the camera loop failed infeasible on one); the reacher keeps the capture
    posture CAPTURE_SLACK clear instead, the light where it was."""
    robot, env = small_setup.robot, small_setup.environment
    assert env is not None
    light = small_setup.sphere.position(math.radians(22.0), math.radians(320.0))
    attempt = reacher_of(small_setup).attempt(light, robot.theta_ref)
    row, _ = env.worst_sphere_row(robot, attempt.ik.theta)
    assert attempt.ik.success and 0.0 <= row < CAPTURE_SLACK  # the case: clear, but on the edge
    assert attempt.theta is not None
    assert env.worst_sphere_row(robot, attempt.theta)[0] >= CAPTURE_SLACK - 1e-6  # IPOPT's tolerance
    assert np.linalg.norm(robot.light_pose(attempt.theta)[0] - light) <= POSE_TOL
