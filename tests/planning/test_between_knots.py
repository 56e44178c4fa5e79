"""Clearance between the trajectory's knots (docs/design.md §6, §8): an obstacle that the straight
motion between two clear knots passes through is found by the exact check (coal) and planned around."""

from __future__ import annotations

import warnings

import numpy as np
import pinocchio as pin
import pytest

import optlight
from optlight.errors import CaptureSolverError
from optlight.pipeline import capture_path, knots_on_path, time_knots, verify_knots
from optlight.planning.jerk import jerk_limited_timing
from optlight.planning.path import LightPath
from optlight.planning.policy import knot_ik
from optlight.planning.trajectory import TrajectoryNLPResult, clear_between_knots
from optlight.planning.trajectory.between import timed_between
from optlight.planning.trajectory.windows import optimize_path
from optlight.setup import Setup
from optlight.spec import Problem, SolverSpec, TrajectorySpec, problem_from_dict
from optlight.workcell import Workcell

#: Configurations per knot interval of the test's own dense check (the planner's uses 8).
DENSE = 50


def _with_post(problem: Problem, center: np.ndarray) -> Problem:
    """``problem`` with the environment on and a 3 cm box ("post") at ``center`` (m)."""
    data = problem.to_dict()
    data["environment"] = {
        **data.get("environment", {}),
        "enabled": True,
        "boxes": [{"name": "post", "center_m": [float(x) for x in center], "size_m": [0.03, 0.03, 0.03]}],
    }
    return problem_from_dict(data, source=problem.source)


def _frame_position(robot: object, theta: np.ndarray, frame: str) -> np.ndarray:
    model, data = robot.model, robot.data  # type: ignore[attr-defined]
    pin.forwardKinematics(model, data, robot.to_pin(theta))  # type: ignore[attr-defined]
    pin.updateFramePlacements(model, data)
    return data.oMf[model.getFrameId(frame)].translation.copy()


def _dense(knots: np.ndarray) -> np.ndarray:
    tau = np.arange(DENSE + 1) / DENSE
    return (knots[:-1, None, :] + tau[None, :, None] * np.diff(knots, axis=0)[:, None, :]).reshape(
        -1, knots.shape[1]
    )


def _planning_args(setup: Setup) -> tuple[Workcell, TrajectorySpec, SolverSpec]:
    """What the trajectory stages take of a setup: its work cell, ``[trajectory]`` and ``[solver]``."""
    return setup.workcell, setup.trajectory_spec, setup.solver


def _two_capture_path(setup: Setup, thetas: np.ndarray) -> LightPath:
    """A path of two captures and no knot between them, at the postures ``thetas`` (2, n)."""
    poses = [setup.robot.light_pose(q) for q in thetas]
    positions = np.array([a for a, _ in poses])
    offsets = positions - setup.sphere.center
    return LightPath(
        offsets / np.linalg.norm(offsets, axis=1, keepdims=True),
        positions,
        np.array([r for _, r in poses]),
        np.array([0, 1]),
        np.array([0, 1]),
        np.array([False]),
    )


