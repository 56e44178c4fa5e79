"""The robot in its environment as one pinocchio GeometryModel, the pairs to check, and its spheres.

:class:`CollisionModel` puts together, for one robot and one environment:

- the robot's collision geometry from its URDF (:meth:`Robot.geometry_model`: hand joints reduced
  away, base placement applied), every mesh replaced by its convex hull (coal ``Convex``: GJK/EPA
  give true penetration depths; coal's mesh-vs-shape distances report only a per-triangle depth when
  in contact). The hull contains the mesh, so its distances never exceed the mesh's; the collision
  meshes of the arms in example-robot-data are convex or close to it (panda: hull volume = mesh
  volume to 1 %);
- the light housing: a cylinder (radius, length) behind the light frame, along −z_L, body "light";
- the obstacles (attached to the world) and the view cone.

Bodies are the URDF links (all geometry objects of one link) plus "light". Pairs checked
(:attr:`CollisionModel.pairs`):

- ``obstacle``: every moving body × every obstacle, threshold ``margin`` (bodies fixed to the world,
  such as a base resting on the table, are not checked: nothing the planner does changes them);
- ``self``: body pairs on different joints that are not adjacent (one joint the parent of the other),
  not disabled by the robot's SRDF, and not already in contact at the reference configuration θ_ref
  (touching by design, as MoveIt's "Default"); threshold ``self_margin``. A pair whose relative pose
  depends on at most :data:`~optlight.environment.never_close.NEVER_JOINTS` joints and that stays beyond ``self_margin`` at every angle
  of those joints (:func:`~optlight.environment.never_close.never_close_pairs`, as MoveIt's "Never") is checked exactly but
  gets no sphere rows: the lamp's housing next to a UR's first wrist link, 17 mm apart at the
  closest, is within the margin for the two spheres that cover them at every posture;
- ``view``: every moving body × the view cone, threshold 0 (the cone's margin is in its angle).

For the NLPs, :attr:`CollisionModel.spheres` cover every body (:mod:`.spheres`); the rows of the
clearance constraints are (sphere, obstacle) for moving spheres, except those that can never come
within ``margin`` + :data:`PRUNE_SLACK_M` of the obstacle (the sphere centre stays within a chain-length
bound of its first joint's origin and sd is 1-Lipschitz), and all sphere pairs of the self pairs.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import coal
import numpy as np
import pinocchio as pin
import trimesh
from numpy.typing import NDArray

from optlight.environment.never_close import never_close_pairs, ordered_pair
from optlight.environment.shapes import SMOOTHING_M, HalfSpace, Obstacle, ViewCone
from optlight.environment.spheres import BodySpheres, RobotSpheres, fit_spheres
from optlight.errors import RobotError
from optlight.robot.catalogue import ROBOTS, example_robot_data_dir
from optlight.robot.loading import Robot

Array = NDArray[np.float64]
PairKind = Literal["obstacle", "self", "view"]

#: A row whose spheres are closer than the margin at the (exactly clear) reference configuration
#: keeps this much less than they are there (m; :meth:`CollisionModel._self_row_margins`,
#: :meth:`CollisionModel._obstacle_row_margins`): more than the 2 mm the placements hold their
#: postures inside every row (``optlight.environment.CAPTURE_SLACK``), so that a posture near the
#: reference is still a capture posture (with 1 mm, a UR5 over a table at its base's height had no
#: light clear: its upper arm's sphere keeps about the same height at every angle).
REFERENCE_SLACK_M = 0.005
#: Sphere–obstacle rows are kept when the sphere can come this close beyond the margin (m).
PRUNE_SLACK_M = 0.05
#: Name of the light housing body.
LIGHT = "light"
#: Name of the view cone in pairs and reports.
VIEW_CONE = "view_cone"
#: Sides of the prisms and refinement of the polyhedra that stand in for round primitives when
#: spheres are fitted (they are circumscribed: they contain the exact shape).
_SECTIONS = 64
_ICO_SUBDIVISIONS = 2


@dataclass(frozen=True)
class Body:
    """A rigid body of the robot: a URDF link or the light housing. ``joint`` is its pinocchio
    joint (0 = fixed to the world); ``geometries`` index the geometry model."""

    name: str
    joint: int
    geometries: tuple[int, ...]


@dataclass(frozen=True)
class Pair:
    """A pair of geometry objects to check: ``first`` a robot geometry, ``second`` an obstacle, a
    robot geometry or the view cone; ``threshold`` the smallest allowed distance (m)."""

    kind: PairKind
    first: int
    second: int
    first_body: str
    second_name: str
    threshold: float


def robot_srdf(robot: Robot) -> Path | None:
    """The SRDF of a named example-robot-data robot loaded from its own URDF (None otherwise)."""
    info = ROBOTS.get(robot.name)
    if info is None or info.srdf is None:
        return None
    robots = example_robot_data_dir() / "example-robot-data" / "robots"
    if Path(robot.urdf_path).resolve() != (robots / info.urdf).resolve():
        return None
    return robots / info.srdf


def _surface(geometry: coal.CollisionGeometry, name: str) -> trimesh.Trimesh:
    """A closed triangle surface that contains the shape (in the shape's frame)."""
    if isinstance(geometry, coal.BVHModelBase):
        return trimesh.Trimesh(np.asarray(geometry.vertices(), float)).convex_hull
    if isinstance(geometry, coal.ConvexBase):
        return trimesh.Trimesh(np.asarray(geometry.points(), float)).convex_hull
    if isinstance(geometry, coal.Box):
        return trimesh.creation.box(extents=2.0 * np.asarray(geometry.halfSide, float))
    if isinstance(geometry, coal.Cylinder):
        r = geometry.radius / np.cos(np.pi / _SECTIONS)
        return trimesh.creation.cylinder(radius=r, height=2.0 * geometry.halfLength, sections=_SECTIONS)
    if isinstance(geometry, coal.Sphere):
        unit = trimesh.creation.icosphere(subdivisions=_ICO_SUBDIVISIONS)
        inradius = float(np.min(np.abs(np.einsum("ij,ij->i", unit.face_normals, unit.triangles[:, 0]))))
        unit.apply_scale(geometry.radius / inradius)
        return unit
    raise RobotError(
        f"collision geometry {name!r} is a {type(geometry).__name__}; the environment handles meshes, "
        "convex meshes, boxes, cylinders and spheres"
    )


def _convex(geometry: coal.CollisionGeometry) -> coal.CollisionGeometry:
    """Meshes become their convex hull (coal Convex, the hull's vertices and faces by Qhull);
    primitives stay.

    Not ``BVHModel.buildConvexRepresentation``: its Convex keeps every vertex of the mesh, those
    inside the hull too, and GJK's support search (hill climbing over vertex neighbours) stops at
    them. Between two UR10 links 19 mm apart it reported 465 mm."""
    if isinstance(geometry, coal.BVHModelBase):
        points = coal.StdVec_Vec3s()
        for p in np.asarray(geometry.vertices(), float):
            points.append(p)
        return coal.Convex.convexHull(points, False, "")
    return geometry


class CollisionModel:
    """Robot, light housing, obstacles and view cone in one GeometryModel (module docstring).

    Attributes: ``robot``; ``geometry`` (pin.GeometryModel) and ``geometry_data``; ``bodies``
    (tuple of :class:`Body`, robot links then the light); ``obstacles``; ``view_cone`` (or None);
    ``pairs`` (tuple of :class:`Pair`); ``ignored_self_pairs`` (body-name pairs in contact at θ_ref);
    ``never_close_pairs`` (body-name pairs that can never come within ``self_margin``: no sphere rows);
    ``spheres`` (:class:`RobotSpheres`, same body order); ``obstacle_rows`` ((S_o, 2) int: sphere,
    obstacle index), ``obstacle_row_margin`` ((S_o,) m: each row's margin,
    :meth:`_obstacle_row_margins`), ``self_rows`` ((S_s, 2) int: sphere, sphere), ``self_row_margin`` ((S_s,) m:
    each self row's margin, :meth:`_self_row_margins`), ``view_rows`` (sphere indices), ``beam_rows``
    (sphere indices: those not on the light's joint); ``fixed_obstacle_distance`` ((body, obstacle) →
    m: the pairs no motion changes, with their exact distance, :meth:`_fixed_obstacle_distances`);
    ``motion_weights`` (G, n): ρ such that a point of geometry g moves at most Σ_i ρ[g, i] |Δθ_i|
    between two configurations (m per rad, or m per m for prismatic joints).
    """

    def __init__(
        self,
        robot: Robot,
        obstacles: tuple[Obstacle, ...],
        view_cone: ViewCone | None,
        *,
        margin: float,
        self_margin: float,
        housing: coal.CollisionGeometry,
        housing_offset: float,
        max_spheres: int,
        self_collision: bool = True,
    ) -> None:
        self.robot = robot
        self.obstacles = obstacles
        self.view_cone = view_cone
        self.margin = float(margin)
        self.self_margin = float(self_margin)
        geom, surfaces, robot_pairs = self._robot_geometry(robot)
        light_id = self._add_housing(geom, housing, housing_offset, surfaces)
        body_of = self._group_bodies(geom, light_id)
        n_robot = len(geom.geometryObjects)
        candidates = self._self_candidates(geom, robot_pairs, light_id) if self_collision else []
        obstacle_ids, cone_id = self._add_scene(geom)
        self.geometry = geom
        self.geometry_data = pin.GeometryData(geom)
        touching, exact_ref = self._touching_at_reference(candidates, body_of)
        self.pairs = self._collision_pairs(n_robot, candidates, touching, obstacle_ids, cone_id, body_of)
        self.motion_weights = self._motion_weights(n_robot)
        self.never_close_pairs = never_close_pairs(self, body_of, surfaces)
        self._sphere_rows(surfaces, max_spheres, obstacle_ids, body_of, exact_ref)

    # ------------------------------------------------------------------ builders (in __init__'s order)
    @staticmethod
    def _robot_geometry(
        robot: Robot,
    ) -> tuple[pin.GeometryModel, list[trimesh.Trimesh], list[tuple[int, int]]]:
        """The robot's collision geometry with each shape replaced by its convex hull (coal's
        distances), the true surfaces (robot frame at the parent joint, for the sphere fit) and the
        robot-only pairs: all pairs on different joints, minus the SRDF's."""
        model = robot.model
        geom = robot.geometry_model("collision")
        surfaces: list[trimesh.Trimesh] = []
        for obj in geom.geometryObjects:
            surfaces.append(_surface(obj.geometry, obj.name).apply_transform(obj.placement.homogeneous))
            obj.geometry = _convex(obj.geometry)
        geom.addAllCollisionPairs()
        srdf = robot_srdf(robot)
        if srdf is not None:
            pin.removeCollisionPairs(model, geom, str(srdf))
        robot_pairs = [(cp.first, cp.second) for cp in geom.collisionPairs]
        geom.removeAllCollisionPairs()
        return geom, surfaces, robot_pairs

    def _add_housing(
        self,
        geom: pin.GeometryModel,
        housing: coal.CollisionGeometry,
        housing_offset: float,
        surfaces: list[trimesh.Trimesh],
    ) -> int:
        """Add the light housing, its shape centred ``housing_offset`` (m) behind the light frame
        along −z_L, to ``geom`` and its surface to ``surfaces``; its geometry index."""
        model = self.robot.model
        light_frame = model.frames[self.robot.light_frame_id]
        placement = light_frame.placement * pin.SE3(np.eye(3), np.array([0.0, 0.0, -housing_offset]))
        light_id = geom.addGeometryObject(
            pin.GeometryObject(LIGHT, light_frame.parentJoint, self.robot.light_frame_id, placement, housing)
        )
        surfaces.append(_surface(housing, LIGHT).apply_transform(placement.homogeneous))
        return int(light_id)

    def _group_bodies(self, geom: pin.GeometryModel, light_id: int) -> dict[int, Body]:
        """Set :attr:`bodies` (the geometry objects grouped by their link, the housing as the light);
        the body of each geometry index."""
        model = self.robot.model
        names: dict[str, list[int]] = {}
        joint_of: dict[str, int] = {}
        for g, obj in enumerate(geom.geometryObjects):
            body = LIGHT if g == light_id else model.frames[obj.parentFrame].name
            names.setdefault(body, []).append(g)
            joint_of[body] = int(obj.parentJoint)
        self.bodies = tuple(Body(n, joint_of[n], tuple(gs)) for n, gs in names.items())
        return {g: b for b in self.bodies for g in b.geometries}

    def _self_candidates(
        self, geom: pin.GeometryModel, robot_pairs: list[tuple[int, int]], light_id: int
    ) -> list[tuple[int, int]]:
        """The self pairs worth checking: the robot pairs and the light against every robot
        geometry, minus those on the same or adjacent joints."""
        model = self.robot.model
        n_robot = len(geom.geometryObjects)

        def adjacent(a: int, b: int) -> bool:
            ja, jb = int(geom.geometryObjects[a].parentJoint), int(geom.geometryObjects[b].parentJoint)
            return ja == jb or model.parents[ja] == jb or model.parents[jb] == ja

        candidates = [(a, b) for a, b in robot_pairs if not adjacent(a, b)]
        candidates += [(light_id, g) for g in range(n_robot) if g != light_id and not adjacent(light_id, g)]
        return candidates

    def _add_scene(self, geom: pin.GeometryModel) -> tuple[list[int], int | None]:
        """Add the obstacles and the view cone (world-fixed) to ``geom``; their geometry indices."""
        obstacle_ids = [
            geom.addGeometryObject(pin.GeometryObject(obs.name, 0, 0, obs.placement, obs.coal_geometry()))
            for obs in self.obstacles
        ]
        cone_id = None
        if self.view_cone is not None:
            cone_id = geom.addGeometryObject(
                pin.GeometryObject(VIEW_CONE, 0, 0, self.view_cone.placement, self.view_cone.coal_geometry())
            )
        return obstacle_ids, cone_id

    def _touching_at_reference(
        self, candidates: list[tuple[int, int]], body_of: dict[int, Body]
    ) -> tuple[set[tuple[int, int]], dict[tuple[str, str], float]]:
        """Place the geometry at θ_ref and measure the candidate self pairs there: those in contact
        are touching by design (set :attr:`ignored_self_pairs`). The touching pairs and the exact
        distance (m) per self body pair at θ_ref."""
        robot = self.robot
        pin.updateGeometryPlacements(
            robot.model, robot.data, self.geometry, self.geometry_data, robot.to_pin(robot.theta_ref)
        )
        reference = {(a, b): self.distance(a, b) for a, b in candidates}
        touching = {pair for pair, d in reference.items() if d <= 0.0}
        exact_ref: dict[tuple[str, str], float] = {}
        for (a, b), d in reference.items():
            pair = ordered_pair(body_of[a].name, body_of[b].name)
            exact_ref[pair] = min(exact_ref.get(pair, np.inf), d)
        self.ignored_self_pairs = tuple(sorted({(body_of[a].name, body_of[b].name) for a, b in touching}))
        return touching, exact_ref

    def _collision_pairs(
        self,
        n_robot: int,
        candidates: list[tuple[int, int]],
        touching: set[tuple[int, int]],
        obstacle_ids: list[int],
        cone_id: int | None,
        body_of: dict[int, Body],
    ) -> tuple[Pair, ...]:
        """The checked pairs: every moving robot geometry against every obstacle (``margin``), the
        candidate self pairs not touching at θ_ref (``self_margin``) and, with a view cone, every
        moving geometry against it (margin 0)."""
        geom = self.geometry
        moving = [g for g in range(n_robot) if geom.geometryObjects[g].parentJoint != 0]
        pairs = [
            Pair("obstacle", g, o, body_of[g].name, obs.name, self.margin)
            for g in moving
            for o, obs in zip(obstacle_ids, self.obstacles, strict=True)
        ]
        pairs += [
            Pair("self", a, b, body_of[a].name, body_of[b].name, self.self_margin)
            for a, b in candidates
            if (a, b) not in touching
        ]
        if cone_id is not None:
            pairs += [Pair("view", g, cone_id, body_of[g].name, VIEW_CONE, 0.0) for g in moving]
        return tuple(pairs)

    def _sphere_rows(
        self,
        surfaces: list[trimesh.Trimesh],
        max_spheres: int,
        obstacle_ids: list[int],
        body_of: dict[int, Body],
        exact_ref: dict[tuple[str, str], float],
    ) -> None:
        """Fit the spheres to each body's true surfaces and set their rows and margins (class
        docstring): obstacle and view rows, beam rows, self rows."""
        robot = self.robot
        self.spheres = RobotSpheres(
            tuple(
                BodySpheres(b.name, b.joint, *fit_spheres([surfaces[g] for g in b.geometries], max_spheres))
                for b in self.bodies
            )
        )
        self.fixed_obstacle_distance = self._fixed_obstacle_distances(obstacle_ids, body_of)
        self.obstacle_rows, self.view_rows = self._reachable_rows()
        # The beam: every sphere but those carried with the light (they stand where they stand
        # relative to its beam at any θ, so no plan can move them out of it).
        light_joint = int(robot.model.frames[robot.light_frame_id].parentJoint)
        self.beam_rows = np.flatnonzero(self.spheres.joint != light_joint)
        self.obstacle_row_margin = self._obstacle_row_margins(robot, obstacle_ids)
        self.self_rows = self._self_sphere_rows()
        self.self_row_margin = self._self_row_margins(robot, touching_free=exact_ref)

    def _self_sphere_rows(self) -> NDArray[np.int64]:
        """(S_s, 2) every (sphere, sphere) pair of the bodies of the self pairs (lower body first)."""
        body_index = {b.name: i for i, b in enumerate(self.bodies)}
        self_bodies = sorted(
            {
                tuple(sorted((body_index[p.first_body], body_index[p.second_name])))
                for p in self.pairs
                if p.kind == "self" and ordered_pair(p.first_body, p.second_name) not in self.never_close_pairs
            }
        )
        sb = self.spheres.body
        return np.array(
            [
                (s, t)
                for a, b in self_bodies
                for s in np.flatnonzero(sb == a)
                for t in np.flatnonzero(sb == b)
            ],
            dtype=int,
        ).reshape(-1, 2)

    # ------------------------------------------------------------------ helpers
    def _obstacle_row_margins(self, robot: Robot, obstacle_ids: list[int]) -> Array:
        """(S_o,) the margin of each (sphere, obstacle) row (m): ``margin``, lowered to what the
        sphere keeps from the obstacle at θ_ref less :data:`REFERENCE_SLACK_M` where it comes closer
        there while its body's exact distance to the obstacle is at least the margin (the reasons of
        :meth:`_self_row_margins`; a UR5's upper-arm sphere over a table at its base's height, 0.2 mm
        into it while the arm is 24 mm above it). Called with the geometry placed at θ_ref."""
        sp, rows = self.spheres, self.obstacle_rows
        margins = np.full(len(rows), self.margin)
        if not len(rows):
            return margins
        c = sp.world_centers(robot.model, robot.data, robot.to_pin(robot.theta_ref))
        exact: dict[tuple[int, int], float] = {}
        for k, (s, o) in enumerate(rows):
            b = int(sp.body[s])
            if (b, o) not in exact:
                exact[b, o] = min(self.distance(g, obstacle_ids[o]) for g in self.bodies[b].geometries)
            gap = float(self.obstacles[o].signed_distance(c[s : s + 1])[0]) - sp.radii[s]
            if exact[b, o] >= self.margin and gap < self.margin:
                margins[k] = gap - REFERENCE_SLACK_M
        return margins

    def _self_row_margins(self, robot: Robot, touching_free: dict[tuple[str, str], float]) -> Array:
        """(S_s,) the margin of each self row (m): ``self_margin``, lowered to what the two spheres
        keep at θ_ref less :data:`REFERENCE_SLACK_M` where the spheres come closer there than the
        margin while the two bodies' exact distance is at least the margin. The reference
        configuration is clear (coal); spheres closer there are the fit's excess over the shapes
        (up to a few cm), and a row below 0 at θ_ref would make every plan that starts or passes
        there infeasible for the NLPs. ``touching_free``: exact distance per self body pair at θ_ref."""
        sp, rows = self.spheres, self.self_rows
        margins = np.full(len(rows), self.self_margin)
        if not len(rows):
            return margins
        c = sp.world_centers(robot.model, robot.data, robot.to_pin(robot.theta_ref))
        gap = np.sqrt(np.sum((c[rows[:, 0]] - c[rows[:, 1]]) ** 2, axis=1) + SMOOTHING_M**2)
        gap -= sp.radii[rows].sum(axis=1)
        names = [b.name for b in sp.bodies]
        for k, (s, t) in enumerate(rows):
            pair = ordered_pair(names[sp.body[s]], names[sp.body[t]])
            if touching_free.get(pair, -np.inf) >= self.self_margin and gap[k] < self.self_margin:
                margins[k] = gap[k] - REFERENCE_SLACK_M
        return margins
    def distance(self, a: int, b: int) -> float:
        """coal distance (m, < 0 in contact) between geometry objects a and b at the current placements."""
        req, res = coal.DistanceRequest(), coal.DistanceResult()
        return float(
            coal.distance(
                self.geometry.geometryObjects[a].geometry,
                _transform(self.geometry_data.oMg[a]),
                self.geometry.geometryObjects[b].geometry,
                _transform(self.geometry_data.oMg[b]),
                req,
                res,
            )
        )

    def chain(self, joint: int) -> list[int]:
        """Moving joints from the root to ``joint`` (both included)."""
        return [int(j) for j in self.robot.model.supports[joint]][1:]

    def travel(self, j: int) -> float:
        """How far joint j can move its child's origin along its axis (m): prismatic range, else 0."""
        joint = self.robot.model.joints[j]
        if joint.shortname().removeprefix("JointModel").startswith("P"):
            k = joint.idx_v
            return float(max(abs(self.robot.lower[k]), abs(self.robot.upper[k])))
        return 0.0

    def _link_length(self, after: list[int]) -> float:
        """Upper bound on the distance between the origins of the joint before ``after`` and the
        last joint of ``after``: Σ (|translation of the joint placement| + travel)."""
        model = self.robot.model
        return float(
            sum(np.linalg.norm(model.jointPlacements[k].translation) + self.travel(k) for k in after)
        )

    def _motion_weights(self, n_robot: int) -> Array:
        """ρ[g, θ index] (class docstring): the distance from joint i's origin to any point of g
        bounds |∂p/∂θ_i| for a revolute joint; it is 1 for a prismatic joint."""
        model = self.robot.model
        weights = np.zeros((n_robot, self.robot.n))
        for g in range(n_robot):
            obj = self.geometry.geometryObjects[g]
            obj.geometry.computeLocalAABB()
            extent = np.linalg.norm(obj.placement.act(np.asarray(obj.geometry.aabb_center))) + float(
                obj.geometry.aabb_radius
            )
            chain = self.chain(int(obj.parentJoint))
            for i, j in enumerate(chain):
                if self.travel(j) > 0.0:
                    weights[g, model.joints[j].idx_v] = 1.0
                else:
                    weights[g, model.joints[j].idx_v] = self._link_length(chain[i + 1 :]) + extent
        return weights

    def _fixed_obstacle_distances(
        self, obstacle_ids: list[int], body_of: dict[int, Body]
    ) -> dict[tuple[str, str], float]:
        """Exact distances (m) of the (body, obstacle) pairs no motion changes: a body on the robot's
        first joint, a revolute joint whose axis is the normal of a half-space obstacle (a base joint
        turning about the vertical over a table), keeps every point's height over it. Measured at
        θ_ref (the geometry placements are θ_ref's when this is called)."""
        model, data = self.robot.model, self.robot.data
        pin.computeJointJacobians(model, data, self.robot.to_pin(self.robot.theta_ref))
        out: dict[tuple[str, str], float] = {}
        for oid, obs in zip(obstacle_ids, self.obstacles, strict=True):
            if not isinstance(obs, HalfSpace):
                continue
            for g, body in body_of.items():
                j = body.joint
                if j == 0 or model.parents[j] != 0 or self.travel(j) > 0.0:
                    continue
                axis = pin.getJointJacobian(model, data, j, pin.ReferenceFrame.WORLD)[3:, model.joints[j].idx_v]
                if abs(abs(float(axis @ obs.normal)) - 1.0) > 1e-9:
                    continue
                key = (body.name, obs.name)
                out[key] = min(out.get(key, np.inf), self.distance(g, oid))
        return out

    def _reachable_rows(self) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """(sphere, obstacle) rows and view-cone sphere rows that can come within margin + slack; a
        body's rows against an obstacle it keeps a fixed distance from, at least the margin
        (:attr:`fixed_obstacle_distance`), are left out: no motion can break them, and the spheres'
        excess over the shape there would be a violation no motion can mend either."""
        model, sp = self.robot.model, self.spheres
        rows, view = [], []
        for s in range(len(sp)):
            j = int(sp.joint[s])
            if j == 0:
                continue
            chain = self.chain(j)
            origin = model.jointPlacements[chain[0]].translation[None, :]
            reach = self.travel(chain[0]) + self._link_length(chain[1:]) + np.linalg.norm(sp.centers[s])
            reach += sp.radii[s] + self.margin + PRUNE_SLACK_M
            body = sp.bodies[int(sp.body[s])].name
            rows += [
                (s, o)
                for o, obs in enumerate(self.obstacles)
                if obs.signed_distance(origin)[0] < reach
                and self.fixed_obstacle_distance.get((body, obs.name), -np.inf) < self.margin
            ]
            if self.view_cone is not None and self.view_cone.signed_distance(origin)[0] < reach:
                view.append(s)
        return np.array(rows, dtype=int).reshape(-1, 2), np.array(view, dtype=int)


def _transform(m: pin.SE3) -> coal.Transform3s:
    return coal.Transform3s(m.rotation, m.translation)
