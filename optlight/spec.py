"""Problem files: TOML -> validated, typed, immutable dataclasses.

A problem file is data. Every key is declared once, here, with its type, unit, default, allowed
range and a one-line description; :func:`load_problem` checks a file against these declarations and
``python -m optlight.spec`` writes the reference (``docs/problems.md``) from them, so the code and
the documentation cannot drift apart.

Conventions (docs/design.md §2): metres and degrees in files (keys end in ``_m`` / ``_deg``), radians in
code. Paths inside a file are relative to that file.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from optlight.errors import ProblemError

Vec3 = tuple[float, float, float]

#: Robots that load by name (example-robot-data); :mod:`optlight.robot.catalogue` has their details.
ROBOT_NAMES: tuple[str, ...] = ("panda", "ur3", "ur5", "ur10", "xarm7", "kinova", "z1")

#: Largest seed of a random generator: NumPy's and Mitsuba's (a 32-bit sample seed, offset per capture).
SEED_MAX = 2**31 - 1
#: Largest IPOPT or generalized-IK iteration cap: one unreachable pose at 10⁴ IK iterations already
#: costs a second, and a plan solves hundreds of them.
MAX_ITERATIONS = 10_000
#: Camera responses ``[world] gamma`` may have: real ones are 1–2.4; at 1/10 or 10 every capture is all
#: but black or white.
GAMMA_RANGE = (0.1, 10.0)

#: Folder of the built-in problem files and their data, shipped inside the package (the
#: repository's top-level ``problems/`` points here).
PROBLEMS_DIR = Path(__file__).resolve().parent / "problems"


def key(
    default: Any,
    doc: str,
    *,
    unit: str = "",
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
) -> Any:
    """Declare a problem-file key: default, one-line doc, unit and closed (or left-open) range."""
    meta = {"doc": doc, "unit": unit, "lo": lo, "hi": hi, "lo_open": lo_open}
    if isinstance(default, list | dict) or dataclasses.is_dataclass(default):
        value = default
        return field(default_factory=lambda: value, metadata=meta)
    return field(default=default, metadata=meta)


def section(cls: type, doc: str) -> Any:
    """Declare a nested table whose keys all have defaults."""
    return field(default_factory=cls, metadata={"doc": doc})


# --------------------------------------------------------------------------------------------
# Sections
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FaceSpec:
    """The procedural face (object kind "face"): a head-sized relief, mirror-symmetric."""

    height_m: float = key(0.22, "chin-to-forehead height of the face", unit="m", lo=0.02, lo_open=True)
    nose_m: float = key(0.028, "how far the nose tip stands out of the face", unit="m", lo=0.0)
    brow_m: float = key(0.010, "height of the brow ridges", unit="m", lo=0.0)
    eye_depth_m: float = key(0.014, "depth of the eye sockets", unit="m", lo=0.0)
    lip_m: float = key(0.008, "how far the lips stand out", unit="m", lo=0.0)
    cheek_m: float = key(0.010, "fullness of the cheeks", unit="m", lo=0.0)
    skin_albedo: float = key(0.75, "albedo of the skin", lo=0.0, hi=1.0)
    brow_albedo: float = key(0.25, "albedo of the eyebrows", lo=0.0, hi=1.0)
    lip_albedo: float = key(0.45, "albedo of the lips", lo=0.0, hi=1.0)
    resolution: int = key(160, "vertices along each side of the face grid", lo=16, hi=1024)


@dataclass(frozen=True)
class ObjectSpec:
    """The observed object. Its frame is the light-sphere frame S at the centre O: +z towards the
    camera, +y up (docs/design.md §2), so a mesh's front is its +z side and its top is +y."""

    kind: Literal["face", "sphere", "mesh"] = key("face", "what the camera looks at")
    center_m: Vec3 = key((0.5, 0.0, 0.4), "object centre O in the world frame", unit="m")
    radius_m: float = key(0.1, "sphere radius (kind = sphere)", unit="m", lo=0.0, lo_open=True)
    path: str | None = key(None, "mesh file trimesh reads: OBJ, PLY, STL, GLB (kind = mesh)")
    scale: float = key(1.0, "factor from mesh units to metres (kind = mesh)", lo=0.0, lo_open=True)
    albedo: float = key(0.8, "albedo where the mesh has no vertex colours (sphere, mesh)", lo=0.0, hi=1.0)
    face: FaceSpec = section(FaceSpec, "procedural face parameters (kind = face)")


@dataclass(frozen=True)
class CameraSpec:
    """Pinhole camera, OpenCV axes (z forward, y down), placed by position and look-at point."""

    position_m: Vec3 = key((-0.151, 0.376, 0.674), "camera centre in the world frame", unit="m")
    look_at_m: Vec3 | None = key(
        None, "point the optical axis passes through (default: object centre)", unit="m"
    )
    width: int = key(256, "image width", unit="px", lo=1, hi=8192)
    height: int = key(256, "image height", unit="px", lo=1, hi=8192)
    fov_deg: float = key(
        20.0,
        "vertical field of view, used where fy_px is not given",
        unit="deg",
        lo=0.0,
        hi=170.0,
        lo_open=True,
    )
    fx_px: float | None = key(
        None, "focal length along x (default: from fov_deg)", unit="px", lo=0.0, lo_open=True
    )
    fy_px: float | None = key(
        None, "focal length along y (default: from fov_deg)", unit="px", lo=0.0, lo_open=True
    )
    cx_px: float | None = key(None, "principal point x (default: image centre)", unit="px")
    cy_px: float | None = key(None, "principal point y (default: image centre)", unit="px")


@dataclass(frozen=True)
class LightSphereSpec:
    """The sphere the light moves on: centre O, radius b, zenith 0 = towards the camera."""

    radius_m: float = key(0.40, "radius b of the light sphere", unit="m", lo=0.0, lo_open=True)
    zenith_min_deg: float = key(
        0.0, "smallest allowed zenith (angle from the camera axis)", unit="deg", lo=0.0, hi=90.0
    )
    zenith_max_deg: float = key(60.0, "largest allowed zenith", unit="deg", lo=0.0, hi=90.0)


@dataclass(frozen=True)
class LightSpec:
    """Lambertian light model (docs/design.md §4): I = clip(gain·ρ(E·v·max(0, n·l)·falloff + ambient))."""

    model: Literal["directional", "point"] = key(
        "directional", "directional light, or point light with (b/r)² falloff"
    )
    power: float = key(1.0, "light power E (irradiance at the sphere radius)", lo=0.0)
    ambient: float = key(0.05, "ambient term k_amb", lo=0.0)
    gain: float = key(1.0, "camera gain g", lo=0.0, lo_open=True)
    saturation: float = key(1.0, "pixel value where the sensor saturates (clip level)", lo=0.0, lo_open=True)
    cast_shadows: bool = key(True, "trace shadow rays (the differentiable model uses them as a fixed mask)")
    noise_std: float = key(0.0, "standard deviation of additive Gaussian sensor noise", lo=0.0)
    seed: int = key(0, "seed of the sensor noise", lo=0, hi=SEED_MAX)
    softplus_sharpness: float = key(
        60.0, "β of the smooth max(0, n·l) in the differentiable model", lo=0.0, lo_open=True
    )
    clip_sharpness: float = key(
        60.0, "sharpness of the smooth saturation clip in the differentiable model", lo=0.0, lo_open=True
    )
    housing: Literal["cylinder", "sphere"] = key(
        "cylinder",
        "shape of the light's housing behind its emitting face (the exact view check casts rays against it)",
    )
    housing_radius_m: float = key(
        0.03, "radius of the light housing (a small LED head)", unit="m", lo=0.0, lo_open=True
    )
    housing_length_m: float = key(
        0.06, "length of a cylindrical housing along the light's −z", unit="m", lo=0.0, lo_open=True
    )
    mass_kg: float = key(
        0.3,
        "mass of the lamp the flange carries, for the joint torques (default: a small LED head, assumed "
        "0.3 kg for an LED, its heat sink and driver in the 60 mm housing; weigh yours)",
        unit="kg",
        lo=0.0,
    )
    com_m: Vec3 = key(
        (0.0, 0.0, 0.04),
        "the lamp's centre of mass in the flange frame (default: assumed 0.04 m out along the tool axis, "
        "the middle of a lamp that long; its rotational inertia is a solid cylinder of the housing's size)",
        unit="m",
    )


