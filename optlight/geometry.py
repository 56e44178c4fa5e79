"""Light-sphere geometry (docs/design.md §2–§3): sphere coordinates, great circles, light frames, h(q).

The light sphere S has centre O, radius b and pole axis z_S from O towards the camera, so
zenith θ = 0 is frontal light. x_S = normalize(up × z_S) with up the world z axis (world x when
parallel), y_S = z_S × x_S. A light at zenith θ, azimuth φ sits at

    a(θ, φ) = O + b (sinθ cosφ x_S + sinθ sinφ y_S + cosθ z_S).

All angles in radians, lengths in metres.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]


def sphere_frame(center: ArrayLike, camera_position: ArrayLike) -> Array:
    """Rotation R_WS (columns x_S, y_S, z_S) of the light-sphere frame in the world frame."""
    z = np.asarray(camera_position, float) - np.asarray(center, float)
    z = z / np.linalg.norm(z)
    up = np.array([0.0, 0.0, 1.0])
    if np.linalg.norm(np.cross(up, z)) < 1e-9:
        up = np.array([1.0, 0.0, 0.0])
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.column_stack([x, y, z])


@dataclass(frozen=True)
class LightSphere:
    """The sphere the light moves on: centre O (m), radius b (m), frame R_WS, zenith range (rad)."""

    center: Array
    radius: float
    rotation: Array
    zenith_min: float = 0.0
    zenith_max: float = np.pi / 2

    @classmethod
    def from_problem(cls, problem) -> LightSphere:  # noqa: ANN001 - spec.Problem, avoids a cycle
        """The light sphere of a problem: centre at the object, pole towards the camera."""
        center = np.asarray(problem.object.center_m, float)
        return cls(
            center=center,
            radius=float(problem.light_sphere.radius_m),
            rotation=sphere_frame(center, problem.camera.position_m),
            zenith_min=np.deg2rad(problem.light_sphere.zenith_min_deg),
            zenith_max=np.deg2rad(problem.light_sphere.zenith_max_deg),
        )

    def direction(self, zenith: ArrayLike, azimuth: ArrayLike) -> Array:
        """Unit vector(s) from O towards the light, world frame; shape (..., 3)."""
        return direction_in_sphere_frame(zenith, azimuth) @ self.rotation.T

    def position(self, zenith: ArrayLike, azimuth: ArrayLike) -> Array:
        """Light position(s) a(θ, φ) in the world frame; shape (..., 3)."""
        return self.center + self.radius * self.direction(zenith, azimuth)

    def angles(self, position: ArrayLike) -> tuple[Array, Array]:
        """Zenith θ ∈ [0, π] and azimuth φ ∈ [0, 2π) of world point(s) seen from O."""
        d = (np.asarray(position, float) - self.center) @ self.rotation
        zenith = np.arctan2(np.hypot(d[..., 0], d[..., 1]), d[..., 2])
        azimuth = np.mod(np.arctan2(d[..., 1], d[..., 0]), 2 * np.pi)
        return zenith, azimuth


def direction_in_sphere_frame(zenith: ArrayLike, azimuth: ArrayLike) -> Array:
    """(sinθ cosφ, sinθ sinφ, cosθ), shape (..., 3)."""
    t, p = np.broadcast_arrays(np.asarray(zenith, float), np.asarray(azimuth, float))
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)


def great_circle(u: ArrayLike, v: ArrayLike, max_step: float) -> Array:
    """Unit vectors along the shorter great-circle arc from u to v (both included).

    Slerp: s(t) = (sin((1−t)Ω) u + sin(tΩ) v) / sinΩ, Ω = ∠(u, v), with knots at most
    ``max_step`` rad apart. Antipodal u, v have no unique arc and raise ValueError.
    """
    a = np.asarray(u, float) / np.linalg.norm(u)
    b = np.asarray(v, float) / np.linalg.norm(v)
    omega = float(np.arccos(np.clip(a @ b, -1.0, 1.0)))
    if omega < 1e-12:
        return np.stack([a, b])
    if np.pi - omega < 1e-6:
        raise ValueError("antipodal points: the great circle between them is not unique")
    n = max(1, int(np.ceil(omega / max_step)))
    t = np.linspace(0.0, 1.0, n + 1)[:, None]
    return (np.sin((1 - t) * omega) * a + np.sin(t * omega) * b) / np.sin(omega)


def aim_rotation(position: ArrayLike, center: ArrayLike, reference_x: ArrayLike) -> Array:
    """Rotation whose z axis points from ``position`` to ``center`` and whose x axis is the
    component of ``reference_x`` orthogonal to it (the roll, fixed by a reference vector)."""
    z = np.asarray(center, float) - np.asarray(position, float)
    z /= np.linalg.norm(z)
    x = np.asarray(reference_x, float) - (np.asarray(reference_x, float) @ z) * z
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("reference_x is parallel to the optical axis")
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def h_residual(position: Any, rotation: Any, center: Any, radius: Any) -> Any:
    """The light constraints h1–h3 (docs/design.md §3): h = R_Lᵀ (O − a_L) − [0, 0, b]; zero iff the
    light is on the sphere and its +z axis passes through O. Units: metres.

    The one definition of h: NumPy arrays give a (3,) array, or (k, 3) for k poses (positions
    (k, 3), rotations (k, 3, 3)); when any argument is a CasADi expression (SX/MX, e.g. the symbolic
    light pose or a parametrised centre) a 3×1 expression."""
    if any(isinstance(x, ca.SX | ca.MX) for x in (position, rotation, center, radius)):
        o = center if isinstance(center, ca.SX | ca.MX) else ca.DM(np.asarray(center, float))
        return rotation.T @ (o - position) - ca.vertcat(0.0, 0.0, radius)
    to_center = np.asarray(center, float) - np.asarray(position, float)
    return np.einsum("...ji,...j->...i", np.asarray(rotation, float), to_center) - np.array([0.0, 0.0, radius])
