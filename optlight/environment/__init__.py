"""The robot's environment: obstacles, self-collision and the camera's view of the object.

:class:`Environment` is what the planners and the verifier use::

    env = Environment.from_problem(problem)
    g = env.clearance_function(robot)     # casadi θ -> distances − margins (≥ 0: clear)
    v = env.view_cone_function(robot)     # casadi θ -> distances to the view cone and the beam (≥ 0: clear)
    report = env.check(robot, thetas, times, capture_times=...)   # exact, coal

Three models of the same geometry, from coarse to exact:

- the NLPs see spheres fitted to each robot body (:mod:`.spheres`; they contain the body's convex
  collision shapes) against analytic obstacles (:mod:`.shapes`): row ``(s, o)`` of the clearance is
  sd_o(c_s(θ)) − r_s − margin, row ``(s, t)`` of two bodies that can collide is
  |c_s(θ) − c_t(θ)| − r_s − r_t − self_margin, a view row is sd_cone(c_s(θ)) − r_s, and a beam
  row is sd_beam(c_s(θ); a(θ)) − r_s, the beam's cone from the light a(θ) to the object
  (:class:`BeamCone`): what blocks the beam at a capture is planned around as what blocks the view;
- :meth:`Environment.sphere_clearance` evaluates the same rows with NumPy and pinocchio's kinematics
  (the reference the CasADi graph is tested against);
- :meth:`Environment.check` computes exact distances with coal between the robot's collision shapes,
  the light housing, the obstacles and the view cone (:mod:`.check`).

Obstacles of a problem (``[environment]``): the object's bounding sphere ("object", centre O, radius
``object_radius_m`` or the farthest point of the object's mesh), the table (a half-space below
``table_height_m``, "table"), the camera body (a box behind the camera centre, camera axes,
"camera_body") and its stand (a vertical cylinder from the body's lowest point down to the table, or
to z = 0, "camera_stand"), and the boxes, cylinders and spheres listed. The view cone is
:class:`ViewCone` around the object's bounding sphere, half-angle asin(R/d) + ``view_margin_deg``;
with it, the beam :class:`BeamCone` from the light to the same sphere, the same margin, starting
beyond the housing's radius (where the exact beam check starts its rays).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import casadi as ca
import coal
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from optlight.environment.check import (
    EnvironmentReport,
    EnvironmentViolation,
    PairClearance,
    check_configurations,
)
from optlight.environment.collision import LIGHT, VIEW_CONE, CollisionModel, robot_srdf
from optlight.environment.shapes import (
    SMOOTHING_M,
    Ball,
    BeamCone,
    Box,
    Cylinder,
    HalfSpace,
    Obstacle,
    ViewCone,
    rotation_rpy_deg,
)
from optlight.environment.spheres import RobotSpheres, fit_spheres
from optlight.errors import ProblemError
from optlight.robot.kinematics import symbolic_frame_pose
from optlight.robot.loading import Robot
from optlight.scene.camera import Camera
from optlight.scene.objects import build_object
from optlight.spec import EnvironmentSpec, Problem

Array = NDArray[np.float64]

__all__ = [
    "LIGHT",
    "OBJECT",
    "VIEW_CONE",
    "Ball",
    "BeamCone",
    "Box",
    "CollisionModel",
    "Cylinder",
    "Environment",
    "EnvironmentReport",
    "EnvironmentViolation",
    "HalfSpace",
    "Obstacle",
    "PairClearance",
    "RobotSpheres",
    "ViewCone",
    "fit_spheres",
    "listed_obstacles",
    "robot_srdf",
]

#: Names the environment gives its own obstacles (and the light housing, the view cone).
#: Environment rows (m) a capture keeps beyond the trajectory NLP's (c, v ≥ 0): the placements hold
#: their postures this far inside, and the landmark search's lights keep the housing this far out of
#: the view cone. A capture exactly on a row's bound, its light pinned, leaves the trajectory NLP no
#: interior there, and IPOPT reports it infeasible (seen on an RTI dome of 48 lights, a link
#: touching the view cone).
CAPTURE_SLACK = 0.002

#: Name of the obstacle that stands for the object: its bounding sphere (the object's mesh is drawn).
OBJECT = "object"

#: Name of the light's beam in row labels.
BEAM = "beam"

RESERVED_NAMES = (OBJECT, "table", "camera_body", "camera_stand", LIGHT, VIEW_CONE, BEAM)


def listed_obstacles(spec: EnvironmentSpec) -> list[tuple[str, Obstacle]]:
    """The boxes, cylinders and spheres of ``[environment]``, each with its key path
    (``environment.boxes[0]`` …), in file order."""
    out: list[tuple[str, Obstacle]] = []
    for i, b in enumerate(spec.boxes):
        box = Box(
            b.name, np.asarray(b.center_m, float), rotation_rpy_deg(b.rpy_deg), 0.5 * np.asarray(b.size_m)
        )
        out.append((f"environment.boxes[{i}]", box))
    for i, c in enumerate(spec.cylinders):
        cyl = Cylinder(
            c.name, np.asarray(c.center_m, float), rotation_rpy_deg(c.rpy_deg), c.radius_m, 0.5 * c.length_m
        )
        out.append((f"environment.cylinders[{i}]", cyl))
    for i, s in enumerate(spec.spheres):
        out.append((f"environment.spheres[{i}]", Ball(s.name, np.asarray(s.center_m, float), s.radius_m)))
    return out


def _check_layout(p: Problem) -> None:
    """Obstacle names unique and not reserved, no obstacle holding O or the camera centre, the table
    below both, the camera above the floor its stand ends on: a :class:`ProblemError` naming the key
    otherwise."""
    file = str(p.source) if p.source else "<inline>"
    env = p.environment
    seen: set[str] = set()
    center = np.asarray(p.object.center_m, float)
    eye = np.asarray(p.camera.position_m, float)
    for where, obstacle in listed_obstacles(env):
        if obstacle.name in RESERVED_NAMES or obstacle.name in seen:
            raise ProblemError(
                file,
                f"{where}.name",
                f"a name no other obstacle has (reserved: {', '.join(RESERVED_NAMES)})",
                obstacle.name,
            )
        seen.add(obstacle.name)
        for point, what in ((center, "the object centre"), (eye, "the camera centre")):
            if obstacle.signed_distance(point)[0] <= 0.0:
                raise ProblemError(file, where, f"an obstacle that does not contain {what} {point.tolist()}")
    floor = env.table_height_m
    if floor is not None and center[2] <= floor:
        raise ProblemError(
            file,
            "environment.table_height_m",
            f"a table below the object centre (z = {center[2]:g} m)",
            floor,
        )
    if env.camera_body and eye[2] <= (floor if floor is not None else 0.0):
        raise ProblemError(
            file,
            "camera.position_m",
            "a camera above the table (or above z = 0 without a table), where its stand ends",
            list(p.camera.position_m),
        )


class Environment:
    """Obstacles, view cone and margins of a problem (module docstring), independent of the robot;
    the robot-specific models (:class:`CollisionModel`: geometry, pairs, spheres) are built on first
    use per robot and cached.

    Attributes: ``obstacles`` (tuple of shapes with ``name``), ``view_cone`` (:class:`ViewCone`, or
    None when ``view_mode`` is "off"), ``view_mode`` ("off", "capture", "path"), ``margin`` and
    ``self_margin`` (m), ``beam`` (:class:`BeamCone`, None when the view is off), ``housing`` (the
    light housing's coal shape) and ``housing_offset`` (m, its
    centre behind the light frame along −z), ``spheres_per_link``, ``collisions`` (obstacles and
    self-collision modelled: ``[environment] enabled``; without them only the view is).
    """

    def __init__(
        self,
        obstacles: tuple[Obstacle, ...],
        view_cone: ViewCone | None,
        *,
        view_mode: str,
        margin: float,
        self_margin: float,
        housing: coal.CollisionGeometry,
        housing_offset: float,
        spheres_per_link: int,
        collisions: bool = True,
        beam: BeamCone | None = None,
    ) -> None:
        names = [o.name for o in obstacles]
        if len(set(names)) != len(names):
            raise ValueError(f"obstacle names must be unique, got {names}")
        if view_mode not in ("off", "capture", "path") or (view_mode != "off") != (view_cone is not None):
            raise ValueError(f"view_mode {view_mode!r} does not match the view cone {view_cone}")
        if beam is not None and view_cone is None:
            raise ValueError("the beam is planned with the view: no beam without a view cone")
        self.beam = beam
        self.obstacles = tuple(obstacles)
        self.view_cone = view_cone
        self.view_mode = view_mode
        self.margin = float(margin)
        self.self_margin = float(self_margin)
        self.housing = housing
        self.housing_offset = float(housing_offset)
        self.spheres_per_link = int(spheres_per_link)
        self.collisions = bool(collisions)
        self._models: dict[int, CollisionModel] = {}
        self._functions: dict[tuple[int, str], tuple[Robot, ca.Function]] = {}
        self._labels: dict[int, tuple[Robot, tuple[str, ...]]] = {}
        self._rows_sx: dict[int, tuple[Robot, ca.SX, list[ca.SX]]] = {}

    @classmethod
    def from_problem(cls, problem: Problem, object_vertices: ArrayLike | None = None) -> Environment:
        """The environment of a problem: the obstacles of ``[environment]`` and self-collision when it
        is enabled, the camera's view (``[view]``) unless its mode is "off", the light housing of
        ``[light]``. ``object_vertices`` (V, 3), world frame, m: the built object's, for its bounding
        sphere when ``object_radius_m`` is not set (built from the problem when not given)."""
        spec = problem.environment
        center = np.asarray(problem.object.center_m, float)
        if spec.enabled:
            _check_layout(problem)
        if spec.object_radius_m is not None:
            radius = float(spec.object_radius_m)
        else:
            vertices = build_object(problem).mesh.vertices if object_vertices is None else object_vertices
            radius = float(np.max(np.linalg.norm(np.asarray(vertices, float) - center, axis=1)))
        obstacles: list[Obstacle] = [Ball(OBJECT, center, radius)]
        if spec.table_height_m is not None:
            obstacles.append(HalfSpace("table", np.array([0.0, 0.0, 1.0]), float(spec.table_height_m)))
        camera = Camera.from_spec(problem.camera, center)
        if spec.camera_body:
            half = 0.5 * np.asarray(spec.camera_body_size_m, float)
            body_center = camera.position - half[2] * camera.rotation[:, 2]
            obstacles.append(Box("camera_body", body_center, camera.rotation, half))
            bottom = body_center[2] - float(np.abs(camera.rotation[2]) @ half)
            floor = spec.table_height_m if spec.table_height_m is not None else 0.0
            if bottom > floor:
                stand_center = np.array([body_center[0], body_center[1], 0.5 * (bottom + floor)])
                obstacles.append(
                    Cylinder(
                        "camera_stand",
                        stand_center,
                        np.eye(3),
                        spec.camera_stand_radius_m,
                        0.5 * (bottom - floor),
                    )
                )
        obstacles += [obs for _, obs in listed_obstacles(spec)]
        view = problem.view
        cone, beam = None, None
        light = problem.light
        if view.mode != "off":
            cone = ViewCone.around(camera.position, center, radius, math.radians(view.margin_deg))
            beam = BeamCone(center, radius, math.radians(view.margin_deg), light.housing_radius_m)
        if light.housing == "cylinder":
            housing, offset = (
                coal.Cylinder(light.housing_radius_m, light.housing_length_m),
                0.5 * light.housing_length_m,
            )
        else:
            housing, offset = coal.Sphere(light.housing_radius_m), light.housing_radius_m
        return cls(
            tuple(obstacles) if spec.enabled else (),
            cone,
            view_mode=view.mode,
            margin=spec.margin_m,
            self_margin=spec.self_margin_m,
            housing=housing,
            housing_offset=offset,
            spheres_per_link=spec.spheres_per_link,
            collisions=spec.enabled,
            beam=beam,
        )

    # ------------------------------------------------------------------ robot models
    def collision_model(self, robot: Robot) -> CollisionModel:
        """The robot in this environment: geometry, pairs and spheres (built once per robot)."""
        key = id(robot)
        if key not in self._models or self._models[key].robot is not robot:
            self._models[key] = CollisionModel(
                robot,
                self.obstacles,
                self.view_cone,
                margin=self.margin,
                self_margin=self.self_margin,
                housing=self.housing,
                housing_offset=self.housing_offset,
                max_spheres=self.spheres_per_link,
                self_collision=self.collisions,
            )
        return self._models[key]

    def clearance_labels(self, robot: Robot) -> list[str]:
        """One label per row of :meth:`clearance_function`: ``"<body>[i] ↔ <obstacle>"`` for the
        obstacle rows, then ``"<body>[i] ↔ <body>[j]"`` for the self-collision rows."""
        cm = self.collision_model(robot)
        sp = cm.spheres
        obs = [f"{sp.label(s)} ↔ {self.obstacles[o].name}" for s, o in cm.obstacle_rows]
        own = [f"{sp.label(s)} ↔ {sp.label(t)}" for s, t in cm.self_rows]
        return obs + own

    def view_labels(self, robot: Robot, *, beam: bool = True) -> list[str]:
        """One label per row of :meth:`view_cone_function`: ``"<body>[i] ↔ view_cone"``, then (with
        ``beam``) ``"<body>[i] ↔ beam"`` (empty when the view cone is off)."""
        if self.view_cone is None:
            return []
        cm = self.collision_model(robot)
        labels = [f"{cm.spheres.label(s)} ↔ {VIEW_CONE}" for s in cm.view_rows]
        if beam and self.beam is not None:
            labels += [f"{cm.spheres.label(int(s))} ↔ {BEAM}" for s in cm.beam_rows]
        return labels

    def worst_sphere_row(self, robot: Robot, theta: ArrayLike) -> tuple[float, str]:
        """The smallest row of :meth:`sphere_clearance` at θ (rad), clearance and view rows together,
        and its label (:meth:`clearance_labels`, :meth:`view_labels`): (m, label); (inf, "") when
        there are no rows. Negative means the spheres at θ break a margin or enter the view cone."""
        clearance, view = self.sphere_clearance(robot, theta)
        rows = np.concatenate([clearance, view])
        if rows.size == 0:
            return math.inf, ""
        k = int(np.argmin(rows))
        return float(rows[k]), self._row_labels(robot)[k]

    def _row_labels(self, robot: Robot) -> tuple[str, ...]:
        """:meth:`clearance_labels` then :meth:`view_labels`, made once per robot: the placement asks
        for the worst row at every posture it tries (111k labels made for 144 captures, 0.5 s)."""
        key = id(robot)
        if key not in self._labels or self._labels[key][0] is not robot:
            self._labels[key] = (robot, (*self.clearance_labels(robot), *self.view_labels(robot)))
        return self._labels[key][1]

    def _cached(self, robot: Robot, name: str, build: Callable[[], ca.Function]) -> ca.Function:
        """The CasADi function ``name`` of ``robot``, built on first use and kept (building the SX
        graph of every sphere row costs ~0.1–0.5 s, and every NLP asks for it)."""
        key = (id(robot), name)
        if key not in self._functions or self._functions[key][0] is not robot:
            self._functions[key] = (robot, build())
        return self._functions[key][1]

    def clearance_function(self, robot: Robot, rows: Sequence[int] | None = None) -> ca.Function:
        """``casadi.Function("clearance", [theta (n×1)], [c (m×1)])``, m = obstacle rows + self rows
        (:meth:`clearance_labels`): c ≥ 0 means every sphere clears every obstacle by ``margin`` and
        every self pair by ``self_margin`` (m). ``rows``: only these rows, in this order (indices
        into the full list, e.g. the rows that can bind near some knots); all by default. SX graph, common subexpressions
        eliminated; built once per robot and row selection."""
        name = "clearance" if rows is None else f"clearance{tuple(int(i) for i in rows)}"
        return self._cached(robot, name, lambda: self._build_clearance(robot, rows))

    def _build_clearance(self, robot: Robot, selected: Sequence[int] | None) -> ca.Function:
        theta, rows = self._clearance_rows_sx(robot)
        if selected is not None:
            rows = [rows[i] for i in selected]
        out = ca.vertcat(*rows) if rows else ca.SX(0, 1)
        return ca.Function("clearance", [theta], [out], ["theta"], ["clearance"], {"cse": True})

    def _clearance_rows_sx(self, robot: Robot) -> tuple[ca.SX, list[ca.SX]]:
        """θ and every clearance row as an SX expression of it, built once per robot: each NLP window
        selects its own rows, and the kinematics of the spheres were most of the
        time of building a selection's function."""
        key = id(robot)
        if key not in self._rows_sx or self._rows_sx[key][0] is not robot:
            cm = self.collision_model(robot)
            theta = ca.SX.sym("theta", robot.n)
            centers = self._symbolic_centers(robot, cm.spheres, theta)
            r = cm.spheres.radii
            rows = [
                self.obstacles[o].signed_distance_sx(centers[s]) - r[s] - self.margin
                for s, o in cm.obstacle_rows
            ]
            rows += [
                ca.sqrt(ca.sumsqr(centers[s] - centers[t]) + SMOOTHING_M**2) - r[s] - r[t] - self.self_margin
                for s, t in cm.self_rows
            ]
            self._rows_sx[key] = (robot, theta, rows)
        return self._rows_sx[key][1], self._rows_sx[key][2]

    def clearance_values(self, robot: Robot, thetas: ArrayLike) -> Array:
        """(K, m): the clearance rows of :meth:`sphere_clearance` (m) at each of ``thetas`` (K, n),
        rad; with no configuration, (0, m)."""
        values = [self.sphere_clearance(robot, theta, beam=False)[0] for theta in np.atleast_2d(thetas)]
        if values:
            return np.array(values)
        cm = self.collision_model(robot)
        return np.zeros((0, len(cm.obstacle_rows) + len(cm.self_rows)))

    def view_cone_function(self, robot: Robot, *, beam: bool = True) -> ca.Function:
        """``casadi.Function("view_clearance", [theta (n×1)], [v (m×1)])``: per robot sphere that can
        reach the cone (:attr:`CollisionModel.view_rows`, the light's included), its signed distance to
        the view cone minus its radius (m); then, with ``beam`` (the light at a capture), per sphere
        not carried with the light (:attr:`CollisionModel.beam_rows`) its signed distance to the beam
        from the light a(θ) minus its radius. v ≥ 0 means out of the camera's view of the object and
        out of the light's beam onto it. Raises ValueError when ``view_mode`` is "off". Built once per
        robot."""
        if self.view_cone is None:
            raise ValueError("the view cone is off (environment.view_cone = 'off')")
        with_beam = beam and self.beam is not None
        return self._cached(robot, "view+beam" if with_beam else "view", lambda: self._build_view(robot, with_beam))

    def _build_view(self, robot: Robot, beam: bool) -> ca.Function:
        assert self.view_cone is not None
        cm = self.collision_model(robot)
        theta = ca.SX.sym("theta", robot.n)
        centers = self._symbolic_centers(robot, cm.spheres, theta)
        rows = [self.view_cone.signed_distance_sx(centers[s]) - cm.spheres.radii[s] for s in cm.view_rows]
        if beam and self.beam is not None:
            apex = robot.symbolic_light_pose(theta)[0]
            rows += [self.beam.signed_distance_sx(centers[s], apex) - cm.spheres.radii[s] for s in cm.beam_rows]
        out = ca.vertcat(*rows) if rows else ca.SX(0, 1)
        return ca.Function("view_clearance", [theta], [out], ["theta"], ["view_clearance"], {"cse": True})

    @staticmethod
    def _symbolic_centers(robot: Robot, spheres: RobotSpheres, theta: ca.SX) -> list[ca.SX]:
        model = robot.model
        poses = {}
        for j in np.unique(spheres.joint):
            if j == 0:
                continue
            fid = model.getFrameId(model.names[int(j)], pin.FrameType.JOINT)
            p, r = symbolic_frame_pose(model, fid, name=f"joint_{int(j)}_pose")(theta)
            poses[int(j)] = (p, r)
        return spheres.symbolic_centers(poses)

    def sphere_clearance(self, robot: Robot, theta: ArrayLike, *, beam: bool = True) -> tuple[Array, Array]:
        """NumPy twin of :meth:`clearance_function` and :meth:`view_cone_function` (``beam`` the
        same) at one θ (rad), from pinocchio's kinematics: (clearance rows (m,), view rows) in m."""
        cm = self.collision_model(robot)
        sp = cm.spheres
        c = sp.world_centers(robot.model, robot.data, robot.to_pin(theta))
        r = sp.radii
        obs = np.empty(len(cm.obstacle_rows))
        for o in np.unique(cm.obstacle_rows[:, 1]):  # one call per obstacle, over all its spheres
            rows = np.flatnonzero(cm.obstacle_rows[:, 1] == o)
            spheres = cm.obstacle_rows[rows, 0]
            obs[rows] = self.obstacles[o].signed_distance(c[spheres]) - r[spheres] - self.margin
        d = c[cm.self_rows[:, 0]] - c[cm.self_rows[:, 1]]
        own = np.sqrt(np.sum(d * d, axis=1) + SMOOTHING_M**2) - r[cm.self_rows].sum(axis=1) - self.self_margin
        clearance = np.concatenate([obs, own])
        view = (
            self.view_cone.signed_distance(c[cm.view_rows]) - r[cm.view_rows]
            if self.view_cone is not None
            else np.zeros(0)
        )
        if beam and self.beam is not None:
            apex = robot.light_pose(theta)[0]
            view = np.concatenate([view, self.beam.signed_distance(c[cm.beam_rows], apex) - r[cm.beam_rows]])
        return clearance, view

    # ------------------------------------------------------------------ exact checks
    def check(
        self,
        robot: Robot,
        thetas: ArrayLike,
        times: ArrayLike,
        capture_times: ArrayLike | None = None,
    ) -> EnvironmentReport:
        """Exact coal checks of the configurations ``thetas`` (T, n) at ``times`` (T,) (s):
        robot–obstacle distance ≥ ``margin``, self distance ≥ ``self_margin``, and, per
        ``view_mode``, no robot body or light in the view cone at the samples at ``capture_times``
        ("capture"; each must be one of ``times``) or at every sample ("path").
        See :func:`optlight.environment.check.check_configurations`."""
        return check_configurations(
            self.collision_model(robot), thetas, times, view=self.view_mode, capture_times=capture_times
        )
