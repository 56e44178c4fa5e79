"""Meshcat preview of a plan: the robot, the shaded object, the light sphere, the landmarks, the
light path, the camera with its frustum and the light, with the timed trajectory as an animation.

The scene is built once, as meshcat commands kept in a scene tree (the one meshcat's server keeps),
so it can be written as one self-contained HTML file (:meth:`Preview.static_html`, no server: the
viewer's JavaScript, the meshes and the animation are inlined) or served live
(:meth:`Preview.serve`, a meshcat server on 127.0.0.1 that ends with the ``with`` block)::

    preview = Preview(scene, robot, landmarks, costs, path, trajectory)
    preview.save_html("plan.html")
    with preview.serve() as url:
        input(f"open {url}, then press Enter")

What is drawn (node paths under ``/meshcat``, see the ``*_NODE`` constants):

- ``robot``: pinocchio's ``MeshcatVisualizer`` with the robot's visual meshes, decimated for display
  with their material colours (:mod:`optlight.viz.meshes`); UR robots with their collision meshes
  (their COLLADA visuals render broken in meshcat, docs/design.md §7);
- ``object``: the object mesh (decimated to :data:`OBJECT_MESH_FACES` triangles when larger), unlit,
  coloured by the luminance model of docs/design.md §4 evaluated per vertex (no cast shadows) for the light at
  ``light_position``, as a grey level (white = saturation);
- ``light_sphere``: the sphere of radius b around O, transparent;
- ``landmarks/NNN``: one small sphere per landmark, coloured by its cost (viridis, low = dark);
- ``path``: a line through the light positions of the planned path;
- ``camera``: the camera body and its frustum (lines from the centre to the image corners, at the
  object's depth);
- ``obstacles/<name>``: the environment's obstacles the plan keeps clear of (``obstacles``), grey and
  half transparent, each as the exact shape the verification checks (a box, a cylinder, a ball; a
  half-space, the table, as a slab :data:`TABLE_SIDE_M` wide and :data:`TABLE_THICKNESS_M` thick
  whose top is its plane, centred under the object);
- ``light``: the light frame (animated), a bulb at its origin and a cone along its +z axis.

With a trajectory, an animation moves the robot's links and the light from the trajectory's start to
its end; it plays once when the page opens and can be replayed or scrubbed in the viewer's
"Animations" panel. The viewer interpolates between keyframes (positions linearly, orientations by
slerp), so of the poses at ``fps`` frames per second only the keyframes are kept that this
interpolation needs to stay within :data:`~optlight.viz.keyframes.KEY_TOLERANCE_M` and
:data:`~optlight.viz.keyframes.KEY_TOLERANCE_RAD` of every frame
(:func:`~optlight.viz.keyframes.select_keyframes`): a robot at rest during a dwell needs two.
"""

from __future__ import annotations

import base64
import html
import json
import re
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Protocol

import matplotlib
import meshcat
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
import trimesh
from meshcat.servers.zmqserver import VIEWER_ROOT
from numpy.typing import ArrayLike, NDArray
from pinocchio.visualize import MeshcatVisualizer
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from optlight.environment.shapes import Ball, Box, Cylinder, HalfSpace, Obstacle
from optlight.geometry import LightSphere
from optlight.scene.camera import Camera
from optlight.scene.render import lambertian
from optlight.spec import LightSpec
from optlight.viz.keyframes import (
    KEY_TOLERANCE_M,
    KEY_TOLERANCE_RAD,
    animation_times,
    continuous_quaternions,
    select_keyframes,
)
from optlight.viz.meshes import CompactMeshGeometry, decimate, display_mesh, float32_ext
from optlight.viz.recording import HTML_TEMPLATE, SceneCommand, SceneRecorder
from optlight.viz.server import MeshcatServer

Array = NDArray[np.float64]

