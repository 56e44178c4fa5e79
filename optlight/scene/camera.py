"""Pinhole camera with OpenCV axes (x right, y down, z forward), placed by position and look-at."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    from optlight.spec import CameraSpec

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Camera:
    """Intrinsics (pixels) and pose: ``rotation`` = R_WC (columns are the camera axes in the
    world frame), ``position`` = camera centre in the world frame (m)."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    position: Array
    rotation: Array

    @classmethod
    def look_at(
        cls,
        position: ArrayLike,
        target: ArrayLike,
        width: int,
        height: int,
        fov_deg: float = 20.0,
        fx: float | None = None,
        fy: float | None = None,
        cx: float | None = None,
        cy: float | None = None,
    ) -> Camera:
        """Camera at ``position`` whose optical axis passes through ``target``; the image's
        up direction is the world z axis projected on the image plane (world x when parallel)."""
        eye = np.asarray(position, float)
        z = np.asarray(target, float) - eye
        z /= np.linalg.norm(z)
        up = np.array([0.0, 0.0, 1.0])
        if np.linalg.norm(np.cross(up, z)) < 1e-9:
            up = np.array([1.0, 0.0, 0.0])
        x = np.cross(z, up)
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        f_default = 0.5 * height / np.tan(np.deg2rad(fov_deg) / 2)
        return cls(
            fx=float(fx if fx is not None else f_default),
            fy=float(fy if fy is not None else f_default),
            cx=float(cx if cx is not None else (width - 1) / 2),
            cy=float(cy if cy is not None else (height - 1) / 2),
            width=int(width),
            height=int(height),
            position=eye,
            rotation=np.column_stack([x, y, z]),
        )

    @classmethod
    def from_spec(cls, spec: CameraSpec, object_center: ArrayLike) -> Camera:
        """The camera of a problem file; ``look_at_m`` defaults to the object centre."""
        target = spec.look_at_m if spec.look_at_m is not None else object_center
        return cls.look_at(
            spec.position_m,
            target,
            spec.width,
            spec.height,
            spec.fov_deg,
            spec.fx_px,
            spec.fy_px,
            spec.cx_px,
            spec.cy_px,
        )

    @property
    def intrinsics(self) -> Array:
        """The 3×3 matrix K."""
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])

    def project(self, points: ArrayLike) -> tuple[Array, Array, Array]:
        """Pixel coordinates (u, v) and depth z_C of world points, shape (N, 3) -> 3 × (N,)."""
        pc = (np.asarray(points, float) - self.position) @ self.rotation
        z = pc[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = self.fx * pc[:, 0] / z + self.cx
            v = self.fy * pc[:, 1] / z + self.cy
        return u, v, z

    def rays(self) -> tuple[Array, Array]:
        """One ray per pixel through its centre, row-major: origins (H·W, 3), unit directions (H·W, 3)."""
        v, u = np.mgrid[0 : self.height, 0 : self.width]
        d = np.stack([(u - self.cx) / self.fx, (v - self.cy) / self.fy, np.ones_like(u, float)], -1).reshape(
            -1, 3
        )
        d = d @ self.rotation.T
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        return np.broadcast_to(self.position, d.shape).copy(), d

    def to_camera_frame(self, vectors: ArrayLike) -> Array:
        """World direction vectors expressed in the camera (OpenCV) frame."""
        return np.asarray(vectors, float) @ self.rotation