@dataclass(frozen=True)
class RobotSpec:
    """The arm that carries the light. A named robot comes from example-robot-data."""

    name: str = key(
        "panda", "robot name (panda, ur3, ur5, ur10, xarm7, kinova, z1), or a label when urdf is set"
    )
    urdf: str | None = key(
        None,
        "path of a user URDF instead of a named robot; its package://NAME/… meshes are looked up as "
        "ROS does: a folder NAME (or one holding NAME/package.xml) in the URDF's folder or any folder "
        "above it, then in each folder of the ROS_PACKAGE_PATH environment variable",
    )
    frame: str | None = key(None, "flange frame the light is attached to (default: the robot's tool frame)")
    base_position_m: Vec3 = key((0.0, 0.0, 0.0), "robot base position in the world frame", unit="m")
    base_rpy_deg: Vec3 = key((0.0, 0.0, 0.0), "robot base roll, pitch, yaw in the world frame", unit="deg")
    light_offset_m: Vec3 = key((0.0, 0.0, 0.0), "light frame origin in the flange frame", unit="m")
    light_rpy_deg: Vec3 = key(
        (0.0, 0.0, 0.0), "light frame roll, pitch, yaw in the flange frame (light emits along +z)", unit="deg"
    )
    acceleration_limit: float | tuple[float, ...] | None = key(
        None,
        "joint acceleration limit: one for all joints or a list per joint (default: per robot)",
        unit="rad/s²",
        lo=0.0,
        lo_open=True,
    )
    jerk_limit: float | tuple[float, ...] | None = key(
        None,
        "joint jerk limit: one for all joints or a list per joint (default: per robot)",
        unit="rad/s³",
        lo=0.0,
        lo_open=True,
    )
    velocity_scale: float = key(
        1.0, "fraction of the URDF velocity limits the plan may use", lo=0.0, hi=1.0, lo_open=True
    )
    start: str | tuple[float, ...] | None = key(
        None,
        "where the robot is when the plan starts: joint angles (rad, one per joint) or the name of an SRDF "
        "configuration (default: the robot's reference configuration, its SRDF ready/default pose; when "
        "that is not clear of the environment, the clear configuration nearest it, named in a warning)",
    )


@dataclass(frozen=True)
class TermSpec:
    """One weighted term of the luminance objective."""

    kind: Literal["histogram", "image", "mean", "contrast", "saturation", "shadow"] = key(
        "histogram",
        "histogram distance, image difference, mean or contrast target, saturated or shadowed fraction",
    )
    weight: float = key(1.0, "weight of the term in the sum", lo=0.0)
    distance: Literal["l2", "chi2", "emd", "emd2"] = key("emd2", "histogram distance (kind = histogram)")
    target: float | None = key(None, "target mean or standard deviation (kind = mean or contrast)", lo=0.0)
    level: float | None = key(
        None,
        "normalised luminance where a pixel counts as saturated or shadowed (default 0.98, 0.05)",
        lo=0.0,
        hi=1.0,
    )
    softness: float = key(
        0.01, "width τ of the sigmoid of the saturated or shadowed fraction", lo=0.0, lo_open=True
    )


@dataclass(frozen=True)
class ReferenceSpec:
    """What the image is compared with."""

    kind: Literal["light", "image", "bins"] = key(
        "light", "render at a reference light, read an image, or take given bins"
    )
    zenith_deg: float = key(
        10.0, "reference light zenith (kind = light; the paper uses 10°)", unit="deg", lo=0.0, hi=90.0
    )
    azimuth_deg: float = key(0.0, "reference light azimuth (kind = light)", unit="deg")
    image: str | None = key(None, "reference image, PNG or NPY (kind = image)")
    mask: str | None = key(None, "mask image of the pixels to compare, non-zero = used (kind = image)")
    resize: bool = key(
        False,
        "resize an image or mask of another size than the camera's to it (bilinear; nearest for the mask); "
        "false: such a file is refused",
    )
    bins: tuple[float, ...] | None = key(
        None, "reference histogram (kind = bins), renormalised to sum 1", lo=0.0
    )


@dataclass(frozen=True)
class ObjectiveSpec:
    """The luminance objective: a weighted sum of terms against one reference."""

    terms: tuple[TermSpec, ...] = key((TermSpec(),), "the terms, as [[objective.terms]] tables")
    bins: int = key(32, "number K of histogram bins on [0, 1]", lo=2, hi=1024)
    sigma_bins: float = key(
        1.0, "Gaussian kernel σ of the soft histogram, in bin widths", lo=0.0, lo_open=True
    )
    reference: ReferenceSpec = section(ReferenceSpec, "the reference")


@dataclass(frozen=True)
class LandmarksSpec:
    """Where the light should go (paper, Section 4)."""

    mode: Literal["azimuth", "free"] = key(
        "azimuth", "best zenith per equally spaced azimuth, or the best positions on the cap"
    )
    count: int = key(
        36,
        "number M of landmarks searched (azimuths, or free positions); landmarks within distinct_deg of "
        "each other are one capture, so a plan can have fewer captures than count",
        lo=1,
        hi=720,
    )
    min_separation_deg: float = key(
        10.0, "smallest angle between two landmarks (mode = free)", unit="deg", lo=0.0
    )
    sweep_step_deg: float = key(
        2.0,
        "zenith step of the coarse sweep that seeds the refinement (a finer sweep only multiplies the renders)",
        unit="deg",
        lo=0.1,
        hi=45.0,
    )
    seeds: int = key(3, "sweep minima refined by IPOPT per azimuth", lo=1, hi=50)
    resolution: int = key(
        64,
        "longer image side of the search renders (the camera's when smaller); reported costs use the camera's",
        unit="px",
        lo=8,
        hi=8192,
    )
    allow_partial: bool = key(False, "drop unreachable landmarks with a warning instead of failing")
    distinct_deg: float = key(
        0.5,
        "landmarks closer than this angle are one capture (the same image): the lower-cost one is kept",
        unit="deg",
        lo=0.0,
    )


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


@dataclass(frozen=True)
class BoxSpec:
    """A box obstacle: centre, edge lengths along its own axes, orientation."""

    name: str = key("box", "name in reports (unique in the environment)")
    center_m: Vec3 = key((0.0, 0.0, 0.0), "box centre in the world frame", unit="m")
    size_m: Vec3 = key(
        (0.1, 0.1, 0.1), "edge lengths along the box's x, y, z axes", unit="m", lo=0.0, lo_open=True
    )
    rpy_deg: Vec3 = key((0.0, 0.0, 0.0), "roll, pitch, yaw of the box axes in the world frame", unit="deg")