ROBOT_NODE = "robot"
OBJECT_NODE = "object"
SPHERE_NODE = "light_sphere"
LANDMARKS_NODE = "landmarks"
PATH_NODE = "path"
CAMERA_NODE = "camera"
LIGHT_NODE = "light"
OBSTACLES_NODE = "obstacles"
#: Side and thickness (m) of the slab that shows a half-space obstacle (the table).
TABLE_SIDE_M = 1.6
TABLE_THICKNESS_M = 0.02

#: Robots drawn with their collision meshes: meshcat renders their COLLADA visual meshes broken.
_COLLISION_MESH_ROBOTS = re.compile(r"^ur\d+")
_COLLISION_MESH_COLOR = (0.62, 0.66, 0.72, 1.0)
_LIGHT_COLOR = 0xFFC800
#: Triangles of the object on display; a larger mesh is decimated. The default face (101,760) is
#: kept whole: decimated to 30,000 (0.5 MB of the page instead of 1.8 MB) its shading, what the
#: preview shows of the plan, came out streaked, the eyes and lips smeared.
OBJECT_MESH_FACES = 120_000


class SceneLike(Protocol):
    """What the preview reads from :class:`optlight.scene.Scene`."""

    camera: Camera
    sphere: LightSphere
    mesh: trimesh.Trimesh
    albedo: Array
    light: LightSpec


class RobotLike(Protocol):
    """What the preview reads from :class:`optlight.robot.Robot`."""

    name: str
    model: pin.Model
    light_frame_id: int
    theta_ref: Array
    base_placement: pin.SE3

    def to_pin(self, theta: ArrayLike) -> Array: ...

    def geometry_model(self, kind: Any = "collision") -> pin.GeometryModel: ...


class TrajectoryLike(Protocol):
    """What the preview reads from a timed trajectory (:class:`optlight.motion.Trajectory`)."""

    @property
    def duration(self) -> float: ...

    def sample(self, t: ArrayLike) -> tuple[Array, Array, Array]: ...


