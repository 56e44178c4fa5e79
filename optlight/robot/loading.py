"""Robots by name (example-robot-data) or from a user URDF, in joint-angle coordinates.

A :class:`Robot` is a pinocchio model of the arm that carries the light, with

- the hand/gripper joints locked (``pin.buildReducedModel``), so every remaining joint moves the light;
- the base placement ``T_WB`` (``base_position_m``, ``base_rpy_deg``) folded into the model: every
  joint and frame attached to the universe is pre-multiplied by ``T_WB``, so pinocchio's ``oMi``,
  ``oMf`` and everything built from the model (the CasADi mirror, Jacobians, geometry) are in the
  world frame W;
- two frames added at the end of the model: ``flange`` = the robot's tool frame, rotated where needed
  so that its +z points out of the tool, and ``light`` = ``flange · T(light_offset_m, light_rpy_deg)``.
  The light emits along +z of ``light`` (docs/design.md §2).

**Joint coordinates.** The rest of optlight works with joint *angles* θ ∈ Rⁿ, n = ``model.nv``, one
per joint, in URDF joint order. Pinocchio stores a continuous joint (kinova joints 1, 4, 6) as
(cos θ, sin θ); :meth:`Robot.to_pin` / :meth:`Robot.from_pin` convert. Continuous joints get the limits
±2π in θ (two full turns of cable; a trajectory never needs more), every other joint its URDF limits.

**Supported robots** (``SUPPORTED_ROBOTS``), their flange frames and reference configurations:

========  =======================  =============================
robot     flange (URDF frame)      reference θ_ref
========  =======================  =============================
panda     ``panda_hand_tcp``       SRDF ``default``
ur3/5/10  ``tool0``                (0, −π/2, π/2, −π/2, −π/2, 0)
xarm7     ``link_eef``             (0, −0.5, 0, 1, 0, 1.5, 0)
kinova    ``j2s6s200_end_effector``  SRDF ``arm_up`` [1]
z1        ``gripperStator``        (0, 1.2, −1.0, −0.2, 0, 0)
========  =======================  =============================

[1] Joint values outside the URDF limits are wrapped by ±2π (the same pose).

**Joint limits** (:data:`ROBOTS`, each row cites its source): velocity = min(URDF, the maker's
published joint speed), acceleration and jerk from the maker where published. Where a maker publishes
none (UR publishes no joint acceleration or jerk limits; none for kinova's JACO² or the z1 that we
could find), the value is ours, marked so: an acceleration the maker's own motion-planning
configuration uses where there is one, else conservative, and the jerk :data:`DEFAULT_JERK_RAMP_S`
ramp: the acceleration limit reached in 0.05 s, J = a_max / 0.05 s. ``robot.acceleration_limit`` and
``robot.jerk_limit`` override them (one value or one per joint).

**Torque limits** (``RobotInfo.torque_limit``, N·m, checked along the plan with the lamp's mass by
:mod:`optlight.robot.dynamics`): the maker's published joint torques where there are some (Franka's
datasheet for panda; Universal Robots' for UR3/5/10), else the effort limits of the maker's URDF
(xarm7, kinova, z1, and a user URDF), else none: a robot without them has its torques reported,
not checked (:attr:`Robot.torque_limit` None).

**User URDFs** (``robot.urdf``). Mesh files are found as ROS finds them (:func:`find_package`):
``package://NAME/rest`` is ``rest`` inside the package folder NAME, looked up in the URDF's folder
and every folder above it (nearest first: a folder named NAME, or one holding a folder NAME), then
in each folder of the ``ROS_PACKAGE_PATH`` environment variable (the folder itself when it is
named NAME, a folder NAME in it, or one up to :data:`PACKAGE_SEARCH_DEPTH` levels below it holding a
``package.xml``); ``file://`` and plain paths are files, relative ones relative to the URDF. Every
mesh must resolve when the robot is loaded; a URDF the parser rejects, a mesh that does not resolve
and a flange frame it does not have are errors naming ``robot.urdf`` or ``robot.frame``, and the
parser's own messages on stderr are kept out of the terminal (the first one is quoted in ours).

Kinova's and z1's tool frames point their +x out of the tool; their ``flange`` is rotated by
Ry(+90°) so that +z does. The panda fingers and the z1 gripper joint are locked (closed).
``robot.velocity_scale`` is *not* applied here (the timing applies it).
"""

from __future__ import annotations

import importlib.metadata
import os
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import coal
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from optlight.errors import ProblemError, RobotError
from optlight.robot.kinematics import (
    CONTINUOUS_JOINTS,
    PRISMATIC_JOINTS,
    REVOLUTE_JOINTS,
    symbolic_frame_pose,
)
from optlight.spec import ROBOT_NAMES, Problem, RobotSpec

if TYPE_CHECKING:
    import casadi

Array = NDArray[np.float64]

#: Robot names :func:`load_robot` knows (files from example-robot-data).
SUPPORTED_ROBOTS: tuple[str, ...] = ROBOT_NAMES

#: Limits given to continuous joints, in θ (rad).
CONTINUOUS_LIMIT = 2 * np.pi

#: Acceleration limit of a user URDF when ``robot.acceleration_limit`` is not set (rad/s²).
DEFAULT_ACCELERATION_LIMIT = 2.0
#: Where no jerk limit is published: the time (s) to reach the acceleration limit, J = a_max / ramp.
DEFAULT_JERK_RAMP_S = 0.05

