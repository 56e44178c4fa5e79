"""Everything a run will touch, checked before the run starts.

``optlight check`` and the first step of every command build what a run builds first, so that each
check done at build time runs: the scene (the object's mesh file loads, the light sphere holds the
object, the camera sees it), the objective's reference image and mask (they load, the mask covers
object pixels), the robot (the URDF parses, its meshes resolve and load, the flange frame exists) and,
when enabled, the environment. The checks that need nothing built (key types and ranges, the
camera outside the light sphere, image-name patterns, the memory a solve needs) ran already when
the problem file was loaded (:func:`optlight.spec.load_problem`). Every failure is a one-line
:class:`~optlight.errors.OptlightError` naming the file and the key.
"""

from __future__ import annotations

from dataclasses import dataclass

from optlight.environment import Environment
from optlight.robot import Robot, load_robot
from optlight.scene import Scene
from optlight.spec import Problem


@dataclass(frozen=True)
class Built:
    """What :func:`preflight` built: the scene at the camera's resolution, the robot and the
    environment (None unless ``[environment] enabled``)."""

    scene: Scene
    robot: Robot
    environment: Environment | None


def preflight(problem: Problem) -> Built:
    """Build the scene, the reference, the robot (its geometry too, for a user URDF) and the
    environment of ``problem``; raises the first :class:`~optlight.errors.OptlightError` met."""
    from optlight.objectives import SoftHistogram, reference_from_image  # imports the scene's CasADi side

    scene = Scene.from_problem(problem)
    ref = problem.objective.reference
    if ref.kind == "image" and ref.image is not None:
        reference_from_image(
            scene,
            SoftHistogram(problem.objective.bins, problem.objective.sigma_bins),
            problem.resolve(ref.image),
            problem.resolve(ref.mask) if ref.mask is not None else None,
            problem.light.saturation,
            str(problem.source) if problem.source else "<inline>",
        )
    robot = load_robot(problem)
    if problem.robot.urdf is not None:
        # the preview and the environment read the meshes: a user URDF's must load now
        robot.geometry_model("visual")
        robot.geometry_model("collision")
    environment = Environment.from_problem(problem) if problem.environment.enabled else None
    return Built(scene, robot, environment)
