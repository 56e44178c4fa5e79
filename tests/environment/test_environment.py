"""Environment: analytic shapes against coal, conservative spheres, the CasADi clearance against its
NumPy twin and finite differences, and the exact checks (table, view cone, clear, skipping)."""

from __future__ import annotations

import casadi as ca
import coal
import numpy as np
import pinocchio as pin
import pytest
import trimesh

from optlight.environment import Ball, Box, Cylinder, Environment, HalfSpace, ViewCone, spheres
from optlight.environment.check import EXACT_BAND_M
from optlight.environment.collision import LIGHT
from optlight.environment.shapes import SMOOTHING_M, rotation_rpy_deg
from optlight.errors import ProblemError
from optlight.geometry import LightSphere
from optlight.robot import generalized_ik, load_robot
from optlight.robot.loading import Robot
from optlight.spec import load_problem, problem_from_dict

RNG_SEED = 7


@pytest.fixture(scope="module")
def problem():
    return load_problem("table_wall")


@pytest.fixture(scope="module")
def robot(problem) -> Robot:
    return load_robot(problem)


@pytest.fixture(scope="module")
def env(problem, robot) -> Environment:
    e = Environment.from_problem(problem)
    e.collision_model(robot)
    return e


@pytest.fixture(scope="module")
def clear_theta(problem, robot) -> np.ndarray:
    """The light at zenith 32°, azimuth 90° (above the face), from the generalized IK."""
    ik = generalized_ik(robot, LightSphere.from_problem(problem), (np.radians(32.0), np.radians(90.0)))
    assert ik.success
    return ik.theta


@pytest.fixture(scope="module")
def table_theta(robot) -> np.ndarray:
    """Shoulder forward, elbow open: the flange ends below the table top (z = 0)."""
    theta = robot.theta_ref.copy()
    theta[1], theta[3] = 1.7, -0.2
    assert robot.within_limits(theta)
    assert robot.frame_pose("flange", theta).translation[2] < -0.03
    return theta


# ------------------------------------------------------------------------------------ shapes


def _exact_box_distance(point: np.ndarray, box: Box) -> float:
    """Textbook signed distance to a box (no smoothing)."""
    q = np.abs(box.rotation.T @ (point - box.center)) - box.half_extents
    return float(np.linalg.norm(np.maximum(q, 0.0)) + min(q.max(), 0.0))


def test_coal_sphere_box_distance_matches_the_analytic_distance() -> None:
    rng = np.random.default_rng(RNG_SEED)
    box = Box("b", np.array([0.3, -0.2, 0.5]), rotation_rpy_deg([20, -35, 50]), np.array([0.15, 0.05, 0.1]))
    req = coal.DistanceRequest()
    centres = box.center + rng.uniform(-0.4, 0.4, size=(300, 3))
    radius = 0.03
    for c in centres:
        exact = _exact_box_distance(c, box) - radius
        got = coal.distance(
            coal.Sphere(radius),
            coal.Transform3s(np.eye(3), c),
            box.coal_geometry(),
            coal.Transform3s(box.rotation, box.center),
            req,
            coal.DistanceResult(),
        )
        assert got == pytest.approx(exact, abs=1e-6)
        # the smooth analytic distance the NLPs use: equal inside, within ε outside, never above
        smooth = float(box.signed_distance(c)[0]) - radius
        assert exact - SMOOTHING_M - 1e-12 <= smooth <= exact + 1e-12


@pytest.mark.parametrize(
    "shape",
    [
        HalfSpace("table", np.array([0.0, 0.0, 1.0]), 0.1),
        Ball("ball", np.array([0.2, 0.1, 0.3]), 0.12),
        Cylinder("post", np.array([0.1, 0.0, 0.4]), rotation_rpy_deg([30, 10, 0]), 0.05, 0.2),
    ],
    ids=lambda s: s.name,
)
def test_every_shape_agrees_with_coal(shape) -> None:
    rng = np.random.default_rng(RNG_SEED)
    req = coal.DistanceRequest()
    place = shape.placement
    for c in rng.uniform([-0.3, -0.4, -0.1], [0.6, 0.5, 0.8], size=(200, 3)):
        ours = float(shape.signed_distance(c)[0]) - 0.02
        theirs = coal.distance(
            coal.Sphere(0.02),
            coal.Transform3s(np.eye(3), c),
            shape.coal_geometry(),
            coal.Transform3s(place.rotation, place.translation),
            req,
            coal.DistanceResult(),
        )
        if theirs > 0:  # separated: exact to ε; in contact coal's EPA depth is approximate
            assert ours == pytest.approx(theirs, abs=1e-5)
        else:
            assert ours < 1e-5


