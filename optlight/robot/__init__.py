"""The robot that carries the light: loading, CasADi kinematics, h(θ), generalized IK.

- :func:`load_robot` / :class:`Robot` (:mod:`.loading`): named arms from example-robot-data or a user
  URDF, hand joints locked, base placement applied, ``flange`` and ``light`` frames added, joint angles
  θ (one per joint) as the coordinates the rest of optlight uses.
- :mod:`.kinematics`: the CasADi mirror of pinocchio's forward kinematics
  (:attr:`Robot.symbolic_light_pose`), the light residual :func:`light_residual` (docs/design.md §3) and the
  light's sphere coordinates :func:`light_angles`.
- :class:`Dynamics` (:mod:`.dynamics`): joint torques of a motion by RNEA, the lamp included.
- :func:`generalized_ik` (:mod:`.ik`, tasks in :mod:`.tasks`): δθ = J# e + (I − J⁺J) γ.
"""

from optlight.robot.catalogue import SUPPORTED_ROBOTS
from optlight.robot.dynamics import Dynamics, Lamp
from optlight.robot.ik import DEFAULT_GAINS, IKResult, generalized_ik, ik_settings, null_space_step
from optlight.robot.kinematics import light_angles, light_residual, symbolic_frame_pose
from optlight.robot.loading import Robot, load_robot
from optlight.robot.tasks import (
    JointLimitTask,
    KinematicState,
    LightPointingTask,
    LightPoseTask,
    ManipulabilityTask,
    PostureTask,
    manipulability,
)

__all__ = [
    "DEFAULT_GAINS",
    "SUPPORTED_ROBOTS",
    "Dynamics",
    "IKResult",
    "JointLimitTask",
    "KinematicState",
    "Lamp",
    "LightPointingTask",
    "LightPoseTask",
    "ManipulabilityTask",
    "PostureTask",
    "Robot",
    "generalized_ik",
    "ik_settings",
    "light_angles",
    "light_residual",
    "load_robot",
    "manipulability",
    "null_space_step",
    "symbolic_frame_pose",
]
