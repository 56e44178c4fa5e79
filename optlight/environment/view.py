"""Exact view and beam check at the captures: rays against the robot's collision meshes (docs/design.md §9).

Written independently of the planners' sphere and cone models (:mod:`optlight.environment.spheres`,
:class:`optlight.environment.shapes.ViewCone`): nothing here approximates the robot or the view.

- **View.** From the camera centre c, one ray to each of a set of object points the camera sees
  (the G-buffer's first hits, every pixel or an even subsample of them). A ray is blocked when a
  robot body or the light housing meets the open segment [c, p): its first hit is nearer than
  |p − c| − :data:`SURFACE_EPSILON_M`.
- **Beam.** From the light's emitting point a (the light frame's origin), one ray to each of those
  points that faces the light (n·(a − p) > 0); blocked when a robot body meets the segment farther
  than the housing radius from a. The housing is not an obstacle to its own beam, and neither is
  what the light is mounted in within that radius (the panda's closed fingers sit around its
  tool centre point): the head of the lamp occupies that ball.

Robot bodies: every collision geometry of the robot (example-robot-data's collision meshes, or its
boxes and cylinders), placed by pinocchio at the capture's joint angles, named by the link that
carries it. Meshes are used as they are (their exact triangles); boxes exactly; cylinders, spheres
and capsules by polygons circumscribed about them, so a ray that misses the polygon misses the
shape. The housing (``[light] housing``): a cylinder of radius r and length ℓ behind the emitting
point, along −z of the light frame, or a ball of radius r centred r behind it.

Rays are cast with Embree (:class:`~optlight.scene.gbuffer.RayCaster`) in each body's own frame, so
the bodies' BVHs are built once: a ray o + t d in the world is R^T(o − p) + t R^T d in a body placed
at (R, p). The distance to a hit comes from the hit triangle's plane, in float64.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import coal
import numpy as np
import pinocchio as pin
import trimesh
from numpy.typing import ArrayLike, NDArray

from optlight.errors import RobotError
from optlight.robot.loading import Robot
from optlight.scene.gbuffer import RayCaster

Array = NDArray[np.float64]

#: Name of the light housing in reports.
HOUSING = "light housing"
#: A hit this close to the object point (m) is the point's own neighbourhood, not an obstacle.
SURFACE_EPSILON_M = 1e-5
#: Object points cast per capture by default (an even subsample of the object pixels).
MAX_POINTS = 4096
#: Polygon sides of circumscribed cylinders; icosphere subdivisions of circumscribed spheres.
_SECTIONS = 48
_SUBDIVISIONS = 3


@dataclass(frozen=True)
class Housing:
    """The light's housing: ``shape`` "cylinder" (radius, length along −z of the light frame) or
    "sphere" (radius, centre ``radius`` behind the emitting point), in m."""

    shape: Literal["cylinder", "sphere"]
    radius_m: float
    length_m: float

    def mesh(self) -> trimesh.Trimesh:
        """The housing's surface in the light frame (circumscribed polygons)."""
        if self.shape == "cylinder":
            body = _cylinder(self.radius_m, self.length_m)
            body.apply_translation([0.0, 0.0, -0.5 * self.length_m])
        else:
            body = _ball(self.radius_m)
            body.apply_translation([0.0, 0.0, -self.radius_m])
        return body


@dataclass(frozen=True)
class CaptureView:
    """What blocks the camera and the beam at one capture. Fractions are of the rays cast;
    ``*_body`` is the body that is the first obstacle of the most blocked rays (None when clear),
    ``*_bodies`` every body that blocks some ray, most rays first."""

    capture: int
    time_s: float
    view_blocked: float
    view_body: str | None
    view_bodies: tuple[str, ...]
    beam_blocked: float
    beam_body: str | None
    beam_bodies: tuple[str, ...]


