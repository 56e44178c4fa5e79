"""G-buffer and shadow rays: what the camera sees of the object, per pixel (docs/design.md §4).

Rays are cast with Embree (``embreex``, :class:`RayCaster`); trimesh's pure NumPy ray caster is
~400× slower and is never used. Embree's queries release the GIL, so a large batch is split over
the cores. Embree works in float32 and only reports *which*
triangle a ray hits first; the hit point is recomputed in float64 as the intersection of the ray
with that triangle's plane, t = ((v₀ − o)·n_f)/(d·n_f).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh
from numpy.typing import ArrayLike, NDArray
from trimesh import Trimesh

from optlight.scene.camera import Camera
from optlight.scene.objects import SceneObject
from optlight.threads import map_slices

Array = NDArray[np.float64]

#: Rays whose |d·n_f| falls below this are treated as grazing the hit triangle (no usable hit point).
_GRAZING = 1e-9
#: Fewest rays a thread casts: Embree takes ~0.15 µs a ray, a thread ~0.1 ms to start and join.
_RAYS_PER_THREAD = 8192


@dataclass(frozen=True)
class GBuffer:
    """The object pixels of an image, P of them, in row-major order.

    ``points`` (P, 3): first hit of the pixel-centre ray, world frame, m. ``normals`` (P, 3): unit
    shading normals — barycentric interpolation of the vertex normals, renormalised and flipped
    towards the camera when the ray hits a triangle's back side (sphere: (p − c)/r exactly).
    ``albedo`` (P,): barycentric interpolation of the vertex albedo. ``mask`` (H, W): True on
    object pixels. ``pixel_index`` (P,): flat row-major index v·W + u of each object pixel.
    """

    points: Array
    normals: Array
    albedo: Array
    mask: NDArray[np.bool_]
    pixel_index: NDArray[np.int64]

    @property
    def size(self) -> int:
        """The number P of object pixels."""
        return int(self.pixel_index.size)


class RayCaster:
    """Embree's first-hit query on one triangle mesh, its BVH built once (``embreex``, float32).

    Vertices are shifted by their minimum and scaled to a box of diagonal 100 before the cast to
    float32, as trimesh's wrapper does, so the float32 grid is as fine whatever the mesh's units; ray
    origins get the same map. Ours rather than ``trimesh.ray.ray_pyembree``: that wrapper re-hashes
    the mesh on every query (~1 ms, holding the GIL, on a 256² face's rays), which also kept two
    threads from casting faster than one.
    """

    def __init__(self, mesh: Trimesh) -> None:
        self._build(mesh)

    def __getstate__(self) -> dict[str, Trimesh]:
        return {"mesh": self.mesh}  # Embree's scene does not pickle: it is built again

    def __setstate__(self, state: dict[str, Trimesh]) -> None:
        self._build(state["mesh"])

    def _build(self, mesh: Trimesh) -> None:
        self.mesh = mesh
        vertices = np.asarray(mesh.vertices, float)
        self._origin = vertices.min(axis=0)
        self._scale = 100.0 / float(np.linalg.norm(np.ptp(vertices, axis=0)))
        self._scene = rtcore_scene.EmbreeScene()
        TriangleMesh(
            scene=self._scene,
            vertices=((vertices - self._origin) * self._scale).astype(np.float32),
            indices=np.asarray(mesh.faces, dtype=np.int32),
        )
        self._scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))  # commits the BVH now

    def first_hits(self, origins: ArrayLike, directions: ArrayLike) -> NDArray[np.int32]:
        """Index of the first triangle each ray (origins, world frame, m; directions, any length:
        (N, 3)) hits, −1 for a miss. The rays split over :func:`optlight.threads.map_slices` in runs
        of at least :data:`_RAYS_PER_THREAD`; each ray is cast on its own, so the result does not
        depend on the split."""
        return self.cast(self.framed(origins), _float32(directions))

    def any_hits(self, origins: ArrayLike, directions: ArrayLike) -> NDArray[np.bool_]:
        """Whether each ray (as :meth:`first_hits`) hits any triangle: Embree's occlusion query, which
        stops at the first hit it finds instead of looking for the nearest (7 % less time on the
        default face's shadow rays, on two threads: most of them hit nothing). Split over the
        threads as :meth:`first_hits`."""
        return self.cast(self.framed(origins), _float32(directions), occluded=True) >= 0

    def framed(self, points: ArrayLike) -> NDArray[np.float32]:
        """Points (N, 3), world frame (m), in the BVH's float32 frame: shifted and scaled as the mesh."""
        return ((np.asarray(points, float).reshape(-1, 3) - self._origin) * self._scale).astype(np.float32)

    def cast(
        self, origins: NDArray[np.float32], directions: NDArray[np.float32], occluded: bool = False
    ) -> NDArray[np.int32]:
        """Embree's query on rays already in the BVH's frame (origins from :meth:`framed`, float32
        directions, (N, 3) each), split over the threads as :meth:`first_hits`: the first triangle
        each hits (−1: a miss) or, ``occluded``, 0 where it hits any and −1 where it hits none."""
        if len(origins) == 0:
            return np.empty(0, np.int32)
        query = "OCCLUDED" if occluded else "INTERSECT"
        parts = map_slices(
            lambda s: self._scene.run(origins[s], directions[s], query=query), len(origins), _RAYS_PER_THREAD
        )
        return np.concatenate(parts)

    def first_hit_distances(self, origins: ArrayLike, directions: ArrayLike) -> Array:
        """Distance t (m) along each ray (origins (N, 3), unit directions (N, 3), world frame) to the
        first triangle it hits (:meth:`first_hits`), from that triangle's plane in float64: inf for
        a miss, or for a ray that grazes the plane."""
        o = np.asarray(origins, float).reshape(-1, 3)
        d = np.asarray(directions, float).reshape(-1, 3)
        tri = self.first_hits(o, d)
        out = np.full(len(o), np.inf)
        hit = np.flatnonzero(tri >= 0)
        out[hit] = _plane_distance(self.mesh, tri[hit], o[hit], d[hit])
        return out


def _float32(directions: ArrayLike) -> NDArray[np.float32]:
    """Ray directions (N, 3) as the float32 Embree takes."""
    return np.asarray(directions, np.float32).reshape(-1, 3)


def _plane_distance(mesh: Trimesh, triangles: NDArray[np.integer], origins: Array, directions: Array) -> Array:
    """Ray parameter t of the hit with each ray's triangle plane; inf where the ray grazes it."""
    normals = mesh.face_normals[triangles]
    denom = np.einsum("ij,ij->i", directions, normals)
    num = np.einsum("ij,ij->i", mesh.vertices[mesh.faces[triangles, 0]] - origins, normals)
    ok = np.abs(denom) > _GRAZING
    return np.where(ok, num / np.where(ok, denom, 1.0), np.inf)


def _barycentric(triangles: Array, points: Array) -> Array:
    """Barycentric coordinates (P, 3) of points in the planes of triangles (P, 3, 3):
    b_k = ((v_{k+1} − p) × (v_{k+2} − p))·n / |n|², n = (v₁ − v₀) × (v₂ − v₀)."""
    v0, v1, v2 = (triangles[:, k] - points for k in range(3))
    n = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    inv = 1.0 / np.einsum("ij,ij->i", n, n)
    b0 = np.einsum("ij,ij->i", np.cross(v1, v2), n) * inv
    b1 = np.einsum("ij,ij->i", np.cross(v2, v0), n) * inv
    return np.column_stack([b0, b1, 1.0 - b0 - b1])


def build_gbuffer(camera: Camera, obj: SceneObject, caster: RayCaster) -> GBuffer:
    """Cast one ray through each pixel centre (:meth:`Camera.rays`) and keep the object pixels.

    Per hit on triangle (v₀, v₁, v₂) with barycentric coordinates (b₀, b₁, b₂) (clipped to ≥ 0 and
    renormalised against float32 edge hits): n = Σ b_k n_k / |Σ b_k n_k|, ρ = Σ b_k ρ_k. For an
    exact sphere (centre c, radius r) the point is the nearer root of |o + t d − c| = r and
    n = (p − c)/r; the tessellation (inscribed) only decides which pixels are object pixels.
    """
    origins, directions = camera.rays()
    mesh = obj.mesh
    tri = caster.first_hits(origins, directions)
    hit = np.flatnonzero(tri >= 0)
    tri = tri[hit]
    t = _plane_distance(mesh, tri, origins[hit], directions[hit])
    keep = np.isfinite(t) & (t > 0)
    hit, tri, t = hit[keep], tri[keep], t[keep]
    o, d = origins[hit], directions[hit]
    if obj.sphere is not None:
        center, radius = obj.sphere
        oc = o - center
        half_b = np.einsum("ij,ij->i", d, oc)
        disc = np.maximum(half_b**2 - (np.einsum("ij,ij->i", oc, oc) - radius**2), 0.0)
        points = o + (-half_b - np.sqrt(disc))[:, None] * d
        normals = (points - center) / radius
    else:
        points = o + t[:, None] * d
    corners = mesh.faces[tri]
    bary = np.clip(_barycentric(mesh.vertices[corners], o + t[:, None] * d), 0.0, None)
    bary /= bary.sum(axis=1, keepdims=True)
    albedo = np.einsum("ij,ij->i", bary, obj.albedo[corners])
    if obj.sphere is None:
        normals = np.einsum("ij,ijk->ik", bary, mesh.vertex_normals[corners])
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        back = np.einsum("ij,ij->i", d, mesh.face_normals[tri]) > 0
        normals[back] *= -1.0
    mask = np.zeros(camera.height * camera.width, bool)
    mask[hit] = True
    return GBuffer(
        points=points,
        normals=normals,
        albedo=albedo,
        mask=mask.reshape(camera.height, camera.width),
        pixel_index=hit.astype(np.int64),
    )


class ShadowRays:
    """The cast-shadow rays of a G-buffer's points, their origins o_i = p_i + ε n_i built once: in
    the world frame (float64, the point light's distances) and in the caster's float32 frame (what
    Embree takes), so that a query only gathers the rays of the lit points (building and converting
    them at every query would take 5–6 % of its time on one thread: 0.3 ms of 6.1 ms for one light on the
    default face's 256² G-buffer, 0.4 ms of 7.0 ms for a sweep's 19 lights at 64²).

    ``model`` is the light's ("directional" or "point"), ``center`` (3,) the light sphere's centre
    (m, the directional light's direction is from it) and ``epsilon`` (m) the origins' offset along
    the normal, which clears the surface despite float32.
    """

    def __init__(
        self,
        caster: RayCaster,
        gbuffer: GBuffer,
        model: Literal["directional", "point"],
        center: ArrayLike,
        epsilon: float,
    ) -> None:
        self.caster, self.gbuffer, self.model, self.epsilon = caster, gbuffer, model, epsilon
        self.center = np.asarray(center, float)
        self._origins = gbuffer.points + epsilon * gbuffer.normals
        self._framed = caster.framed(self._origins)

    def visibility(self, light_position: ArrayLike) -> Array:
        """Visibility v_i ∈ {0, 1} of each G-buffer point for a light at ``light_position`` (3,),
        shape (P,); or for several lights (S, 3), shape (S, P), their rays cast in one call.

        The shadow ray starts at o_i and goes towards the light: directional, along
        l = (a − O)/|a − O| with O = ``center``, to infinity; point, towards a, and only a hit closer
        than a counts (a ray grazing the plane of the triangle it hits counts as unblocked). Rays
        are cast only where the point faces the light (n_i·l_i > 0); elsewhere v_i = 1, because that
        point is dark through max(0, n·l) (attached shadow), and v models cast shadows only. All
        the lights' rays go in one call: the ray caster's cost per call is ~40 % of a 64-px search
        render.
        """
        a = np.asarray(light_position, float)
        lights = a.reshape(-1, 3)
        n = self.gbuffer.normals
        if self.model == "directional":
            axis = lights - self.center
            unit = axis / np.linalg.norm(axis, axis=1, keepdims=True)
            lit = np.nonzero(np.einsum("ij,sj->si", n, unit) > 0)
            # one direction per light: gathered per ray, no (S, P, 3) array; any hit blocks the light
            directions = unit.astype(np.float32)[lit[0]]
            blocked = self.caster.cast(self._framed[lit[1]], directions, occluded=True) >= 0
        else:  # only a hit nearer than the light: the nearest hit's distance
            to_light = lights[:, None] - self.gbuffer.points
            dist = np.linalg.norm(to_light, axis=2)
            d = to_light / dist[..., None]
            lit = np.nonzero(np.einsum("ij,sij->si", n, d) > 0)
            dirs = d[lit]
            tri = self.caster.cast(self._framed[lit[1]], dirs.astype(np.float32))
            blocked = tri >= 0
            idx = np.flatnonzero(blocked)
            t = _plane_distance(self.caster.mesh, tri[idx], self._origins[lit[1][idx]], dirs[idx])
            blocked[idx] = t < dist[lit[0][idx], lit[1][idx]] - self.epsilon
        visibility = np.ones((len(lights), len(n)))
        visibility[lit[0][blocked], lit[1][blocked]] = 0.0
        return visibility.reshape(*a.shape[:-1], len(n))
