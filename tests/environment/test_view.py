"""The exact view and beam check: analytic spheres on and beside the line of sight, the nearer link
named, the housing, and the panda's meshes against a brute-force ray-triangle test."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import trimesh

from optlight.environment import view as view_module
from optlight.environment.view import HOUSING, Housing, ViewCheck, _surface
from optlight.robot import load_robot
from optlight.spec import RobotSpec

#: Two links turning about the world z axis: a ball (radius 0.05) 0.5 m out on "ball_link", a box on
#: "box_link" 0.3 m out, and the tool frame 0.8 m out along y of the first joint, light along +z.
URDF = """<?xml version="1.0"?>
<robot name="probe">
  <link name="base"/>
  <link name="ball_link">
    <collision><origin xyz="0.5 0 0.5"/><geometry><sphere radius="0.05"/></geometry></collision>
  </link>
  <link name="box_link">
    <collision><origin xyz="0.3 0 0.5"/><geometry><box size="0.04 0.04 0.04"/></geometry></collision>
  </link>
  <link name="tool"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="ball_link"/>
    <axis xyz="0 0 1"/><limit lower="-3.2" upper="3.2" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="ball_link"/><child link="box_link"/>
    <axis xyz="0 0 1"/><limit lower="-3.2" upper="3.2" effort="1" velocity="1"/></joint>
  <joint name="tool_joint" type="fixed"><parent link="ball_link"/><child link="tool"/>
    <origin xyz="0 0.8 0.5"/></joint>
</robot>
"""
CAMERA = np.array([1.0, 0.0, 0.5])
HOUSING_SMALL = Housing("cylinder", 0.03, 0.06)


@pytest.fixture(scope="module")
def probe(tmp_path_factory: pytest.TempPathFactory):  # noqa: ANN201
    path = Path(tmp_path_factory.mktemp("probe")) / "probe.urdf"
    path.write_text(URDF)
    return load_robot(RobotSpec(name="probe", urdf=str(path), frame="tool"))


def disc(center: np.ndarray, radius: float, count: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """Points on a disc in the plane x = center_x facing +x (towards the camera), and their normals."""
    rng = np.random.default_rng(0)
    r, a = radius * np.sqrt(rng.uniform(0, 1, count)), rng.uniform(0, 2 * np.pi, count)
    points = center + np.column_stack([np.zeros(count), r * np.cos(a), r * np.sin(a)])
    return points, np.tile([1.0, 0.0, 0.0], (count, 1))


def segment_distance(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Distance from point c to each segment [a, b_i]."""
    d = b - a
    u = np.clip(((c - a) @ d.T) / np.einsum("ij,ij->i", d, d), 0.0, 1.0)
    return np.linalg.norm(a + u[:, None] * d - c, axis=1)


def test_a_ball_on_the_line_of_sight_blocks_exactly_the_rays_it_meets(probe) -> None:
    # joint j2 turns the box out of the way; the ball (centre (0.5, 0, 0.5)) sits on the line of sight
    points, normals = disc(np.array([0.0, 0.0, 0.5]), 0.15)
    check = ViewCheck(probe, CAMERA, points, normals, HOUSING_SMALL)
    capture = check.check([[0.0, np.pi / 2]], [1.5]).captures[0]
    distance = segment_distance(CAMERA, points, np.array([0.5, 0.0, 0.5]))
    meets, misses = distance < 0.05 * 0.999, distance > 0.05 / np.cos(np.pi / 48) * 1.02
    assert meets.any() and misses.any()
    # every ray that meets the ball is blocked; none that clearly misses it (circumscribed polygon)
    assert meets.sum() / len(points) <= capture.view_blocked <= 1 - misses.sum() / len(points)
    assert capture.view_body == "ball_link" and capture.time_s == 1.5


def test_a_ball_beside_the_view_cone_blocks_nothing(probe) -> None:
    points, normals = disc(np.array([0.0, 0.0, 0.5]), 0.15)
    check = ViewCheck(probe, CAMERA, points, normals, HOUSING_SMALL)
    report = check.check([[np.pi / 2, np.pi / 2]], [0.0])  # the ball at (0, 0.5, 0.5), box and tool away
    assert report.captures[0].view_blocked == 0.0 and report.captures[0].view_body is None
    assert report.passed


def test_the_nearer_link_is_named_first(probe) -> None:
    # j2 = 0: the box (x = 0.3) and the ball (x = 0.5) both on the line of sight; the ball is nearer
    points, normals = disc(np.array([0.0, 0.0, 0.5]), 0.01)
    check = ViewCheck(probe, CAMERA, points, normals, HOUSING_SMALL)
    capture = check.check([[0.0, 0.0]], [0.0]).captures[0]
    assert capture.view_blocked == 1.0 and capture.view_bodies == ("ball_link",)
    # from the other side, with the points beyond the ball, the box (x = 0.3) is met first
    behind = ViewCheck(probe, np.array([-1.0, 0.0, 0.5]), points + [0.7, 0, 0], -normals, HOUSING_SMALL)
    assert behind.check([[0.0, 0.0]], [0.0]).captures[0].view_bodies == ("box_link",)