@dataclass(frozen=True)
class ViewReport:
    """The view and beam at every capture; ``view_rays`` rays from the camera per capture,
    ``beam_rays`` (per capture) those of the object points that face the light."""

    captures: tuple[CaptureView, ...]
    view_rays: int
    beam_rays: tuple[int, ...]

    @property
    def passed(self) -> bool:
        """No ray blocked at any capture."""
        return all(c.view_blocked == 0.0 and c.beam_blocked == 0.0 for c in self.captures)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-safe data."""
        return {
            "passed": self.passed,
            "view_rays": self.view_rays,
            "beam_rays": list(self.beam_rays),
            "captures": [
                {**c.__dict__, "view_bodies": list(c.view_bodies), "beam_bodies": list(c.beam_bodies)}
                for c in self.captures
            ],
        }


@dataclass(frozen=True)
class _Body:
    name: str
    caster: RayCaster
    geometry_index: int  # into the pinocchio GeometryModel; −1 for the housing (light frame)
    center: Array  # a ball holding the mesh, in the mesh's frame (m): rays far from it skip the mesh
    radius: float

    @classmethod
    def of(cls, name: str, mesh: trimesh.Trimesh, geometry_index: int) -> _Body:
        """The body of ``mesh``, with the ball about its bounding box's centre."""
        vertices = np.asarray(mesh.vertices, float)
        center = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
        radius = float(np.linalg.norm(vertices - center, axis=1).max())
        return cls(name, RayCaster(mesh), geometry_index, center, radius)