def test_view_cone_distance_is_exact_inside_and_a_lower_bound_outside() -> None:
    cone = ViewCone.around([0.0, 0.0, 0.0], [0.8, 0.0, 0.0], 0.15, np.radians(1.0))
    rng = np.random.default_rng(RNG_SEED)
    req = coal.DistanceRequest()
    place = cone.placement
    for p in rng.uniform([-0.2, -0.4, -0.4], [1.0, 0.4, 0.4], size=(300, 3)):
        ours = float(cone.signed_distance(p)[0])
        theirs = coal.distance(
            coal.Sphere(1e-4),
            coal.Transform3s(np.eye(3), p),
            cone.coal_geometry(),
            coal.Transform3s(place.rotation, place.translation),
            req,
            coal.DistanceResult(),
        )
        if theirs > 0:
            assert ours <= theirs + 1e-4 + 1e-6
        else:
            assert ours < 1e-6


# ------------------------------------------------------------------------------------ spheres


def test_spheres_cover_every_collision_mesh_vertex_and_surface(env, robot) -> None:
    cm = env.collision_model(robot)
    geom = robot.geometry_model("collision")
    sp = cm.spheres
    rng = np.random.default_rng(RNG_SEED)
    for b, body in enumerate(cm.bodies):
        centres, radii = sp.centers[sp.body == b], sp.radii[sp.body == b]
        points = []
        for g in body.geometries:
            obj = cm.geometry.geometryObjects[g]
            if body.name == LIGHT:
                housing = env.housing  # the [light] housing: a coal cylinder by default
                mesh = trimesh.creation.cylinder(
                    radius=housing.radius, height=2 * housing.halfLength, sections=256
                )
                points.append(mesh.vertices @ obj.placement.rotation.T + obj.placement.translation)
                continue
            original = geom.geometryObjects[g].geometry  # the URDF's mesh or primitive, not the hull
            if isinstance(original, coal.BVHModelBase):
                v = np.asarray(original.vertices(), float)
            else:
                v = trimesh.creation.box(extents=2 * np.asarray(original.halfSide)).vertices
            hull = trimesh.Trimesh(v).convex_hull
            v = np.concatenate([v, trimesh.sample.sample_surface(hull, 2000, seed=rng)[0]])
            points.append(v @ obj.placement.rotation.T + obj.placement.translation)
        pts = np.concatenate(points)
        inside = np.linalg.norm(pts[:, None, :] - centres[None], axis=2) <= radii[None] + 1e-9
        assert inside.any(axis=1).all(), f"{body.name}: {np.sum(~inside.any(axis=1))} points outside"


def test_sphere_fits_are_read_back_from_the_disk_cache(tmp_path, monkeypatch) -> None:
    surfaces = [trimesh.creation.box(extents=[0.2, 0.05, 0.04]), trimesh.creation.icosphere(radius=0.03)]
    surfaces[1].apply_translation([0.1, 0.0, 0.02])
    monkeypatch.setenv("OPTLIGHT_CACHE", str(tmp_path))
    centers, radii = spheres.fit_spheres(surfaces, 3)
    (entry,) = (tmp_path / "spheres").glob("*.npz")

    def fail(*args, **kwargs):
        raise AssertionError("fitted again instead of read from the cache")

    monkeypatch.setattr(spheres, "_fit", fail)
    again = spheres.fit_spheres(surfaces, 3)
    np.testing.assert_array_equal(again[0], centers)
    np.testing.assert_array_equal(again[1], radii)
    # another sphere count, or moved surfaces, are other entries; a damaged file is fitted again
    with pytest.raises(AssertionError, match="fitted again"):
        spheres.fit_spheres(surfaces, 2)
    with pytest.raises(AssertionError, match="fitted again"):
        spheres.fit_spheres([surfaces[0].copy().apply_translation([0.0, 0.0, 1e-3]), surfaces[1]], 3)
    entry.write_bytes(b"not an npz")
    with pytest.raises(AssertionError, match="fitted again"):
        spheres.fit_spheres(surfaces, 3)


