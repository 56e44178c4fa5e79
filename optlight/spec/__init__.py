"""Problem files: TOML -> validated, typed, immutable dataclasses.

A problem file is data. Every key is declared once, in the section modules here (:mod:`.scene`,
:mod:`.objective`, :mod:`.landmarks`, :mod:`.trajectory`, :mod:`.environment`, :mod:`.loop`), with its
type, unit, default, allowed range and a one-line description (:func:`.keys.key`); :func:`load_problem`
checks a file against these declarations (:mod:`.load`, :mod:`.consistency`) and
:func:`reference_markdown` writes the reference (``docs/problems.md``, by ``make docs``) from them, so
the code and the documentation cannot drift apart. :mod:`.sizing` checks what a run will need of this
machine.

Conventions (docs/design.md §2): metres and degrees in files (keys end in ``_m`` / ``_deg``), radians in
code. Paths inside a file are relative to that file.
"""

from optlight.spec.environment import BoxSpec, CylinderSpec, EnvironmentSpec, SphereSpec, ViewSpec
from optlight.spec.landmarks import LandmarksSpec, LightSetSpec
from optlight.spec.load import (
    PROBLEMS_DIR,
    available_problems,
    load_problem,
    problem_from_dict,
    read_toml,
    resolve_problem_path,
)
from optlight.spec.loop import LoopSpec, WorldSpec
from optlight.spec.objective import ObjectiveSpec, ReferenceSpec, TermSpec
from optlight.spec.problem import Problem
from optlight.spec.reference import reference_markdown
from optlight.spec.scene import (
    ROBOT_NAMES,
    CameraSpec,
    FaceSpec,
    LightSpec,
    LightSphereSpec,
    ObjectSpec,
    RobotSpec,
)
from optlight.spec.trajectory import SolverSpec, TrajectorySpec

__all__ = [
    "PROBLEMS_DIR",
    "ROBOT_NAMES",
    "BoxSpec",
    "CameraSpec",
    "CylinderSpec",
    "EnvironmentSpec",
    "FaceSpec",
    "LandmarksSpec",
    "LightSetSpec",
    "LightSpec",
    "LightSphereSpec",
    "LoopSpec",
    "ObjectSpec",
    "ObjectiveSpec",
    "Problem",
    "ReferenceSpec",
    "RobotSpec",
    "SolverSpec",
    "SphereSpec",
    "TermSpec",
    "TrajectorySpec",
    "ViewSpec",
    "WorldSpec",
    "available_problems",
    "load_problem",
    "problem_from_dict",
    "read_toml",
    "reference_markdown",
    "resolve_problem_path",
]
