"""The trajectory NLP: constraints met (checked with pinocchio), solver built once, free vs arc paths."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from optlight.geometry import h_residual
from optlight.plan import joint_path_length
from optlight.planning.path import build_path
from optlight.planning.policy import knot_ik
from optlight.planning.trajectory import TrajectoryOptimizer
from optlight.robot import generalized_ik
from optlight.setup import Setup


@pytest.fixture(scope="module")
def setup(small_setup: Setup):
    robot, sphere = small_setup.robot, small_setup.sphere
    zen = np.deg2rad([10, 25, 40, 25, 15])
    az = np.deg2rad([0, 60, 120, 200, 300])
    path = build_path(sphere, sphere.position(zen, az), np.arange(5), np.deg2rad(3.0))
    postures = [generalized_ik(robot, sphere, path.positions[0]).theta]
    for k in path.landmark_knots[1:]:
        postures.append(generalized_ik(robot, sphere, path.positions[k], postures[-1], restarts=False).theta)
    warm, failures = knot_ik(small_setup, path, np.array(postures))
    assert failures == 0
    return robot, sphere, path, warm


def test_knots_meet_the_light_constraints_and_the_arcs(setup) -> None:
    robot, sphere, path, warm = setup
    opt = TrajectoryOptimizer(robot, max_step=0.25)
    result = opt.solve(path, sphere, warm)
    assert result.success
    theta = result.theta
    positions = []
    for k, q in enumerate(theta):
        assert robot.within_limits(q, tol=1e-7)
        p, r = robot.light_pose(q)  # pinocchio, not the CasADi mirror the NLP used
        assert np.abs(h_residual(p, r, sphere.center, sphere.radius)).max() < 1e-7, k
        positions.append(p)
    positions = np.array(positions)
    np.testing.assert_allclose(positions[path.landmark_knots], path.positions[path.landmark_knots], atol=1e-7)
    for seg in path.segments():  # every knot on its segment's great circle, between its ends
        u0, u1 = path.directions[seg.start], path.directions[seg.stop - 1]
        normal = np.cross(u0, u1) / np.linalg.norm(np.cross(u0, u1))
        d = positions[seg] - sphere.center
        assert np.abs(d @ normal).max() < 1e-7
        assert (d @ np.cross(normal, u0)).min() > -1e-7 and (d @ np.cross(u1, normal)).min() > -1e-7
    assert np.abs(np.diff(theta, axis=0)).max() <= 0.25 + 1e-7
    assert joint_path_length(theta) <= joint_path_length(warm) + 1e-9


def test_free_path_stays_on_the_sphere_and_costs_no_more(setup) -> None:
    robot, sphere, path, warm = setup
    arc = TrajectoryOptimizer(robot, path_mode="arc").solve(path, sphere, warm)
    free = TrajectoryOptimizer(robot, path_mode="free").solve(path, sphere, warm)
    assert arc.success and free.success
    assert free.cost <= arc.cost + 1e-9  # the free path relaxes the arc constraints
    off_arc = 0.0
    for k, q in enumerate(free.theta):
        p, r = robot.light_pose(q)
        assert np.abs(h_residual(p, r, sphere.center, sphere.radius)).max() < 1e-7
        off_arc = max(off_arc, float(np.linalg.norm(p - path.positions[k])))
    assert off_arc > 1e-4, "the free path did leave the planned knots somewhere"


def test_the_solver_is_built_once_per_size(setup, monkeypatch) -> None:
    robot, sphere, path, warm = setup
    built = []
    real = ca.nlpsol
    monkeypatch.setattr(ca, "nlpsol", lambda *a, **k: built.append(a[0]) or real(*a, **k))
    opt = TrajectoryOptimizer(robot)
    for _ in range(3):
        assert opt.solve(path, sphere, warm + 1e-3).success
    assert built == ["trajectory_nlp"]
