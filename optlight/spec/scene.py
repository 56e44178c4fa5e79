"""Sections of the scene: the observed object, the fixed camera, the light sphere, the light and the
robot that carries it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from optlight.spec.keys import SEED_MAX, Vec3, key, section

#: Robots that load by name (example-robot-data); :mod:`optlight.robot.catalogue` has their details.
ROBOT_NAMES: tuple[str, ...] = ("panda", "ur3", "ur5", "ur10", "xarm7", "kinova", "z1")


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