#: The light's constraints at a capture (docs/design.md §3): h1–h3 (on the sphere, its axis through
#: O) and the capture's zenith and azimuth. An arm with fewer joints meets them only by chance.
LIGHT_CONSTRAINTS = 5

#: How many folder levels below a ``ROS_PACKAGE_PATH`` entry :func:`find_package` looks for a package.
PACKAGE_SEARCH_DEPTH = 3

_UR_REFERENCE = (0.0, -np.pi / 2, np.pi / 2, -np.pi / 2, -np.pi / 2, 0.0)


@dataclass(frozen=True)
class RobotInfo:
    """Where a named robot's files are and how optlight uses it.

    ``urdf``/``srdf`` are relative to example-robot-data's ``robots`` folder; ``tool_rpy_deg`` rotates
    the URDF tool frame into the flange frame (+z out of the tool); ``reference`` names an SRDF
    reference configuration, else ``theta_ref`` is used; ``locked_joints`` are held at 0;
    ``torque_limit`` (N·m) the maker's published joint torques and ``torque_source`` where they are
    published (None: the URDF's effort limits, if it has them).
    """

    urdf: str
    srdf: str | None
    tool_frame: str
    tool_rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    reference: str | None = None
    theta_ref: tuple[float, ...] | None = None
    locked_joints: tuple[str, ...] = ()
    velocity_limit: tuple[float, ...] | float | None = None
    acceleration_limit: tuple[float, ...] | float = DEFAULT_ACCELERATION_LIMIT
    jerk_limit: tuple[float, ...] | float | None = None
    torque_limit: tuple[float, ...] | None = None
    torque_source: str = ""

    def jerk(self) -> tuple[float, ...] | float:
        """The published jerk limit, else the acceleration limit over :data:`DEFAULT_JERK_RAMP_S`."""
        if self.jerk_limit is not None:
            return self.jerk_limit
        return tuple(np.asarray(self.acceleration_limit, float).ravel() / DEFAULT_JERK_RAMP_S)


_DEG = np.pi / 180.0
#: UR CB3 datasheets ("Technical specifications UR3/UR5/UR10", universal-robots.com): joint speeds.
_UR3_SPEED = (180 * _DEG,) * 3 + (360 * _DEG,) * 3
_UR5_SPEED = 180 * _DEG
_UR10_SPEED = (120 * _DEG,) * 2 + (180 * _DEG,) * 4
#: UR publishes no joint acceleration limit ("the robot does not inherently have any limits on joint
#: accelerations (only on torques)"); UR's own MoveIt configuration uses 5 rad/s² for every joint
#: (UniversalRobots/Universal_Robots_ROS2_Driver, ur_moveit_config/config/joint_limits.yaml).
_UR_ACCELERATION = 5.0
#: Universal Robots, "Max. joint torques" (universal-robots.com/articles/ur-articles/max-joint-torques,
#: the CB3 and e-Series sizes): base, shoulder, elbow, wrist 1–3 (N·m). example-robot-data's UR3 URDF
#: carries the UR10's efforts (330, 330, 150, 54, 54, 54) and its UR10 URDF 54 on the wrists.
_UR_TORQUE_SOURCE = "Universal Robots, Max. joint torques (universal-robots.com)"
_UR3_TORQUE = (56.0, 56.0, 28.0, 12.0, 12.0, 12.0)
_UR5_TORQUE = (150.0, 150.0, 150.0, 28.0, 28.0, 28.0)
_UR10_TORQUE = (330.0, 330.0, 150.0, 56.0, 56.0, 56.0)