class Preview:
    """The meshcat scene of a plan (see the module docstring); built in the constructor.

    Arguments: the problem's ``scene`` and ``robot``; ``landmarks_positions`` (M, 3) in m with their
    ``landmark_costs`` (M,); ``path_positions`` (K, 3), the light's planned path in m; an optional
    timed ``trajectory`` (joint angles θ). Keywords: ``theta``, the joint angles shown without a
    trajectory (default: the trajectory's start, else the robot's reference configuration);
    ``light_position`` (m), where the light is for the object's shading (default: the light frame's
    origin in the configuration shown); ``obstacles``, the environment's shapes to draw;
    ``show_robot`` False leaves the robot's meshes out (the
    light is still placed by its kinematics); ``fps``, the rate (frames/s) of the poses the
    animation's keyframes are chosen from.
    """

    def __init__(
        self,
        scene: SceneLike,
        robot: RobotLike,
        landmarks_positions: ArrayLike,
        landmark_costs: ArrayLike,
        path_positions: ArrayLike,
        trajectory: TrajectoryLike | None = None,
        *,
        theta: ArrayLike | None = None,
        light_position: ArrayLike | None = None,
        obstacles: Sequence[Obstacle] = (),
        show_robot: bool = True,
        fps: float = 30.0,
    ) -> None:
        landmarks = np.asarray(landmarks_positions, float).reshape(-1, 3)
        costs = np.asarray(landmark_costs, float).reshape(-1)
        if costs.shape != (len(landmarks),):
            raise ValueError(f"{len(landmarks)} landmarks but {costs.size} landmark costs")
        if fps <= 0:
            raise ValueError(f"fps must be positive, got {fps}")
        self.scene = scene
        self.robot = robot
        self.trajectory = trajectory
        self.fps = float(fps)
        if trajectory is not None:
            theta0 = trajectory.sample(0.0)[0][0]
        elif theta is not None:
            theta0 = np.asarray(theta, float)
        else:
            theta0 = np.asarray(robot.theta_ref, float)
        self.theta = theta0
        #: whether the robot holds the light where it should (see :meth:`at_best_landmark`)
        self.reached = True
        self._data = robot.model.createData()
        self.light_pose = self._light_placement(theta0)
        joint_positions = np.array([placement.translation for placement in self._data.oMi])
        self.light_position = (
            self.light_pose.translation.copy()
            if light_position is None
            else np.asarray(light_position, float)
        )
        #: Times (s) of the frames the animation's keyframes are chosen from; empty without a trajectory.
        self.frame_times = (
            animation_times(trajectory.duration, self.fps) if trajectory is not None else np.zeros(0)
        )
        #: Times (s) of the animation's keyframes, a subset of :attr:`frame_times` with its first and
        #: last; empty without a trajectory.
        self.key_times = np.zeros(0)

        self._recorder = SceneRecorder()
        vis = meshcat.Visualizer(window=self._recorder)
        robot_view = self._add_robot(vis) if show_robot else None
        self._add_object(vis)
        self._add_sphere(vis)
        self._add_landmarks(vis, landmarks, costs)
        self._add_path(vis, np.asarray(path_positions, float).reshape(-1, 3))
        self._add_camera(vis)
        self._add_obstacles(vis, obstacles)
        self._add_light(vis)
        self._set_view(vis, np.vstack([joint_positions, landmarks]))
        if trajectory is not None:
            self._add_animation(vis, robot_view)

    # ------------------------------------------------------------------ outputs
    def static_html(self) -> str:
        """A standalone HTML page of the scene: meshcat's viewer, the meshes and the animation
        inlined; opens from disk without a server or network."""
        viewer_js = (Path(VIEWER_ROOT) / "main.min.js").read_text(encoding="utf-8")
        commands = [base64.b64encode(packed).decode("ascii") for _, _, packed in self._recorder.commands()]
        return HTML_TEMPLATE.format(
            title=html.escape(f"optlight preview: {self.robot.name}"),
            viewer_js=viewer_js,
            commands=json.dumps(commands),
        )

    def save_html(self, path: str | Path) -> Path:
        """Write :meth:`static_html` to ``path`` (folders created); returns the path."""
        out = Path(path)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(self.static_html(), encoding="utf-8")
        return out

    @contextmanager
    def serve(self) -> Iterator[str]:
        """Serve the scene live: start a meshcat server on 127.0.0.1, send it the scene and yield
        the viewer's URL; the server ends when the block exits (normally, by an exception or by
        Ctrl-C). Prints nothing."""
        with MeshcatServer() as server:
            server.send(self._recorder.commands())
            yield server.web_url

    @classmethod
    def at_best_landmark(cls, scene: SceneLike, robot: RobotLike, landmarks: Any) -> Preview:
        """The landmarks of a search (a :class:`LandmarkSet`, coloured by cost) with the robot holding
        the light at the lowest-cost one, by generalized IK; ``reached`` says whether the IK
        converged (otherwise the robot is shown at the closest pose it found)."""
        from optlight.robot import generalized_ik

        best = min(landmarks.landmarks, key=lambda lm: lm.cost)
        ik = generalized_ik(robot, scene.sphere, best.position)  # type: ignore[arg-type]
        preview = cls(
            scene,
            robot,
            landmarks.positions,
            landmarks.costs,
            np.empty((0, 3)),
            theta=ik.theta,
            light_position=best.position,
        )
        preview.reached = ik.success
        return preview

    def show(self, what: str = "") -> None:
        """Serve the scene live (:meth:`serve`), print its URL and wait until the user presses Enter
        or Ctrl-C (or standard input closes); the server stops then. ``what`` says what is shown."""
        with self.serve() as url:
            print(f"live preview at {url}{f' ({what})' if what else ''} — press Enter (or Ctrl-C) to stop")
            try:
                input()
            except (KeyboardInterrupt, EOFError):
                pass

    # ------------------------------------------------------------------ scene content
    def _light_placement(self, theta: ArrayLike) -> pin.SE3:
        model = self.robot.model
        pin.forwardKinematics(model, self._data, self.robot.to_pin(theta))
        return pin.updateFramePlacement(model, self._data, self.robot.light_frame_id).copy()

    def _add_robot(self, vis: meshcat.Visualizer) -> _RobotView:
        robot = self.robot
        if _COLLISION_MESH_ROBOTS.match(robot.name):
            geometry, color = robot.geometry_model("collision"), _COLLISION_MESH_COLOR
        else:
            geometry, color = robot.geometry_model("visual"), None
        view = _RobotView(robot.model, None, geometry)
        view.mesh_color = color
        view.initViewer(viewer=vis)
        view.loadViewerModel(rootNodeName=ROBOT_NODE)
        view.display(robot.to_pin(self.theta))
        return view

    def _add_object(self, vis: meshcat.Visualizer) -> None:
        scene = self.scene
        gray = vertex_shading(scene.mesh, scene.albedo, self.light_position, scene.light, scene.sphere)
        mesh, gray = display_object(scene.mesh, gray, OBJECT_MESH_FACES)
        geometry = CompactMeshGeometry(mesh.vertices, mesh.faces, np.repeat(gray[:, None], 3, axis=1))
        vis[OBJECT_NODE].set_object(geometry, mg.MeshBasicMaterial(vertexColors=True))

    def _add_sphere(self, vis: meshcat.Visualizer) -> None:
        sphere = self.scene.sphere
        material = mg.MeshLambertMaterial(color=0x6FA8DC, opacity=0.12, transparent=True, depthWrite=False)
        vis[SPHERE_NODE].set_object(mg.Sphere(sphere.radius), material)
        vis[SPHERE_NODE].set_transform(_translation(sphere.center))

    def _add_landmarks(self, vis: meshcat.Visualizer, positions: Array, costs: Array) -> None:
        radius = 0.03 * self.scene.sphere.radius
        span = float(np.ptp(costs)) if costs.size else 0.0
        levels = (costs - costs.min()) / span if span > 0 else np.full(costs.shape, 0.5)
        colormap = matplotlib.colormaps["viridis"]
        for i, (position, level) in enumerate(zip(positions, levels, strict=True)):
            node = vis[f"{LANDMARKS_NODE}/{i:03d}"]
            node.set_object(mg.Sphere(radius), mg.MeshLambertMaterial(color=_rgb_int(colormap(level))))
            node.set_transform(_translation(position))

    def _add_path(self, vis: meshcat.Visualizer, positions: Array) -> None:
        if len(positions) < 2:
            return
        line = mg.Line(
            mg.PointsGeometry(positions.T.astype(np.float32)), mg.LineBasicMaterial(color=0xE8590C)
        )
        vis[PATH_NODE].set_object(line)

    def _add_camera(self, vis: meshcat.Visualizer) -> None:
        camera = self.scene.camera
        depth = float((self.scene.sphere.center - camera.position) @ camera.rotation[:, 2])
        corners = camera_corners(camera, depth)
        segments = np.concatenate(
            [np.repeat(camera.position[None], 4, 0), corners, corners, np.roll(corners, -1, axis=0)], axis=1
        ).reshape(-1, 3)
        frustum = mg.LineSegments(
            mg.PointsGeometry(segments.T.astype(np.float32)), mg.LineBasicMaterial(color=0x222222)
        )
        vis[f"{CAMERA_NODE}/frustum"].set_object(frustum)
        body = vis[f"{CAMERA_NODE}/body"]
        size = 0.08 * self.scene.sphere.radius
        body.set_object(mg.Box([1.4 * size, size, 1.8 * size]), mg.MeshLambertMaterial(color=0x333333))
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = camera.rotation, camera.position - 0.9 * size * camera.rotation[:, 2]
        body.set_transform(pose)

    def _add_obstacles(self, vis: meshcat.Visualizer, obstacles: Sequence[Obstacle]) -> None:
        material = mg.MeshLambertMaterial(color=0x8A8F98, opacity=0.45, transparent=True, depthWrite=False)
        for obstacle in obstacles:
            geometry, pose = obstacle_display(obstacle, self.scene.sphere.center)
            node = vis[f"{OBSTACLES_NODE}/{obstacle.name}"]
            node.set_object(geometry, material)
            node.set_transform(pose)

    def _add_light(self, vis: meshcat.Visualizer) -> None:
        size = 0.05 * self.scene.sphere.radius
        vis[f"{LIGHT_NODE}/bulb"].set_object(mg.Sphere(0.5 * size), mg.MeshBasicMaterial(color=_LIGHT_COLOR))
        length = 4.0 * size
        # three.js cylinders run along +y: the wide end at +y, turned onto +z, apex at the light.
        beam = mg.Cylinder(length, radiusTop=1.2 * size, radiusBottom=0.0)
        vis[f"{LIGHT_NODE}/beam"].set_object(
            beam, mg.MeshBasicMaterial(color=_LIGHT_COLOR, opacity=0.45, transparent=True, depthWrite=False)
        )
        turn = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0.5 * length], [0, 0, 0, 1]])
        vis[f"{LIGHT_NODE}/beam"].set_transform(turn)
        vis[LIGHT_NODE].set_transform(self.light_pose.homogeneous)

    def _set_view(self, vis: meshcat.Visualizer, points: Array) -> None:
        """Frame the scene in meshcat's orbiting camera, seen from the camera's side (the side away
        from the robot's base) and above.

        meshcat 0.3.2's camera always looks at (and orbits) the viewer's origin, and has no command
        to move that target; so the scene, grid and axes are shifted by −c instead, c the centre of
        ``points`` (the robot's joints in the pose shown and the landmarks), the object and the
        camera, and the camera is placed relative to it.
        """
        sphere, camera = self.scene.sphere, self.scene.camera
        points = np.vstack([points, sphere.center, camera.position])
        center = 0.5 * (points.min(axis=0) + points.max(axis=0))
        extent = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
        for node in ("/meshcat", "/Grid", "/Axes"):
            vis[node].set_transform(_translation(-center))
        toward_camera = camera.position - sphere.center
        toward_camera[2] = 0.0
        horizontal = float(np.linalg.norm(toward_camera))
        toward_camera = toward_camera / horizontal if horizontal > 1e-9 else np.array([1.0, 0.0, 0.0])
        side = np.cross([0.0, 0.0, 1.0], toward_camera)
        # from the side away from the robot's base, so that the arm does not hide the object
        if (self.robot.base_placement.translation - sphere.center) @ side > 0.0:
            side = -side
        direction = toward_camera + 0.8 * side + np.array([0.0, 0.0, 0.6])
        offset = 0.7 * max(extent, 0.5) * direction / np.linalg.norm(direction)
        # The camera node is y-up (three.js): world (x, y, z) is (x, z, −y) there.
        vis["/Cameras/default/rotated/<object>"].set_property("position", [offset[0], offset[2], -offset[1]])

    def _add_animation(self, vis: meshcat.Visualizer, robot_view: _RobotView | None) -> None:
        """The trajectory as one clip per moving node (the light, every robot mesh): the pose at
        every frame of :attr:`frame_times` by the robot's kinematics, of which :func:`select_keyframes`
        keeps what the viewer's interpolation needs; tracks hold float32 arrays (times in s)."""
        assert self.trajectory is not None
        thetas = self.trajectory.sample(self.frame_times)[0]
        model = self.robot.model
        nodes = [LIGHT_NODE]
        poses: list[list[pin.SE3]] = []
        for theta in thetas:
            pin.forwardKinematics(model, self._data, self.robot.to_pin(theta))
            frame = [pin.updateFramePlacement(model, self._data, self.robot.light_frame_id).copy()]
            if robot_view is not None:
                placements = robot_view.placements(self._data)
                nodes[1:] = [node for node, _ in placements]
                frame += [placement.copy() for _, placement in placements]
            poses.append(frame)
        positions = np.array([[p.translation for p in frame] for frame in poses])
        rotations = np.array([[p.rotation for p in frame] for frame in poses])
        # (x, y, z, w), three.js's order; all at once (a pin.Quaternion per pose took 0.2 s)
        quaternions = continuous_quaternions(
            Rotation.from_matrix(rotations.reshape(-1, 3, 3)).as_quat().reshape(len(poses), -1, 4)
        )
        keys = select_keyframes(
            self.frame_times, positions, quaternions, KEY_TOLERANCE_M, KEY_TOLERANCE_RAD
        )
        self.key_times = self.frame_times[keys]
        times = float32_ext(self.key_times)

        def clip(i: int) -> dict[str, Any]:
            position, quaternion = float32_ext(positions[keys, i]), float32_ext(quaternions[keys, i])
            return {
                "fps": 1.0,  # three.js divides the key times by it: they are in seconds
                "name": "default",
                "tracks": [
                    {"name": ".position", "type": "vector3", "times": times, "values": position},
                    {"name": ".quaternion", "type": "quaternion", "times": times, "values": quaternion},
                ],
            }

        animations = [{"path": vis[node].path.lower(), "clip": clip(i)} for i, node in enumerate(nodes)]
        options = {"play": True, "repetitions": 1}
        self._recorder.send(SceneCommand({"type": "set_animation", "path": "", "animations": animations, "options": options}))