@pytest.fixture(scope="module")
def default_plan(small_default: Problem) -> optlight.Plan:
    """The small default problem's plan (no environment): its capture postures."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return optlight.solve(small_default)


@pytest.mark.slow
def test_an_obstacle_between_two_clear_knots_is_planned_around_and_coal_finds_the_motion_clear(
    small_default: Problem, default_plan: optlight.Plan
) -> None:
    robot, q = default_plan.setup.robot, default_plan.landmark_thetas
    # a post where panda_link5 is halfway between two captures: clear of both, in the way between them
    for i in range(len(q) - 1):
        post = _frame_position(robot, 0.5 * (q[i] + q[i + 1]), "panda_link5")
        setup = Setup.from_problem(_with_post(small_default, post))
        env = setup.environment
        assert env is not None
        ends = q[i : i + 2]
        if env.check(robot, ends, [0.0, 1.0]).passed:
            break
    else:
        pytest.fail("no two captures of the small default plan are clear of a post between them")
    before = _dense(ends)
    report = env.check(robot, before, np.arange(len(before), dtype=float))
    assert not report.passed  # the motion the old planner timed: straight through the post
    assert any(v.second == "post" for v in report.violations)

    path = _two_capture_path(setup, ends)
    nlp = TrajectoryNLPResult(ends, True, "given", 0.0, 0.0, 0, 0.0)
    clear = clear_between_knots(*_planning_args(setup), path, ends, nlp, knots_on_path)
    knots = clear.timed_knots
    np.testing.assert_array_equal(knots[[0, -1]], ends)  # the captures' postures are kept
    after = _dense(knots)
    assert env.check(robot, after, np.arange(len(after), dtype=float)).passed
    assert clear.path.n_knots == len(clear.nlp.theta) == len(clear.warm)


@pytest.mark.slow
def test_an_obstacle_at_a_capture_is_refused_naming_the_captures_the_link_and_the_obstacle(
    small_default: Problem, default_plan: optlight.Plan
) -> None:
    robot, q = default_plan.setup.robot, default_plan.landmark_thetas
    ends = q[:2]
    setup = Setup.from_problem(_with_post(small_default, _frame_position(robot, ends[1], "panda_link5")))
    assert setup.environment is not None
    assert not setup.environment.check(
        robot, ends, [0.0, 1.0]
    ).passed  # no way around it: it is at the capture
    nlp = TrajectoryNLPResult(ends, True, "given", 0.0, 0.0, 0, 0.0)
    with pytest.raises(CaptureSolverError) as refused:
        clear_between_knots(*_planning_args(setup), _two_capture_path(setup, ends), ends, nlp, knots_on_path)
    message = str(refused.value)
    assert (refused.value.first, refused.value.last) == (0, 1)
    assert message.startswith("between captures 0 and 1 (visiting order): ")
    assert "post" in message and "panda_link" in message and "\n" not in message


def _with_plate(problem: Problem, center: np.ndarray, normal: np.ndarray) -> Problem:
    """``problem`` with the environment on, the path free, joint steps up to 1.5 rad between knots
    (sparse knots), and a 4 mm plate, 12 cm square, at ``center`` (m) across ``normal``."""
    data = problem.to_dict()
    yaw = np.degrees(np.arctan2(normal[1], normal[0]))
    pitch = -np.degrees(np.arcsin(normal[2] / np.linalg.norm(normal)))
    plate = {
        "name": "plate",
        "center_m": [float(x) for x in center],
        "size_m": [0.004, 0.12, 0.12],
        "rpy_deg": [0.0, float(pitch), float(yaw)],
    }
    data["environment"] = {**data.get("environment", {}), "enabled": True, "boxes": [plate]}
    data["trajectory"] = {**data.get("trajectory", {}), "path": "free", "max_step_rad": 1.5}
    return problem_from_dict(data, source=problem.source)


@pytest.mark.slow
def test_knots_on_either_side_of_a_thin_plate_are_refined_and_the_timed_motion_verifies(
    small_default: Problem, default_plan: optlight.Plan
) -> None:
    """A plate across the path panda_link5 takes between two captures, thinner than a knot step: the
    trajectory NLP puts its knots on either side (clear at each), the straight motion between them
    passes through it; after :func:`clear_between_knots` the timed motion passes the pipeline's own
    verification (exact coal distances at ≥ 1 kHz)."""
    robot, q = default_plan.setup.robot, default_plan.landmark_thetas
    positions = np.array([lm.position for lm in default_plan.visited])
    for i in range(len(q) - 1):
        ends, middle, step = q[i : i + 2], 0.5 * (q[i] + q[i + 1]), 0.01 * (q[i + 1] - q[i])
        center = _frame_position(robot, middle, "panda_link5")
        normal = _frame_position(robot, middle + step, "panda_link5") - _frame_position(
            robot, middle - step, "panda_link5"
        )
        setup = Setup.from_problem(_with_plate(small_default, center, normal))
        assert setup.environment is not None
        if not setup.environment.check(robot, ends, [0.0, 1.0]).passed:
            continue
        path = capture_path(setup.sphere, setup.trajectory_spec, positions[i : i + 2], ends)
        warm, failures = knot_ik(setup.workcell, path, ends)
        path, warm, nlp = optimize_path(*_planning_args(setup), path, warm, failures, ends)
        old_path, old_knots = knots_on_path(setup.workcell, path, nlp.theta)  # what the timing followed
        old = verify_knots(
            setup, time_knots(setup, old_path, old_knots), positions[i : i + 2], old_knots, old_path.transfers
        )
        if not old.passed:
            break
    else:
        pytest.fail("no two captures of the small default plan have their knots on either side of a plate")
    assert "plate" in old.summary()  # the plan failed its own verification at the plate

    clear = clear_between_knots(*_planning_args(setup), path, warm, nlp, knots_on_path)
    trajectory = time_knots(setup, clear.timed_path, clear.timed_knots)
    report = verify_knots(
        setup, trajectory, positions[i : i + 2], clear.timed_knots, clear.timed_path.transfers
    )
    assert report.passed, report.summary()
    np.testing.assert_array_equal(clear.timed_knots[[0, -1]], nlp.theta[[0, -1]])  # the captures kept



def test_the_check_between_knots_looks_where_the_timed_motion_goes(small_setup: Setup) -> None:
    """The configurations the check between knots looks at are on the jerk-limited timing's motion
    through the knots (sampled at 20 kHz), not on the straight lines between them, which the motion
    swings past where the path turns."""
    limits = small_setup.limits
    rng = np.random.default_rng(3)
    steps = np.cumsum(rng.normal(0.0, 1.0, (6, small_setup.robot.n)), axis=0)
    knots = small_setup.workcell.start + 0.1 * np.sign(steps) * rng.uniform(0.5, 1.0, steps.shape)
    knots = np.vstack([small_setup.workcell.start, knots])  # a zig-zag, 0.05–0.1 rad steps
    bounds = (limits.lower, limits.upper)
    samples = timed_between(knots, bounds)
    assert len(samples) == len(knots) - 1
    trajectory = jerk_limited_timing(
        [knots], limits.velocity, limits.acceleration, limits.jerk, 0.1, position_bounds=bounds
    )
    motion = trajectory.sample(trajectory.sample_times(20000.0))[0]

    def off_motion(q: np.ndarray) -> np.ndarray:
        return np.linalg.norm(q[:, None, :] - motion[None, :, :], axis=2).min(axis=1)

    assert off_motion(np.vstack(samples)).max() < 2e-4  # rad: on the motion, to its sampling
    chords = np.vstack([(a + b) / 2 for a, b in zip(knots[:-1], knots[1:], strict=True)])
    assert off_motion(chords).max() > 5e-3  # the straight line's middles are not