ROBOTS: dict[str, RobotInfo] = {
    "panda": RobotInfo(
        "panda_description/urdf/panda.urdf",
        "panda_description/srdf/panda.srdf",
        "panda_hand_tcp",
        reference="default",
        locked_joints=("panda_finger_joint1", "panda_finger_joint2"),
        # Franka Emika, "Robot and interface specifications" (frankaemika.github.io/docs/control_parameters):
        # q̇_max 2.175 (joints 1–4) / 2.61 rad/s, q̈_max 15 7.5 10 12.5 15 20 20 rad/s², jerk 7500 rad/s³
        velocity_limit=(2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61),
        acceleration_limit=(15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0),
        jerk_limit=7500.0,
        # the same page: τ_max 87 N·m (joints 1–4), 12 N·m (joints 5–7)
        torque_limit=(87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0),
        torque_source="Franka Emika, Robot and interface specifications",
    ),
    "ur3": RobotInfo(
        "ur_description/urdf/ur3_robot.urdf",
        None,
        "tool0",
        theta_ref=_UR_REFERENCE,
        torque_limit=_UR3_TORQUE,
        torque_source=_UR_TORQUE_SOURCE,
        velocity_limit=_UR3_SPEED,  # UR3 CB3 datasheet: base, shoulder, elbow 180°/s, wrists 360°/s
        acceleration_limit=_UR_ACCELERATION,  # ours (UR's MoveIt value, see _UR_ACCELERATION)
    ),
    "ur5": RobotInfo(
        "ur_description/urdf/ur5_robot.urdf",
        "ur_description/srdf/ur5.srdf",
        "tool0",
        theta_ref=_UR_REFERENCE,
        torque_limit=_UR5_TORQUE,
        torque_source=_UR_TORQUE_SOURCE,
        velocity_limit=_UR5_SPEED,  # UR5 CB3 datasheet: every joint 180°/s
        acceleration_limit=_UR_ACCELERATION,  # ours (UR's MoveIt value, see _UR_ACCELERATION)
    ),
    "ur10": RobotInfo(
        "ur_description/urdf/ur10_robot.urdf",
        None,
        "tool0",
        theta_ref=_UR_REFERENCE,
        torque_limit=_UR10_TORQUE,
        torque_source=_UR_TORQUE_SOURCE,
        velocity_limit=_UR10_SPEED,  # UR10 CB3 datasheet: base, shoulder 120°/s, the others 180°/s
        acceleration_limit=_UR_ACCELERATION,  # ours (UR's MoveIt value, see _UR_ACCELERATION)
    ),
    "xarm7": RobotInfo(
        "xarm_description/urdf/xarm7.urdf",
        "xarm_description/srdf/xarm7.srdf",
        "link_eef",
        theta_ref=(0.0, -0.5, 0.0, 1.0, 0.0, 1.5, 0.0),
        # UFACTORY xArm user manual, §8 technical specifications: "Maximum Joint Speed 180°/s"
        velocity_limit=180 * _DEG,
        # UFACTORY's own MoveIt configuration: 20 rad/s² for every joint
        # (xArm-Developer/xarm_ros2, xarm_moveit_config/config/xarm7/joint_limits.yaml)
        acceleration_limit=20.0,
    ),
    "kinova": RobotInfo(
        "kinova_description/robots/kinova.urdf",
        "kinova_description/srdf/kinova.srdf",
        "j2s6s200_end_effector",
        tool_rpy_deg=(0.0, 90.0, 0.0),
        reference="arm_up",
        # the JACO² 6-DOF spherical-wrist arm (j2s6s200, Kinova Gen2, not Gen3); its URDF (Kinova's
        # kinova-ros) has 36°/s on joints 1–3, 48°/s on 4–6. No published acceleration: ours.
        acceleration_limit=1.0,
    ),
    "z1": RobotInfo(
        "z1_description/urdf/z1.urdf",
        "z1_description/srdf/z1.srdf",
        "gripperStator",
        tool_rpy_deg=(0.0, 90.0, 0.0),
        theta_ref=(0.0, 1.2, -1.0, -0.2, 0.0, 0.0),
        locked_joints=("jointGripper",),
        # Unitree's URDF: π rad/s on every joint; no published acceleration: ours
        acceleration_limit=2.0,
    ),
}


def example_robot_data_dir() -> Path:
    """The ``share`` folder of the installed example-robot-data wheel (its ``package://`` root)."""
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        raise RobotError("example-robot-data is not installed (pip install example-robot-data)") from None
    share = Path(str(dist.locate_file("cmeel.prefix"))) / "share"
    if not (share / "example-robot-data" / "robots").is_dir():
        raise RobotError(f"example-robot-data has no robots folder under {share}")
    return share


def placement(position: ArrayLike, rpy_deg: ArrayLike) -> pin.SE3:
    """SE(3) from a position (m) and URDF roll-pitch-yaw (deg): R = Rz(yaw)·Ry(pitch)·Rx(roll)."""
    r, p, y = np.deg2rad(np.asarray(rpy_deg, float))
    return pin.SE3(pin.rpy.rpyToMatrix(r, p, y), np.asarray(position, float))


class JointCoordinates:
    """The map between joint angles θ (n = nv, URDF joint order) and pinocchio's q (nq).

    Revolute and prismatic joints: q = θ. Continuous joints: q = (cos θ, sin θ), θ = atan2(sin, cos).
    """

    def __init__(self, model: pin.Model) -> None:
        joints = sorted(model.joints[1:], key=lambda j: j.idx_v)
        self.nq, self.n = int(model.nq), int(model.nv)
        self.names: list[str] = [model.names[j.id] for j in joints]
        self.kinds: list[str] = [j.shortname() for j in joints]
        self.continuous = np.array([k in CONTINUOUS_JOINTS for k in self.kinds], bool)
        self.idx_q = np.array([j.idx_q for j in joints], int)
        self._v_angle = np.flatnonzero(~self.continuous)
        self._q_angle = self.idx_q[~self.continuous]
        self._v_cont = np.flatnonzero(self.continuous)
        self._q_cos = self.idx_q[self.continuous]
        self._q_sin = self._q_cos + 1
        self.identity = bool(not self.continuous.any() and np.array_equal(self.idx_q, np.arange(self.n)))

    def to_pin(self, theta: ArrayLike) -> Array:
        """Pinocchio configuration q (..., nq) from joint angles θ (..., n): continuous joints become
        (cos θ, sin θ), every other joint is copied."""
        theta = np.asarray(theta, float)
        if self.identity:
            return theta.copy()
        q = np.empty(theta.shape[:-1] + (self.nq,))
        q[..., self._q_angle] = theta[..., self._v_angle]
        c = theta[..., self._v_cont]
        q[..., self._q_cos] = np.cos(c)
        q[..., self._q_sin] = np.sin(c)
        return q

    def from_pin(self, q: ArrayLike) -> Array:
        """Joint angles θ (..., n) from a pinocchio configuration q (..., nq); a continuous joint's
        angle is atan2(sin, cos) ∈ (−π, π]."""
        q = np.asarray(q, float)
        if self.identity:
            return q.copy()
        theta = np.empty(q.shape[:-1] + (self.n,))
        theta[..., self._v_angle] = q[..., self._q_angle]
        theta[..., self._v_cont] = np.arctan2(q[..., self._q_sin], q[..., self._q_cos])
        return theta


