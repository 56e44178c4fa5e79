"""Everything a run will touch, checked before the run starts, by building it once.

``optlight check`` and the first step of ``solve`` and ``reach`` build the problem's
:class:`~optlight.setup.Setup`: that build is the check of what the problem file alone cannot show
(the object's mesh loads, the light sphere holds the object, the camera sees it, the reference image
and mask load and cover object pixels, the URDF parses, its meshes resolve and it has the flange
frame, the environment's layout, the solve's estimated memory and the trajectory's samples fit in
this machine's). The command
then hands that same Setup to :func:`optlight.solve` or :func:`optlight.reachability_map`, so nothing
is built twice. What the Setup does not build is checked here: a grid light set's directions are read and must be
distinct, and a user URDF's visual and collision meshes must load (the preview, the view check and
the environment read them only after the solve).

The checks that need nothing built (key types and ranges, the camera outside the light sphere,
image-name patterns) ran already when the problem file was loaded (:func:`optlight.spec.load_problem`),
and the output location is checked by the command before the problem is even loaded
(:mod:`optlight.export`). Every failure is a one-line :class:`~optlight.errors.OptlightError` naming
the file and the key.
"""

from __future__ import annotations

from optlight.planning.lightsets import grid_from_problem
from optlight.setup import Setup
from optlight.spec import Problem


def preflight(problem: Problem) -> Setup:
    """The built :class:`Setup` of ``problem``, after loading a user URDF's meshes; raises the first
    :class:`~optlight.errors.OptlightError` met."""
    if problem.lightset.kind == "grid":
        grid_from_problem(problem)  # read again by the light-set stage, after the landmark search
    setup = Setup.from_problem(problem)
    if problem.robot.urdf is not None:
        # read after the solve (preview, view check, environment): a user URDF's meshes must load now
        setup.robot.geometry_model("visual", read_meshes=True)
        setup.robot.geometry_model("collision")
    return setup
