"""Sections of what is around the robot: obstacles, self-collision, the camera's view."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from optlight.spec.keys import Vec3, key


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
