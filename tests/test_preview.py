"""The meshcat preview: what the static HTML holds, the animation, the shading, the live server."""

from __future__ import annotations

import base64
import json
import re
import urllib.request

import matplotlib
import numpy as np
import psutil
import pytest
import trimesh
import umsgpack
import zmq
from conftest import reduced_problem

from optlight.errors import OptlightError
from optlight.geometry import great_circle
from optlight.planning.timing import time_parameterize
from optlight.robot import load_robot
from optlight.scene import Scene
from optlight.spec import LightSpec, problem_from_dict
from optlight.viz.preview import (
    Preview,
    animation_times,
    camera_corners,
    vertex_shading,
)
from optlight.viz.server import MeshcatServer

M = 6


def scene_commands(html: str) -> list[dict]:
    """The meshcat commands a static preview replays, decoded."""
    match = re.search(r'<script type="application/json" id="optlight-scene">(.*?)</script>', html, re.S)
    assert match is not None
    return [umsgpack.unpackb(base64.b64decode(c)) for c in json.loads(match.group(1))]


def packed_array(attribute: dict) -> np.ndarray:
    """A numpy array packed by meshcat (``pack_numpy_array``)."""
    dtype = {"Float32Array": np.float32, "Uint32Array": np.uint32}[attribute["type"]]
    return np.frombuffer(attribute["array"].data, dtype).reshape(-1, attribute["itemSize"])


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
    |Δ| ≤ g·ρ·E·f·(1 + 3δ/r)·(Δangle + 3δ/r)/s."""
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
    bound = light.gain * gb.albedo * light.power * growth * (angle + 3 * offset) / light.saturation + 1e-6
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


def test_animation_frames_duration_and_poses(commands, preview, plan):
    _, robot, _, _, _, trajectory = plan
    animation = next(c for c in commands if c["type"] == "set_animation")
    n_frames = int(np.floor(trajectory.duration * 30)) + 1
    n_frames += trajectory.duration * 30 - (n_frames - 1) > 1e-9
    clips = {a["path"]: a["clip"] for a in animation["animations"]}
    assert set(clips) == {"/meshcat/light"} | {
        f"/meshcat/robot/visuals/{g.name}" for g in robot.geometry_model("visual").geometryObjects
    }
    for clip in clips.values():
        assert clip["fps"] == 30
        for track in clip["tracks"]:
            assert len(track["keys"]) == n_frames == len(preview.frame_times)
            assert track["keys"][-1]["time"] / clip["fps"] == pytest.approx(trajectory.duration)
    # The light's last key is where the robot's kinematics put it at the end of the trajectory.
    light = {t["name"]: t["keys"] for t in clips["/meshcat/light"]["tracks"]}
    end, _ = robot.light_pose(trajectory.sample(trajectory.duration)[0][0])
    np.testing.assert_allclose(light[".position"][-1]["value"], end, atol=1e-9)
    start, _ = robot.light_pose(trajectory.sample(0.0)[0][0])
    np.testing.assert_allclose(light[".position"][0]["value"], start, atol=1e-9)
    assert animation["options"] == {"play": True, "repetitions": 1}


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
    from optlight import Setup, find_landmarks

    setup = Setup.from_problem(reduced_problem(camera_px=48, landmarks={"count": 4}))
    landmarks = find_landmarks(setup)
    scene, robot = setup.scene, setup.robot
    preview = Preview.at_best_landmark(scene, robot, landmarks)
    best = min(landmarks.landmarks, key=lambda lm: lm.cost)
    assert preview.reached
    # within the IK tolerance |e|² < 1e-9 (m²)
    assert np.linalg.norm(robot.light_pose(preview.theta)[0] - best.position) < np.sqrt(1e-9)