@dataclass(frozen=True)
class CylinderSpec:
    """A cylinder obstacle: axis along its own z, centred at ``center_m``."""

    name: str = key("cylinder", "name in reports (unique in the environment)")
    center_m: Vec3 = key((0.0, 0.0, 0.0), "cylinder centre (middle of its axis) in the world frame", unit="m")
    radius_m: float = key(0.05, "cylinder radius", unit="m", lo=0.0, lo_open=True)
    length_m: float = key(0.3, "cylinder length along its axis", unit="m", lo=0.0, lo_open=True)
    rpy_deg: Vec3 = key(
        (0.0, 0.0, 0.0), "roll, pitch, yaw of the cylinder axes in the world frame (axis = z)", unit="deg"
    )


@dataclass(frozen=True)
class SphereSpec:
    """A sphere obstacle."""

    name: str = key("sphere", "name in reports (unique in the environment)")
    center_m: Vec3 = key((0.0, 0.0, 0.0), "sphere centre in the world frame", unit="m")
    radius_m: float = key(0.05, "sphere radius", unit="m", lo=0.0, lo_open=True)


@dataclass(frozen=True)
class EnvironmentSpec:
    """What surrounds the robot: a table, the camera body and stand, the object's bounding sphere,
    extra boxes, cylinders and spheres; the robot's own links. Off by default: with
    ``enabled = false`` none of it is modelled, constrained or checked (the camera's view is
    ``[view]``'s, on by default)."""

    enabled: bool = key(False, "model the environment: clearance constraints and exact checks")
    margin_m: float = key(
        0.01, "smallest allowed distance between the robot (light included) and an obstacle", unit="m", lo=0.0
    )
    self_margin_m: float = key(
        0.005, "smallest allowed distance between two robot links that can come close", unit="m", lo=0.0
    )
    table_height_m: float | None = key(
        None, "world z of the table top; everything below it is solid (unset: no table)", unit="m"
    )
    object_radius_m: float | None = key(
        None,
        "radius of the object's bounding sphere around O (default: its farthest point from O)",
        unit="m",
        lo=0.0,
        lo_open=True,
    )
    camera_body: bool = key(True, "the camera body and its stand are obstacles")
    camera_body_size_m: Vec3 = key(
        (0.10, 0.08, 0.12),
        "camera body width, height, depth: a box behind the camera centre, in camera axes",
        unit="m",
        lo=0.0,
        lo_open=True,
    )
    camera_stand_radius_m: float = key(
        0.02,
        "radius of the stand, a vertical cylinder from the body down to the table (or to z = 0)",
        unit="m",
        lo=0.0,
        lo_open=True,
    )
    spheres_per_link: int = key(
        4, "most spheres fitted to one link's collision geometry (the NLPs' approximation)", lo=1, hi=16
    )
    boxes: tuple[BoxSpec, ...] = key((), "box obstacles, as [[environment.boxes]] tables")
    cylinders: tuple[CylinderSpec, ...] = key((), "cylinder obstacles, as [[environment.cylinders]] tables")
    spheres: tuple[SphereSpec, ...] = key((), "sphere obstacles, as [[environment.spheres]] tables")


@dataclass(frozen=True)
class ViewSpec:
    """The camera's view of the object: the cone from the camera centre to the object's bounding
    sphere (half-angle asin(R/d) + ``margin_deg``). No robot link and no part of the light housing
    may enter it, and the beam from the light to the object must be clear of the robot: at every
    capture (default), along the whole motion, or not at all (``off``: the report says so first)."""

    mode: Literal["capture", "path", "off"] = key(
        "capture", "keep the view clear at every capture, along the whole motion, or not at all"
    )
    margin_deg: float = key(1.0, "added to the view cone's half-angle asin(R/d)", unit="deg", lo=0.0, hi=30.0)


@dataclass(frozen=True)
class LightSetSpec:
    """A set of N lights scored together (docs/design.md §10) instead of landmarks matched one by one:
    photometric stereo (the expected normal error of the set), RTI (even coverage of the cap) or a
    given grid (a face database's directions, each mapped to the nearest allowed light). Off
    (kind = "none") by default."""

    kind: Literal["none", "photometric_stereo", "rti", "grid"] = key(
        "none",
        "no light set (the landmarks of [landmarks]), a photometric-stereo set, an RTI dome, or a grid",
    )
    count: int = key(12, "number N of lights (photometric_stereo: at least 3; rti: at least 2)", lo=1, hi=720)
    starts: int = key(8, "random starts of the set design, uniform on the cap", lo=1, hi=1000)
    seed: int = key(0, "seed of the random starts", lo=0, hi=SEED_MAX)
    regularization: float = key(
        1e-2,
        "ε of the per-pixel M + εI (photometric_stereo): a pixel lit by fewer than 3 lights costs ~1/ε",
        lo=0.0,
        lo_open=True,
    )
    saturation_level: float = key(
        0.98,
        "normalised luminance from which a pixel counts as saturated (its light is not used)",
        lo=0.0,
        hi=1.0,
        lo_open=True,
    )
    dark_level: float = key(
        0.02,
        "normalised luminance (ambient removed) below which a pixel counts as shadowed in normal recovery",
        lo=0.0,
        hi=1.0,
    )
    softness: float = key(0.01, "width τ of the saturation sigmoid in the set cost", lo=0.0, lo_open=True)
    riesz_exponent: float = key(
        4.0, "exponent s of the Riesz energy (rti); s > 2 spreads the lights evenly", lo=0.0, lo_open=True
    )
    image_weight: float = key(
        0.0,
        "weight of the [objective] image objective, averaged over the set's lights, added to the set cost",
        lo=0.0,
    )
    grid_file: str | None = key(
        None,
        "CSV of the grid (kind = grid): columns azimuth_deg, elevation_deg relative to the camera axis "
        "[, name]; default: the 64 Yale B directions shipped with optlight",
    )
    grid_deg: tuple[tuple[float, float], ...] | None = key(
        None,
        "the grid as [azimuth_deg, elevation_deg] pairs relative to the camera axis (kind = grid)",
        unit="deg",
    )
    grid_outside_cap: Literal["replace", "error"] = key(
        "replace", "grid directions off the cap: replace by the nearest allowed light, or refuse the file"
    )
    design_over: Literal["reachable", "cap"] = key(
        "reachable",
        "map where the robot reaches the light clear first (a reachability map of the cap) and design "
        "photometric_stereo and rti sets over those lights (a grid's replacements start from the map too), "
        "or design on the whole allowed cap (lights the robot cannot reach are then replaced one by one)",
    )
    reach_step_deg: float = key(
        5.0,
        "zenith step of that reachability map (its azimuth step is twice this)",
        unit="deg",
        lo=1.0,
        hi=30.0,
    )
    candidate_spacing_deg: float = key(
        2.0,
        "spacing of the candidate lights a grid direction may be replaced by (their count grows as its "
        "inverse square)",
        unit="deg",
        lo=0.5,
        hi=30.0,
    )