def test_the_housing_blocks_the_view_and_not_its_own_beam(probe) -> None:
    # turn j1 by −90°: the tool (0.8 m along the link's y) comes to (0.8, 0, 0.5), on the line of sight,
    # light axis +z, the housing hanging 6 cm below it; j2 = π turns the box to (0, 0.3, 0.5), out of the
    # beam from the light to the points
    points, normals = disc(np.array([0.0, 0.0, 0.47]), 0.01)
    check = ViewCheck(probe, CAMERA, points, normals, HOUSING_SMALL)
    capture = check.check([[-np.pi / 2, np.pi]], [2.0]).captures[0]
    assert capture.view_body == HOUSING and capture.view_blocked == 1.0
    assert capture.beam_blocked == 0.0


def test_the_beam_is_blocked_by_a_link_between_light_and_object(probe) -> None:
    # j1 = 0: the light at (0, 0.8, 0.5); points beyond the ball on the line from the light through its
    # centre, facing the light; the camera looks at them from above, clear of everything
    light = np.array([0.0, 0.8, 0.5])
    ball = np.array([0.5, 0.0, 0.5])
    target = light + 2.0 * (ball - light)  # beyond the ball, on the line light → ball
    points = target + np.random.default_rng(1).normal(0, 0.003, (50, 3))
    normals = np.tile((light - target) / np.linalg.norm(light - target), (50, 1))
    check = ViewCheck(probe, np.array([0.5, 0.9, 3.0]), points, normals, HOUSING_SMALL)
    capture = check.check([[0.0, np.pi / 2]], [0.0]).captures[0]
    assert capture.beam_body == "ball_link" and capture.beam_blocked == 1.0
    assert capture.view_blocked == 0.0


