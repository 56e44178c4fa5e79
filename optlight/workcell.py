"""What the planning stages share, as they use it: the work cell (the robot, the light sphere it may
use, its motion limits, the environment, the IK's settings, the view's zenith and the start) and the
image costs (the objective on the camera's scene and on the search scene).

:class:`~optlight.setup.Setup` builds both once from a problem (``setup.workcell``,
``setup.image_costs``); the planners take them with their own spec section (``[landmarks]``,
``[trajectory]``, ``[lightset]``, ``[solver]``) and never the problem itself. Angles are radians,
lengths metres.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from optlight.environment import Environment
from optlight.geometry import LightSphere
from optlight.objectives import Objective
from optlight.robot import Robot
from optlight.scene import Scene

Array = NDArray[np.float64]


@dataclass(frozen=True)
class MotionLimits:
    """The joint limits a plan keeps, per joint: position ``lower``/``upper`` (rad or m),
    ``velocity`` (the robot's times ``[robot] velocity_scale``, rad/s), ``acceleration`` (rad/s²) and
    ``jerk`` (rad/s³)."""

    lower: Array
    upper: Array
    velocity: Array
    acceleration: Array
    jerk: Array

    @classmethod
    def of(cls, robot: Robot, velocity_scale: float) -> MotionLimits:
        """The limits of ``robot`` with its velocity limits scaled by ``velocity_scale`` ∈ (0, 1]."""
        return cls(
            robot.lower,
            robot.upper,
            robot.velocity_limit * velocity_scale,
            robot.acceleration_limit,
            robot.jerk_limit,
        )


@dataclass(frozen=True, eq=False)
class Workcell:
    """The robot and where it may put the light, as every planning stage sees them.

    ``sphere``: the light sphere (centre O, radius b, m; its frame) with the zenith range the lights
    may use, ``[light_sphere]``'s less the lights whose housing would enter the camera's view
    (``view_zenith``, rad; 0 with the view off). ``limits``: the joint limits a plan keeps.
    ``environment``: obstacles, self-collision and the camera's view, None when all are off.
    ``ik``: the generalized IK's keyword settings from ``[solver]``. ``start``: the joint angles
    (rad) the motion starts and ends at."""

    robot: Robot
    sphere: LightSphere
    limits: MotionLimits
    environment: Environment | None
    ik: Mapping[str, Any]
    view_zenith: float
    start: Array


@dataclass(frozen=True, eq=False)
class ImageCosts:
    """The image objective where the light is chosen: ``scene`` and ``objective`` at the camera's
    resolution (reported costs, the final scoring), ``search_scene`` and ``search_objective`` at
    ``[landmarks] resolution`` (sweeps, the landmark and placement NLPs; the same objects when that
    resolution is not smaller). ``scene.sphere`` is the light sphere as requested, before the view
    takes its lights away."""

    scene: Scene
    objective: Objective
    search_scene: Scene
    search_objective: Objective