@dataclass(frozen=True)
class WorldSpec:
    """How the real scene differs from the model (docs/design.md §11): what the model and physically based
    cameras of the camera-in-the-loop capture (:mod:`optlight.capture`), never what the planner
    assumes. Every default is the model itself (a Lambertian object, the exact light, no
    inter-reflection, a linear camera without noise)."""

    power_scale: float = key(
        1.0,
        "real light power over the model's light.power (0 would leave every capture unlit)",
        lo=0.0,
        lo_open=True,
    )
    ambient: float | None = key(None, "real ambient k_amb (default: the model's light.ambient)", lo=0.0)
    albedo_scale: float = key(
        1.0, "factor on the model's albedo (0 would make every capture black)", lo=0.0, lo_open=True
    )
    albedo_texture: float = key(
        0.0, "relative amplitude of a multiplicative albedo texture, 1 + t·sin·sin·sin of the position", lo=0.0, hi=1.0
    )
    texture_period_m: float = key(0.04, "period of the albedo texture", unit="m", lo=0.0, lo_open=True)
    bsdf: Literal["lambertian", "roughplastic", "principled"] = key(
        "lambertian", "reflectance of the real surface (the physically based camera; the model camera is Lambertian)"
    )
    roughness: float = key(0.3, "surface roughness (roughplastic α, principled roughness)", lo=0.0, hi=1.0, lo_open=True)
    specular: float = key(
        0.5, "specular strength (roughplastic specular reflectance, principled specular)", lo=0.0, hi=1.0
    )
    light_offset_m: Vec3 = key(
        (0.0, 0.0, 0.0),
        "where the real light is, relative to where the robot puts it (world frame); shorter than the light "
        "sphere's radius",
        unit="m",
    )
    light_radius_m: float = key(
        0.0, "radius of the real light's emitting area (0: a point; the physically based camera)", unit="m", lo=0.0
    )
    light_profile: Literal["isotropic", "lambertian", "spot"] = key(
        "isotropic",
        "angular emission: the same in every direction (point, sphere), cos of the angle to the light's axis "
        "(a disk facing the object), or a spot beam (point)",
    )
    spot_cutoff_deg: float = key(
        40.0, "half-angle where the spot beam ends (light_profile = spot)", unit="deg", lo=0.0, hi=90.0, lo_open=True
    )
    gamma: float = key(
        1.0,
        "camera response: recorded value s·(I/s)^(1/gamma) (beyond the range every capture is nearly "
        "black or white)",
        lo=GAMMA_RANGE[0],
        hi=GAMMA_RANGE[1],
    )
    noise_std: float = key(
        0.0, "sensor noise σ, pixel units, added before the response (at most light.saturation)", lo=0.0
    )
    seed: int = key(
        0, "seed of the sensor noise and of the physically based camera's samples", lo=0, hi=SEED_MAX
    )
    bounces: int = key(
        1, "light bounces the physically based camera traces (1: direct light only; more: inter-reflections)", lo=1, hi=32
    )
    spp: int = key(64, "samples per pixel of the physically based camera", lo=1, hi=65536)


@dataclass(frozen=True)
class LoopSpec:
    """The camera in the loop (docs/design.md §11): plan, capture at the landmarks, calibrate the model from
    the captures, re-plan on the calibrated model, until the measured objective stops improving."""

    iterations: int = key(4, "most plan-capture-calibrate rounds (the first is the open-loop plan)", lo=1, hi=50)
    tolerance: float = key(
        0.02, "relative decrease of the measured objective below which the loop stops", lo=0.0, hi=1.0
    )
    normals: Literal["model", "photometric_stereo"] = key(
        "model",
        "normals of the calibrated model: the mesh's, or photometric stereo's where 3 or more lights light a pixel",
    )
    saturation_level: float = key(
        0.98, "normalised camera value from which a pixel counts as saturated (left out of the fit)", lo=0.0, hi=1.0,
        lo_open=True,
    )
    dark_level: float = key(
        0.02, "normalised camera value below which a whole capture counts as black (its 99th percentile)", lo=0.0, hi=1.0
    )
    max_saturated_fraction: float = key(
        0.5, "a capture with more of its object pixels saturated is left out of the calibration", lo=0.0, hi=1.0,
        lo_open=True,
    )
    min_cosine: float = key(
        0.1, "smallest modelled shading v·max(0, n·l) of a lit pixel in the fit; dimmer lit pixels (shadow edges) are left out",
        lo=0.0, hi=1.0,
    )
    specular_mad: float = key(
        3.0, "pixels brighter than the fit by more than this many robust deviations (MAD) count as specular", lo=0.0,
        lo_open=True,
    )
    servo_steps: int = key(8, "captures of the local photometric servo", lo=1, hi=1000)
    servo_step_deg: float = key(
        4.0, "first step of the photometric servo along the light sphere", unit="deg", lo=0.0, hi=45.0, lo_open=True
    )


@dataclass(frozen=True)
class Problem:
    """A whole light-positioning problem."""

    description: str = key("", "one line that says what the problem is")
    object: ObjectSpec = section(ObjectSpec, "the observed object")
    camera: CameraSpec = section(CameraSpec, "the fixed camera")
    light_sphere: LightSphereSpec = section(LightSphereSpec, "where the light may be")
    light: LightSpec = section(LightSpec, "the light and image model")
    robot: RobotSpec = section(RobotSpec, "the robot carrying the light")
    objective: ObjectiveSpec = section(ObjectiveSpec, "what a good image is")
    landmarks: LandmarksSpec = section(LandmarksSpec, "the landmark search")
    trajectory: TrajectorySpec = section(TrajectorySpec, "path, timing and export")
    solver: SolverSpec = section(SolverSpec, "numerical settings")
    environment: EnvironmentSpec = section(EnvironmentSpec, "obstacles, self-collision, the camera's view")
    lightset: LightSetSpec = section(LightSetSpec, "lights designed as a set (photometric stereo, RTI, grid)")
    view: ViewSpec = section(ViewSpec, "the camera's view of the object, kept clear of the robot and the light")
    world: WorldSpec = section(WorldSpec, "how the real scene differs from the model (the cameras in the loop)")
    loop: LoopSpec = section(LoopSpec, "the camera in the loop: capture, calibrate, re-plan")
    source: Path | None = field(default=None, compare=False, metadata={"internal": True})

    @property
    def name(self) -> str:
        """The problem's name: its file stem, or "inline"."""
        return self.source.stem if self.source else "inline"

    def resolve(self, relative: str) -> Path:
        """A path written in the problem file, made absolute against the file's folder."""
        path = Path(relative).expanduser()
        if path.is_absolute() or self.source is None:
            return path
        return (self.source.parent / path).resolve()

    def to_dict(self) -> dict[str, Any]:
        """The problem as plain data (for plan.json): every set key, defaults included."""
        return _to_plain(self)


# --------------------------------------------------------------------------------------------
# What a run will need: image names, memory
# --------------------------------------------------------------------------------------------


