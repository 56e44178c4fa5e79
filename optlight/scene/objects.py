"""The observed objects: procedural face, analytic sphere, mesh files.

Every object is built in its own frame, which is the light-sphere frame S (docs/design.md §2): origin at
the object centre O, +z towards the camera, +y up, +x to the image's right. A mesh file's
coordinates are read as S coordinates (times ``scale``), so its front is its +z side and its top
its +y side; it is not recentred. :func:`build_object` then moves the object into the world frame,
``p_W = O + R_WS p_S``.

Albedo is per vertex and travels *alongside* the mesh in :class:`SceneObject` (``albedo[k]``
belongs to ``mesh.vertices[k]``), so it survives any trimesh processing of the mesh object.
Lengths are in metres, albedo is dimensionless in [0, 1].
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import trimesh
from numpy.typing import NDArray
from trimesh.visual import ColorVisuals, TextureVisuals

from optlight.errors import ProblemError
from optlight.geometry import sphere_frame

if TYPE_CHECKING:
    from pathlib import Path

    from optlight.spec import FaceSpec, Problem

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Subdivisions of the icosphere that carries the analytic sphere's mask (20·4⁵ = 20480 triangles).
SPHERE_SUBDIVISIONS = 5


@dataclass(frozen=True)
class SceneObject:
    """An object in the world frame.

    ``mesh``: triangles in the world frame (m), outward normals; ``albedo``: (V,) per-vertex albedo;
    ``sphere``: ``(centre, radius)`` when the object is an exact sphere, whose points and normals
    the G-buffer then takes from the sphere equation rather than from the tessellation.
    """

    mesh: trimesh.Trimesh
    albedo: Array
    sphere: tuple[Array, float] | None = None


# --------------------------------------------------------------------------------------------
# Procedural face
# --------------------------------------------------------------------------------------------

# Head: ellipsoid with semi-axes (A, B, C)·height, centred at (0, HEAD_Y, 0)·height in S, so the
# chin (Y = −0.5) sits low on its front and the crown above the forehead (Y = +0.5).
_HEAD_AXES = (0.38, 0.60, 0.52)
_HEAD_Y = 0.06


def _bump(x: Array, y: Array, x0: float, y0: float, sx: float, sy: float) -> Array:
    """Gaussian bump exp(−½((x−x0)/sx)² − ½((y−y0)/sy)²)."""
    return np.exp(-0.5 * ((x - x0) / sx) ** 2 - 0.5 * ((y - y0) / sy) ** 2)


def _patch(x: Array, y: Array, x0: float, y0: float, sx: float, sy: float) -> Array:
    """Soft-edged elliptical patch: 1 inside the ellipse of semi-axes (sx, sy), 0 outside 1.3× it,
    a smoothstep between."""
    r = np.sqrt(((x - x0) / sx) ** 2 + ((y - y0) / sy) ** 2)
    t = np.clip((1.3 - r) / 0.3, 0.0, 1.0)
    return t * t * (3 - 2 * t)


def face_relief(x: Array, y: Array, spec: FaceSpec) -> Array:
    """Relief height (m) of the face features at face coordinates (x, y) = (x_S, y_S)/height_m.

    A sum of Gaussian features, each a function of |x| (so mirror-symmetric), placed by the rule
    of thirds (hairline y = 0.5, brows 0.17, nose base −0.16, chin −0.5): the nose (a ridge rising
    from the bridge at y = 0.12 to the tip at y = −0.13, with alae), brow ridges, eye sockets with
    eyeballs, cheeks, lips with the mouth line between them, the chin, and a broad jaw
    (0.07·height_m, fixed) that makes the lower face less receding than the bare ellipsoid.
    """
    ax = np.abs(x)
    bridge, tip = 0.12, -0.13
    t = np.clip((bridge - y) / (bridge - tip), 0.0, 1.0)
    along = np.where(y > tip, 0.25 + 0.75 * t**1.5, np.exp(-0.5 * ((y - tip) / 0.025) ** 2))
    along = along * np.where(y > bridge, np.exp(-0.5 * ((y - bridge) / 0.04) ** 2), 1.0)
    width = 0.02 + 0.025 * t
    nose = along * np.exp(-0.5 * (x / width) ** 2) + 0.3 * _bump(ax, y, 0.055, -0.12, 0.022, 0.022)
    brows = _bump(ax, y, 0.14, 0.17, 0.065, 0.022)
    sockets = _bump(ax, y, 0.14, 0.095, 0.055, 0.035)
    eyeballs = _bump(ax, y, 0.14, 0.09, 0.03, 0.018)
    cheeks = _bump(ax, y, 0.17, -0.07, 0.06, 0.07)
    lips = _bump(x, y, 0.0, -0.265, 0.06, 0.016) + _bump(x, y, 0.0, -0.31, 0.05, 0.018)
    mouth_line = _bump(x, y, 0.0, -0.287, 0.055, 0.005)
    chin = _bump(x, y, 0.0, -0.43, 0.07, 0.05)
    jaw = _bump(x, y, 0.0, -0.30, 0.22, 0.16)
    return (
        spec.nose_m * nose
        + spec.brow_m * brows
        - spec.eye_depth_m * (sockets - 0.5 * eyeballs)
        + spec.cheek_m * (cheeks + chin)
        + spec.lip_m * (lips - 0.6 * mouth_line)
        + 0.07 * spec.height_m * jaw
    )


def face_albedo(x: Array, y: Array, spec: FaceSpec) -> Array:
    """Albedo at face coordinates (x, y) = (x_S, y_S)/height_m: skin, with soft-edged eyebrow
    patches (``brow_albedo``) above the brow ridges and lips (``lip_albedo``); symmetric in x."""
    ax = np.abs(x)
    brows = _patch(ax, y + 0.4 * (ax - 0.14) ** 2, 0.14, 0.19, 0.06, 0.013)
    lips = np.maximum(_patch(x, y, 0.0, -0.265, 0.05, 0.012), _patch(x, y, 0.0, -0.31, 0.045, 0.014))
    rho = spec.skin_albedo + (spec.brow_albedo - spec.skin_albedo) * brows
    return rho + (spec.lip_albedo - rho) * lips


def face_mesh(spec: FaceSpec) -> tuple[Array, IntArray, Array]:
    """The procedural face in the object frame S: vertices (V, 3) in m, faces (F, 3), albedo (V,).

    A closed, watertight head: the ellipsoid (A, B, C)·h with h = ``height_m``, parameterised by
    longitude λ ∈ [−π, π) (λ = 0 on the +z front) and latitude μ ∈ (−π/2, π/2), pole vertices on
    ±y. ``resolution`` = n gives 2n longitudes and n − 1 latitude rings, so the front half is an
    n × n grid. Each base point p₀ with unit ellipsoid normal n₀ moves along it by the relief:
    p = p₀ + w(n₀·z) r(x₀/h, y₀/h) n₀, where r is :func:`face_relief` and w a smoothstep that fades
    the features out towards the sides (n₀·z from 0.15 to 0.55) so the back stays a plain
    ellipsoid. Longitudes come in ± pairs and the quad diagonals are mirrored across λ = 0, so the
    mesh is exactly mirror-symmetric about the y–z plane. Deterministic: a pure function of ``spec``.
    """
    h = spec.height_m
    n = int(spec.resolution)
    n_lon = 2 * n
    lam = 2 * np.pi * (np.arange(n_lon) - n) / n_lon  # λ_k = −λ_{2n−k}
    mu = np.pi * (np.arange(1, n) - n / 2) / n  # n − 1 rings, symmetric about 0
    big_a, big_b, big_c = (h * s for s in _HEAD_AXES)
    m, lm = np.meshgrid(mu, lam, indexing="ij")  # (n−1, 2n)
    base = np.stack(
        [big_a * np.cos(m) * np.sin(lm), big_b * np.sin(m) + _HEAD_Y * h, big_c * np.cos(m) * np.cos(lm)],
        axis=-1,
    ).reshape(-1, 3)
    poles = np.array([[0.0, -big_b + _HEAD_Y * h, 0.0], [0.0, big_b + _HEAD_Y * h, 0.0]])
    base = np.vstack([base, poles])
    # Ellipsoid normal ∝ ((x)/A², (y − y_c)/B², z/C²).
    grad = np.column_stack(
        [base[:, 0] / big_a**2, (base[:, 1] - _HEAD_Y * h) / big_b**2, base[:, 2] / big_c**2]
    )
    normal = grad / np.linalg.norm(grad, axis=1, keepdims=True)
    fx, fy = base[:, 0] / h, base[:, 1] / h
    s = np.clip((normal[:, 2] - 0.15) / 0.40, 0.0, 1.0)
    weight = s * s * (3 - 2 * s)
    vertices = base + (weight * face_relief(fx, fy, spec))[:, None] * normal
    albedo = spec.skin_albedo + weight * (face_albedo(fx, fy, spec) - spec.skin_albedo)
    faces = _uv_faces(n - 1, n_lon, lam)
    return vertices, faces, albedo


def _uv_faces(rings: int, n_lon: int, lam: Array) -> IntArray:
    """Outward-wound triangles of a UV sphere with ``rings`` latitude rings of ``n_lon`` vertices
    (ring-major, south to north), then the south and north pole vertices."""
    j, k = np.meshgrid(np.arange(rings - 1), np.arange(n_lon), indexing="ij")
    k1 = (k + 1) % n_lon
    v00, v01 = j * n_lon + k, j * n_lon + k1  # ring j (south), columns k, k+1
    v10, v11 = (j + 1) * n_lon + k, (j + 1) * n_lon + k1  # ring j+1 (north)
    # Diagonal v00–v11 on the +x side, v01–v10 on the −x side: mirror images of each other.
    east = (lam[k] + np.where(k1 == 0, np.pi, lam[k1])) >= 0
    quads = np.where(
        east[..., None, None],
        np.stack([np.stack([v00, v01, v11], -1), np.stack([v00, v11, v10], -1)], -2),
        np.stack([np.stack([v00, v01, v10], -1), np.stack([v01, v11, v10], -1)], -2),
    ).reshape(-1, 3)
    south, north = rings * n_lon, rings * n_lon + 1
    kk = np.arange(n_lon)
    south_fan = np.column_stack([np.full(n_lon, south), (kk + 1) % n_lon, kk])
    top = (rings - 1) * n_lon
    north_fan = np.column_stack([np.full(n_lon, north), top + kk, top + (kk + 1) % n_lon])
    return np.vstack([quads, south_fan, north_fan]).astype(np.int64)


# --------------------------------------------------------------------------------------------
# Sphere and mesh files
# --------------------------------------------------------------------------------------------


def srgb_luminance(colors: NDArray[np.uint8] | Array) -> Array:
    """Albedo from 8-bit sRGB(A) colours: linearise each channel (IEC 61966-2-1,
    c ≤ 0.04045 ? c/12.92 : ((c+0.055)/1.055)^2.4) and take the Rec. 709 luminance
    Y = 0.2126 R + 0.7152 G + 0.0722 B. Alpha is ignored."""
    c = np.asarray(colors, float)[:, :3] / 255.0
    lin = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return lin @ np.array([0.2126, 0.7152, 0.0722])


def load_mesh(path: Path, scale: float, albedo: float) -> tuple[trimesh.Trimesh, Array]:
    """A mesh file (any format trimesh reads; scenes are concatenated) scaled by ``scale``, in
    the object frame, and its per-vertex albedo: the luminance of the vertex colours (face colours
    and textures are first turned into vertex colours by trimesh) when the file has colours, else
    the constant ``albedo``. Shading normals are trimesh's vertex normals: the file's where it
    has them, else the area-weighted face normals of the merged vertices (smooth shading).

    Raises ValueError saying why when the file cannot be used: trimesh cannot read it (any of its
    exceptions: unknown format, garbage bytes, an encoding it cannot guess), it holds no triangle, or
    a vertex is not finite."""
    try:
        mesh = trimesh.load(path, force="mesh")
    except Exception as e:  # trimesh's readers raise anything on a malformed file
        raise ValueError(f"trimesh cannot read it: {type(e).__name__}: {e}") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ValueError("no triangles in it")
    if not np.isfinite(mesh.vertices).all():
        raise ValueError("a vertex coordinate is not a finite number")
    visual = mesh.visual
    if isinstance(visual, TextureVisuals) and visual.kind == "texture":
        visual = visual.to_color()
    if isinstance(visual, ColorVisuals) and visual.kind in ("vertex", "face"):
        rho = srgb_luminance(visual.vertex_colors)
    else:
        rho = np.full(len(mesh.vertices), float(albedo))
    mesh.apply_scale(scale)
    return mesh, rho


def build_object(problem: Problem) -> SceneObject:
    """The problem's object in the world frame: built in S, then p_W = O + R_WS p_S with
    O = ``object.center_m`` and R_WS the light-sphere frame (:func:`optlight.geometry.sphere_frame`)."""
    spec = problem.object
    center = np.asarray(spec.center_m, float)
    transform = np.eye(4)
    transform[:3, :3] = sphere_frame(center, problem.camera.position_m)
    transform[:3, 3] = center
    sphere: tuple[Array, float] | None = None
    if spec.kind == "face":
        vertices, faces, albedo = face_mesh(spec.face)
        mesh = trimesh.Trimesh(vertices, faces, process=False)
    elif spec.kind == "sphere":
        mesh = trimesh.creation.icosphere(subdivisions=SPHERE_SUBDIVISIONS, radius=spec.radius_m)
        albedo = np.full(len(mesh.vertices), spec.albedo)
        sphere = (center, float(spec.radius_m))
    else:
        assert spec.path is not None  # checked by load_problem
        path = problem.resolve(spec.path)
        try:
            mesh, albedo = load_mesh(path, spec.scale, spec.albedo)
        except (ValueError, OSError) as e:
            file = str(problem.source) if problem.source else "<inline>"
            detail = " ".join(str(e).split())[:200]  # one line, whatever the reader said
            raise ProblemError(
                file, "object.path", f"a mesh file trimesh reads, with triangles ({detail})", spec.path
            ) from None
    mesh.apply_transform(transform)
    return SceneObject(mesh=mesh, albedo=np.clip(albedo, 0.0, 1.0), sphere=sphere)