class ViewCheck:
    """The exact check of one robot, camera and object (module docstring).

    Args:
        robot: the robot (its collision geometry is read once here).
        camera_center: (3,) camera centre in the world (m).
        points: (P, 3) object points the camera sees (world, m), e.g. ``scene.gbuffer.points``.
        normals: (P, 3) their unit normals (for the beam's lit points).
        housing: the light housing.
        max_points: at most this many points are cast (an even subsample in pixel order).
    """

    def __init__(
        self,
        robot: Robot,
        camera_center: ArrayLike,
        points: ArrayLike,
        normals: ArrayLike,
        housing: Housing,
        *,
        max_points: int = MAX_POINTS,
    ) -> None:
        pts = np.asarray(points, float).reshape(-1, 3)
        nrm = np.asarray(normals, float).reshape(-1, 3)
        if pts.shape != nrm.shape or pts.shape[0] == 0:
            raise ValueError(f"points and normals must be the same non-empty (P, 3), got {pts.shape}, {nrm.shape}")
        keep = np.unique(np.linspace(0, len(pts) - 1, min(max_points, len(pts))).round().astype(int))
        self.points, self.normals = pts[keep], nrm[keep]
        self.camera_center = np.asarray(camera_center, float).reshape(3)
        self.robot = robot
        self.housing = housing
        self._geometry = robot.geometry_model("collision")
        self._geometry_data = self._geometry.createData()
        self._data = robot.model.createData()
        bodies = []
        for i, obj in enumerate(self._geometry.geometryObjects):
            link = robot.model.frames[obj.parentFrame].name
            bodies.append(_Body.of(link, _surface(obj.geometry, obj.name), i))
        self._bodies = tuple(bodies)
        self._housing = _Body.of(HOUSING, housing.mesh(), -1)

    def check(self, thetas: ArrayLike, times: ArrayLike) -> ViewReport:
        """View and beam at each capture: ``thetas`` (M, n) joint angles, ``times`` (M,) their times (s)."""
        q = np.asarray(thetas, float).reshape(-1, self.robot.n)
        t = np.asarray(times, float).reshape(-1)
        if t.size != q.shape[0]:
            raise ValueError(f"{q.shape[0]} configurations for {t.size} capture times")
        captures, beam_rays = [], []
        view_dirs, view_len = _unit(self.points - self.camera_center)
        for k, (theta, time_s) in enumerate(zip(q, t, strict=True)):
            placements = self._placements(theta)
            light = placements[-1]
            every = (*self._bodies, self._housing)
            view = self._first_hits(every, placements, self.camera_center, view_dirs, view_len, 0.0)
            a = light.translation
            lit = np.einsum("ij,ij->i", self.normals, a - self.points) > 0
            beam_dirs, beam_len = _unit(self.points[lit] - a)
            beam = self._first_hits(
                self._bodies, placements, a, beam_dirs, beam_len, self.housing.radius_m
            )
            beam_rays.append(int(lit.sum()))
            captures.append(
                CaptureView(
                    capture=k,
                    time_s=float(time_s),
                    view_blocked=_fraction(view, view_len.size),
                    view_body=_ranked(view)[0] if view else None,
                    view_bodies=_ranked(view),
                    beam_blocked=_fraction(beam, max(beam_len.size, 1)),
                    beam_body=_ranked(beam)[0] if beam else None,
                    beam_bodies=_ranked(beam),
                )
            )
        return ViewReport(tuple(captures), int(view_len.size), tuple(beam_rays))

    def _placements(self, theta: Array) -> list[pin.SE3]:
        """World placement of every collision geometry, then of the light frame (last)."""
        model, data = self.robot.model, self._data
        q = self.robot.to_pin(theta)
        pin.forwardKinematics(model, data, q)
        pin.updateGeometryPlacements(model, data, self._geometry, self._geometry_data)
        light = pin.updateFramePlacement(model, data, self.robot.light_frame_id)
        return [m.copy() for m in self._geometry_data.oMg] + [light.copy()]

    @staticmethod
    def _first_hits(
        bodies: Sequence[_Body],
        placements: list[pin.SE3],
        origin: Array,
        directions: Array,
        lengths: Array,
        skip_m: float,
    ) -> list[str]:
        """For each ray origin + s·direction, s ∈ (skip_m, length − ε), blocked by some body: the
        name of the body it meets first. Returns the names of the blocked rays' first bodies."""
        nearest = np.full(lengths.size, np.inf)
        first = np.full(lengths.size, -1)
        if lengths.size == 0:
            return []
        # the rays lie in the cone from the origin about their mean direction u, half-angle α, up to
        # the longest length: a body whose bounding sphere misses that cone cannot block any of them
        u = directions.sum(axis=0)
        u /= np.linalg.norm(u)
        alpha = float(np.arccos(np.clip((directions @ u).min(), -1.0, 1.0)))
        reach = float(lengths.max())
        for b, body in enumerate(bodies):
            m = placements[body.geometry_index]
            r, p = m.rotation, m.translation
            w = r @ body.center + p - origin
            if not _sphere_meets_cone(w, body.radius, u, alpha, reach):
                continue
            # only the rays whose segment (skip_m, length) passes within the body's ball can meet it
            along = np.clip(directions @ w, skip_m, lengths)
            gap = np.linalg.norm(w - along[:, None] * directions, axis=1)
            near = np.flatnonzero(gap <= body.radius * (1.0 + 1e-9) + 1e-12)
            if near.size == 0:
                continue
            local_o = np.broadcast_to(r.T @ (origin - p), (near.size, 3))
            hits = np.full(lengths.size, np.inf)
            hits[near] = _hit_distances(body.caster, local_o, directions[near] @ r, skip_m)
            closer = hits < nearest
            nearest[closer], first[closer] = hits[closer], b
        blocked = nearest < lengths - SURFACE_EPSILON_M
        return [bodies[i].name for i in first[blocked]]


def _sphere_meets_cone(w: Array, radius: float, axis: Array, alpha: float, reach: float) -> bool:
    """Whether the ball of ``radius`` (m) centred at ``w`` (m, from the apex) meets the cone of unit
    ``axis`` and half-angle ``alpha`` (rad) cut at distance ``reach`` (m) from the apex: the ball's
    centre is within ``radius`` of the apex, or nearer than ``reach`` + ``radius`` and at an angle
    from the axis at most ``alpha`` + asin(radius / |w|)."""
    distance = float(np.linalg.norm(w))
    if distance <= radius:
        return True
    if distance - radius > reach:
        return False
    angle = float(np.arccos(np.clip(w @ axis / distance, -1.0, 1.0)))
    return angle - float(np.arcsin(radius / distance)) <= alpha


