"""The meshcat preview: what the static HTML holds, the animation, the shading, the live server."""

from __future__ import annotations

import base64
import json
import re
import urllib.request

import matplotlib
import numpy as np
import pinocchio as pin
import psutil
import pytest
import trimesh
import umsgpack
import zmq
from conftest import reduced_problem, search_landmarks
from scipy.spatial.transform import Rotation, Slerp

from optlight.errors import OptlightError
from optlight.geometry import great_circle
from optlight.planning.timing import time_parameterize
from optlight.robot import load_robot
from optlight.scene import Scene
from optlight.spec import LightSpec, load_problem, problem_from_dict
from optlight.viz.keyframes import KEY_TOLERANCE_M, KEY_TOLERANCE_RAD, animation_times, select_keyframes
from optlight.viz.preview import Preview, camera_corners, vertex_shading
from optlight.viz.server import MeshcatServer

M = 6


def scene_commands(html: str) -> list[dict]:
    """The meshcat commands a static preview replays, decoded."""
    match = re.search(r'<script type="application/json" id="optlight-scene">(.*?)</script>', html, re.S)
    assert match is not None
    return [umsgpack.unpackb(base64.b64decode(c)) for c in json.loads(match.group(1))]


TYPED_ARRAYS = {
    "Float32Array": np.float32,
    "Uint32Array": np.uint32,
    "Uint16Array": np.uint16,
    "Uint8Array": np.uint8,
    "Int8Array": np.int8,
}


def packed_array(attribute: dict) -> np.ndarray:
    """A three.js buffer attribute as the viewer reads it: normalized integers as [0, 1] (unsigned)
    or [−1, 1] (signed), as three.js's ``BufferAttribute`` does."""
    dtype = np.dtype(TYPED_ARRAYS[attribute["type"]]).newbyteorder("<")
    values = np.frombuffer(attribute["array"].data, dtype).reshape(-1, attribute["itemSize"])
    if attribute["normalized"]:
        return np.maximum(values / np.iinfo(dtype).max, -1.0)
    return values


def float32s(ext) -> np.ndarray:
    """A Float32Array msgpack extension (meshcat's code 0x17) as a numpy array."""
    assert ext.type == 0x17
    return np.frombuffer(ext.data, "<f4").astype(float)


def tracks(animation: dict) -> dict[str, dict[str, tuple[np.ndarray, np.ndarray]]]:
    """node path → track name → (times in s, values (K, 3 or 4)) of a set_animation command."""
    out: dict[str, dict[str, tuple[np.ndarray, np.ndarray]]] = {}
    for item in animation["animations"]:
        clip = item["clip"]
        for track in clip["tracks"]:
            times = float32s(track["times"]) / clip["fps"]
            values = float32s(track["values"]).reshape(len(times), -1)
            out.setdefault(item["path"], {})[track["name"]] = (times, values)
    return out


def objects(commands: list[dict]) -> dict[str, dict]:
    return {c["path"]: c for c in commands if c["type"] == "set_object"}


@pytest.fixture(scope="module")
def plan():
    """A small panda problem with landmarks on a circle of the cap and a real timed trajectory."""
    problem = problem_from_dict({"robot": {"name": "panda"}, "object": {"face": {"resolution": 24}}})
    scene = Scene.from_problem(problem, width=32, height=32)
    robot = load_robot(problem)
    azimuths = np.linspace(0.0, 2 * np.pi, M, endpoint=False)
    landmarks = scene.sphere.position(np.full(M, 0.5), azimuths)
    costs = np.linspace(1.0, 2.0, M)
    directions = (landmarks - scene.sphere.center) / scene.sphere.radius
    path = np.vstack(
        [
            scene.sphere.center + scene.sphere.radius * great_circle(u, v, 0.05)
            for u, v in zip(directions[:-1], directions[1:], strict=True)
        ]
    )
    step = np.array([0.3, 0.2, 0.0, -0.2, 0.0, 0.2, 0.4])
    knots = robot.theta_ref + np.linspace(0.0, 1.0, 5)[:, None] * step
    trajectory = time_parameterize(
        [knots[:3], knots[2:]], robot.velocity_limit, robot.acceleration_limit, dwell_s=0.2
    )
    return scene, robot, landmarks, costs, path, trajectory