def _segment_hits(origin: np.ndarray, targets: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Möller–Trumbore in float64: the smallest t ∈ (0, 1) where origin + t (target − origin) meets a
    triangle, inf where none."""
    v0, e1, e2 = triangles[:, 0], triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]
    out = np.full(len(targets), np.inf)
    for i, p in enumerate(targets):
        d = p - origin
        h = np.cross(d, e2)
        a = np.einsum("ij,ij->i", e1, h)
        ok = np.abs(a) > 1e-12
        f = np.where(ok, 1.0 / np.where(ok, a, 1.0), 0.0)
        s = origin - v0
        u = f * np.einsum("ij,ij->i", s, h)
        qv = np.cross(s, e1)
        v = f * (qv @ d)
        t = f * np.einsum("ij,ij->i", e2, qv)
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        if hit.any():
            out[i] = t[hit].min()
    return out


def test_panda_meshes_against_brute_force() -> None:
    robot = load_robot("panda")
    rng = np.random.default_rng(4)
    theta = robot.theta_ref + rng.normal(0, 0.3, robot.n)
    hand = robot.frame_pose("panda_link5", theta).translation
    camera = hand + np.array([0.6, -0.5, 0.2])
    points = hand - np.array([0.5, -0.4, 0.1]) + rng.normal(0, 0.12, (300, 3))
    normals = np.tile(_unit(camera - points.mean(axis=0)), (300, 1))
    check = ViewCheck(robot, camera, points, normals, HOUSING_SMALL)
    capture = check.check(theta[None], [0.0]).captures[0]
    # the same bodies placed independently (pinocchio's placements, one world mesh), float64 rays
    geometry = robot.geometry_model("collision")
    data, gdata = robot.model.createData(), geometry.createData()
    pin.forwardKinematics(robot.model, data, robot.to_pin(theta))
    pin.updateGeometryPlacements(robot.model, data, geometry, gdata)
    meshes = []
    for i, obj in enumerate(geometry.geometryObjects):
        mesh = _surface(obj.geometry, obj.name).copy()
        mesh.apply_transform(gdata.oMg[i].homogeneous)
        meshes.append(mesh)
    position, rotation = robot.light_pose(theta)
    housing = HOUSING_SMALL.mesh()
    housing.apply_transform(np.block([[rotation, position[:, None]], [np.zeros((1, 3)), np.ones((1, 1))]]))
    world = trimesh.util.concatenate([*meshes, housing])
    hits = _segment_hits(camera, points, world.triangles)
    lengths = np.linalg.norm(points - camera, axis=1)
    blocked = hits * lengths < lengths - 1e-4
    grazing = np.abs(hits * lengths - lengths) < 1e-4
    assert 0.05 < blocked.mean() < 0.95, "the setup puts links across part of the view"
    assert capture.view_blocked == pytest.approx(blocked.mean(), abs=grazing.mean() + 1 / len(points))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def test_inputs_are_checked(probe) -> None:
    with pytest.raises(ValueError, match="points and normals"):
        ViewCheck(probe, CAMERA, np.zeros((3, 3)), np.zeros((2, 3)), HOUSING_SMALL)
    check = ViewCheck(probe, CAMERA, *disc(np.zeros(3), 0.1, 10), HOUSING_SMALL)
    with pytest.raises(ValueError, match="capture times"):
        check.check([[0.0, 0.0]], [0.0, 1.0])


@pytest.mark.parametrize(
    ("shape", "surface_distance"),
    [
        # analytic distance from the origin to the shape's surface along unit direction d
        (lambda: __import__("coal").Sphere(0.05), lambda d: 0.05),
        (
            lambda: __import__("coal").Cylinder(0.05, 0.2),
            lambda d: min(0.05 / max(np.hypot(d[0], d[1]), 1e-12), 0.1 / max(abs(d[2]), 1e-12)),
        ),
        (
            lambda: __import__("coal").Box(0.04, 0.1, 0.06),
            lambda d: min(
                0.02 / max(abs(d[0]), 1e-12), 0.05 / max(abs(d[1]), 1e-12), 0.03 / max(abs(d[2]), 1e-12)
            ),
        ),
    ],
)
def test_primitive_surfaces_contain_the_shapes(shape, surface_distance) -> None:
    from trimesh.ray.ray_pyembree import RayMeshIntersector

    mesh = _surface(shape(), "probe")
    rng = np.random.default_rng(6)
    directions = rng.normal(size=(300, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    # a ray from far outside towards the centre meets the polygon no later than the shape itself
    origins = directions * 1.0
    locations, index, _ = RayMeshIntersector(mesh).intersects_location(
        origins, -directions, multiple_hits=False
    )
    assert len(index) == len(directions)
    reach = np.linalg.norm(locations, axis=1)
    analytic = np.array([surface_distance(d) for d in directions[index]])
    assert np.all(reach >= analytic - 1e-6) and np.all(reach <= analytic * 1.01 + 1e-6)


def test_a_capsule_is_a_cylinder_with_ball_ends() -> None:
    import coal

    mesh = _surface(coal.Capsule(0.03, 0.2), "capsule")
    lo, hi = mesh.bounds
    assert hi[2] == pytest.approx(0.1 + 0.03, rel=0.02) and lo[2] == pytest.approx(-0.13, rel=0.02)
    assert hi[0] >= 0.03 and hi[0] <= 0.03 * 1.02


def test_the_cone_cull_never_skips_a_ball_a_ray_meets() -> None:
    """_sphere_meets_cone against sampled rays of the cone: wherever a sampled segment passes through
    the ball, the cull keeps it; and it drops balls behind the apex or beyond the reach."""
    rng = np.random.default_rng(11)
    kept_by_rays = culled = 0
    for _ in range(300):
        axis = _unit(rng.normal(size=3))
        alpha, reach = rng.uniform(0.05, 0.6), rng.uniform(0.5, 2.0)
        center = axis * rng.uniform(-0.3, reach + 0.3) + rng.normal(0, 0.4, 3)
        radius = rng.uniform(0.02, 0.3)
        # rays: directions uniform in the cap of half-angle alpha about the axis, segments [0, reach]
        helper = _unit(np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0]))
        other = np.cross(axis, helper)
        cos_t = rng.uniform(np.cos(alpha), 1.0, 4000)
        phi = rng.uniform(0, 2 * np.pi, 4000)
        sin_t = np.sqrt(1 - cos_t**2)
        dirs = cos_t[:, None] * axis + sin_t[:, None] * (
            np.cos(phi)[:, None] * helper + np.sin(phi)[:, None] * other
        )
        t = np.clip(dirs @ center, 0.0, reach)
        met = (np.linalg.norm(t[:, None] * dirs - center, axis=1) <= radius).any()
        keep = view_module._sphere_meets_cone(center, radius, axis, alpha, reach)
        assert keep or not met
        kept_by_rays += met
        culled += not keep
    assert kept_by_rays > 50 and culled > 50  # both cases were exercised
    axis = np.array([0.0, 0.0, 1.0])
    assert not view_module._sphere_meets_cone(np.array([0.0, 0.0, -1.0]), 0.2, axis, 0.3, 2.0)  # behind
    assert not view_module._sphere_meets_cone(np.array([0.0, 0.0, 3.0]), 0.2, axis, 0.3, 2.0)  # too far
    assert view_module._sphere_meets_cone(np.array([0.0, 0.0, 2.1]), 0.2, axis, 0.3, 2.0)  # reaches into it
