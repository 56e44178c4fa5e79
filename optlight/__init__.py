"""optlight: camera-driven robotic light source positioning.

Where the light should go (landmarks that minimise a luminance objective through a differentiable
Lambertian model) and how the robot gets there (light constraints h1–h3, generalized IK, great-circle
paths, trajectory optimisation, TOPPRA timing, independent verification, Meshcat preview)::

    import optlight
    plan = optlight.solve("default")       # a problem file path or a built-in name
    plan.save("results/default")

The heavy parts (CasADi, pinocchio, meshcat) are imported on first use of the names that need them.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from optlight.errors import (
    OptlightError,
    OutputError,
    ProblemError,
    RobotError,
    SolverError,
    UnreachableError,
    VerificationError,
)
from optlight.geometry import LightSphere
from optlight.spec import Problem, available_problems, load_problem, problem_from_dict

if TYPE_CHECKING:  # the same names as _LAZY (tests/test_structure.py checks they agree)
    from optlight.acquisition import Acquisition, acquire
    from optlight.batch import BatchResult, run_batch
    from optlight.capture import ModelCamera
    from optlight.capture.calibration import calibrate
    from optlight.capture.folder import FolderCamera
    from optlight.capture.mitsuba import MitsubaCamera
    from optlight.cell import CellResult, design_cell
    from optlight.motion import Exposure, Trajectory
    from optlight.objectives import Objective
    from optlight.photometric_stereo import NormalRecovery, recover_normals
    from optlight.pipeline import solve
    from optlight.plan import Plan
    from optlight.planning.flying import flying_timing
    from optlight.planning.landmarks import Landmark, LandmarkSet, find_landmarks
    from optlight.planning.lightsets import LightSetResult, design_light_set
    from optlight.planning.policy import Reacher
    from optlight.planning.reach import ReachabilityMap, reachability_map
    from optlight.planning.timing import time_parameterize
    from optlight.planning.waypoints import Waypoints, controller_waypoints
    from optlight.random_cells import RandomCell, random_cell
    from optlight.report import FigureDrafts
    from optlight.robot import Dynamics, IKResult, Lamp, Robot, generalized_ik, load_robot
    from optlight.scene import Camera, Scene
    from optlight.setup import Setup
    from optlight.simulation import SimulationReport, simulate_folder
    from optlight.verify import VerificationReport, verify_trajectory
    from optlight.viz.drawing import FigureWorker
    from optlight.viz.images import save_gray_png
    from optlight.viz.preview import Preview
    from optlight.workcell import ImageCosts, Workcell

__version__ = "0.1.0"

#: The public names imported on first use, and the module that defines each.
_LAZY = {
    "Camera": "optlight.scene",
    "Scene": "optlight.scene",
    "Objective": "optlight.objectives",
    "Setup": "optlight.setup",
    "Workcell": "optlight.workcell",
    "ImageCosts": "optlight.workcell",
    "LightSetResult": "optlight.planning.lightsets",
    "design_light_set": "optlight.planning.lightsets",
    "NormalRecovery": "optlight.photometric_stereo",
    "recover_normals": "optlight.photometric_stereo",
    "Landmark": "optlight.planning.landmarks",
    "LandmarkSet": "optlight.planning.landmarks",
    "find_landmarks": "optlight.planning.landmarks",
    "Robot": "optlight.robot",
    "IKResult": "optlight.robot",
    "load_robot": "optlight.robot",
    "generalized_ik": "optlight.robot",
    "Reacher": "optlight.planning.policy",
    "ReachabilityMap": "optlight.planning.reach",
    "reachability_map": "optlight.planning.reach",
    "Trajectory": "optlight.motion",
    "Exposure": "optlight.motion",
    "flying_timing": "optlight.planning.flying",
    "time_parameterize": "optlight.planning.timing",
    "Waypoints": "optlight.planning.waypoints",
    "controller_waypoints": "optlight.planning.waypoints",
    "Dynamics": "optlight.robot",
    "Lamp": "optlight.robot",
    "SimulationReport": "optlight.simulation",
    "simulate_folder": "optlight.simulation",
    "VerificationReport": "optlight.verify",
    "verify_trajectory": "optlight.verify",
    "Plan": "optlight.plan",
    "solve": "optlight.pipeline",
    "Preview": "optlight.viz.preview",
    "FigureWorker": "optlight.viz.drawing",
    "FigureDrafts": "optlight.report",
    "save_gray_png": "optlight.viz.images",
    "acquire": "optlight.acquisition",
    "Acquisition": "optlight.acquisition",
    "ModelCamera": "optlight.capture",
    "MitsubaCamera": "optlight.capture.mitsuba",
    "FolderCamera": "optlight.capture.folder",
    "calibrate": "optlight.capture.calibration",
    "BatchResult": "optlight.batch",
    "run_batch": "optlight.batch",
    "CellResult": "optlight.cell",
    "design_cell": "optlight.cell",
    "RandomCell": "optlight.random_cells",
    "random_cell": "optlight.random_cells",
}


def __getattr__(name: str) -> Any:
    """Import the module that defines ``name`` on first use (PEP 562)."""
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'optlight' has no attribute {name!r}")


#: The public API: the names imported above, then the lazy ones.
__all__ = [
    "LightSphere",
    "OptlightError",
    "OutputError",
    "Problem",
    "ProblemError",
    "RobotError",
    "SolverError",
    "UnreachableError",
    "VerificationError",
    "available_problems",
    "load_problem",
    "problem_from_dict",
    *_LAZY,
]