@pytest.fixture(scope="module")
def preview(plan):
    return Preview(*plan)


@pytest.fixture(scope="module")
def commands(preview):
    return scene_commands(preview.static_html())


def test_static_html_is_standalone(preview, tmp_path):
    html = preview.static_html()
    assert "new MeshCat.Viewer" in html
    assert "<script src" not in html and "viewer.connect" not in html
    saved = preview.save_html(tmp_path / "out" / "preview.html")
    assert saved.read_text(encoding="utf-8") == html


def test_scene_holds_every_part(commands, plan):
    _, robot, *_ = plan
    paths = set(objects(commands))
    expected = {
        "/meshcat/object",
        "/meshcat/light_sphere",
        "/meshcat/path",
        "/meshcat/camera/frustum",
        "/meshcat/camera/body",
        "/meshcat/light/bulb",
        "/meshcat/light/beam",
    } | {f"/meshcat/landmarks/{i:03d}" for i in range(M)}
    assert expected <= paths
    visuals = {f"/meshcat/robot/visuals/{g.name}" for g in robot.geometry_model("visual").geometryObjects}
    assert visuals and visuals <= paths
    # Every object comes before any animation, which comes last.
    assert [c["type"] for c in commands].count("set_animation") == 1
    assert commands[-1]["type"] == "set_animation"


def surface_points(geometry: dict, n: int = 24) -> np.ndarray:
    """Points (N, 3) on the surface of a three.js box, cylinder (along its y axis) or sphere, in its
    own frame, from the geometry's parameters as the viewer reads them."""
    rng = np.random.default_rng(0)
    if geometry["type"] == "BoxGeometry":
        half = 0.5 * np.array([geometry["width"], geometry["height"], geometry["depth"]])
        points = rng.uniform(-1.0, 1.0, (n, 3))
        face = rng.integers(0, 3, n)
        points[np.arange(n), face] = np.sign(points[np.arange(n), face])  # onto a face
        return points * half
    if geometry["type"] == "CylinderGeometry":
        a = rng.uniform(0.0, 2 * np.pi, n)
        r, h = geometry["radiusTop"], geometry["height"]
        side = np.column_stack([r * np.cos(a), rng.uniform(-h / 2, h / 2, n), r * np.sin(a)])
        caps = np.column_stack([0.5 * r * np.cos(a), np.sign(a - np.pi) * h / 2, 0.5 * r * np.sin(a)])
        return np.vstack([side, caps])
    assert geometry["type"] == "SphereGeometry"
    d = rng.normal(size=(n, 3))
    return geometry["radius"] * d / np.linalg.norm(d, axis=1, keepdims=True)


def test_obstacles_are_drawn_as_the_shapes_the_verification_checks(plan):
    """Points on each drawn obstacle's surface, through its pose, are on the shape's surface by the
    shape's own signed distance (the one the NLP and the verification use): a rotated box and
    cylinder, a ball, and the table's half-space, whose slab has its top face on the plane."""
    from optlight.environment.shapes import Ball, Box, Cylinder, HalfSpace

    scene, robot, landmarks, costs, path, _ = plan
    turned = Rotation.from_euler("xyz", [0.3, -0.2, 0.5]).as_matrix()
    shapes = {
        "crate": Box("crate", np.array([0.4, -0.3, 0.2]), turned, np.array([0.05, 0.1, 0.15])),
        "post": Cylinder("post", np.array([-0.3, 0.2, 0.5]), turned, 0.03, 0.5),
        "lamp": Ball("lamp", np.array([0.1, 0.5, 0.9]), 0.07),
        "table": HalfSpace("table", np.array([0.0, 0.0, 1.0]), 0.1),
    }
    commands = scene_commands(
        Preview(scene, robot, landmarks, costs, path, obstacles=list(shapes.values()), show_robot=False).static_html()
    )
    drawn = objects(commands)
    poses = {c["path"]: np.array(c["matrix"], float).reshape(4, 4).T for c in commands if c["type"] == "set_transform"}
    for name, shape in shapes.items():
        node = f"/meshcat/obstacles/{name}"
        geometry = drawn[node]["object"]["geometries"][0]
        local = surface_points(geometry)
        world = local @ poses[node][:3, :3].T + poses[node][:3, 3]
        sd = shape.signed_distance(world)
        if name == "table":  # the slab: its top face on the plane, the rest below it
            top = np.isclose(local[:, 2], 0.5 * geometry["depth"])
            assert top.any() and np.abs(sd[top]).max() < 1e-6 and (sd[~top] < 1e-6).all()
            assert np.abs(world[:, :2].mean(axis=0) - scene.sphere.center[:2]).max() < 0.2
        else:
            assert np.abs(sd).max() < 1e-4, name  # the shapes' smoothing: ε²/2r at most


