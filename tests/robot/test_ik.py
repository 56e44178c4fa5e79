"""Generalized IK: the null-space step, the secondary tasks, the 5-D/6-D tasks, joint limits."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from optlight.errors import UnreachableError
from optlight.geometry import LightSphere, h_residual, sphere_frame
from optlight.robot import (
    JointLimitTask,
    KinematicState,
    LightPointingTask,
    LightPoseTask,
    ManipulabilityTask,
    PostureTask,
    Robot,
    generalized_ik,
    ik_settings,
    load_robot,
    null_space_step,
)
from optlight.robot.tasks import SecondaryTask
from optlight.spec import SolverSpec, problem_from_dict


@functools.cache
def robot(name: str) -> Robot:
    return load_robot(name)


def reachable_target(
    r: Robot, seed: int, radius: float = 0.4
) -> tuple[LightSphere, np.ndarray, np.ndarray, np.ndarray]:
    """A light pose from a random configuration, with the sphere centre `radius` along its axis."""
    theta = r.random_configuration(np.random.default_rng(seed))
    p, rot = r.light_pose(theta)
    centre = p + radius * rot[:, 2]
    sphere = LightSphere(centre, radius, sphere_frame(centre, centre + np.array([0.0, -1.0, 0.0])))
    return sphere, p, rot, theta


def test_null_space_step_solves_the_primary_task_and_projects_gamma() -> None:
    rng = np.random.default_rng(0)
    jac, e, gamma = rng.normal(size=(5, 7)), rng.normal(size=5), rng.normal(size=7)
    step = null_space_step(jac, e, gamma, 0.0)
    assert np.allclose(jac @ step, e)
    assert np.allclose(jac @ null_space_step(jac, np.zeros(5), gamma, 0.3), 0.0, atol=1e-9)
    # γ = 0 gives the damped least-squares step Jᵀ(JJᵀ + λ²I)⁻¹e
    lam2 = 0.1
    expect = jac.T @ np.linalg.solve(jac @ jac.T + lam2 * np.eye(5), e)
    assert np.allclose(null_space_step(jac, e, None, lam2), expect)


@pytest.mark.parametrize("name", ["panda", "xarm7", "ur5"])
def test_null_space_motion_leaves_the_light_task_unchanged_to_first_order(name: str) -> None:
    r = robot(name)
    sphere, p, _, theta = reachable_target(r, 1)
    task = LightPointingTask(sphere, p)
    state = KinematicState.compute(r, theta)
    e0, jac = task.error_and_jacobian(state)
    assert np.abs(e0).max() < 1e-12
    gamma = -PostureTask(theta_ref=r.random_configuration(np.random.default_rng(2))).gradient(r, state)
    direction = null_space_step(jac, e0, gamma, 1e-6)
    assert np.linalg.norm(direction) > 1e-3
    for eps in (1e-2, 5e-3, 2.5e-3):
        e, _ = task.error_and_jacobian(KinematicState.compute(r, theta + eps * direction))
        # second order in the step: |e| ≤ K |ε δθ|², K of the order of the arm's size (m)
        assert np.linalg.norm(e) <= 2.0 * np.linalg.norm(eps * direction) ** 2


@pytest.mark.parametrize(
    "secondary",
    [JointLimitTask(), ManipulabilityTask(), PostureTask(theta_ref=np.zeros(7))],
    ids=lambda s: s.name,
)
def test_each_secondary_task_decreases_its_objective_in_the_null_space(secondary: SecondaryTask) -> None:
    r = robot("panda")
    for seed in range(5):
        sphere, p, _, theta = reachable_target(r, 10 + seed)
        task = LightPointingTask(sphere, p)
        state = KinematicState.compute(r, theta)
        e, jac = task.error_and_jacobian(state)
        step = null_space_step(jac, e, -secondary.gradient(r, state), 1e-6)
        h0 = secondary.value(r, state)
        h1 = secondary.value(r, KinematicState.compute(r, theta + 1e-3 * step / np.linalg.norm(step)))
        assert h1 < h0


def test_joint_limit_task_moves_a_joint_away_from_its_limit() -> None:
    r = robot("panda")
    theta = np.array(r.theta_ref)
    theta[6] = r.upper[6] - 0.02  # joint 7 (the roll about the optical axis) close to its upper limit
    p, rot = r.light_pose(theta)
    centre = p + 0.4 * rot[:, 2]
    sphere = LightSphere(centre, 0.4, sphere_frame(centre, centre + np.array([1.0, 0.0, 0.0])))
    task, jl = LightPointingTask(sphere, p), JointLimitTask()
    for _ in range(20):  # null-space motion only: the light stays where it is
        state = KinematicState.compute(r, theta)
        e, jac = task.error_and_jacobian(state)
        theta = theta + null_space_step(jac, e, -0.5 * jl.gradient(r, state), 1e-6)
    assert r.upper[6] - theta[6] > 0.05
    assert np.linalg.norm(r.light_pose(theta)[0] - p) < 1e-3


def test_manipulability_gradient_matches_finite_differences() -> None:
    task = ManipulabilityTask()
    for name in ("panda", "ur5", "kinova"):
        r = robot(name)
        for seed in range(3):
            theta = r.random_configuration(np.random.default_rng(seed))
            grad = task.gradient(r, KinematicState.compute(r, theta))
            fd = np.zeros(r.n)
            for i in range(r.n):
                d = np.zeros(r.n)
                d[i] = 1e-6
                fd[i] = (
                    task.value(r, KinematicState.compute(r, theta + d))
                    - task.value(r, KinematicState.compute(r, theta - d))
                ) / 2e-6
            assert np.allclose(grad, fd, rtol=1e-5, atol=1e-6)


def test_task_jacobians_match_finite_differences() -> None:
    """de/dθ = −J exactly at the solution (e = 0); near it, to first order in |e|."""
    r = robot("xarm7")
    sphere, p, rot, theta_true = reachable_target(r, 5)
    for task in (LightPointingTask(sphere, p), LightPoseTask(sphere, p, rot)):
        for offset, tol in ((0.0, 1e-6), (1e-3, 5e-3)):
            theta = theta_true + offset
            _, jac = task.error_and_jacobian(KinematicState.compute(r, theta))
            fd = np.zeros_like(jac)
            for i in range(r.n):
                d = np.zeros(r.n)
                d[i] = 1e-7
                ep, _ = task.error_and_jacobian(KinematicState.compute(r, theta + d))
                em, _ = task.error_and_jacobian(KinematicState.compute(r, theta - d))
                fd[:, i] = -(ep - em) / 2e-7  # e is what is left to close: de/dθ = −J
            assert np.allclose(jac, fd, atol=tol)


def test_world_aligned_jacobian_of_the_state_is_pinocchios() -> None:
    r = robot("kinova")
    for theta in r.random_configuration(np.random.default_rng(8), 5):
        assert np.allclose(KinematicState.compute(r, theta).jacobian, r.light_jacobian(theta))


@pytest.mark.parametrize("name", ["panda", "ur5", "xarm7", "kinova"])
def test_5d_ik_reaches_the_light_constraints(name: str) -> None:
    r = robot(name)
    for seed in range(5):
        sphere, p, _, _ = reachable_target(r, 100 + seed)
        res = generalized_ik(r, sphere, p)
        assert res.success, res.message
        assert r.within_limits(res.theta, tol=0.0)
        a, rot = r.light_pose(res.theta)
        assert np.linalg.norm(a - p) < 1e-4
        assert np.abs(h_residual(a, rot, sphere.center, sphere.radius)).max() < 1e-4
        assert res.iterations >= 1 and res.time_s > 0 and res.residual < 1e-4


def test_ik_target_as_zenith_azimuth_on_the_default_problem() -> None:
    problem = problem_from_dict({})
    r = load_robot(problem)
    sphere = LightSphere.from_problem(problem)
    zenith, azimuth = np.deg2rad(40.0), np.deg2rad(130.0)
    res = generalized_ik(r, sphere, (zenith, azimuth), **ik_settings(problem.solver))
    assert res.success, res.message
    z, a = sphere.angles(r.light_pose(res.theta)[0])
    assert np.isclose(z, zenith, atol=1e-4) and np.isclose(a, azimuth, atol=1e-4)


def test_6d_ik_fixes_the_roll() -> None:
    r = robot("panda")
    sphere, p, rot, _ = reachable_target(r, 7)
    res = generalized_ik(r, sphere, p, task="6d", rotation=rot)
    assert res.success, res.message
    assert np.allclose(r.light_pose(res.theta)[1], rot, atol=1e-4)
    # default roll: the aim rotation with x_L in the plane of x_S
    res = generalized_ik(r, sphere, p, task="6d")
    default = LightPoseTask(sphere, p).rotation
    assert res.success and np.allclose(r.light_pose(res.theta)[1], default, atol=1e-4)


def test_ik_never_reports_success_outside_the_limits() -> None:
    r = load_robot("ur5")
    sphere, p, _, _ = reachable_target(r, 3)
    # a box of ±0.05 rad around θ_ref: the target is out of reach inside it
    r.lower, r.upper = r.theta_ref - 0.05, r.theta_ref + 0.05
    res = generalized_ik(r, sphere, p, max_iter=60)
    assert not res.success
    assert r.within_limits(res.theta, tol=0.0)
    assert "iterations" in res.message


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 10_000),
    radius=st.floats(0.1, 1.5),
    zenith=st.floats(0.0, np.pi / 2),
    azimuth=st.floats(0.0, 2 * np.pi),
)
def test_ik_result_is_within_limits_and_success_means_solved(
    seed: int, radius: float, zenith: float, azimuth: float
) -> None:
    """Any target, reachable or not: θ stays in the limits and success implies |e|² < tol."""
    r = robot("panda")
    rng = np.random.default_rng(seed)
    centre = rng.uniform([-0.8, -0.8, -0.2], [0.8, 0.8, 1.2])
    sphere = LightSphere(centre, radius, sphere_frame(centre, centre + rng.normal(size=3)))
    res = generalized_ik(r, sphere, (zenith, azimuth), max_iter=40)
    assert r.within_limits(res.theta, tol=0.0)
    if res.success:
        e, _ = LightPointingTask(sphere, (zenith, azimuth)).error_and_jacobian(
            KinematicState.compute(r, res.theta)
        )
        assert e @ e < SolverSpec().ik_tol


def test_target_off_the_sphere_is_an_error() -> None:
    r = robot("panda")
    sphere, p, _, _ = reachable_target(r, 2)
    with pytest.raises(UnreachableError, match="off the light sphere"):
        generalized_ik(r, sphere, p + 0.05)
    with pytest.raises(ValueError, match="unknown secondary task"):
        generalized_ik(r, sphere, p, secondary=("elegance",))