class Robot:
    """The arm carrying the light, in joint-angle coordinates θ (see the module docstring).

    Attributes: ``name``; pinocchio ``model`` and its scratch ``data`` (used by the numeric methods);
    ``flange_frame_id``/``light_frame_id`` (frames ``flange``, ``light``); ``joint_names`` (URDF names,
    θ order); ``n``; ``lower``/``upper`` (rad or m), ``velocity_limit`` (rad/s or m/s),
    ``acceleration_limit`` (rad/s² or m/s²), ``jerk_limit`` (rad/s³ or m/s³), ``theta_ref``: arrays of
    length n; ``torque_limit`` (N·m or N, length n, or None where none are published) and
    ``torque_limit_source`` (where they come from, or why there are none). ``base_placement`` is
    T_WB. ``urdf_path``/``package_dirs``/``locked_joints`` rebuild geometry (:meth:`geometry_model`).
    """

    def __init__(
        self,
        name: str,
        model: pin.Model,
        *,
        theta_ref: ArrayLike | None,
        acceleration_limit: ArrayLike,
        jerk_limit: ArrayLike,
        base_placement: pin.SE3,
        velocity_limit: ArrayLike | None = None,
        urdf_path: Path,
        package_dirs: Sequence[Path],
        locked_joints: dict[str, float],
        torque_limit: ArrayLike | None = None,
        torque_limit_source: str = "no published torque limits",
    ) -> None:
        self.name = name
        self.model = model
        self.data = model.createData()
        self.base_placement = base_placement
        self.urdf_path = urdf_path
        self.package_dirs = list(package_dirs)
        self.locked_joints = dict(locked_joints)
        self.flange_frame_id = model.getFrameId("flange")
        self.light_frame_id = model.getFrameId("light")
        self.n = int(model.nv)
        coords = JointCoordinates(model)
        self.joint_names: list[str] = coords.names
        self.joint_kinds: list[str] = coords.kinds
        #: True when q = θ (no continuous joint): the hot paths skip the conversion.
        self.angles_are_q = coords.identity
        self.to_pin = coords.to_pin
        self.from_pin = coords.from_pin
        cont = coords.continuous
        angle_v, angle_q = np.flatnonzero(~cont), coords.idx_q[~cont]

        self.lower = np.full(self.n, -CONTINUOUS_LIMIT)
        self.upper = np.full(self.n, CONTINUOUS_LIMIT)
        self.lower[angle_v] = model.lowerPositionLimit[angle_q]
        self.upper[angle_v] = model.upperPositionLimit[angle_q]
        self.velocity_limit = np.array(model.velocityLimit, float).copy()
        if velocity_limit is not None:
            published = np.broadcast_to(np.asarray(velocity_limit, float), (self.n,))
            self.velocity_limit = np.minimum(self.velocity_limit, published)
        self.acceleration_limit = np.broadcast_to(np.asarray(acceleration_limit, float), (self.n,)).copy()
        self.jerk_limit = np.broadcast_to(np.asarray(jerk_limit, float), (self.n,)).copy()
        if theta_ref is None:
            ref = np.where(cont, 0.0, 0.5 * (self.lower + self.upper))
        else:
            ref = _wrap_into_limits(np.asarray(theta_ref, float), self.lower, self.upper)
        self.theta_ref = ref
        self.torque_limit: Array | None = None
        if torque_limit is not None:
            self.torque_limit = np.broadcast_to(np.asarray(torque_limit, float), (self.n,)).copy()
            self.torque_limit.setflags(write=False)
        self.torque_limit_source = torque_limit_source
        #: The SRDF's named configurations (group states), as joint angles θ; filled by load_robot.
        self.named_configurations: dict[str, Array] = {}
        limits = (self.velocity_limit, self.acceleration_limit, self.jerk_limit)
        for arr in (self.lower, self.upper, *limits, self.theta_ref):
            arr.setflags(write=False)
        self._symbolic: casadi.Function | None = None

    def __repr__(self) -> str:
        tool = self.model.frames[self.model.frames[self.flange_frame_id].parentFrame].name
        return f"Robot({self.name!r}, n={self.n}, flange at {tool!r})"

    # ---------------------------------------------------------------- coordinates
    def within_limits(self, theta: ArrayLike, tol: float = 1e-9) -> bool:
        """Whether lower − tol ≤ θ ≤ upper + tol for every joint."""
        theta = np.asarray(theta, float)
        return bool((theta >= self.lower - tol).all() and (theta <= self.upper + tol).all())

    def random_configuration(self, rng: np.random.Generator, size: int | None = None) -> Array:
        """Joint angles drawn uniformly within the limits; shape (n,) or (size, n)."""
        shape = (self.n,) if size is None else (size, self.n)
        return rng.uniform(self.lower, self.upper, size=shape)

    # ---------------------------------------------------------------- numeric kinematics
    def light_pose(self, theta: ArrayLike) -> tuple[Array, Array]:
        """Light position a_L (3,) in m and rotation R_WL (3, 3) in the world frame (pinocchio)."""
        pin.forwardKinematics(self.model, self.data, self.to_pin(theta))
        m = pin.updateFramePlacement(self.model, self.data, self.light_frame_id)
        return m.translation.copy(), m.rotation.copy()

    def light_positions(self, thetas: ArrayLike) -> Array:
        """Light positions (K, 3) in m, world frame, at the joint angles ``thetas`` (K, n)."""
        return np.array([self.light_pose(theta)[0] for theta in np.reshape(thetas, (-1, self.n))])

    def frame_pose(self, frame: str, theta: ArrayLike) -> pin.SE3:
        """World placement of a frame of the model (any URDF link, ``flange`` or ``light``)."""
        fid = self.frame_id(frame)
        pin.forwardKinematics(self.model, self.data, self.to_pin(theta))
        return pin.updateFramePlacement(self.model, self.data, fid).copy()

    def light_jacobian(self, theta: ArrayLike) -> Array:
        """Light-frame Jacobian (6, n) in LOCAL_WORLD_ALIGNED: rows 0–2 the velocity of the light's
        origin (m/s), rows 3–5 its angular velocity (rad/s), both in world axes, per unit θ̇."""
        pin.computeJointJacobians(self.model, self.data, self.to_pin(theta))
        return pin.getFrameJacobian(self.model, self.data, self.light_frame_id, pin.LOCAL_WORLD_ALIGNED)

    def frame_id(self, frame: str) -> int:
        """Index of a frame by name; :class:`RobotError` lists the frames when it does not exist."""
        return _find_frame(self.model, frame, self.name)

    # ---------------------------------------------------------------- symbolic kinematics
    @property
    def symbolic_light_pose(self) -> casadi.Function:
        """CasADi ``light_pose``: θ (n×1) → (a_L (3×1), R_WL (3×3)); built once, then cached."""
        if self._symbolic is None:
            self._symbolic = symbolic_frame_pose(self.model, self.light_frame_id, name="light_pose")
        return self._symbolic

    # ---------------------------------------------------------------- geometry
    def geometry_model(
        self, kind: Literal["collision", "visual"] = "collision", *, read_meshes: bool = False
    ) -> pin.GeometryModel:
        """Collision or visual geometry of the robot, consistent with :attr:`model`: locked joints
        reduced away, base placement applied.

        Collision meshes are read from the URDF's packages (distances are taken on them). Visual
        meshes are only drawn, by the preview, which reads each file itself
        (:mod:`optlight.viz.meshes`): by default they are not read (:func:`_unread_visual_meshes`;
        reading the Panda's COLLADA files into coal costs 0.18 s, for nothing). ``read_meshes=True``
        reads them too, into axis-aligned bounding-box trees (less than half the time of the
        default OBBRSS trees), as the check of a user URDF does."""
        gtype = pin.GeometryType.COLLISION if kind == "collision" else pin.GeometryType.VISUAL
        dirs = [str(p) for p in self.package_dirs]
        with quiet_stderr() as said:
            try:
                full = pin.buildModelFromUrdf(str(self.urdf_path))
                if kind == "collision":
                    geom = pin.buildGeomFromUrdf(full, str(self.urdf_path), gtype, package_dirs=dirs)
                elif read_meshes:
                    loader = coal.MeshLoader(coal.BV_AABB)
                    geom = pin.buildGeomFromUrdf(full, str(self.urdf_path), gtype, package_dirs=dirs, mesh_loader=loader)
                else:
                    geom = _unread_visual_meshes(full, self.urdf_path)
            except (RuntimeError, ValueError) as e:
                detail = _first_error(said, e)
                raise RobotError(
                    f"{self.name}: cannot read the {kind} meshes of {self.urdf_path}: {detail}"
                ) from None
        if self.locked_joints:
            ids = [full.getJointId(j) for j in self.locked_joints]
            q = pin.neutral(full)
            for j, value in self.locked_joints.items():
                q[full.joints[full.getJointId(j)].idx_q] = value
            _, geom = pin.buildReducedModel(full, geom, ids, q)
        for obj in geom.geometryObjects:
            if obj.parentJoint == 0:
                obj.placement = self.base_placement * obj.placement
        return geom