def test_a_plan_with_an_environment_draws_its_obstacles() -> None:
    """Plan.preview draws the obstacles the plan keeps clear of; the object's bounding ball, a
    modelling stand-in for the object's mesh, is left out."""
    import optlight
    from optlight.setup import Setup

    setup = Setup.from_problem(reduced_problem("table_wall", camera_px=48, landmarks={"count": 3}))
    assert setup.environment is not None
    preview_plan = optlight.solve(setup)
    paths = set(objects(scene_commands(preview_plan.preview().static_html())))
    names = {o.name for o in setup.environment.obstacles} - {"object"}
    assert {"table", "wall", "camera_body", "camera_stand"} <= names
    assert {f"/meshcat/obstacles/{name}" for name in names} <= paths
    assert "/meshcat/obstacles/object" not in paths


def test_object_is_coloured_by_the_shading(commands, preview, plan):
    scene = plan[0]
    geometry = objects(commands)["/meshcat/object"]["object"]["geometries"][0]["data"]["attributes"]
    colors = packed_array(geometry["color"])
    np.testing.assert_allclose(packed_array(geometry["position"]), scene.mesh.vertices, atol=1e-6)
    assert np.ptp(colors[:, 0]) > 0.05 and np.allclose(colors[:, 0:1], colors, atol=1e-6)  # gray, shaded
    np.testing.assert_allclose(preview.light_position, preview.light_pose.translation)


@pytest.mark.parametrize("model", ["directional", "point"])
def test_object_colours_agree_with_the_renderer(model):
    """The preview's vertex colours (decoded from the HTML) against the NumPy renderer's pixels on a
    sphere, whose pixel normals are exact: at each object pixel the nearest vertex's colour may
    differ only by the shading change over the angle between the two normals and, for a point light,
    over the distance δ between the points (direction: δ/r; falloff f = (b/r)²: 2δ/r relative):
    |Δ| ≤ g·ρ·E·f·(1 + 3δ/r)·(Δangle + 3δ/r)/s, plus half a step of the 8-bit colours sent."""
    problem = problem_from_dict(
        {"object": {"kind": "sphere", "radius_m": 0.08}, "light": {"cast_shadows": False, "model": model}}
    )
    scene = Scene.from_problem(problem, width=48, height=48)
    a = scene.sphere.position(0.6, 1.0)
    robot = load_robot(problem)
    preview = Preview(scene, robot, a[None], np.ones(1), a[None], light_position=a, show_robot=False)
    geometry = objects(scene_commands(preview.static_html()))["/meshcat/object"]["object"]["geometries"][0]
    colors = packed_array(geometry["data"]["attributes"]["color"])[:, 0]
    gb, light = scene.gbuffer, scene.light
    rendered = scene.pixels(a, np.ones(gb.size)) / light.saturation
    nearest = np.argmin(np.linalg.norm(gb.points[:, None, :] - scene.mesh.vertices[None], axis=2), axis=1)
    vertex_normals = np.asarray(scene.mesh.vertex_normals)[nearest]
    angle = np.arccos(np.clip(np.einsum("ij,ij->i", gb.normals, vertex_normals), -1.0, 1.0))
    offset = np.linalg.norm(gb.points - scene.mesh.vertices[nearest], axis=1) / np.linalg.norm(
        a - gb.points, axis=1
    )
    falloff = (scene.sphere.radius / np.linalg.norm(a - gb.points, axis=1)) ** 2 if model == "point" else 1.0
    growth = falloff * (1 + 3 * offset)
    bound = light.gain * gb.albedo * light.power * growth * (angle + 3 * offset) / light.saturation + 0.5 / 255 + 1e-6
    assert np.all(np.abs(colors[nearest] - rendered) <= bound)
    assert np.median(np.abs(colors[nearest] - rendered)) < 0.02