class _RobotView(MeshcatVisualizer):
    """pinocchio's ``MeshcatVisualizer``, reading mesh files through trimesh, decimated for display
    with their normals (:mod:`optlight.viz.meshes`): sent whole, the Panda's COLLADA files alone
    made a 15 MB page, and meshcat's own STL loader uses the file's facet normals, which some files
    (the UR collision meshes) leave at zero: such a mesh renders black."""

    #: RGBA for every mesh, or None for their files' material colours (else the URDF's colour).
    mesh_color: tuple[float, ...] | None = None

    def loadMeshFromFile(self, geometry_object: pin.GeometryObject) -> Any:
        """The meshcat object of a mesh file: decimated for display, with its colours
        (:func:`optlight.viz.meshes.display_mesh`), Phong-shaded; a file trimesh cannot read goes to
        pinocchio's own loader, which sends it whole."""
        try:
            mesh = display_mesh(
                geometry_object.meshPath,
                scale=geometry_object.meshScale,
                color=self.mesh_color,
                default_color=geometry_object.meshColor,
            )
        except (ValueError, OSError, ImportError):  # trimesh: unknown format, unreadable file
            return super().loadMeshFromFile(geometry_object)
        return mg.Mesh(
            CompactMeshGeometry(mesh.vertices, mesh.faces, mesh.colors, mesh.normals),
            mg.MeshPhongMaterial(vertexColors=True),
        )

    def placements(self, data: pin.Data) -> list[tuple[str, pin.SE3]]:
        """Viewer node and world placement of every mesh, for the joint placements in ``data``
        (forward kinematics already done on the model)."""
        pin.updateGeometryPlacements(self.model, data, self.visual_model, self.visual_data)
        return [
            (self.getViewerNodeName(obj, pin.GeometryType.VISUAL), self.visual_data.oMg[k])
            for k, obj in enumerate(self.visual_model.geometryObjects)
        ]