def image_names(pattern: str, count: int) -> list[str]:
    """``pattern.format(index=i)`` for i = 0 … count−1; names must be distinct and free of whitespace
    (lights.lp separates fields by spaces), and each a file name in the dataset's own folder (no path
    separator, no ``..``). Raises ValueError saying what is wrong."""
    try:
        names = [pattern.format(index=i) for i in range(count)]
    except (KeyError, IndexError, ValueError, AttributeError, TypeError) as e:
        raise ValueError(f"image pattern {pattern!r} must format with only {{index}} ({e!r})") from None
    if len(set(names)) != len(names):
        raise ValueError(f"image pattern {pattern!r} gives repeated names; use {{index}}")
    bad = [n for n in names if not n or any(c.isspace() for c in n)]
    if bad:
        raise ValueError(f"image names may not be empty or contain whitespace (.lp format): {bad[0]!r}")
    outside = [n for n in names if any(c in n for c in "/\\") or ".." in n or n.startswith("~")]
    if outside:
        raise ValueError(
            f"an image name is a file in the dataset's folder, without / \\ or ..: {outside[0]!r}"
        )
    return names


#: Peak memory of a solve: a fixed part (the libraries, the robot, the NLPs; ~250 MB over the
#: imports) plus a part per object pixel at the camera's resolution (rays, G-buffer, images). Whole
#: solves of the default problem grow by ~80 bytes per pixel at 128²–320² and by up to ~800 at
#: 256²–1024²; the constant keeps the larger (temporaries of the G-buffer's rays grow with the
#: image). The soft histogram adds almost nothing per pixel and bin: its NumPy kernel runs in chunks
#: of fixed size (~1 byte per pixel and bin, 32 → 128 bins at 320²).
#: Every image pixel is counted as an object pixel, since the object may fill the image.
MEMORY_BASE_BYTES = 600e6
MEMORY_BYTES_PER_PIXEL = 1200.0
#: Fraction of the available memory a run may plan to use (the rest: other processes, estimate error).
MEMORY_SAFETY = 0.8


def estimated_peak_memory(problem: Problem) -> float:
    """Bytes a solve of ``problem`` is expected to hold at its peak (see :data:`MEMORY_BASE_BYTES`):
    base + W·H·per pixel."""
    return MEMORY_BASE_BYTES + problem.camera.width * problem.camera.height * MEMORY_BYTES_PER_PIXEL


def available_memory() -> float | None:
    """Bytes of memory a new allocation can get without swapping: MemAvailable from /proc/meminfo
    (Linux), else the free physical pages (``os.sysconf``); None where neither is known."""
    import os

    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def check_memory(problem: Problem) -> None:
    """Raise :class:`ProblemError` (key ``camera.width``) when the solve's estimated peak memory
    (:func:`estimated_peak_memory`) exceeds :data:`MEMORY_SAFETY` of the memory available now;
    unchecked where that is unknown. A check of this machine, not of the file: it runs where the
    problem is built (:class:`optlight.setup.Setup`), not when the file is loaded, so a problem
    loaded on one machine can be solved on another with more memory."""
    available = available_memory()
    need = estimated_peak_memory(problem)
    if available is None or need <= MEMORY_SAFETY * available:
        return
    cam = problem.camera
    raise ProblemError(
        str(problem.source) if problem.source else "<inline>",
        "camera.width",
        f"a camera.width × camera.height image whose solve fits in memory: {cam.width} × {cam.height} "
        f"pixels with {problem.objective.bins} objective.bins needs about {need / 1e9:.1f} GB, "
        f"{available / 1e9:.1f} GB is available; lower camera.width and camera.height",
        cam.width,
    )


#: Bytes a sampled trajectory holds per sample and joint in its largest writer: the text of
#: joint_trajectory.yaml (~210 B per sample and joint measured with 7 joints; trajectory.csv's rows
#: ~175 B, the verification's arrays ~120 B, each one at a time).
SAMPLE_BYTES_PER_JOINT = 250.0


def planned_captures(problem: Problem) -> int:
    """The captures a plan of ``problem`` is planned with: ``[lightset] count`` for a designed set,
    the grid's length for a grid (``grid_deg``'s pairs, a ``grid_file``'s lines that are neither
    blank, comments nor its header; the 64 Yale B directions by default), else ``[landmarks] count``
    (landmarks that merge make fewer)."""
    ls = problem.lightset
    if ls.kind == "grid":
        if ls.grid_deg is not None:
            return len(ls.grid_deg)
        if ls.grid_file is None:
            return 64
        try:
            lines = problem.resolve(ls.grid_file).read_text().splitlines()
        except (OSError, UnicodeDecodeError):
            return 1  # the grid's reader names the file and the key
        return max(sum(1 for s in lines if s.strip() and not s.lstrip().startswith("#")) - 1, 1)
    return ls.count if ls.kind != "none" else problem.landmarks.count


def trajectory_samples_budget(problem: Problem, joints: int) -> float | None:
    """The most samples (:data:`SAMPLE_BYTES_PER_JOINT` × ``joints`` bytes each) the trajectory's
    writers can hold in :data:`MEMORY_SAFETY` of the memory available now, beside the solve's own
    (:func:`estimated_peak_memory`); None where the available memory is unknown."""
    available = available_memory()
    if available is None:
        return None
    free = MEMORY_SAFETY * available - estimated_peak_memory(problem)
    return max(free, 0.0) / (SAMPLE_BYTES_PER_JOINT * joints)


def sample_rate(problem: Problem) -> float:
    """Samples per second of the motion (Hz): ``[trajectory] rate_hz`` for the exports, at least 1 kHz
    for the verification."""
    return max(problem.trajectory.rate_hz, 1000.0)


def least_move_time(
    distance_m: float,
    reach_m: float,
    velocity: np.ndarray,
    acceleration: np.ndarray,
    jerk: np.ndarray | None,
) -> tuple[float, str]:
    """A lower bound (s) of the time of a rest-to-rest move that carries the light ``distance_m``, and
    the key of the limit that sets it (``robot.velocity_scale``, ``robot.acceleration_limit`` or
    ``robot.jerk_limit``).

    The light's speed is at most Σ_j |q̇_j| R (``reach_m`` = R ≥ the distance from any joint axis to
    the light), so d ≤ R Σ_j ∫|q̇_j| dt, and over a move of time T from rest to rest each joint
    travels ∫|q̇_j| dt ≤ v_j T, ≤ a_j T²/4 and, starting and ending with q̈ = 0 (jerk-limited
    timing), ≤ j_j T³/24. Hence T ≥ max(d / (R Σv), 2 √(d / (R Σa)), ∛(24 d / (R Σj)))."""
    x = distance_m / reach_m
    times = {
        "robot.velocity_scale": x / float(np.sum(velocity)),
        "robot.acceleration_limit": 2.0 * math.sqrt(x / float(np.sum(acceleration))),
    }
    if jerk is not None:
        times["robot.jerk_limit"] = (24.0 * x / float(np.sum(jerk))) ** (1.0 / 3.0)
    limit = max(times, key=lambda k: times[k])
    return times[limit], limit