def test_landmarks_are_coloured_by_cost(commands):
    objs = objects(commands)
    viridis = matplotlib.colormaps["viridis"]
    for index, level in ((0, 0.0), (M - 1, 1.0)):
        material = objs[f"/meshcat/landmarks/{index:03d}"]["object"]["materials"][0]
        rgb = [(material["color"] >> s) & 0xFF for s in (16, 8, 0)]
        np.testing.assert_allclose(rgb, np.round(255 * np.array(viridis(level)[:3])))


def test_frustum_reaches_the_image_corners(plan):
    camera = plan[0].camera
    corners = camera_corners(camera, 0.7)
    u, v, depth = camera.project(corners)
    np.testing.assert_allclose(depth, 0.7)
    np.testing.assert_allclose(u, [-0.5, camera.width - 0.5, camera.width - 0.5, -0.5], atol=1e-9)
    np.testing.assert_allclose(v, [-0.5, -0.5, camera.height - 0.5, camera.height - 0.5], atol=1e-9)


def test_animation_covers_the_trajectory_and_ends_at_its_poses(commands, preview, plan):
    _, robot, _, _, _, trajectory = plan
    animation = next(c for c in commands if c["type"] == "set_animation")
    clips = tracks(animation)
    assert set(clips) == {"/meshcat/light"} | {
        f"/meshcat/robot/visuals/{g.name}" for g in robot.geometry_model("visual").geometryObjects
    }
    for node in clips.values():
        assert set(node) == {".position", ".quaternion"}
        for name, (times, values) in node.items():
            # from the start to the end of the trajectory, in order, at frames of the 30 fps grid
            assert times[0] == 0.0 and times[-1] == pytest.approx(trajectory.duration, abs=1e-5)
            assert np.all(np.diff(times) > 0)
            np.testing.assert_allclose(times, preview.key_times, atol=1e-5)
            assert values.shape == (len(times), 3 if name == ".position" else 4)
    assert set(preview.key_times) <= set(preview.frame_times)
    assert len(preview.frame_times) == len(animation_times(trajectory.duration, 30))
    # The light's first and last keys are where the robot's kinematics put it at the ends.
    light = clips["/meshcat/light"][".position"][1]
    for key, t in ((0, 0.0), (-1, trajectory.duration)):
        np.testing.assert_allclose(light[key], robot.light_pose(trajectory.sample(t)[0][0])[0], atol=1e-6)
    assert animation["options"] == {"play": True, "repetitions": 1}


def world_poses(robot, visual, theta) -> dict[str, tuple[np.ndarray, Rotation]]:
    """node path → world position and rotation of the light frame and every visual mesh, by
    pinocchio's forward kinematics (the reference the animation is checked against)."""
    data, geometry_data = robot.model.createData(), visual.createData()
    pin.framesForwardKinematics(robot.model, data, robot.to_pin(theta))
    pin.updateGeometryPlacements(robot.model, data, visual, geometry_data)
    light = data.oMf[robot.light_frame_id]
    out = {"/meshcat/light": (light.translation.copy(), Rotation.from_matrix(light.rotation))}
    for k, obj in enumerate(visual.geometryObjects):
        placement = geometry_data.oMg[k]
        out[f"/meshcat/robot/visuals/{obj.name}"] = (
            placement.translation.copy(),
            Rotation.from_matrix(placement.rotation),
        )
    return out