# ------------------------------------------------------------------------------------ NLP functions


def _fd_jacobian(f, theta: np.ndarray, h: float = 1e-6) -> np.ndarray:
    cols = []
    for i in range(theta.size):
        e = np.zeros_like(theta)
        e[i] = h
        cols.append((f(theta + e) - f(theta - e)) / (2 * h))
    return np.stack(cols, axis=1)


def test_casadi_clearance_equals_numpy_and_its_jacobian_finite_differences(env, robot) -> None:
    clearance, view = env.clearance_function(robot), env.view_cone_function(robot)
    assert clearance.size_out(0)[0] == len(env.clearance_labels(robot))
    theta = ca.SX.sym("theta", robot.n)
    jac = ca.Function(
        "clearance_jacobians",
        [theta],
        [ca.jacobian(clearance(theta), theta), ca.jacobian(view(theta), theta)],
    )
    rng = np.random.default_rng(RNG_SEED)
    for th in robot.random_configuration(rng, 3):
        c_np, v_np = env.sphere_clearance(robot, th)
        np.testing.assert_allclose(np.asarray(clearance(th)).ravel(), c_np, atol=1e-12)
        np.testing.assert_allclose(np.asarray(view(th)).ravel(), v_np, atol=1e-12)
        jc, jv = (np.asarray(j) for j in jac(th))
        np.testing.assert_allclose(
            jc, _fd_jacobian(lambda t: env.sphere_clearance(robot, t)[0], th), atol=1e-6
        )
        np.testing.assert_allclose(
            jv, _fd_jacobian(lambda t: env.sphere_clearance(robot, t)[1], th), atol=1e-6
        )


# ------------------------------------------------------------------------------------ exact checks


def test_a_configuration_through_the_table_is_caught(env, robot, clear_theta, table_theta) -> None:
    s = np.linspace(0.0, 1.0, 41)[:, None]
    thetas = np.concatenate(
        [(1 - s) * clear_theta + s * table_theta, (1 - s[1:]) * table_theta + s[1:] * clear_theta]
    )
    times = np.arange(len(thetas)) * 0.01
    report = env.check(robot, thetas, times)
    assert not report.passed
    table = [v for v in report.violations if v.second == "table"]
    assert table and all(v.kind == "obstacle" for v in table)
    worst = min(table, key=lambda v: v.distance_m)
    assert worst.distance_m < -0.02  # penetration depth, m
    assert worst.time_s == pytest.approx(0.40, abs=0.015)  # the deepest sample: the turning point
    assert worst.point_m[2] < 0.0  # the reported point on the robot is under the table top
    assert "table" in worst.message and "t = " in worst.message


def test_skipped_samples_never_hide_a_violation_or_a_near_minimum(
    env, robot, clear_theta, table_theta
) -> None:
    """The certified skipping of check() against every pair at every sample: a hold of 700 samples
    (certified in blocks, nothing due) and then the move into the table (due at every sample)."""
    s = np.linspace(0.0, 1.0, 61)[:, None]
    thetas = np.vstack([np.repeat(clear_theta[None], 700, axis=0), (1 - s) * clear_theta + s * table_theta])
    times = np.arange(len(thetas)) * 0.01
    report = env.check(robot, thetas, times)
    cm = env.collision_model(robot)
    brute: dict[tuple[str, str], list[float]] = {}
    for th in thetas[699:]:
        pin.updateGeometryPlacements(robot.model, robot.data, cm.geometry, cm.geometry_data, robot.to_pin(th))
        per: dict[tuple[str, str], float] = {}
        for pair in cm.pairs:
            if pair.kind == "view":
                continue
            key = (pair.first_body, pair.second_name)
            per[key] = min(per.get(key, np.inf), cm.distance(pair.first, pair.second))
        for key, d in per.items():
            brute.setdefault(key, []).extend([d] * (700 if not brute.get(key) else 1))  # the hold: one value
    assert report.evaluations < 61 * sum(p.kind != "view" for p in cm.pairs)
    for pc in report.pairs:
        if pc.kind == "view":
            continue
        d = np.array(brute[(pc.first, pc.second)])
        assert pc.failing_samples == int(np.sum(d < pc.threshold_m))
        if d.min() < pc.threshold_m + EXACT_BAND_M:
            assert pc.min_distance_m == pytest.approx(d.min(), abs=1e-12)
        else:
            assert pc.min_distance_m >= pc.threshold_m + EXACT_BAND_M


