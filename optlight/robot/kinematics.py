"""Forward kinematics mirrored from pinocchio into CasADi, and the light residual h(θ).

Pinocchio's Python wheels have no ``pinocchio.casadi`` (docs/design.md §7), so the kinematic tree is
rebuilt here as a CasADi SX graph from the (reduced, base-placed) ``pin.Model``:

    oMi[j] = oMi[parent(j)] · jointPlacements[j] · motion_j(θ_j),      oMf = oMi[parentJoint] · placement

with motion_j a rotation R(u, θ) = I + sinθ [u]× + (1 − cosθ) [u]×² about the joint axis u for revolute
joints (X, Y, Z, unaligned) and continuous joints (which take the angle θ directly, not cos/sin), and a
translation θ u for prismatic joints. Lengths in metres, angles in radians, world frame W.

The light residual (docs/design.md §3): h(θ) = R_L(θ)ᵀ (O − a_L(θ)) − [0, 0, b]ᵀ, zero iff the light is on the
sphere (centre O, radius b) and its +z axis passes through O.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, overload

import casadi as ca
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from optlight.errors import RobotError
from optlight.geometry import LightSphere, h_residual

if TYPE_CHECKING:
    from optlight.robot.loading import Robot

Array = NDArray[np.float64]

_AXES = {"X": np.array([1.0, 0.0, 0.0]), "Y": np.array([0.0, 1.0, 0.0]), "Z": np.array([0.0, 0.0, 1.0])}

#: pinocchio joint types optlight handles: 1-DoF revolute, prismatic, and continuous (q = cos, sin).
REVOLUTE_JOINTS = frozenset({"JointModelRX", "JointModelRY", "JointModelRZ", "JointModelRevoluteUnaligned"})
PRISMATIC_JOINTS = frozenset({"JointModelPX", "JointModelPY", "JointModelPZ", "JointModelPrismaticUnaligned"})
CONTINUOUS_JOINTS = frozenset(
    {"JointModelRUBX", "JointModelRUBY", "JointModelRUBZ", "JointModelRevoluteUnboundedUnaligned"}
)


def joint_axis(model: pin.Model, joint: pin.JointModel) -> tuple[str, Array]:
    """("revolute" | "prismatic", unit axis in the joint frame) of a supported joint, read from its
    motion subspace S = (linear, angular) (constant for these joints)."""
    if joint.shortname() in PRISMATIC_JOINTS:
        kind = "prismatic"
    elif joint.shortname() in REVOLUTE_JOINTS | CONTINUOUS_JOINTS:
        kind = "revolute"
    else:
        raise RobotError(f"the CasADi kinematics does not handle joint type {joint.shortname()}")
    data = joint.createData()
    joint.calc(data, pin.neutral(model))
    s = np.asarray(data.S, float).ravel()
    return kind, s[3:] if kind == "revolute" else s[:3]


def _rotation(axis: Array, angle: ca.SX) -> ca.SX:
    """Rodrigues: R(u, θ) = I + sinθ [u]× + (1 − cosθ) [u]×², written out for an exact graph."""
    c, s = ca.cos(angle), ca.sin(angle)
    if np.allclose(axis, _AXES["X"]):
        return ca.vertcat(ca.horzcat(1, 0, 0), ca.horzcat(0, c, -s), ca.horzcat(0, s, c))
    if np.allclose(axis, _AXES["Y"]):
        return ca.vertcat(ca.horzcat(c, 0, s), ca.horzcat(0, 1, 0), ca.horzcat(-s, 0, c))
    if np.allclose(axis, _AXES["Z"]):
        return ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(s, c, 0), ca.horzcat(0, 0, 1))
    k = ca.DM(pin.skew(axis))
    return ca.DM.eye(3) + s * k + (1 - c) * ca.DM(pin.skew(axis) @ pin.skew(axis))


def symbolic_frame_pose(model: pin.Model, frame_id: int, name: str = "frame_pose") -> ca.Function:
    """``casadi.Function(name, [theta (nv×1)], [p (3×1), R (3×3)])``: world placement of a frame of
    ``model``, θ in joint-angle coordinates (one per joint, θ_j = theta[idx_v(j)]).

    Only the joints that support the frame enter the graph.
    """
    theta = ca.SX.sym("theta", model.nv)
    frame = model.frames[frame_id]
    chain = [int(j) for j in model.supports[frame.parentJoint]][1:]
    rot: dict[int, ca.SX] = {0: ca.SX.eye(3)}
    pos: dict[int, ca.SX] = {0: ca.SX.zeros(3, 1)}
    for j in chain:
        joint = model.joints[j]
        kind, axis = joint_axis(model, joint)
        place = model.jointPlacements[j]
        parent = model.parents[j]
        r_place = rot[parent] @ ca.DM(place.rotation)
        p_place = pos[parent] + rot[parent] @ ca.DM(place.translation)
        angle = theta[joint.idx_v]
        if kind == "revolute":
            rot[j] = r_place @ _rotation(axis, angle)
            pos[j] = p_place
        else:
            rot[j] = r_place
            pos[j] = p_place + r_place @ ca.DM(axis) * angle
    j = frame.parentJoint
    p = pos[j] + rot[j] @ ca.DM(frame.placement.translation)
    r = rot[j] @ ca.DM(frame.placement.rotation)
    return ca.Function(name, [theta], [p, r], ["theta"], ["p", "R"])


@overload
def light_residual(robot: Robot, sphere: LightSphere, theta: ca.SX) -> ca.SX: ...
@overload
def light_residual(robot: Robot, sphere: LightSphere, theta: ca.MX) -> ca.MX: ...
@overload
def light_residual(robot: Robot, sphere: LightSphere, theta: ArrayLike) -> Array: ...


def light_residual(
    robot: Robot, sphere: LightSphere, theta: ArrayLike | ca.SX | ca.MX
) -> Array | ca.SX | ca.MX:
    """h(θ) = R_L(θ)ᵀ (O − a_L(θ)) − [0, 0, b]ᵀ (m), in the light frame.

    Numeric θ (array of length n) → NumPy (3,) through pinocchio; CasADi θ (SX/MX, n×1) → a 3×1
    expression through :attr:`Robot.symbolic_light_pose`. h = 0 iff the light is on the sphere and
    points at its centre; h_z = −(distance error), (h_x, h_y) ≈ b·(pointing error in rad).
    """
    pose: Any = robot.symbolic_light_pose(theta) if isinstance(theta, ca.SX | ca.MX) else robot.light_pose(theta)
    position, rotation = pose  # SX in → SX out, MX in → MX out
    return h_residual(position, rotation, sphere.center, sphere.radius)


def light_angles(robot: Robot, sphere: LightSphere, theta: ArrayLike) -> tuple[float, float]:
    """Sphere coordinates (zenith θ_S, azimuth φ_S) in rad of the light position a_L(θ) seen from O."""
    zenith, azimuth = sphere.angles(robot.light_pose(theta)[0])
    return float(zenith), float(azimuth)