def _unread_visual_meshes(model: pin.Model, urdf: Path) -> pin.GeometryModel:
    """The visual geometry of ``urdf`` as pinocchio's parser makes it (names ``<link>_<k>``, parent
    joints and frames, placements, materials, primitives), its mesh files found but not read: the
    parser is given the URDF with each visual ``<mesh>`` replaced by a point (a sphere of radius 0),
    and each of those objects then gets back the mesh's file (``meshPath``, resolved as
    :func:`resolve_mesh` does), its ``scale`` (``meshScale``) and an empty BVH as geometry, which
    meshcat viewers take for a mesh to read from its file. Raises ValueError for a mesh file that
    does not resolve."""
    root = ET.parse(urdf).getroot()
    meshes: dict[str, tuple[Path, Array]] = {}
    for link in root.findall("link"):
        for k, visual in enumerate(link.findall("visual")):
            geometry = visual.find("geometry")
            mesh = geometry.find("mesh") if geometry is not None else None
            if geometry is None or mesh is None:
                continue
            filename = mesh.get("filename", "")
            found = resolve_mesh(filename, urdf)
            if found is None:
                raise ValueError(f"the mesh {filename!r} does not resolve")
            meshes[f"{link.get('name')}_{k}"] = (found, np.array(mesh.get("scale", "1 1 1").split(), float))
            geometry.remove(mesh)
            ET.SubElement(geometry, "sphere", radius="0")
    geom = pin.buildGeomFromUrdfString(model, ET.tostring(root, encoding="unicode"), pin.GeometryType.VISUAL)
    for obj in geom.geometryObjects:
        if obj.name in meshes:
            path, scale = meshes[obj.name]
            obj.geometry, obj.meshPath, obj.meshScale = coal.BVHModelOBBRSS(), str(path), scale
    return geom