def test_a_light_inside_the_view_cone_is_caught_at_capture_times(problem, env, robot) -> None:
    sphere = LightSphere.from_problem(problem)
    ik = generalized_ik(robot, sphere, (0.0, 0.0))  # zenith 0: between the camera and the object
    assert ik.success
    assert np.asarray(env.view_cone_function(robot)(ik.theta)).min() < 0.0
    thetas, times = np.stack([ik.theta, ik.theta]), np.array([0.0, 1.0])
    report = env.check(robot, thetas, times, capture_times=[1.0])
    light = [v for v in report.violations if v.kind == "view" and v.first == LIGHT]
    assert len(light) == 1 and light[0].time_s == 1.0 and light[0].distance_m < 0.0
    assert report.view_samples == 1
    # between captures the view cone is not a constraint
    assert not any(v.kind == "view" for v in env.check(robot, thetas, times).violations)
    with pytest.raises(ValueError, match="not one of the sample times"):
        env.check(robot, thetas, times, capture_times=[0.5])


def test_the_capture_samples_are_those_within_the_tolerance_of_a_capture_time() -> None:
    """Against the definition, sample by sample: unsorted times, samples just inside and just outside
    the tolerance of a capture, two samples at one capture."""
    from optlight.environment.check import TIME_TOLERANCE_S, _capture_mask

    rng = np.random.default_rng(3)
    captures = np.array([0.25, 1.5, 7.0])
    times = np.r_[rng.uniform(0.0, 8.0, 500), captures, 1.5 + 0.9 * TIME_TOLERANCE_S, 7.0 - 1.1 * TIME_TOLERANCE_S]
    rng.shuffle(times)
    expected = (np.abs(times[:, None] - captures[None]) <= TIME_TOLERANCE_S).any(axis=1)
    assert expected.sum() == 4
    np.testing.assert_array_equal(_capture_mask(times, captures), expected)
    with pytest.raises(ValueError, match="not one of the sample times"):
        _capture_mask(times, [7.0 + 1.5 * TIME_TOLERANCE_S])


def test_a_clear_configuration_passes(env, robot, clear_theta) -> None:
    report = env.check(robot, clear_theta[None], [0.0], capture_times=[0.0])
    assert report.passed, report.summary()
    assert report.min_clearance_m >= env.margin
    assert {p.kind for p in report.pairs} == {"obstacle", "self", "view"}
    assert report.to_dict()["passed"] is True


# ------------------------------------------------------------------------------------ problem files


def test_environment_is_off_by_default_and_on_in_the_obstacle_problems() -> None:
    assert not load_problem("default").environment.enabled
    names = {o.name for o in Environment.from_problem(load_problem("table_wall")).obstacles}
    assert names == {"object", "table", "camera_body", "camera_stand", "wall"}
    collision = load_problem("collision")
    assert collision.environment.enabled and collision.view.mode == "capture"


@pytest.mark.parametrize(
    ("change", "key"),
    [
        (
            {"boxes": [{"name": "b", "center_m": [0.35, 0.0, 0.45], "size_m": [0.1, 0.1, 0.1]}]},
            "environment.boxes[0]",
        ),
        ({"spheres": [{"name": "table", "center_m": [1.0, 1.0, 1.0]}]}, "environment.spheres[0].name"),
        (
            {"cylinders": [{"name": "p"}, {"name": "p", "center_m": [2.0, 0.0, 0.0]}]},
            "environment.cylinders[1].name",
        ),
        ({"table_height_m": 0.5}, "environment.table_height_m"),
    ],
)
def test_inconsistent_environments_name_the_key(change: dict, key: str) -> None:
    data = load_problem("table_wall").to_dict()
    data["environment"] = {"enabled": True, **change}
    with pytest.raises(ProblemError) as err:
        Environment.from_problem(problem_from_dict(data))  # the layout is checked where it is built
    assert err.value.key == key