def obstacle_display(obstacle: Obstacle, center: ArrayLike) -> tuple[mg.Geometry, Array]:
    """Meshcat geometry and world pose (4, 4) of an obstacle shape. Three.js cylinders run along
    their y axis, ours along z: the pose turns y onto z. A half-space {x : nᵀx ≤ h} is a slab whose
    top face is its plane, centred at the projection of ``center`` (m) onto it."""
    pose = np.eye(4)
    if isinstance(obstacle, Box):
        pose[:3, :3], pose[:3, 3] = obstacle.rotation, obstacle.center
        return mg.Box(2.0 * obstacle.half_extents), pose
    if isinstance(obstacle, Cylinder):
        y_to_z = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
        pose[:3, :3], pose[:3, 3] = obstacle.rotation @ y_to_z, obstacle.center
        return mg.Cylinder(2.0 * obstacle.half_length, obstacle.radius), pose
    if isinstance(obstacle, Ball):
        pose[:3, 3] = obstacle.center
        return mg.Sphere(obstacle.radius), pose
    if isinstance(obstacle, HalfSpace):
        n = obstacle.normal / np.linalg.norm(obstacle.normal)
        c = np.asarray(center, float)
        on_plane = c - (n @ c - obstacle.offset) * n
        x = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
        x /= np.linalg.norm(x)
        pose[:3, :3] = np.column_stack([x, np.cross(n, x), n])
        pose[:3, 3] = on_plane - 0.5 * TABLE_THICKNESS_M * n
        return mg.Box([TABLE_SIDE_M, TABLE_SIDE_M, TABLE_THICKNESS_M]), pose
    raise TypeError(f"no display for the obstacle {obstacle.name!r} ({type(obstacle).__name__})")


