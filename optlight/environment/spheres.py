"""Spheres fitted to the robot's collision geometry: the NLPs' stand-in for the exact shapes.

Each body (a URDF link, or the light housing) is covered by k ≤ ``max_spheres`` spheres, fixed in its
joint frame. The fit (:func:`fit_spheres`) covers the *surface* of the body's convex pieces exactly:

1. the surface of each piece's convex hull (what the exact checks use) is subdivided to triangles
   with edges ≤ :data:`EDGE_M`;
2. its vertices are cut into k slabs of equal width along the principal axis (largest variance);
   each slab gets a near-smallest ball holding its points (:func:`_enclosing_balls`);
3. every triangle whose three corners are not inside one sphere grows the sphere that needs the
   least growth until they are. A sphere is convex, so then every triangle — the whole surface — is
   inside the union of spheres: clearance of the spheres ≥ m implies clearance of the surface ≥ m.

k is the count ≤ ``max_spheres`` with the least total volume Σ r³ (a long link gets more spheres; a
compact one, one). A robot's fit takes ~0.6 s (the Panda's 12 bodies) and depends only on the
surfaces, so it is kept in the disk cache (:mod:`optlight.cache`). Lengths in metres.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
import pinocchio as pin
import trimesh
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import ConvexHull

from optlight.cache import cached_arrays

Array = NDArray[np.float64]

#: Longest triangle edge of the subdivided hull surfaces the spheres are fitted to (m).
EDGE_M = 0.015
#: Iterations of the enclosing-ball approximation per sphere.
BALL_ITERATIONS = 400
#: Changed whenever what :func:`fit_spheres` computes changes, so that older cache entries are not read.
_CACHE_VERSION = 1


@dataclass(frozen=True)
class BodySpheres:
    """Spheres of one body: ``centers`` (k, 3) in the frame of ``joint`` (pinocchio joint index;
    0 = the world), ``radii`` (k,) in m."""

    name: str
    joint: int
    centers: Array
    radii: Array


def _subdivided(surfaces: list[trimesh.Trimesh]) -> tuple[Array, NDArray[np.int64]]:
    """Vertices and triangles of the convex hulls of ``surfaces``, subdivided to edges ≤ EDGE_M."""
    verts, tris, offset = [], [], 0
    for mesh in surfaces:
        hull = mesh.convex_hull
        v, f = trimesh.remesh.subdivide_to_size(hull.vertices, hull.faces, max_edge=EDGE_M)
        verts.append(v)
        tris.append(f + offset)
        offset += len(v)
    return np.concatenate(verts), np.concatenate(tris).astype(np.int64)


def _slabs(points: Array, k: int) -> list[NDArray[np.intp]]:
    """The indices of the points in each of k equal-width slabs along their principal axis (step 2);
    a slab without points (a gap in the shape) is left out, so it gets no sphere."""
    mean = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - mean, full_matrices=False)
    s = (points - mean) @ vt[0]
    edges = np.linspace(s.min(), s.max(), k + 1)
    slab = np.clip(np.searchsorted(edges, s, side="right") - 1, 0, k - 1)
    return [np.flatnonzero(slab == i) for i in np.unique(slab)]


def _enclosing_balls(point_sets: list[Array]) -> tuple[Array, Array]:
    """For each set of points, a ball holding them all, near the smallest one: Bădoiu–Clarkson,
    c ← c + (p_far − c)/(i + 1) from the mean for :data:`BALL_ITERATIONS` steps (radius within
    ~1/sqrt(iterations) of the optimum); each radius is the exact distance to the farthest point from
    the final centre. Centres (n, 3), radii (n,).

    The farthest point from any centre is a vertex of the points' convex hull, so the steps search
    the hull's vertices only (Qhull, joggled so that flat slabs still give one), and all sets step
    together (their vertices padded with copies of their first): the sequential steps cost one set's."""
    extremes = [p[ConvexHull(p, qhull_options="QJ").vertices] if len(p) > 4 else p for p in point_sets]
    width = max(len(e) for e in extremes)
    x = np.stack([np.concatenate([e, np.repeat(e[:1], width - len(e), axis=0)]) for e in extremes])
    c = np.stack([p.mean(axis=0) for p in point_sets])
    rows = np.arange(len(point_sets))
    for i in range(1, BALL_ITERATIONS + 1):
        d = x - c[:, None]
        c = c + d[rows, np.argmax(np.einsum("nij,nij->ni", d, d), axis=1)] / (i + 1)
    radii = np.array([np.linalg.norm(p - ci, axis=1).max() for p, ci in zip(point_sets, c, strict=True)])
    return c, radii