def check_trajectory_size(
    problem: Problem,
    *,
    joints: int,
    reach_m: float,
    velocity: np.ndarray,
    acceleration: np.ndarray,
    jerk: np.ndarray,
    captures: int,
) -> None:
    """Raise :class:`ProblemError` when the sampled trajectory cannot fit in this machine's memory
    (:func:`trajectory_samples_budget`), by a lower estimate of its duration made before any work:
    ``captures`` dwells of ``dwell_s`` and ``captures − 1`` moves between captures at least
    ``[landmarks] distinct_deg`` apart on the light sphere, each at least :func:`least_move_time`
    under the robot's limits (``velocity`` already scaled by ``velocity_scale``). The refusal names the
    key that makes the trajectory too long (``rate_hz``, ``dwell_s`` or a motion limit) and the
    largest (or smallest) value this machine can do. Unchecked where the available memory is unknown.
    Like :func:`check_memory`, a check of this machine, run where the problem is built."""
    budget = trajectory_samples_budget(problem, joints)
    if budget is None:
        return
    traj, rate = problem.trajectory, sample_rate(problem)
    angle = math.radians(problem.landmarks.distinct_deg)
    distance = 2.0 * problem.light_sphere.radius_m * math.sin(angle / 2.0)
    jerk_used = jerk if traj.timing == "jerk_limited" else None
    move, limit = least_move_time(distance, reach_m, velocity, acceleration, jerk_used)
    moves = max(captures - 1, 0)
    dwell = captures * traj.dwell_s
    duration = dwell + moves * move
    if duration * rate <= budget:
        return
    file = str(problem.source) if problem.source else "<inline>"
    need = duration * rate * SAMPLE_BYTES_PER_JOINT * joints
    why = (
        f"a trajectory of at least {duration:.3g} s ({captures} captures × dwell_s {traj.dwell_s:g} s, "
        f"{moves} moves of at least {move:.3g} s) sampled at {rate:g} Hz needs {need / 1e9:.3g} GB for "
        f"its {joints}-joint samples, {budget * SAMPLE_BYTES_PER_JOINT * joints / 1e9:.3g} GB is free here"
    )
    seconds = budget / rate  # the longest trajectory this machine can sample at this rate
    if traj.rate_hz > 1000.0 and duration * 1000.0 <= budget:
        expected = f"a value ≤ {budget / duration:.3g} Hz on this machine: {why}"
        raise ProblemError(file, "trajectory.rate_hz", expected, traj.rate_hz)
    if dwell >= duration - dwell or seconds <= dwell:
        if captures > 0 and seconds > moves * move:
            largest = (seconds - moves * move) / captures
            expected = f"a value ≤ {largest:.3g} s on this machine: {why}"
            raise ProblemError(file, "trajectory.dwell_s", expected, traj.dwell_s)
        raise ProblemError(file, "trajectory.dwell_s", f"a shorter dwell: {why}", traj.dwell_s)
    per_move = (seconds - dwell) / moves  # the time a move may take
    ratio = move / per_move  # > 1: how much faster the moves must be
    value: object
    if limit == "robot.velocity_scale":
        value, smallest = problem.robot.velocity_scale, problem.robot.velocity_scale * ratio
        expected = f"a value ≥ {smallest:.3g} on this machine: {why}"
    elif limit == "robot.acceleration_limit":
        value = problem.robot.acceleration_limit or float(np.max(acceleration))
        fastest = float(np.max(acceleration)) * ratio**2
        expected = (
            f"limits ≥ {ratio**2:.3g} × the present ones ({fastest:.3g} rad/s² on the fastest joint) "
            f"on this machine: {why}"
        )
    else:
        value = problem.robot.jerk_limit or float(np.max(jerk))
        fastest = float(np.max(jerk)) * ratio**3
        expected = (
            f"limits ≥ {ratio**3:.3g} × the present ones ({fastest:.3g} rad/s³ on the fastest joint) "
            f"on this machine: {why}"
        )
    raise ProblemError(file, limit, expected, value)


def check_trajectory_samples(problem: Problem, joints: int, duration: float, dwell: float) -> None:
    """Raise :class:`ProblemError` when a timed trajectory of ``duration`` s (``dwell`` s of them
    dwells) has more samples than this machine can hold (:func:`trajectory_samples_budget`): the
    check, on the trajectory itself, after its timing and before it is sampled, of what
    :func:`check_trajectory_size` estimated. Names ``rate_hz`` when a lower rate would do, else
    ``dwell_s`` or ``velocity_scale`` after the larger of the dwells and the motion."""
    budget = trajectory_samples_budget(problem, joints)
    rate = sample_rate(problem)
    if budget is None or duration * rate <= budget:
        return
    file = str(problem.source) if problem.source else "<inline>"
    traj = problem.trajectory
    per_sample = SAMPLE_BYTES_PER_JOINT * joints
    why = (
        f"the timed trajectory lasts {duration:.4g} s ({duration - dwell:.4g} s moving): "
        f"{duration * rate:.3g} samples at {rate:g} Hz need {duration * rate * per_sample / 1e9:.3g} GB, "
        f"{budget * per_sample / 1e9:.3g} GB is free here"
    )
    if traj.rate_hz > 1000.0 and duration * 1000.0 <= budget:
        expected = f"a value ≤ {budget / duration:.3g} Hz on this machine: {why}"
        raise ProblemError(file, "trajectory.rate_hz", expected, traj.rate_hz)
    if dwell >= duration - dwell:
        raise ProblemError(file, "trajectory.dwell_s", f"a shorter dwell: {why}", traj.dwell_s)
    raise ProblemError(
        file,
        "robot.velocity_scale",
        f"a faster motion (a larger velocity_scale, acceleration_limit or jerk_limit): {why}",
        problem.robot.velocity_scale,
    )


# --------------------------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------------------------


def available_problems() -> dict[str, str]:
    """Built-in problem names mapped to their one-line descriptions."""
    out = {}
    for path in sorted(PROBLEMS_DIR.glob("*.toml")):
        try:
            with path.open("rb") as f:
                out[path.stem] = str(tomllib.load(f).get("description", ""))
        except (OSError, tomllib.TOMLDecodeError):
            out[path.stem] = "(unreadable)"
    return out


def resolve_problem_path(name_or_path: str | Path) -> Path:
    """A problem file from a path, or from the name of a file in ``problems/``."""
    path = Path(name_or_path).expanduser()
    if path.is_file():
        return path.resolve()
    named = PROBLEMS_DIR / f"{name_or_path}.toml"
    if named.is_file():
        return named
    names = ", ".join(available_problems()) or "none"
    raise ProblemError(str(name_or_path), "", f"an existing file or a built-in problem ({names})")


def read_toml(path: Path) -> dict[str, Any]:
    """The parsed TOML file at ``path``; a :class:`ProblemError` naming the file when it cannot be
    read or parsed (problem files, batch and cell specs)."""
    try:
        with path.open("rb") as f:
            return tomllib.load(f)
    except tomllib.TOMLDecodeError as e:
        raise ProblemError(str(path), "", f"valid TOML ({e})") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ProblemError(str(path), "", f"a readable TOML file ({e})") from None


def load_problem(name_or_path: str | Path) -> Problem:
    """Read and validate a problem file (a path or a built-in name) into a :class:`Problem`."""
    path = resolve_problem_path(name_or_path)
    return problem_from_dict(read_toml(path), source=path)


def problem_from_dict(data: dict[str, Any], source: Path | None = None) -> Problem:
    """Validate a parsed problem (as from TOML) into a :class:`Problem`."""
    file = str(source) if source else "<inline>"
    problem = _build(Problem, data, "", file)
    problem = dataclasses.replace(problem, source=source)
    robot = data.get("robot", {})
    if problem.robot.urdf is not None and "name" not in robot:  # a user arm is named by its file
        problem = dataclasses.replace(
            problem, robot=dataclasses.replace(problem.robot, name=Path(problem.robot.urdf).stem)
        )
    _check_consistency(problem, file)
    return problem