def test_animation_follows_the_kinematics(commands, preview, plan):
    """Interpolated as the viewer does (positions linearly, rotations by slerp), the kept keyframes
    put the light and every link where pinocchio's kinematics does: within the keyframe tolerance at
    every frame of the 30 fps grid, and within 1 mm and 0.2° at random times between frames."""
    _, robot, _, _, _, trajectory = plan
    clips = tracks(next(c for c in commands if c["type"] == "set_animation"))
    visual = robot.geometry_model("visual")
    rng = np.random.default_rng(3)
    frames = preview.frame_times
    checks = [(frames, KEY_TOLERANCE_M + 1e-5, KEY_TOLERANCE_RAD + 1e-4)]
    checks.append((rng.uniform(0.0, trajectory.duration, 40), 1e-3, np.radians(0.2)))
    assert len(preview.key_times) < len(frames)  # keyframes were dropped: the check is not trivial
    for times, tol_m, tol_rad in checks:
        thetas = trajectory.sample(times)[0]
        reference = [world_poses(robot, visual, theta) for theta in thetas]
        for node, node_tracks in clips.items():
            key_t, key_p = node_tracks[".position"]
            position = np.stack([np.interp(times, key_t, key_p[:, c]) for c in range(3)], axis=1)
            key_q = node_tracks[".quaternion"][1]
            rotation = Slerp(key_t, Rotation.from_quat(key_q))(np.clip(times, key_t[0], key_t[-1]))
            expected_p = np.array([r[node][0] for r in reference])
            expected_r = Rotation.concatenate([r[node][1] for r in reference])
            assert np.linalg.norm(position - expected_p, axis=1).max() <= tol_m, node
            assert (rotation * expected_r.inv()).magnitude().max() <= tol_rad, node


def test_keyframes_keep_what_interpolation_needs():
    t = np.arange(61) / 30
    identity = np.tile([0.0, 0.0, 0.0, 1.0], (61, 1, 1))
    still = np.zeros((61, 1, 3))
    line = np.stack([t, 2 * t, 0 * t], axis=1)[:, None, :]
    assert list(select_keyframes(t, still, identity, 1e-3, 1e-3)) == [0, 60]
    assert list(select_keyframes(t, line, identity, 1e-3, 1e-3)) == [0, 60]
    # a circle of radius 0.2 m at π rad/s, facing its centre: kept keys whose chords sag by at most
    # 3 mm, and a uniform turn, which slerp restores exactly
    angle = np.pi * t
    circle = np.stack([0.2 * np.cos(angle), 0.2 * np.sin(angle), 0 * t], axis=1)[:, None, :]
    facing = Rotation.from_rotvec(np.outer(angle, [0.0, 0.0, 1.0])).as_quat()[:, None, :]
    keys = select_keyframes(t, circle, facing, 3e-3, np.radians(0.1))
    assert keys[0] == 0 and keys[-1] == 60 and 5 < len(keys) < 40
    between = np.stack([np.interp(t, t[keys], circle[keys, 0, c]) for c in range(3)], axis=1)
    assert np.linalg.norm(between - circle[:, 0], axis=1).max() <= 3e-3
    # an accelerating turn in place: the rotation tolerance alone keeps keys
    spin = Rotation.from_rotvec(np.outer(0.5 * np.pi * t**2, [0.0, 0.0, 1.0]))
    keys = select_keyframes(t, still, spin.as_quat()[:, None, :], 1e-3, np.radians(1.0))
    assert 2 < len(keys) < 61
    restored = Slerp(t[keys], spin[keys])(t)
    assert (restored * spin.inv()).magnitude().max() <= np.radians(1.0) + 1e-9


def test_animation_times():
    np.testing.assert_allclose(animation_times(1.0, 30), np.arange(31) / 30)
    times = animation_times(1.01, 30)
    assert len(times) == 32 and times[-1] == 1.01 and times[-2] == 1.0


def test_vertex_shading_is_lambertian():
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.1)
    sphere = type("S", (), {"center": np.zeros(3), "radius": 0.5})()
    light = LightSpec(model="directional", power=1.0, ambient=0.1, gain=1.0, saturation=2.0)
    albedo = np.full(len(mesh.vertices), 0.8)
    shade = vertex_shading(mesh, albedo, [0.0, 0.0, 0.5], light, sphere)
    cos = mesh.vertex_normals[:, 2]
    np.testing.assert_allclose(shade, 0.8 * (np.maximum(cos, 0) + 0.1) / 2.0)