def _hit_distances(caster: RayCaster, origins: Array, directions: Array, skip_m: float) -> Array:
    """Distance along each unit ray to its first hit beyond ``skip_m`` (inf where none)."""
    start = origins + skip_m * directions if skip_m > 0 else origins
    return caster.first_hit_distances(start, directions) + skip_m


def _unit(v: Array) -> tuple[Array, Array]:
    n = np.linalg.norm(v, axis=1)
    return v / np.where(n > 0, n, 1.0)[:, None], n


def _fraction(blocked: list[str], total: int) -> float:
    return len(blocked) / total if total else 0.0


def _ranked(names: list[str]) -> tuple[str, ...]:
    return tuple(name for name, _ in Counter(names).most_common())


def _cylinder(radius: float, length: float) -> trimesh.Trimesh:
    """A closed prism circumscribed about the cylinder (axis z, centred at the origin)."""
    return trimesh.creation.cylinder(
        radius=radius / np.cos(np.pi / _SECTIONS), height=length, sections=_SECTIONS
    )


def _ball(radius: float) -> trimesh.Trimesh:
    """An icosphere scaled so that its faces lie outside the ball (centred at the origin)."""
    unit = trimesh.creation.icosphere(subdivisions=_SUBDIVISIONS)
    inradius = float(np.min(np.abs(np.einsum("ij,ij->i", unit.face_normals, unit.triangles[:, 0]))))
    unit.apply_scale(radius / inradius)
    return unit


def _surface(geometry: coal.CollisionGeometry, name: str) -> trimesh.Trimesh:
    """The triangles of a collision geometry in its own frame: a mesh as it is, a primitive as a
    polygon containing it."""
    if isinstance(geometry, coal.BVHModelBase):
        vertices = np.asarray(geometry.vertices(), float)
        faces = np.array([[geometry.tri_indices(i)[k] for k in range(3)] for i in range(geometry.num_tris)], int)
        return trimesh.Trimesh(vertices, faces.reshape(-1, 3), process=False)
    if isinstance(geometry, coal.Box):
        return trimesh.creation.box(extents=2.0 * np.asarray(geometry.halfSide, float))
    if isinstance(geometry, coal.Cylinder):
        return _cylinder(geometry.radius, 2.0 * geometry.halfLength)
    if isinstance(geometry, coal.Sphere):
        return _ball(geometry.radius)
    if isinstance(geometry, coal.Capsule):
        cap = _ball(geometry.radius)
        ends = [cap.copy(), cap.copy()]
        ends[0].apply_translation([0.0, 0.0, geometry.halfLength])
        ends[1].apply_translation([0.0, 0.0, -geometry.halfLength])
        capsule = trimesh.util.concatenate([_cylinder(geometry.radius, 2.0 * geometry.halfLength), *ends])
        assert isinstance(capsule, trimesh.Trimesh)  # concatenating meshes gives a mesh
        return capsule
    raise RobotError(
        f"collision geometry {name!r} is a {type(geometry).__name__}; the view check handles meshes, "
        "boxes, cylinders, spheres and capsules"
    )


def view_check_for(robot: Robot, scene: Any, light: Any, *, max_points: int = MAX_POINTS) -> ViewCheck:
    """The check of a problem's robot and scene (``scene.camera.position``, ``scene.gbuffer``) with the
    housing of its ``[light]`` section (``housing``, ``housing_radius_m``, ``housing_length_m``)."""
    housing = Housing(light.housing, light.housing_radius_m, light.housing_length_m)
    return ViewCheck(
        robot, scene.camera.position, scene.gbuffer.points, scene.gbuffer.normals, housing, max_points=max_points
    )