def _build(cls: type, data: Any, path: str, file: str) -> Any:
    """Build dataclass ``cls`` from ``data``, checking keys, types and ranges."""
    if not isinstance(data, dict):
        raise ProblemError(file, path or "(top level)", "a table", data)
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if not f.metadata.get("internal")}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        where = f"{path}.{unknown[0]}" if path else unknown[0]
        raise ProblemError(file, where, f"one of the keys {', '.join(fields)} (unknown key)")
    values = {}
    for name, value in data.items():
        where = f"{path}.{name}" if path else name
        values[name] = _convert(hints[name], value, fields[name].metadata, where, file)
    return cls(**values)


def _convert(tp: Any, value: Any, meta: Any, where: str, file: str) -> Any:
    """Convert one TOML value to the declared type ``tp``, or raise :class:`ProblemError`."""
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        inner = [a for a in args if a is not type(None)]
        # ``float | tuple[float, ...]``: a TOML list is the per-item form, anything else the scalar
        lists = [a for a in inner if typing.get_origin(a) is tuple]
        scalars = [a for a in inner if typing.get_origin(a) is not tuple]
        if lists and scalars:
            if isinstance(value, list):
                return _convert(lists[0], value, meta, where, file)
            return _convert(scalars[0], value, meta, where, file)
        return _convert(inner[0], value, meta, where, file)
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        return _build(tp, value, where, file)
    if origin is Literal:
        if value not in args:
            raise ProblemError(file, where, "one of " + ", ".join(repr(a) for a in args), value)
        return value
    if origin is tuple:
        if not isinstance(value, list):
            raise ProblemError(file, where, _describe(tp), value)
        if len(args) == 2 and args[1] is Ellipsis:
            items = [_convert(args[0], v, meta, f"{where}[{i}]", file) for i, v in enumerate(value)]
            if not items:
                raise ProblemError(file, where, "a non-empty list", value)
            return tuple(items)
        if len(value) != len(args):
            raise ProblemError(file, where, _describe(tp), value)
        return tuple(
            _convert(a, v, meta, f"{where}[{i}]", file)
            for i, (a, v) in enumerate(zip(args, value, strict=True))
        )
    if tp is bool:
        if not isinstance(value, bool):
            raise ProblemError(file, where, "true or false", value)
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ProblemError(file, where, "an integer", value)
        _check_range(value, meta, where, file)
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise ProblemError(file, where, "a finite number", value)
        _check_range(value, meta, where, file)
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ProblemError(file, where, "a string", value)
        return value
    raise TypeError(f"spec type {tp!r} at {where} is not supported")  # a bug in this module


def _check_range(x: float, meta: Any, where: str, file: str) -> None:
    """``x`` (as the file wrote it, int or float) within the key's declared range."""
    lo, hi, lo_open = meta.get("lo"), meta.get("hi"), meta.get("lo_open", False)
    unit = f" {meta.get('unit')}" if meta.get("unit") else ""
    if lo is not None and (x < lo or (lo_open and x == lo)):
        raise ProblemError(file, where, f"a value {'>' if lo_open else '≥'} {_bound(lo)}{unit}", x)
    if hi is not None and x > hi:
        raise ProblemError(file, where, f"a value ≤ {_bound(hi)}{unit}", x)


def _bound(x: float) -> str:
    """A declared bound as text: an integer in full (2147483647), a float as ``:g``."""
    return str(x) if isinstance(x, int) else f"{x:g}"


def _check_consistency(p: Problem, file: str) -> None:
    """Checks that involve several keys: zenith range, camera placement, per-kind requirements.

    Checks that need a built object (the camera sees the object, the obstacles' geometry) run where
    it is built (:class:`optlight.setup.Setup`), with the same :class:`ProblemError`."""
    ls, cam, obj = p.light_sphere, p.camera, p.object
    if ls.zenith_min_deg >= ls.zenith_max_deg:
        raise ProblemError(
            file,
            "light_sphere.zenith_max_deg",
            f"a value > zenith_min_deg ({ls.zenith_min_deg:g})",
            ls.zenith_max_deg,
        )
    centre = np.asarray(obj.center_m)
    eye = np.asarray(cam.position_m)
    dist = float(np.linalg.norm(eye - centre))
    if dist <= ls.radius_m:
        raise ProblemError(
            file,
            "camera.position_m",
            f"a camera outside the light sphere (distance to the object {dist:.3f} m > radius {ls.radius_m:g} m)",
            list(cam.position_m),
        )
    target = np.asarray(cam.look_at_m) if cam.look_at_m is not None else centre
    forward = target - eye
    if np.linalg.norm(forward) < 1e-9:
        raise ProblemError(
            file, "camera.look_at_m", "a point different from the camera position", list(target)
        )
    if obj.kind == "mesh" and obj.path is None:
        raise ProblemError(file, "object.path", "a mesh file path (object.kind = 'mesh')")
    if obj.kind == "mesh" and obj.path is not None and not p.resolve(obj.path).is_file():
        raise ProblemError(file, "object.path", "an existing mesh file", obj.path)
    if obj.kind == "sphere" and obj.radius_m >= ls.radius_m:
        raise ProblemError(
            file,
            "object.radius_m",
            f"a sphere smaller than the light sphere (< {ls.radius_m:g} m)",
            obj.radius_m,
        )
    ref = p.objective.reference
    if ref.kind == "image":
        if ref.image is None:
            raise ProblemError(file, "objective.reference.image", "an image path (reference.kind = 'image')")
        for name in ("image", "mask"):
            rel = getattr(ref, name)
            if rel is not None and not p.resolve(rel).is_file():
                raise ProblemError(file, f"objective.reference.{name}", "an existing PNG or NPY file", rel)
    if ref.kind == "bins":
        if ref.bins is None or len(ref.bins) != p.objective.bins:
            raise ProblemError(
                file,
                "objective.reference.bins",
                f"{p.objective.bins} non-negative numbers (objective.bins)",
                ref.bins,
            )
        if sum(ref.bins) <= 0:
            raise ProblemError(file, "objective.reference.bins", "bins with a positive sum", ref.bins)
    for i, term in enumerate(p.objective.terms):
        if term.kind in ("mean", "contrast") and term.target is None:
            raise ProblemError(file, f"objective.terms[{i}].target", f"a target value (kind = '{term.kind}')")
    if p.robot.urdf is None and p.robot.name not in ROBOT_NAMES:
        raise ProblemError(
            file,
            "robot.name",
            f"one of {', '.join(ROBOT_NAMES)} (or set robot.urdf and robot.frame)",
            p.robot.name,
        )
    if p.robot.urdf is not None:
        if not p.resolve(p.robot.urdf).is_file():
            raise ProblemError(file, "robot.urdf", "an existing URDF file", p.robot.urdf)
        if p.robot.frame is None:
            raise ProblemError(file, "robot.frame", "the flange frame name (robot.urdf is set)")
    try:
        image_names(p.trajectory.image_pattern, p.landmarks.count)
    except ValueError as e:
        raise ProblemError(
            file,
            "trajectory.image_pattern",
            f'distinct file names from {{index}}, e.g. "img_{{index:03d}}.png" ({e})',
            p.trajectory.image_pattern,
        ) from None
    traj = p.trajectory
    if traj.settle_s >= traj.dwell_s:
        raise ProblemError(
            file,
            "trajectory.settle_s",
            f"a settle time shorter than the dwell (trajectory.dwell_s = {traj.dwell_s:g} s)",
            traj.settle_s,
        )
    light = p.light
    if light.housing_radius_m >= ls.radius_m:
        raise ProblemError(
            file,
            "light.housing_radius_m",
            f"a housing smaller than the light sphere (< light_sphere.radius_m = {ls.radius_m:g} m)",
            light.housing_radius_m,
        )
    if light.housing == "cylinder" and light.housing_length_m >= ls.radius_m:
        raise ProblemError(
            file,
            "light.housing_length_m",
            f"a housing shorter than the light sphere radius (< {ls.radius_m:g} m)",
            light.housing_length_m,
        )
    _check_lightset(p, file)
    if p.world.light_profile == "spot" and p.world.light_radius_m > 0:
        raise ProblemError(
            file, "world.light_radius_m", "0 for a spot beam (light_profile = 'spot' is a point light)", p.world.light_radius_m
        )
    if p.world.light_radius_m >= ls.radius_m:
        raise ProblemError(
            file, "world.light_radius_m", f"a light smaller than the light sphere (< {ls.radius_m:g} m)", p.world.light_radius_m
        )
    offset = float(np.linalg.norm(p.world.light_offset_m))
    if offset >= ls.radius_m:
        raise ProblemError(
            file,
            "world.light_offset_m",
            f"an offset shorter than the light sphere's radius ({offset:.3g} m ≥ {ls.radius_m:g} m puts "
            "the real light anywhere, even behind the object)",
            list(p.world.light_offset_m),
        )
    if p.world.noise_std > light.saturation:
        raise ProblemError(
            file,
            "world.noise_std",
            f"a noise σ ≤ light.saturation = {light.saturation:g} (more drowns every capture)",
            p.world.noise_std,
        )