def test_without_robot_and_without_trajectory(plan):
    scene, robot, landmarks, costs, path, _ = plan
    theta = robot.theta_ref + 0.1
    preview = Preview(scene, robot, landmarks, costs, path, theta=theta, show_robot=False)
    commands = scene_commands(preview.static_html())
    assert not any(c["path"].startswith("/meshcat/robot") for c in commands)
    assert not any(c["type"] == "set_animation" for c in commands)
    light = next(c for c in commands if c["type"] == "set_transform" and c["path"] == "/meshcat/light")
    a, _ = robot.light_pose(theta)
    np.testing.assert_allclose(np.reshape(light["matrix"], (4, 4)).T[:3, 3], a, atol=1e-9)


def test_ur_robots_are_drawn_with_their_collision_meshes(plan):
    scene, _, landmarks, costs, path, _ = plan
    ur5 = load_robot("ur5")
    preview = Preview(scene, ur5, landmarks, costs, path)
    objs = objects(scene_commands(preview.static_html()))
    collision = ur5.geometry_model("collision").geometryObjects
    robot_paths = {p.rsplit("/", 1)[1] for p in objs if p.startswith("/meshcat/robot/visuals/")}
    assert robot_paths == {g.name for g in collision}
    stl = [g.name for g in collision if g.meshPath.lower().endswith(".stl")]
    assert stl
    for name in stl:  # read through trimesh: an indexed mesh, normals computed by the viewer
        geometry = objs[f"/meshcat/robot/visuals/{name}"]["object"]["geometries"][0]
        assert geometry["type"] == "BufferGeometry" and len(packed_array(geometry["data"]["index"])) > 0


def test_inputs_are_checked(plan):
    scene, robot, landmarks, costs, path, _ = plan
    with pytest.raises(ValueError, match="landmark costs"):
        Preview(scene, robot, landmarks, costs[:-1], path)


def listening(process: psutil.Process) -> list[tuple[str, int]]:
    return [(c.laddr.ip, c.laddr.port) for c in process.net_connections(kind="inet") if c.status == "LISTEN"]


def test_live_server_on_loopback_only_and_gone_after(preview):
    before = {p.pid for p in psutil.Process().children(recursive=True)}
    with preview.serve() as url:
        assert url.startswith("http://127.0.0.1:")
        (server,) = [p for p in psutil.Process().children(recursive=True) if p.pid not in before]
        sockets = listening(server)
        assert len(sockets) == 2 and {ip for ip, _ in sockets} == {"127.0.0.1"}
        with urllib.request.urlopen(url, timeout=10) as response:
            assert response.status == 200 and b"MeshCat" in response.read()
        # The server holds the scene: its own static page replays our objects.
        zmq_port = next(port for _, port in sockets if f":{port}/" not in url)
        socket = zmq.Context.instance().socket(zmq.REQ)
        socket.setsockopt(zmq.RCVTIMEO, 10000)
        socket.setsockopt(zmq.LINGER, 0)
        socket.connect(f"tcp://127.0.0.1:{zmq_port}")
        socket.send(b"get_scene")
        page = socket.recv().decode()
        socket.close()
        served = {
            umsgpack.unpackb(base64.b64decode(b))["path"]
            for b in re.findall(r"octet-binary;base64,([A-Za-z0-9+/=]+)", page)
        }
        assert {"/meshcat/object", "/meshcat/light/beam", "/meshcat/landmarks/000"} <= served
    assert not server.is_running()
    assert {p.pid for p in psutil.Process().children(recursive=True)} <= before


@pytest.mark.parametrize("error", [RuntimeError, KeyboardInterrupt])
def test_live_server_stops_on_error_and_ctrl_c(preview, error):
    before = {p.pid for p in psutil.Process().children(recursive=True)}
    with pytest.raises(error), preview.serve():
        (server,) = [p for p in psutil.Process().children(recursive=True) if p.pid not in before]
        raise error("stop")
    assert not server.is_running()


def test_server_that_cannot_start_is_reported(monkeypatch):
    monkeypatch.setattr("optlight.viz.server.sys.executable", "/bin/false")
    with pytest.raises(OptlightError, match="did not start"), MeshcatServer(start_timeout_s=5.0):
        pass


