"""Joint torques by inverse dynamics (RNEA, the lamp included) against independent relations, the
robots' published torque limits, and a plan refused for a lamp too heavy for the arm."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from conftest import reduced_problem

import optlight
from optlight.errors import VerificationError
from optlight.robot import Dynamics, Lamp, load_robot

GRAVITY = np.array([0.0, 0.0, -9.81])
LAMP = Lamp(0.3, (0.0, 0.0, 0.04), 0.03, 0.06)


def potential_energy(dynamics: Dynamics, theta: np.ndarray) -> float:
    """V(θ) = −Σ_i m_i g·c_i(θ) over the bodies of the model (J), from the kinematics alone."""
    model, data = dynamics.model, dynamics.model.createData()
    pin.forwardKinematics(model, data, dynamics.robot.to_pin(theta))
    return -sum(
        model.inertias[i].mass * GRAVITY @ data.oMi[i].act(model.inertias[i].lever) for i in range(1, model.njoints)
    )


@pytest.mark.parametrize("name", ["panda", "kinova"])  # kinova: continuous joints (q = cos, sin)
def test_static_torques_are_the_gradient_of_the_potential_energy(name: str) -> None:
    robot = load_robot(name)
    dynamics = Dynamics(robot, LAMP)
    rng = np.random.default_rng(3)
    for theta in robot.random_configuration(rng, 3):
        zero = np.zeros((1, robot.n))
        tau = dynamics.torques(theta[None], zero, zero)[0]
        step = 1e-6
        gradient = np.array(
            [
                (potential_energy(dynamics, theta + step * e) - potential_energy(dynamics, theta - step * e)) / (2 * step)
                for e in np.eye(robot.n)
            ]
        )
        np.testing.assert_allclose(tau, gradient, rtol=0, atol=1e-5)


def test_the_lamp_weighs_on_the_joints_through_its_centre_of_mass() -> None:
    """At rest, the lamp adds J_c(θ)ᵀ(−m g) to the torques, J_c the Jacobian of its centre of mass's
    world position (finite differences of the flange's pose), m its mass."""
    robot = load_robot("panda")
    bare, lamp = Dynamics(robot, dataclasses.replace(LAMP, mass_kg=0.0)), Dynamics(robot, dataclasses.replace(LAMP, mass_kg=2.0))
    com = np.asarray(LAMP.com_m)

    def centre(theta: np.ndarray) -> np.ndarray:
        return robot.frame_pose("flange", theta).act(com)

    theta = robot.theta_ref + 0.3
    zero = np.zeros((1, robot.n))
    added = lamp.torques(theta[None], zero, zero)[0] - bare.torques(theta[None], zero, zero)[0]
    step = 1e-6
    jacobian = np.column_stack(
        [(centre(theta + step * e) - centre(theta - step * e)) / (2 * step) for e in np.eye(robot.n)]
    )
    np.testing.assert_allclose(added, jacobian.T @ (-2.0 * GRAVITY), rtol=0, atol=1e-6)
    assert np.abs(added).max() > 1.0  # two kilograms are felt


def test_torques_along_a_motion_balance_the_power() -> None:
    """τ·θ̇ = d/dt (kinetic + potential energy) along a smooth motion (finite differences in time)."""
    robot = load_robot("ur5")
    dynamics = Dynamics(robot, LAMP)
    rng = np.random.default_rng(8)
    a, w, phase = rng.uniform(0.2, 0.6, robot.n), rng.uniform(0.5, 2.0, robot.n), rng.uniform(0, 6, robot.n)

    def state(t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        x = w * t + phase
        return robot.theta_ref + a * np.sin(x), a * w * np.cos(x), -a * w**2 * np.sin(x)

    def energy(t: float) -> float:
        theta, theta_dot, _ = state(t)
        data = dynamics.model.createData()
        kinetic = pin.computeKineticEnergy(dynamics.model, data, theta, theta_dot)
        return kinetic + potential_energy(dynamics, theta)

    for t in (0.1, 0.7, 1.3):
        theta, theta_dot, theta_ddot = state(t)
        tau = dynamics.torques(theta[None], theta_dot[None], theta_ddot[None])[0]
        h = 1e-5
        power = (energy(t + h) - energy(t - h)) / (2 * h)
        assert tau @ theta_dot == pytest.approx(power, rel=1e-6, abs=1e-6)


def test_torque_limits_are_the_published_ones() -> None:
    assert tuple(load_robot("panda").torque_limit) == (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)
    # UR's published torques, not example-robot-data's UR3 URDF (which carries the UR10's efforts)
    ur3 = load_robot("ur3")
    assert tuple(ur3.torque_limit) == (56.0, 56.0, 28.0, 12.0, 12.0, 12.0)
    assert tuple(ur3.model.effortLimit) != tuple(ur3.torque_limit) and "Universal Robots" in ur3.torque_limit_source
    assert tuple(load_robot("ur10").torque_limit) == (330.0, 330.0, 150.0, 56.0, 56.0, 56.0)
    xarm = load_robot("xarm7")  # no published table: the maker's URDF effort limits
    np.testing.assert_array_equal(xarm.torque_limit, xarm.model.effortLimit)
    assert "effort limits" in xarm.torque_limit_source


def test_a_lamp_too_heavy_for_the_arm_is_refused_naming_the_joint(tmp_path: Path) -> None:
    heavy = optlight.solve(reduced_problem(camera_px=96, landmarks={"count": 3}, light={"mass_kg": 50.0}))
    report = heavy.verification
    assert not report.passed and not report.checks["torque"].passed
    first = next(v for v in report.violations if v.check == "torque")
    assert first.joint in heavy.robot.joint_names and first.value > first.limit
    assert f"joint {first.joint}: |τ| = " in first.message and f"at t = {first.time_s:.4f} s" in first.message
    assert report.torques is not None and max(report.torques.fraction or ()) > 1.0
    with pytest.raises(VerificationError, match=rf"torque: joint {first.joint}: \|τ\|"):
        heavy.save(tmp_path / "heavy", preview=False)
    assert not any(tmp_path.iterdir()), "nothing may be written for a plan the arm cannot carry"
    # the same plan with the default lamp passes the torque check
    light = optlight.solve(reduced_problem(camera_px=96, landmarks={"count": 3}))
    assert light.verification.checks["torque"].passed
    assert 0.0 < max(light.summary()["torque_peak_fraction"].values()) < 1.0


def test_a_motion_too_fast_for_the_torques_is_slowed_within_the_limits() -> None:
    """A wide swing timed with ten times the Panda's acceleration and jerk limits needs more torque
    than the joints have; re-timed, its torques (RNEA at 1 kHz, the lamp as a plain point mass added
    to an unloaded model) stay within the published limits and the motion takes longer."""
    from optlight.planning.jerk import jerk_limited_timing
    from optlight.planning.torque_scaling import within_torque_limits

    robot = load_robot("panda")
    lamp = dataclasses.replace(LAMP, radius_m=1e-6, length_m=1e-6)  # a point mass, as written below
    dynamics = Dynamics(robot, lamp)
    start = robot.theta_ref.copy()
    start[1], start[3] = 0.3, -1.2  # the arm stretched out: large inertia about the first joint
    end = start.copy()
    end[0] += 2.5
    v, a, j = robot.velocity_limit, 10 * np.full(robot.n, 10.0), 10 * np.full(robot.n, 5000.0)

    def timed(scale: float) -> optlight.Trajectory:
        return jerk_limited_timing([np.vstack([start, end])], np.sqrt(scale) * v, scale * a, scale**1.5 * j, 0.0)

    def peak_ratio(trajectory: optlight.Trajectory) -> float:
        model = robot.model.copy()
        flange = model.frames[robot.flange_frame_id]
        com = flange.placement.act(np.asarray(lamp.com_m))
        model.inertias[flange.parentJoint] += pin.Inertia(lamp.mass_kg, com, np.zeros((3, 3)))
        data = model.createData()
        q, qd, qdd = trajectory.sample(trajectory.sample_times(1000.0))
        tau = np.array([pin.rnea(model, data, robot.to_pin(q[k]), qd[k], qdd[k]) for k in range(len(q))])
        return float(np.max(np.abs(tau) / robot.torque_limit))

    fast = timed(1.0)
    assert peak_ratio(fast) > 1.2
    slowed = within_torque_limits(timed, dynamics)
    assert peak_ratio(slowed) <= 1.0
    assert slowed.duration > fast.duration


def test_a_motion_the_torques_cannot_allow_is_not_stretched_without_bound() -> None:
    """Where only a motion many times slower would keep the torques within the limits, the timing
    stops at its smallest scale and leaves the motion to the verification (which refuses it)."""
    from optlight.planning.torque_scaling import MIN_SCALE, within_torque_limits

    class Heavy:  # half the limit at rest, and a thousand times its limit per rad/s² of motion
        torque_limit = np.ones(2)

        def torques(self, q, qd, qdd):
            return 0.5 + 1e3 * np.abs(np.asarray(qdd))

    scales: list[float] = []

    def timed(scale: float) -> optlight.Trajectory:
        scales.append(scale)
        from optlight.planning.jerk import jerk_limited_timing

        path = np.array([[0.0, 0.0], [1.0, 1.0]])
        return jerk_limited_timing([path], np.sqrt(scale) * np.ones(2), scale * np.ones(2), scale**1.5 * np.ones(2), 0.0)

    within_torque_limits(timed, Heavy())  # type: ignore[arg-type]
    assert min(scales) >= MIN_SCALE