def _cover_triangles(points: Array, triangles: NDArray[np.int64], centers: Array, radii: Array) -> Array:
    """Grow radii until every triangle's corners lie inside one sphere (step 3); the new radii."""
    radii = radii.copy()
    dist = np.linalg.norm(points[:, None, :] - centers[None, :, :], axis=2)  # (V, k)
    need = dist[triangles].max(axis=1)  # (T, k): radius sphere j needs to hold triangle t
    for t in np.flatnonzero(~np.any(need <= radii, axis=1)):
        if np.any(need[t] <= radii):  # covered by an earlier growth
            continue
        j = int(np.argmin(need[t] - radii))
        radii[j] = need[t, j]
    return radii


def fit_spheres(surfaces: list[trimesh.Trimesh], max_spheres: int) -> tuple[Array, Array]:
    """Centres (k, 3) and radii (k,) of spheres covering the convex hulls of ``surfaces`` (all in
    one frame, m): the k ≤ ``max_spheres`` with the least Σ r³ (module docstring); from the disk
    cache when these surfaces were fitted before."""
    digest = hashlib.sha256()
    for mesh in surfaces:
        digest.update(np.ascontiguousarray(mesh.vertices, float).tobytes())
        digest.update(np.ascontiguousarray(mesh.faces, np.int64).tobytes())
    key = repr((_CACHE_VERSION, EDGE_M, BALL_ITERATIONS, int(max_spheres), digest.hexdigest()))

    def compute() -> dict[str, NDArray[Any]]:
        centers, radii = _fit(surfaces, max_spheres)
        return {"centers": centers, "radii": radii}

    fitted = cached_arrays("spheres", key, compute)
    return np.asarray(fitted["centers"], float), np.asarray(fitted["radii"], float)


def _fit(surfaces: list[trimesh.Trimesh], max_spheres: int) -> tuple[Array, Array]:
    """:func:`fit_spheres` computed."""
    points, triangles = _subdivided(surfaces)
    slabs = [_slabs(points, k) for k in range(1, max_spheres + 1)]
    centers, radii = _enclosing_balls([points[idx] for fit in slabs for idx in fit])
    best: tuple[float, Array, Array] | None = None
    start = 0
    for fit in slabs:
        c, r = centers[start : start + len(fit)], radii[start : start + len(fit)]
        start += len(fit)
        r = _cover_triangles(points, triangles, c, r)
        volume = float(np.sum(r**3))
        if best is None or volume < best[0]:
            best = (volume, c, r)
    assert best is not None
    return best[1], best[2]


class RobotSpheres:
    """The spheres of every body of a robot, stacked: ``bodies`` (tuple of :class:`BodySpheres`),
    ``joint`` (S,), ``centers`` (S, 3) in their joint frames, ``radii`` (S,), ``body`` (S,) index
    into ``bodies``."""

    def __init__(self, bodies: tuple[BodySpheres, ...]) -> None:
        self.bodies = bodies
        self.joint = np.concatenate([np.full(len(b.radii), b.joint) for b in bodies]).astype(int)
        self.centers = np.concatenate([b.centers for b in bodies])
        self.radii = np.concatenate([b.radii for b in bodies])
        self.body = np.concatenate([np.full(len(b.radii), i) for i, b in enumerate(bodies)]).astype(int)

    def __len__(self) -> int:
        return len(self.radii)

    def label(self, s: int) -> str:
        """``<body>[<i>]``: the body's name and the sphere's index within the body."""
        b = int(self.body[s])
        return f"{self.bodies[b].name}[{s - int(np.flatnonzero(self.body == b)[0])}]"

    def world_centers(self, model: pin.Model, data: pin.Data, q: ArrayLike) -> Array:
        """Sphere centres (S, 3) in the world frame at pinocchio configuration q (pinocchio FK)."""
        pin.forwardKinematics(model, data, np.asarray(q, float))
        out = np.empty_like(self.centers)
        for j in np.unique(self.joint):
            m = data.oMi[int(j)]
            sel = self.joint == j
            out[sel] = self.centers[sel] @ m.rotation.T + m.translation
        return out

    def symbolic_centers(self, joint_poses: dict[int, tuple[ca.SX, ca.SX]]) -> list[ca.SX]:
        """Sphere centres as CasADi 3×1 expressions from the joints' world poses (p, R), joint 0
        (the world) implied."""
        out = []
        for j, c in zip(self.joint, self.centers, strict=True):
            if j == 0:
                out.append(ca.SX(ca.DM(c)))
            else:
                p, r = joint_poses[int(j)]
                out.append(p + r @ ca.DM(c))
        return out