def test_show_serves_until_enter_then_stops(preview, monkeypatch, capsys):
    before = {p.pid for p in psutil.Process().children(recursive=True)}
    seen = {}

    def enter() -> str:  # the user presses Enter while the server runs
        children = [p for p in psutil.Process().children(recursive=True) if p.pid not in before]
        seen["servers"] = len(children)
        return ""

    monkeypatch.setattr("builtins.input", enter)
    preview.show("test")
    assert seen["servers"] == 1
    assert "live preview at http://127.0.0.1:" in capsys.readouterr().out
    assert {p.pid for p in psutil.Process().children(recursive=True)} <= before


def test_at_best_landmark_holds_the_light_there() -> None:
    from optlight import Setup

    setup = Setup.from_problem(reduced_problem(camera_px=48, landmarks={"count": 4}))
    landmarks = search_landmarks(setup)
    scene, robot = setup.scene, setup.robot
    preview = Preview.at_best_landmark(scene, robot, landmarks)
    best = min(landmarks.landmarks, key=lambda lm: lm.cost)
    assert preview.reached
    # within the IK tolerance |e|² < 1e-9 (m²)
    assert np.linalg.norm(robot.light_pose(preview.theta)[0] - best.position) < np.sqrt(1e-9)


def test_default_sized_preview_stays_under_5_mb():
    """The budget for preview.html (5 MB), on a preview the size of the default problem's: its
    scene (the 101,760-triangle face, kept whole), the Panda, 36 landmarks and a 36-landmark tour of
    about 28 s (dwells of 0.5 s). The robot's meshes, decimated, take under 1.2 MB of it."""
    problem = load_problem("default")
    scene = Scene.from_problem(problem, width=32, height=32)
    robot = load_robot(problem)
    m = problem.landmarks.count
    azimuths = np.linspace(0.0, 2 * np.pi, m + 1)
    landmarks = scene.sphere.position(np.full(m, 0.4), azimuths[:-1])
    # a loop in joint space through 36 configurations, like the default plan's tour around the cap
    phase = azimuths[:, None] + np.arange(7) * np.pi / 7
    thetas = robot.theta_ref + 0.25 * np.sin(phase)
    segments = [np.linspace(a, b, 8) for a, b in zip(thetas[:-1], thetas[1:], strict=True)]
    trajectory = time_parameterize(segments, robot.velocity_limit, robot.acceleration_limit, dwell_s=0.5)
    assert 20.0 < trajectory.duration < 40.0
    preview = Preview(scene, robot, landmarks, np.arange(m, dtype=float), landmarks, trajectory)
    html = preview.static_html()
    size = len(html.encode("utf-8"))
    commands = scene_commands(html)
    robot_bytes = sum(
        len(umsgpack.packb(c)) * 4 / 3 for c in commands if c["path"].startswith("/meshcat/robot/")
    )
    index = packed_array(objects(commands)["/meshcat/object"]["object"]["geometries"][0]["data"]["index"])
    assert index.size == 3 * len(scene.mesh.faces)  # the face, whole
    assert robot_bytes < 1.2e6, f"robot meshes: {robot_bytes / 1e6:.2f} MB"
    assert size <= 5_000_000, f"preview.html: {size / 1e6:.2f} MB"
    animation = tracks(next(c for c in commands if c["type"] == "set_animation"))
    times = animation["/meshcat/light"][".position"][0]
    assert times[-1] == pytest.approx(trajectory.duration, abs=1e-5)


def test_a_mesh_trimesh_cannot_read_goes_to_pinocchios_loader(plan, monkeypatch):
    scene, robot, landmarks, costs, path, _ = plan

    def unreadable(*args, **kwargs):
        raise ValueError("file type not supported")

    monkeypatch.setattr("optlight.viz.preview.display_mesh", unreadable)
    objs = objects(scene_commands(Preview(scene, robot, landmarks, costs, path).static_html()))
    for g in robot.geometry_model("visual").geometryObjects:  # sent whole, as COLLADA text
        assert objs[f"/meshcat/robot/visuals/{g.name}"]["object"]["object"]["format"] == "dae"