def _torque_limit(info: RobotInfo, model: pin.Model, urdf: Path) -> tuple[Array | None, str]:
    """The joint torque limits (N·m) of the (reduced) model and where they come from: the maker's
    published ones (``info.torque_limit``), else the URDF's effort limits when every joint has one
    (> 0), else None."""
    if info.torque_limit is not None:
        limit = np.asarray(info.torque_limit, float)
        if limit.shape != (model.nv,):
            raise RobotError(f"{urdf.name}: {limit.size} torque limits for {model.nv} joints")
        return limit, info.torque_source
    effort = np.array([model.effortLimit[j.idx_v] for j in model.joints[1:]], float)
    if effort.size == model.nv and np.all(np.isfinite(effort)) and np.all(effort > 0):
        return effort, f"the effort limits of {urdf.name}"
    return None, f"no published torque limits ({urdf.name} has no effort limits)"


def _wrap_into_limits(theta: Array, lower: Array, upper: Array) -> Array:
    """θ with each value outside [lower, upper] moved by a multiple of 2π inside when possible."""
    out = theta.copy()
    for i, (t, lo, hi) in enumerate(zip(theta, lower, upper, strict=True)):
        if lo <= t <= hi:
            continue
        k = np.ceil((lo - t) / (2 * np.pi))
        if lo <= t + 2 * np.pi * k <= hi:
            out[i] = t + 2 * np.pi * k
        else:
            out[i] = min(max(t, lo), hi)
    return out


def _find_frame(model: pin.Model, name: str, robot: str) -> int:
    """A frame by name, preferring OP_FRAME, BODY, FIXED_JOINT, JOINT when several share it."""
    for ftype in (pin.FrameType.OP_FRAME, pin.FrameType.BODY, pin.FrameType.FIXED_JOINT, pin.FrameType.JOINT):
        if model.existFrame(name, ftype):
            return int(model.getFrameId(name, ftype))
    raise RobotError(f"{robot}: no frame {name!r}; available frames: {', '.join(_frame_names(model))}")


def _frame_names(model: pin.Model) -> list[str]:
    return sorted({f.name for f in model.frames if f.type != pin.FrameType.JOINT})


# --------------------------------------------------------------------------------------------
# User URDFs: the parser's stderr, package:// lookup, mesh files
# --------------------------------------------------------------------------------------------


@contextmanager
def quiet_stderr() -> Iterator[list[str]]:
    """Send what C/C++ code writes on file descriptor 2 (urdfdom's "Error: …" lines) to a
    temporary file instead of the terminal; the yielded list holds those lines after the block."""
    said: list[str] = []
    sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:  # no stderr to redirect
        yield said
        return
    with tempfile.TemporaryFile(mode="w+b") as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield said
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            said.extend(sink.read().decode(errors="replace").splitlines())


def _first_error(said: Sequence[str], error: Exception) -> str:
    """The parser's first "Error:" line when it printed one, else the exception's message."""
    for line in said:
        if line.strip().startswith("Error:"):
            return f"{error} ({line.strip()[6:].strip()})"
    return str(error)


def find_package(name: str, urdf: Path) -> Path | None:
    """The folder of the ROS package ``name`` for the URDF at ``urdf``, or None.

    Looked up as ROS does, in this order: the URDF's folder and every folder above it, nearest first
    (the folder itself when it is named ``name``, else a folder ``name`` in it); then each folder of
    ``ROS_PACKAGE_PATH`` (the folder itself when it is named ``name``, a folder ``name`` in it, or a
    folder ``name`` holding a ``package.xml`` up to :data:`PACKAGE_SEARCH_DEPTH` levels below it).
    """
    for folder in (urdf.parent, *urdf.parent.parents):
        if folder.name == name:
            return folder
        if (folder / name).is_dir():
            return folder / name
    for entry in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep):
        if not entry:
            continue
        root = Path(entry).expanduser()
        if root.name == name and root.is_dir():
            return root
        if (root / name).is_dir():
            return root / name
        level = [root]
        for _ in range(PACKAGE_SEARCH_DEPTH):
            level = [d for f in level for d in _subfolders(f)]
            for d in level:
                if d.name == name and (d / "package.xml").is_file():
                    return d
    return None


