"""Obstacle shapes and the camera's view cone: signed distances (NumPy and CasADi) and coal geometry.

Every shape gives the signed distance sd(p) from a world point p to its surface (m; > 0 outside,
< 0 inside), twice: :meth:`signed_distance` on NumPy points (N, 3) and :meth:`signed_distance_sx` on a
CasADi 3×1 expression, with the *same* formula, so the two agree to rounding. Non-differentiable
points are smoothed with ε = :data:`SMOOTHING_M` in a way that never overestimates the distance by
more than ε²/(2|·|) (negligible) and keeps gradients finite:

- half-space {x : nᵀx ≤ h}: sd = nᵀp − h (exact);
- ball (c, r): sd = sqrt(|p − c|² + ε²) − r;
- box (pose T_WB, half extents e): with q = |p_B| − e (p_B the point in box axes),
  sd = sqrt(Σ max(q_i, 0)² + ε²) − ε + min(max_i q_i, 0)  (exact inside, ≤ the exact value outside);
- cylinder (pose T_WC, axis z_C, radius r, half-length l): the box formula in 2-D with
  q = (sqrt(x² + y² + ε²) − r, |z| − l).

Each sd is 1-Lipschitz, so sd(p) ≥ sd(o) − |p − o| bounds it from any point o (used to drop pairs
that can never come close). :meth:`coal_geometry` and :attr:`placement` give the exact shape for
coal (docs/design.md §8: pinocchio's GeometryModel), in the world frame.

The view cone (:class:`ViewCone`) is the cone with apex at the camera centre C, axis u = (O − C)/d
(d = |O − C|), half-angle α = asin(R/d) + margin around the object's bounding sphere (centre O,
radius R), truncated at the plane through O normal to u: whatever is inside it stands between the
camera and the object.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import casadi as ca
import coal
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

#: Smoothing length ε (m) of the signed distances: keeps |·| and max(·, 0) differentiable.
SMOOTHING_M = 1e-6


class Obstacle(Protocol):
    """What the clearance constraints and the exact checks need from an obstacle."""

    @property
    def name(self) -> str:
        """Name in reports and labels."""
        ...

    def signed_distance(self, points: ArrayLike) -> Array:
        """sd (N,) in m of world points (N, 3); > 0 outside."""
        ...

    def signed_distance_sx(self, point: ca.SX) -> ca.SX:
        """sd of a CasADi 3×1 world point, the same formula as :meth:`signed_distance`."""
        ...

    def coal_geometry(self) -> coal.CollisionGeometry:
        """The exact shape, in its own frame, for coal."""
        ...

    @property
    def placement(self) -> pin.SE3:
        """Pose of the shape's frame in the world frame."""
        ...


def _smooth_box_sd_np(q: Array) -> Array:
    """Signed distance of a box (or a 2-D cylinder profile) from q = |p_local| − e, shape (N, k)."""
    outside = np.sqrt(np.sum(np.maximum(q, 0.0) ** 2, axis=1) + SMOOTHING_M**2) - SMOOTHING_M
    return outside + np.minimum(q.max(axis=1), 0.0)


def _smooth_box_sd_sx(q: list[ca.SX]) -> ca.SX:
    outside = ca.sqrt(sum(ca.fmax(qi, 0.0) ** 2 for qi in q) + SMOOTHING_M**2) - SMOOTHING_M
    biggest = q[0]
    for qi in q[1:]:
        biggest = ca.fmax(biggest, qi)
    return outside + ca.fmin(biggest, 0.0)


def _points(points: ArrayLike) -> Array:
    return np.asarray(points, float).reshape(-1, 3)


@dataclass(frozen=True)
class HalfSpace:
    """The solid {x : nᵀx ≤ h} (a table top at height h has n = +z)."""

    name: str
    normal: Array
    offset: float

    def signed_distance(self, points: ArrayLike) -> Array:
        return _points(points) @ self.normal - self.offset

    def signed_distance_sx(self, point: ca.SX) -> ca.SX:
        return ca.dot(ca.DM(self.normal), point) - self.offset

    def coal_geometry(self) -> coal.CollisionGeometry:
        return coal.Halfspace(self.normal.copy(), float(self.offset))

    @property
    def placement(self) -> pin.SE3:
        return pin.SE3.Identity()


@dataclass(frozen=True)
class Ball:
    """A solid sphere of radius ``radius`` (m) at ``center`` (world)."""

    name: str
    center: Array
    radius: float

    def signed_distance(self, points: ArrayLike) -> Array:
        d = _points(points) - self.center
        return np.sqrt(np.sum(d * d, axis=1) + SMOOTHING_M**2) - self.radius

    def signed_distance_sx(self, point: ca.SX) -> ca.SX:
        d = point - ca.DM(self.center)
        return ca.sqrt(ca.sumsqr(d) + SMOOTHING_M**2) - self.radius

    def coal_geometry(self) -> coal.CollisionGeometry:
        return coal.Sphere(float(self.radius))

    @property
    def placement(self) -> pin.SE3:
        return pin.SE3(np.eye(3), self.center.copy())