def _check_lightset(p: Problem, file: str) -> None:
    """Light counts per kind, one grid source, grid angles in range, the grid file present."""
    ls = p.lightset
    least = {"photometric_stereo": 3, "rti": 2}.get(ls.kind)
    if least is not None and ls.count < least:
        raise ProblemError(
            file, "lightset.count", f"at least {least} lights (lightset.kind = '{ls.kind}')", ls.count
        )
    if ls.grid_file is not None and ls.grid_deg is not None:
        raise ProblemError(file, "lightset.grid_deg", "either grid_deg or grid_file, not both", "both set")
    if ls.grid_file is not None and not p.resolve(ls.grid_file).is_file():
        raise ProblemError(file, "lightset.grid_file", "an existing CSV file", ls.grid_file)
    for i, (_, elevation) in enumerate(ls.grid_deg or ()):
        if not -90.0 <= elevation <= 90.0:
            raise ProblemError(file, f"lightset.grid_deg[{i}][1]", "an elevation in [−90, 90] deg", elevation)




def _to_plain(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        # Unset (None) keys and empty lists are left out: TOML has no null, a missing key means its
        # default, and no key whose default is non-empty accepts an empty list.
        return {
            f.name: _to_plain(getattr(value, f.name))
            for f in dataclasses.fields(value)
            if not f.metadata.get("internal") and getattr(value, f.name) not in (None, ())
        }
    if isinstance(value, tuple):
        return [_to_plain(v) for v in value]
    return value


# --------------------------------------------------------------------------------------------
# Reference documentation
# --------------------------------------------------------------------------------------------


def _describe(tp: Any) -> str:
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_describe(a) if a is not type(None) else "unset" for a in args)
    if origin is Literal:
        return " or ".join(f'"{a}"' for a in args)
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"list of {_describe(args[0])}"
        return f"list of {len(args)} {_describe(args[0])}s"
    if dataclasses.is_dataclass(tp):
        return "table"
    return {float: "number", int: "integer", bool: "boolean", str: "string"}.get(tp, str(tp))


def _default_text(f: dataclasses.Field) -> str:
    if f.default is not dataclasses.MISSING:
        d = f.default
    elif f.default_factory is not dataclasses.MISSING:
        d = f.default_factory()
    else:
        return ""
    if d is None:
        return "unset"
    if isinstance(d, bool):
        return str(d).lower()
    if isinstance(d, str):
        return f'"{d}"'
    if isinstance(d, tuple) and d and dataclasses.is_dataclass(d[0]):
        return "one term with the defaults below"
    if isinstance(d, tuple):
        return "[" + ", ".join(f"{x:g}" for x in d) + "]"
    if isinstance(d, float):
        return f"{d:g}"
    return str(d)


def reference_markdown() -> str:
    """The problem-file reference, generated from the declarations in this module."""
    lines = [
        "# Problem files",
        "",
        "<!-- generated from optlight/spec.py by `make docs`; do not edit by hand -->",
        "",
        "A problem file is TOML. Every key is optional; a missing key takes its default. Unknown keys,",
        "wrong types and out-of-range values are errors that name the file and the key. Lengths are in",
        "metres (`_m`), angles in degrees (`_deg`), paths relative to the problem file.",
        "The built-in problems are in `problems/`; `optlight problems` lists them.",
        "",
        "`optlight check` (and every command, before its work) also checks what this machine can do: the",
        "solve's memory (`camera.width` × `camera.height`) and the sampled trajectory's (its duration, from",
        "`trajectory.dwell_s` and the robot's limits, × `trajectory.rate_hz`); a refusal names the key and",
        "the largest (or smallest) value that fits here.",
        "",
    ]

    def walk(cls: type, prefix: str) -> None:
        hints = typing.get_type_hints(cls)
        fields = [f for f in dataclasses.fields(cls) if not f.metadata.get("internal")]
        scalars = [
            f
            for f in fields
            if not (dataclasses.is_dataclass(hints[f.name]) or _is_table_list(hints[f.name]))
        ]
        title = f"`[{prefix}]`" if prefix else "Top level"
        lines.extend([f"## {title}", "", " ".join((cls.__doc__ or "").split()), ""])
        if scalars:
            lines.extend(["| key | type | unit | default | range | meaning |", "|---|---|---|---|---|---|"])
            for f in scalars:
                m = f.metadata
                rng = ""
                if m.get("lo") is not None or m.get("hi") is not None:
                    lo = "" if m.get("lo") is None else f"{'>' if m.get('lo_open') else '≥'} {_bound(m['lo'])}"
                    hi = "" if m.get("hi") is None else f"≤ {_bound(m['hi'])}"
                    rng = ", ".join(x for x in (lo, hi) if x)
                lines.append(
                    f"| `{f.name}` | {_describe(hints[f.name])} | {m.get('unit', '')} | {_default_text(f)} | {rng} | {m.get('doc', '')} |"
                )
            lines.append("")
        for f in fields:
            tp = hints[f.name]
            sub = f"{prefix}.{f.name}" if prefix else f.name
            if isinstance(tp, type) and dataclasses.is_dataclass(tp):
                walk(tp, sub)
            elif _is_table_list(tp):
                lines.extend([f"`[[{sub}]]`: {f.metadata.get('doc', '')}", ""])
                walk(typing.get_args(tp)[0], f"[{sub}]")

    walk(Problem, "")
    return "\n".join(lines).rstrip() + "\n"


def _is_table_list(tp: Any) -> bool:
    args = typing.get_args(tp)
    return typing.get_origin(tp) is tuple and len(args) == 2 and dataclasses.is_dataclass(args[0])