def _subfolders(folder: Path) -> list[Path]:
    """The visible subfolders of ``folder`` (none where it cannot be read)."""
    try:
        return sorted(d for d in folder.iterdir() if d.is_dir() and not d.name.startswith("."))
    except OSError:
        return []


def resolve_mesh(filename: str, urdf: Path) -> Path | None:
    """The file a URDF ``<mesh filename=…>`` names (``package://``, ``file://`` or a path, relative
    to the URDF), or None when it does not exist."""
    if filename.startswith("package://"):
        name, _, rest = filename[len("package://") :].partition("/")
        package = find_package(name, urdf)
        path = package / rest if package is not None else None
    elif filename.startswith("file://"):
        path = Path(filename[len("file://") :])
    else:
        path = Path(filename).expanduser()
        path = path if path.is_absolute() else urdf.parent / path
    return path if path is not None and path.is_file() else None


def _urdf_package_dirs(urdf: Path, file: str) -> list[Path]:
    """Check that every mesh of a user URDF resolves (module docstring); return the folders to give
    pinocchio as ``package_dirs`` (it looks for ``dir/NAME/rest``): each package's parent folder."""
    try:
        root = ET.parse(urdf).getroot()
    except (ET.ParseError, OSError, UnicodeDecodeError) as e:
        raise ProblemError(file, "robot.urdf", f"a URDF file (XML: {e})", str(urdf)) from None
    dirs: list[Path] = []
    for mesh in root.iter("mesh"):
        filename = mesh.get("filename", "")
        found = resolve_mesh(filename, urdf)
        if found is None:
            raise ProblemError(
                file,
                "robot.urdf",
                f"a URDF whose meshes exist ({filename!r} does not resolve: package://NAME is looked up in "
                "the URDF's folder and those above it, then in ROS_PACKAGE_PATH)",
                str(urdf),
            )
        if filename.startswith("package://"):
            name = filename[len("package://") :].split("/", 1)[0]
            package = find_package(name, urdf)
            assert package is not None  # resolve_mesh found the file in it
            if package.parent not in dirs:
                dirs.append(package.parent)
    return dirs