@dataclass(frozen=True)
class Box:
    """A solid box: centre and axes ``rotation`` (R_WB, columns = box axes) in the world frame,
    half edge lengths ``half_extents`` (m)."""

    name: str
    center: Array
    rotation: Array
    half_extents: Array

    def signed_distance(self, points: ArrayLike) -> Array:
        local = (_points(points) - self.center) @ self.rotation
        return _smooth_box_sd_np(np.abs(local) - self.half_extents)

    def signed_distance_sx(self, point: ca.SX) -> ca.SX:
        local = ca.DM(self.rotation.T) @ (point - ca.DM(self.center))
        return _smooth_box_sd_sx([ca.fabs(local[i]) - float(self.half_extents[i]) for i in range(3)])

    def coal_geometry(self) -> coal.CollisionGeometry:
        return coal.Box(*(2.0 * self.half_extents))

    @property
    def placement(self) -> pin.SE3:
        return pin.SE3(self.rotation.copy(), self.center.copy())


@dataclass(frozen=True)
class Cylinder:
    """A solid cylinder: centre (middle of the axis) and axes ``rotation`` (R_WC, axis = third
    column) in the world frame, ``radius`` and ``half_length`` (m)."""

    name: str
    center: Array
    rotation: Array
    radius: float
    half_length: float

    def signed_distance(self, points: ArrayLike) -> Array:
        local = (_points(points) - self.center) @ self.rotation
        radial = np.sqrt(local[:, 0] ** 2 + local[:, 1] ** 2 + SMOOTHING_M**2) - self.radius
        axial = np.abs(local[:, 2]) - self.half_length
        return _smooth_box_sd_np(np.stack([radial, axial], axis=1))

    def signed_distance_sx(self, point: ca.SX) -> ca.SX:
        local = ca.DM(self.rotation.T) @ (point - ca.DM(self.center))
        radial = ca.sqrt(local[0] ** 2 + local[1] ** 2 + SMOOTHING_M**2) - self.radius
        return _smooth_box_sd_sx([radial, ca.fabs(local[2]) - self.half_length])

    def coal_geometry(self) -> coal.CollisionGeometry:
        return coal.Cylinder(float(self.radius), 2.0 * float(self.half_length))

    @property
    def placement(self) -> pin.SE3:
        return pin.SE3(self.rotation.copy(), self.center.copy())


def rotation_rpy_deg(rpy_deg: ArrayLike) -> Array:
    """R = Rz(yaw)·Ry(pitch)·Rx(roll) from roll, pitch, yaw in degrees (URDF convention)."""
    r, p, y = np.deg2rad(np.asarray(rpy_deg, float))
    return np.asarray(pin.rpy.rpyToMatrix(r, p, y))


def cone_signed_distance(
    v: Array, axis: Array, half_angle: float, length: float, near: float = 0.0
) -> Array:
    """sd (N,) in m of the points v (N, 3), taken from the apex, to the cone of unit ``axis``,
    half-angle α (rad), cut at the planes a = ``near`` and a = ``length`` (m) along the axis: in the
    (axial a = vᵀu, radial r = |v − a u|) half-plane, sd = max(r cos α − a sin α, a − L, near − a),
    r smoothed as sqrt(r² + ε²) (:class:`ViewCone`)."""
    a = v @ axis
    perp = v - a[:, None] * axis
    r = np.sqrt(np.sum(perp * perp, axis=1) + SMOOTHING_M**2)
    side = r * math.cos(half_angle) - a * math.sin(half_angle)
    return np.maximum(np.maximum(side, a - length), near - a)


def cone_signed_distance_sx(
    v: ca.SX, axis: ca.SX | ca.DM, half_angle: ca.SX | float, length: ca.SX | float, near: ca.SX | float = 0.0
) -> ca.SX:
    """The same for a CasADi 3×1 point v from the apex; axis, angle and lengths may be expressions."""
    a = ca.dot(axis, v)
    perp = v - a * axis
    r = ca.sqrt(ca.sumsqr(perp) + SMOOTHING_M**2)
    side = r * ca.cos(half_angle) - a * ca.sin(half_angle)
    return ca.fmax(ca.fmax(side, a - length), near - a)


