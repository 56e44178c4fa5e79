"""The transfers from the start to the captures and back (docs/design.md §6): each revolute joint of
the captures at the whole turn of least travel from the start (planning/turns.py), so that a
transfer does not sweep the arm through the table to reach a posture it has, the same, a turn away."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import optlight
from optlight.errors import SolverError
from optlight.pipeline import time_knots
from optlight.planning.path import LightPath
from optlight.planning.trajectory import plan_transfer
from optlight.planning.turns import unwrapped_postures
from optlight.setup import Setup
from optlight.spec import Problem, problem_from_dict

#: A UR3 on a table 23 mm below its base, a wall behind it, a 49 mm sphere 0.3 m in front of it
#: under a 0.17 m light sphere, the camera 0.6 m to its side.
UR3_ON_TABLE = {
    "object": {"kind": "sphere", "center_m": [0.2778, -0.1579, 0.2953], "radius_m": 0.0487},
    "camera": {"position_m": [0.0394, -0.5461, 0.299], "width": 96, "height": 96, "fov_deg": 15.82},
    "light_sphere": {"radius_m": 0.1717, "zenith_max_deg": 66.9},
    "robot": {"name": "ur3"},
    "landmarks": {"count": 14, "allow_partial": True},
    "environment": {
        "enabled": True,
        "table_height_m": -0.023,
        "boxes": [
            {"name": "wall", "center_m": [-0.3693, 0.2099, 0.6], "size_m": [0.04, 1.6, 1.2], "rpy_deg": [0, 0, -29.62]}
        ],
    },
}
#: A capture posture of that UR3 (rad) with shoulder_lift past π: the upper arm reaches back over the
#: shoulder. From the start's −π/2 (upper arm up) the joint turns 4.65 rad through +π/2 (upper arm
#: down, into the table); the same posture at 3.081 − 2π = −3.202 rad is 1.63 rad away, over the top.
CAPTURE = np.array([2.437, 3.081, 0.109, -0.424, -2.315, 0.0])


@pytest.fixture(scope="module")
def ur3_on_table() -> Problem:
    return problem_from_dict(UR3_ON_TABLE)


def _one_capture_path(setup: Setup, theta: np.ndarray) -> LightPath:
    """A path of one capture at the posture ``theta`` (n,): its timing is the approach, the dwell and
    the retreat."""
    position, rotation = setup.robot.light_pose(theta)
    offset = position - setup.sphere.center
    return LightPath(
        (offset / np.linalg.norm(offset))[None], position[None], rotation[None], np.array([0]), np.array([0]),
        np.zeros(0, bool),
    )


def test_a_posture_a_turn_away_is_reached_over_the_top_and_the_timed_motion_clears_the_table(
    ur3_on_table: Problem,
) -> None:
    setup = Setup.from_problem(ur3_on_table)
    cell, env = setup.workcell, setup.environment
    assert env is not None
    start = cell.start
    assert env.check(setup.robot, np.array([start, CAPTURE]), [0.0, 1.0]).passed  # both ends clear
    with pytest.raises(SolverError):  # no way through 90°: the upper arm would go into the table
        plan_transfer(cell, setup.solver, start, CAPTURE)

    goal = unwrapped_postures(cell.robot, CAPTURE[None], start)[0]
    np.testing.assert_allclose(goal - CAPTURE, [0.0, -2 * np.pi, 0.0, 0.0, 0.0, 0.0])
    for a, b in zip(setup.robot.light_pose(goal), setup.robot.light_pose(CAPTURE), strict=True):
        np.testing.assert_allclose(a, b, atol=1e-12)  # the same posture

    trajectory = time_knots(setup, _one_capture_path(setup, goal), goal[None])
    t = trajectory.sample_times(1000.0)
    q = trajectory.sample(t)[0]
    report = env.check(setup.robot, q, t)
    assert report.passed, [str(v) for v in report.violations[:3]]
    np.testing.assert_allclose(q[[0, -1]], [start, start], atol=1e-9)


def test_whole_turns_keep_every_capture_within_the_joint_limits(ur3_on_table: Problem) -> None:
    cell = Setup.from_problem(ur3_on_table).workcell
    # the last wrist at 6 rad, near its +2π limit: a start at −6 rad cannot pull it a turn up, only down
    knots = np.array([CAPTURE + [0, 0, 0, 0, 0, -0.5], CAPTURE + [0, 0, 0, 0, 0, 6.0]])
    start = cell.start + [0, 0, 0, 0, 0, -6.0]
    turned = unwrapped_postures(cell.robot, knots, start)
    np.testing.assert_allclose(turned[:, 1] - knots[:, 1], -2 * np.pi)  # shoulder_lift over the top
    assert np.all(turned >= cell.limits.lower) and np.all(turned <= cell.limits.upper)
    for a, b in zip(turned, knots, strict=True):  # the same postures
        for x, y in zip(cell.robot.light_pose(a), cell.robot.light_pose(b), strict=True):
            np.testing.assert_allclose(x, y, atol=1e-12)


@pytest.mark.slow
def test_the_ur3_on_its_table_plans_and_verifies(ur3_on_table: Problem) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plan = optlight.solve(ur3_on_table)
    assert plan.verification.passed, plan.verification.summary()