def display_object(mesh: trimesh.Trimesh, values: ArrayLike, max_faces: int) -> tuple[trimesh.Trimesh, Array]:
    """The object's mesh for display with ``values`` (V,) given per vertex of ``mesh``: the mesh itself
    when it has at most ``max_faces`` triangles, else :func:`optlight.viz.meshes.decimate`'s, each
    new vertex taking the value of the nearest original vertex. (Values computed on the decimated
    mesh would follow its normals, which decimation leaves uneven: the shading shows streaks.)"""
    values = np.broadcast_to(np.asarray(values, float), (len(mesh.vertices),))
    if len(mesh.faces) <= max_faces:
        return mesh, values
    vertices, faces = decimate(mesh.vertices, mesh.faces, max_faces)
    nearest = cKDTree(mesh.vertices).query(vertices)[1]
    return trimesh.Trimesh(vertices, faces, process=False), values[nearest]


def vertex_shading(
    mesh: trimesh.Trimesh, albedo: ArrayLike, light_position: ArrayLike, light: LightSpec, sphere: LightSphere
) -> Array:
    """Luminance per vertex (V,) in [0, 1] (1 = saturation) for a light at ``light_position`` (m):
    docs/design.md §4's model, I = clip(g·ρ(E·max(0, n·l)·f + k_amb)) / s, with the vertex normals, directional
    or point light as ``light.model`` says, and no cast shadows."""
    value = lambertian(
        mesh.vertices, mesh.vertex_normals, albedo, light_position, light, sphere.center, sphere.radius
    )
    return np.clip(value, 0.0, light.saturation) / light.saturation


def camera_corners(camera: Camera, depth: float) -> Array:
    """World points (4, 3) on the rays through the image's outer corners, at ``depth`` (m) along the
    optical axis; order: top-left, top-right, bottom-right, bottom-left."""
    u = np.array([-0.5, camera.width - 0.5, camera.width - 0.5, -0.5])
    v = np.array([-0.5, -0.5, camera.height - 0.5, camera.height - 0.5])
    rays = np.stack([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, np.ones(4)], axis=1)
    return camera.position + depth * rays @ camera.rotation.T


def _translation(position: ArrayLike) -> Array:
    matrix = np.eye(4)
    matrix[:3, 3] = np.asarray(position, float)
    return matrix


def _rgb_int(rgba: Any) -> int:
    r, g, b = (int(round(255 * float(c))) for c in rgba[:3])
    return (r << 16) | (g << 8) | b