@dataclass(frozen=True)
class ViewCone:
    """The camera's view of the object (module docstring): apex ``apex`` = C (m, world), unit
    ``axis`` u towards O, ``half_angle`` α (rad), ``length`` L = d (m), the cone ending at the plane
    through O.

    The signed distance used for the constraints is the largest of the signed distances to the three
    bounding surfaces in the (axial a = (p − C)ᵀu, radial r = |p − C − a u|) half-plane,

        sd = max(r cos α − a sin α,  a − L,  −a),

    exact inside the cone and never above the exact distance outside (a convex set's distance is
    at least the distance to any of its supporting planes); r is smoothed as sqrt(r² + ε²).
    """

    apex: Array
    axis: Array
    half_angle: float
    length: float

    @classmethod
    def around(cls, camera: ArrayLike, center: ArrayLike, radius: float, margin: float) -> ViewCone:
        """The cone from the camera centre to the sphere (``center``, ``radius``), half-angle
        asin(radius/d) + ``margin`` (rad)."""
        c, o = np.asarray(camera, float), np.asarray(center, float)
        d = float(np.linalg.norm(o - c))
        if radius >= d:
            raise ValueError(
                f"the camera ({d:.3f} m from the centre) is inside the sphere of radius {radius}"
            )
        alpha = math.asin(radius / d) + margin
        if alpha >= math.pi / 2:
            raise ValueError(f"view cone half-angle {math.degrees(alpha):.1f}° is not below 90°")
        return cls(apex=c, axis=(o - c) / d, half_angle=alpha, length=d)

    def signed_distance(self, points: ArrayLike) -> Array:
        """sd (N,) in m of world points (N, 3) to the cone (class docstring); < 0 inside."""
        return cone_signed_distance(_points(points) - self.apex, self.axis, self.half_angle, self.length)

    def signed_distance_sx(self, point: ca.SX) -> ca.SX:
        """The same for a CasADi 3×1 world point."""
        return cone_signed_distance_sx(
            point - ca.DM(self.apex), ca.DM(self.axis), self.half_angle, self.length
        )

    def coal_geometry(self) -> coal.CollisionGeometry:
        """coal's cone: base radius L tan α, height L, apex at +L/2 on its own z axis."""
        return coal.Cone(self.length * math.tan(self.half_angle), self.length)

    @property
    def placement(self) -> pin.SE3:
        """Cone frame: origin at the middle of the axis, +z towards the apex (the camera)."""
        z = -self.axis
        helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x = np.cross(helper, z)
        x /= np.linalg.norm(x)
        rot = np.column_stack([x, np.cross(z, x), z])
        return pin.SE3(rot, self.apex + 0.5 * self.length * self.axis)


#: Largest R/d of the beam's half-angle asin(R/d): the light nearer the object than its bounding
#: sphere (never at a capture; a configuration off the path may put it there) keeps a finite cone.
BEAM_MAX_SINE = 0.99


@dataclass(frozen=True)
class BeamCone:
    """The light's beam onto the object: the cone from the light's emitting point a (the apex, which
    moves with the robot) to the object's bounding sphere (``center`` O, ``radius`` R, m), axis
    u = (O − a)/d, d = |O − a|, half-angle α = asin(R/d) + ``margin`` (rad), cut at the plane through
    O and at a = ``skip`` cos α from the apex: the exact check casts the beam's rays from ``skip`` m
    beyond a (the housing's radius), and every point of the cone nearer than ``skip`` cos α along
    the axis is within ``skip`` of a. Whatever else is inside it stands between the light and the
    lit side of the object. Signed distance: :func:`cone_signed_distance` (the view cone's); R/d is
    capped at :data:`BEAM_MAX_SINE`."""

    center: Array
    radius: float
    margin: float
    skip: float

    def _cone(self, apex: Array) -> tuple[Array, float, float]:
        """(u, α, d) for the apex (3,) in m."""
        to_center = self.center - apex
        d = max(float(np.linalg.norm(to_center)), SMOOTHING_M)
        return to_center / d, math.asin(min(self.radius / d, BEAM_MAX_SINE)) + self.margin, d

    def signed_distance(self, points: ArrayLike, apex: ArrayLike) -> Array:
        """sd (N,) in m of world points (N, 3) to the beam from ``apex`` (3,) (m); < 0 inside."""
        a = np.asarray(apex, float).reshape(3)
        axis, alpha, d = self._cone(a)
        return cone_signed_distance(_points(points) - a, axis, alpha, d, self.skip * math.cos(alpha))

    def signed_distance_sx(self, point: ca.SX, apex: ca.SX) -> ca.SX:
        """The same for CasADi 3×1 world points ``point`` and ``apex`` (the light's position)."""
        to_center = ca.DM(self.center) - apex
        d = ca.fmax(ca.sqrt(ca.sumsqr(to_center)), SMOOTHING_M)
        alpha = ca.asin(ca.fmin(self.radius / d, BEAM_MAX_SINE)) + self.margin
        return cone_signed_distance_sx(point - apex, to_center / d, alpha, d, self.skip * ca.cos(alpha))
