"""A problem built once into the objects every stage shares.

``Setup.from_problem(problem)`` builds, in this order and each exactly once:

- the object (mesh, albedo) and its ray intersector, the camera and the G-buffer: ``scene`` at the
  camera's resolution (reported costs, figures) and ``search_scene`` at ``[landmarks] resolution``
  (the landmark search and the placement NLP), the two sharing the object;
- the objectives on both scenes (``objective``, ``search_objective``), with their reference;
- the robot, and the ``limits`` a plan must keep (its URDF velocity limits times ``[robot]
  velocity_scale``);
- the environment when ``[environment] enabled`` (its CasADi clearance and view functions are built
  on first use and kept by the environment);
- the generalized IK's settings from ``[solver]``.

The planners take a ``Setup`` and read their configuration from its typed sections (``landmark_spec``,
``trajectory_spec``, ``solver``, ``environment_spec``); none takes a :class:`~optlight.spec.Problem`.
Building a ``Setup`` is also the check of everything a run touches that the problem file alone cannot
show (the mesh loads, the URDF parses and has the frame, the reference image matches the camera, the
object fits in the light sphere, the camera sees it): each such mistake is a
:class:`~optlight.errors.ProblemError` naming the file and the key.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from optlight.environment import Environment
from optlight.geometry import LightSphere
from optlight.objectives import Objective
from optlight.robot import Robot, ik_settings, load_robot
from optlight.scene import Scene
from optlight.spec import (
    EnvironmentSpec,
    LandmarksSpec,
    Problem,
    SolverSpec,
    TrajectorySpec,
    check_memory,
    load_problem,
)

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
class Setup:
    """Everything a solve shares, built once from a problem (see the module docstring)."""

    problem: Problem
    scene: Scene
    search_scene: Scene
    objective: Objective
    search_objective: Objective
    robot: Robot
    limits: MotionLimits
    environment: Environment | None
    ik: Mapping[str, Any]

    @classmethod
    def from_problem(cls, problem: Problem | str | Path) -> Setup:
        """Build the setup of a problem (a :class:`Problem`, a file path or a built-in name)."""
        problem = problem if isinstance(problem, Problem) else load_problem(problem)
        check_memory(problem)  # this machine's memory (spec.check_memory), before the large allocations
        scene = Scene.from_problem(problem)
        search_scene = _search_scene(scene, problem.landmarks.resolution)
        objective = Objective.from_problem(problem, scene)
        search_objective = (
            objective if search_scene is scene else Objective.from_problem(problem, search_scene)
        )
        robot = load_robot(problem)
        environment = (
            Environment.from_problem(problem, scene.mesh.vertices) if problem.environment.enabled else None
        )
        return cls(
            problem=problem,
            scene=scene,
            search_scene=search_scene,
            objective=objective,
            search_objective=search_objective,
            robot=robot,
            limits=MotionLimits.of(robot, problem.robot.velocity_scale),
            environment=environment,
            ik=MappingProxyType(ik_settings(problem.solver)),
        )

    @property
    def sphere(self) -> LightSphere:
        """The light sphere (centre O, radius b, frame, allowed zenith range)."""
        return self.scene.sphere

    @property
    def landmark_spec(self) -> LandmarksSpec:
        """``[landmarks]``: how the landmark search runs."""
        return self.problem.landmarks

    @property
    def trajectory_spec(self) -> TrajectorySpec:
        """``[trajectory]``: order, path mode, knot spacing, dwell."""
        return self.problem.trajectory

    @property
    def solver(self) -> SolverSpec:
        """``[solver]``: IPOPT's and the IK's settings."""
        return self.problem.solver

    @property
    def environment_spec(self) -> EnvironmentSpec:
        """``[environment]`` as written (``environment`` is the built one, or None when disabled)."""
        return self.problem.environment

    @property
    def file(self) -> str:
        """The problem file's path for error messages ("<inline>" for a problem built in code)."""
        return str(self.problem.source) if self.problem.source else "<inline>"


def _search_scene(scene: Scene, resolution: int) -> Scene:
    """``scene`` itself, or the same view with its longer side at ``resolution`` px when that is
    smaller (the landmark search renders there)."""
    cam = scene.camera
    if resolution >= max(cam.width, cam.height):
        return scene
    if cam.width >= cam.height:
        return scene.resampled(resolution, max(1, round(resolution * cam.height / cam.width)))
    return scene.resampled(max(1, round(resolution * cam.width / cam.height)), resolution)
