"""Joint torques of a timed motion, the lamp included: inverse dynamics by pinocchio's RNEA
(docs/design.md §7).

The arm's links carry the inertias of the robot's URDF (the locked hand joints' bodies merged into
their parent by ``pin.buildReducedModel``). The lamp is one more rigid body fixed to the flange: mass
m (``[light] mass_kg``) with its centre of mass at c (``[light] com_m``, in the flange frame, m) and
the rotational inertia of a solid cylinder of the housing's size (``[light] housing_radius_m``,
``housing_length_m``) about c, its axis along the flange's z. It is added to the body of the flange's
parent joint, moved there by the flange's placement in that joint's frame (inertias add when they are
expressed in one frame: ``Y_j + ^jX_f · Y_lamp``).

For joint angles θ, rates θ̇ and accelerations θ̈ (rad, rad/s, rad/s²), the torques are

    τ = M(θ) θ̈ + C(θ, θ̇) θ̇ + g(θ)    (N·m; N for a prismatic joint),

computed per sample by the recursive Newton–Euler algorithm (``pin.rnea``), gravity −9.81 m/s² along
the world's z. Joint friction and the motors' rotor inertias are not modelled (the URDFs do not hold
them), so the torques are those the links and the lamp need, not what the motors deliver.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from optlight.robot.loading import Robot

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Lamp:
    """The lamp as a rigid body: ``mass_kg``, centre of mass ``com_m`` (3,) in the flange frame (m),
    and the solid cylinder (``radius_m``, ``length_m``) whose rotational inertia it has about it."""

    mass_kg: float
    com_m: tuple[float, float, float]
    radius_m: float
    length_m: float

    def inertia(self) -> pin.Inertia:
        """The lamp's spatial inertia in the flange frame."""
        body = pin.Inertia.FromCylinder(self.mass_kg, self.radius_m, self.length_m)
        return pin.SE3(np.eye(3), np.asarray(self.com_m, float)).act(body)


class Dynamics:
    """Inverse dynamics of ``robot`` carrying ``lamp`` (module docstring). ``torque_limit`` (n,) N·m
    are the robot's limits (None where none are published) and ``torque_limit_source`` where they come
    from."""

    def __init__(self, robot: Robot, lamp: Lamp) -> None:
        self.robot = robot
        self.lamp = lamp
        self.model = robot.model.copy()
        flange = self.model.frames[robot.flange_frame_id]
        joint = flange.parentJoint
        self.model.inertias[joint] = self.model.inertias[joint] + flange.placement.act(lamp.inertia())
        self.data = self.model.createData()
        self.torque_limit: Array | None = robot.torque_limit
        self.torque_limit_source: str = robot.torque_limit_source

    def torques(self, theta: ArrayLike, theta_dot: ArrayLike, theta_ddot: ArrayLike) -> Array:
        """τ (T, n) at the samples (T, n) of θ (rad), θ̇ (rad/s), θ̈ (rad/s²): RNEA per sample."""
        q = np.atleast_2d(np.asarray(theta, float))
        v = np.atleast_2d(np.asarray(theta_dot, float))
        a = np.atleast_2d(np.asarray(theta_ddot, float))
        if not (q.shape == v.shape == a.shape and q.shape[1] == self.robot.n):
            raise ValueError(f"θ, θ̇, θ̈ must be (T, {self.robot.n}) arrays of one shape")
        out = np.empty_like(q)
        to_pin = self.robot.to_pin
        same = self.robot.angles_are_q
        for k in range(q.shape[0]):
            out[k] = pin.rnea(self.model, self.data, q[k] if same else to_pin(q[k]), v[k], a[k])
        return out