def load_robot(source: Problem | RobotSpec | str) -> Robot:
    """The robot of a problem, a ``[robot]`` spec, or a robot name from :data:`SUPPORTED_ROBOTS`.

    A relative ``urdf`` path is resolved against the problem file (``Problem``) or the working
    directory (``RobotSpec``). Raises :class:`RobotError` for an unknown robot, a missing file or an
    unsupported joint type, listing what is available; from a ``Problem``, a user URDF that does not
    parse, whose meshes do not resolve or that has fewer joints than the light's
    :data:`LIGHT_CONSTRAINTS` (the problem's robot is to be planned; a spec's may have fewer, for its
    kinematics alone), and an unknown frame, are :class:`ProblemError` naming ``robot.urdf`` and
    ``robot.frame`` (from a spec or name, RobotError naming the key).
    """
    file: str | None = None
    if isinstance(source, Problem):
        spec = source.robot
        urdf = source.resolve(spec.urdf) if spec.urdf is not None else None
        file = str(source.source) if source.source else "<inline>"
    elif isinstance(source, RobotSpec):
        spec = source
        urdf = Path(spec.urdf).expanduser().resolve() if spec.urdf is not None else None
    else:
        spec = RobotSpec(name=source)
        urdf = None

    if urdf is not None:
        if not urdf.is_file():
            raise RobotError(f"robot.urdf: no file {urdf}")
        if spec.frame is None:
            raise RobotError("robot.frame: a user URDF needs the name of its flange frame")
        info = RobotInfo(str(urdf), None, spec.frame)
        urdf_path, srdf_path = urdf, None
        package_dirs = _urdf_package_dirs(urdf, file or str(urdf))
    else:
        if spec.name not in ROBOTS:
            raise RobotError(
                f"unknown robot {spec.name!r}; supported robots: {', '.join(SUPPORTED_ROBOTS)} "
                "(or set robot.urdf and robot.frame)"
            )
        info = ROBOTS[spec.name]
        share = example_robot_data_dir()
        robots = share / "example-robot-data" / "robots"
        urdf_path = robots / info.urdf
        srdf_path = robots / info.srdf if info.srdf else None
        package_dirs = [share]

    with quiet_stderr() as said:
        try:
            full = pin.buildModelFromUrdf(str(urdf_path))
        except (RuntimeError, ValueError) as e:
            if urdf is not None and file is not None:
                raise ProblemError(
                    file, "robot.urdf", f"a URDF pinocchio reads ({_first_error(said, e)})", spec.urdf
                ) from None
            raise RobotError(f"{spec.name}: cannot read {urdf_path}: {_first_error(said, e)}") from None

    # Reference configuration (full model), then lock the hand joints at 0.
    q_full = pin.neutral(full)
    states: dict[str, Array] = {}
    if srdf_path is not None:
        pin.loadReferenceConfigurations(full, str(srdf_path))
        states = {e.key(): np.array(e.data()) for e in full.referenceConfigurations}
    if info.reference is not None:
        if info.reference not in states:
            raise RobotError(f"{spec.name}: no reference configuration {info.reference!r} in {srdf_path}")
        q_full = states[info.reference]
    missing = [j for j in info.locked_joints if not full.existJointName(j)]
    if missing:
        raise RobotError(f"{spec.name}: no joint {missing[0]!r} to lock in {urdf_path}")
    locked = dict.fromkeys(info.locked_joints, 0.0)
    for j in locked:
        q_full[full.joints[full.getJointId(j)].idx_q] = 0.0
    model = (
        pin.buildReducedModel(full, [full.getJointId(j) for j in locked], q_full) if locked else full.copy()
    )
    bad = [
        f"{model.names[j.id]} ({j.shortname()})"
        for j in model.joints[1:]
        if j.shortname() not in REVOLUTE_JOINTS | PRISMATIC_JOINTS | CONTINUOUS_JOINTS
    ]
    if bad:
        raise RobotError(
            f"{spec.name}: unsupported joint types {', '.join(bad)}; optlight handles revolute, "
            "continuous and prismatic joints"
        )
    # Base placement: pre-multiply everything attached to the universe by T_WB.
    base = placement(spec.base_position_m, spec.base_rpy_deg)
    for jid in range(1, model.njoints):
        if model.parents[jid] == 0:
            model.jointPlacements[jid] = base * model.jointPlacements[jid]
    for f in range(1, model.nframes):
        if model.frames[f].parentJoint == 0:
            model.frames[f].placement = base * model.frames[f].placement

    # Flange (tool frame with +z out of the tool) and light frames.
    frame_name = spec.frame if spec.frame is not None else info.tool_frame
    if not model.existFrame(frame_name):
        expected = f"a frame of {spec.name} ({', '.join(_frame_names(model))})"
        if file is not None:
            raise ProblemError(file, "robot.frame", expected, frame_name)
        raise RobotError(f"robot.frame: expected {expected}, got {frame_name!r}")
    if file is not None and model.nv < LIGHT_CONSTRAINTS:  # a problem's robot is to be planned
        joints = ", ".join(model.names[j.id] for j in model.joints[1:])
        raise ProblemError(
            file,
            "robot.urdf",
            f"an arm with at least {LIGHT_CONSTRAINTS} joints for the light's {LIGHT_CONSTRAINTS} constraints "
            f"(h1–h3, zenith, azimuth); {urdf_path.name} has {model.nv} ({joints})",
        )
    tool = model.frames[_find_frame(model, frame_name, spec.name)]
    for taken in ("flange", "light"):
        if model.existFrame(taken):
            raise RobotError(
                f"{spec.name}: the URDF already has a frame named {taken!r}, which optlight adds"
            )
    fix = placement((0, 0, 0), info.tool_rpy_deg if spec.frame is None else (0, 0, 0))
    flange_id = model.addFrame(
        pin.Frame(
            "flange",
            tool.parentJoint,
            _find_frame(model, frame_name, spec.name),
            tool.placement * fix,
            pin.FrameType.OP_FRAME,
        )
    )
    offset = placement(spec.light_offset_m, spec.light_rpy_deg)
    model.addFrame(
        pin.Frame(
            "light",
            tool.parentJoint,
            flange_id,
            model.frames[flange_id].placement * offset,
            pin.FrameType.OP_FRAME,
        )
    )

    def reduced_angles(q: Array) -> Array:
        """θ of the reduced model from a configuration q of the full one."""
        kept = [q[j.idx_q : j.idx_q + j.nq] for j in full.joints[1:] if full.names[j.id] not in locked]
        return JointCoordinates(model).from_pin(np.concatenate(kept))

    # θ_ref: the SRDF state (reduced), the catalogue's default, or (user URDF) the limits' middle.
    theta_ref: Array | None = None
    if info.reference is not None:
        theta_ref = reduced_angles(q_full)
    elif info.theta_ref is not None:
        theta_ref = np.asarray(info.theta_ref, float)
        if theta_ref.shape != (model.nv,):
            raise RobotError(f"{spec.name}: reference has {theta_ref.size} values for {model.nv} joints")
    accel = spec.acceleration_limit if spec.acceleration_limit is not None else info.acceleration_limit
    jerk = spec.jerk_limit if spec.jerk_limit is not None else info.jerk()
    if spec.jerk_limit is None and spec.acceleration_limit is not None and info.jerk_limit is None:
        jerk = tuple(np.asarray(accel, float).ravel() / DEFAULT_JERK_RAMP_S)  # the ramp of the override
    limits = {}
    for name, value in (("acceleration_limit", accel), ("jerk_limit", jerk)):
        arr = np.asarray(value, float)
        if arr.ndim and arr.shape not in ((1,), (model.nv,)):
            raise RobotError(f"robot.{name}: {arr.size} values for the {model.nv} joints of {spec.name}")
        limits[name] = arr.ravel() if arr.shape != (1,) else arr[0]
    torque, torque_source = _torque_limit(info, model, urdf_path)
    robot = Robot(
        spec.name,
        model,
        theta_ref=theta_ref,
        acceleration_limit=limits["acceleration_limit"],
        jerk_limit=limits["jerk_limit"],
        velocity_limit=info.velocity_limit,
        base_placement=base,
        urdf_path=urdf_path,
        package_dirs=package_dirs,
        locked_joints=locked,
        torque_limit=torque,
        torque_limit_source=torque_source,
    )
    robot.named_configurations = {
        name: _wrap_into_limits(reduced_angles(q), robot.lower, robot.upper) for name, q in states.items()
    }
    return robot
