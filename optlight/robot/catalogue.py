"""The robots optlight knows by name (example-robot-data's files), with the limits their makers publish.

**Supported robots** (``SUPPORTED_ROBOTS``), their flange frames and reference configurations:

========  =======================  =============================
robot     flange (URDF frame)      reference θ_ref
========  =======================  =============================
panda     ``panda_hand_tcp``       SRDF ``default``
ur3/5/10  ``tool0``                (0, −π/2, π/2, −π/2, −π/2, 0)
xarm7     ``link_eef``             (0, −0.5, 0, 1, 0, 1.5, 0)
kinova    ``j2s6s200_end_effector``  SRDF ``arm_up`` [1]
z1        ``gripperStator`` [2]    (0, 1.2, −1.0, −0.2, 0, 0)
========  =======================  =============================

[1] Joint values outside the URDF limits are wrapped by ±2π (the same pose).
[2] The flange is :attr:`RobotInfo.tool_offset_m` = 0.155 m out along the tool axis: the z1's
gripper (its collision meshes) reaches 0.149 m ahead of ``gripperStator``, so a lamp there would
shine into its own jaws at every posture (the beam 100 % blocked); the lamp is held just beyond the
fingertips.

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
"""

from __future__ import annotations

import importlib.metadata
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from optlight.errors import RobotError
from optlight.spec import ROBOT_NAMES

#: Robot names :func:`optlight.robot.load_robot` knows (files from example-robot-data).
SUPPORTED_ROBOTS: tuple[str, ...] = ROBOT_NAMES

#: Acceleration limit of a user URDF when ``robot.acceleration_limit`` is not set (rad/s²).
DEFAULT_ACCELERATION_LIMIT = 2.0
#: Where no jerk limit is published: the time (s) to reach the acceleration limit, J = a_max / ramp.
DEFAULT_JERK_RAMP_S = 0.05

_UR_REFERENCE = (0.0, -np.pi / 2, np.pi / 2, -np.pi / 2, -np.pi / 2, 0.0)


@dataclass(frozen=True)
class RobotInfo:
    """Where a named robot's files are and how optlight uses it.

    ``urdf``/``srdf`` are relative to example-robot-data's ``robots`` folder; ``tool_rpy_deg`` rotates
    the URDF tool frame into the flange frame (+z out of the tool), ``tool_offset_m`` moves the flange
    that far (m) along that +z (past a gripper the lamp must shine clear of); ``reference`` names an SRDF
    reference configuration, else ``theta_ref`` is used; ``locked_joints`` are held at 0;
    ``torque_limit`` (N·m) the maker's published joint torques and ``torque_source`` where they are
    published (None: the URDF's effort limits, if it has them).
    """

    urdf: str
    srdf: str | None
    tool_frame: str
    tool_rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    tool_offset_m: float = 0.0
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
#: The link pairs of a UR arm that cannot collide (MoveIt's "Adjacent" and "Never"): example-robot-data
#: ships them for the UR5 only, but they are the same for every UR of its URDFs (the same link names
#: and joint layout, scaled), as Universal Robots' own MoveIt configuration has one SRDF macro for
#: every UR type (ur_moveit_config, srdf/ur_macro.srdf.xacro). Without them the UR10's base_link and
#: upper_arm_link, 18–20 mm apart in every configuration (the shoulder offset), count as a self pair.
_UR_SRDF = "ur_description/srdf/ur5.srdf"


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
        _UR_SRDF,
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
        _UR_SRDF,
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
        tool_offset_m=0.155,
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
