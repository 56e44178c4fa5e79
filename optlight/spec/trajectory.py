"""Sections of the motion and the numerics: path, timing and export; solver settings."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from optlight.spec.keys import MAX_ITERATIONS, key


@dataclass(frozen=True)
class TrajectorySpec:
    """How the robot gets there (docs/design.md §6)."""

    order: Literal["azimuth", "tour"] = key(
        "azimuth", "visit the landmarks in azimuth order, or a shorter tour in joint space"
    )
    path: Literal["arc", "free"] = key("arc", "keep the light on great-circle arcs, or only on the sphere")
    knot_spacing_deg: float = key(
        2.0,
        "largest angle between two path knots (finer knots only multiply the trajectory NLP's variables)",
        unit="deg",
        lo=0.1,
        hi=30.0,
    )
    max_step_rad: float = key(0.25, "largest joint step between two knots", unit="rad", lo=0.0, lo_open=True)
    dwell_s: float = key(0.5, "time the light stays still at each landmark (exposure)", unit="s", lo=0.0)
    image_pattern: str = key(
        "img_{index:03d}.png",
        "image file names written into lights.lp and captures.csv: a Python format string of {index} "
        "(0, 1, …) giving distinct names without whitespace, path separators or ..",
    )
    timing: Literal["jerk_limited", "toppra"] = key(
        "jerk_limited",
        "time each segment with continuous acceleration under the jerk limits, or time-optimally with "
        "TOPPRA (acceleration steps)",
    )
    rate_hz: float = key(
        1000.0,
        "controller rate: trajectory.csv is sampled at it (joint_trajectory.yaml holds the waypoints "
        "chosen on its grid), the acceleration continuity is checked at it",
        unit="Hz",
        lo=0.0,
        lo_open=True,
    )
    settle_s: float = key(
        0.2,
        "time from the start of a dwell to the camera trigger (must be shorter than dwell_s)",
        unit="s",
        lo=0.0,
    )
    return_home: bool = key(True, "end the plan back at the start configuration ([robot] start)")
    capture: Literal["stop", "flying"] = key(
        "stop",
        "stop for dwell_s at each landmark and trigger settle_s into the dwell, or pass through every "
        "landmark without stopping, slow enough for blur_deg and blur_mm, triggering when the light is there "
        "(flying needs timing = \"jerk_limited\")",
    )
    exposure_s: float = key(
        0.005,
        "the camera's exposure time: it starts at the trigger after a stop and is centred on it on the fly "
        "(captures.csv gives each exposure's start and end)",
        unit="s",
        lo=0.0,
        lo_open=True,
        hi=1.0,
    )
    blur_deg: float = key(
        0.2,
        "largest angle the light may turn about the object's centre during an exposure (flying captures)",
        unit="deg",
        lo=0.0,
        lo_open=True,
        hi=10.0,
    )
    blur_mm: float = key(
        2.0,
        "largest distance the light may travel during an exposure (flying captures)",
        unit="mm",
        lo=0.0,
        lo_open=True,
        hi=100.0,
    )


@dataclass(frozen=True)
class SolverSpec:
    """Numerical settings shared by the NLPs and the IK."""

    max_iter: int = key(
        300, "IPOPT iteration limit (a higher cap only delays the report of an NLP that does not converge)",
        lo=1, hi=MAX_ITERATIONS,
    )
    tol: float = key(1e-8, "IPOPT tolerance", lo=0.0, lo_open=True)
    ik_damping: float = key(1e-6, "damping λ² of the pseudoinverse J# = Jᵀ(JJᵀ + λ²I)⁻¹", lo=0.0)
    ik_max_iter: int = key(
        200, "generalized IK iteration limit (a higher cap only delays the report of an unreachable pose)",
        lo=1, hi=MAX_ITERATIONS,
    )
    ik_tol: float = key(1e-9, "generalized IK residual tolerance (squared norm)", lo=0.0, lo_open=True)
    ik_max_step_rad: float = key(
        0.8, "largest joint change in one generalized IK iteration", unit="rad", lo=0.0, lo_open=True
    )
    ik_joint_limit_gain: float = key(
        0.05, "null-space gain of joint-limit avoidance in the generalized IK (0 = off)", lo=0.0
    )
    ik_manipulability_gain: float = key(
        0.0, "null-space gain of manipulability (−log w) in the generalized IK (0 = off)", lo=0.0
    )
    ik_posture_gain: float = key(
        0.0,
        "null-space gain of the posture task (towards the reference) in the generalized IK (0 = off)",
        lo=0.0,
    )
    verbose: bool = key(False, "print solver output")
