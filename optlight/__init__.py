"""optlight: camera-driven robotic light source positioning.

Where the light should go (landmarks that minimise a luminance objective through a differentiable
Lambertian model) and how the robot gets there (light constraints h1–h3, generalized IK, great-circle
paths, trajectory optimisation, TOPPRA timing, independent verification, Meshcat preview).
"""

from optlight.errors import (
    OptlightError,
    ProblemError,
    RobotError,
    SolverError,
    UnreachableError,
    VerificationError,
)
from optlight.geometry import LightSphere
from optlight.scene.camera import Camera
from optlight.spec import Problem, available_problems, load_problem

__version__ = "0.1.0"

__all__ = [
    "Camera",
    "LightSphere",
    "OptlightError",
    "Problem",
    "ProblemError",
    "RobotError",
    "SolverError",
    "UnreachableError",
    "VerificationError",
    "available_problems",
    "load_problem",
]
