"""Scene construction: objects (face, sphere, mesh files), G-buffer, resolution, errors."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import trimesh
from PIL import Image
from scipy.spatial import cKDTree

from optlight import ProblemError, load_problem
from optlight.scene import Scene
from optlight.scene.gbuffer import RayCaster
from optlight.scene.objects import face_mesh
from optlight.spec import FaceSpec, Problem, problem_from_dict


def make_problem(**sections: dict) -> Problem:
    return problem_from_dict(sections)


def object_frame(scene: Scene, world: np.ndarray) -> np.ndarray:
    """World points in the light-sphere frame S (origin O)."""
    return (world - scene.sphere.center) @ scene.sphere.rotation


@pytest.fixture(scope="module")
def default_scene() -> Scene:
    return Scene.from_problem(load_problem("default"), 128, 128)


# ------------------------------------------------------------------ face


def test_face_is_deterministic() -> None:
    spec = FaceSpec(resolution=48)
    first, second = face_mesh(spec), face_mesh(spec)
    for a, b in zip(first, second, strict=True):
        assert np.array_equal(a, b)


def test_face_mesh_is_mirror_symmetric() -> None:
    """Mirroring x -> -x maps vertices onto vertices, triangles onto triangles, albedo onto albedo."""
    vertices, faces, albedo = face_mesh(FaceSpec(resolution=40))
    mirrored = vertices * np.array([-1.0, 1.0, 1.0])
    dist, index = cKDTree(vertices).query(mirrored)
    assert dist.max() < 1e-12
    assert len(np.unique(index)) == len(vertices)
    assert np.array_equal(albedo[index], albedo)
    original = {tuple(sorted(f)) for f in faces.tolist()}
    assert {tuple(sorted(f)) for f in index[faces].tolist()} == original


def test_face_is_closed_outward_and_head_sized() -> None:
    spec = FaceSpec(resolution=48)
    vertices, faces, _ = face_mesh(spec)
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    # chin to forehead is height_m; the whole head is a bit taller (crown) and about 0.8 h wide
    extent = vertices.max(0) - vertices.min(0)
    assert spec.height_m < extent[1] < 1.4 * spec.height_m
    assert 0.6 * spec.height_m < extent[0] < spec.height_m
    # the nose tip is the frontmost point, on the symmetry plane, below the centre
    tip = vertices[np.argmax(vertices[:, 2])]
    assert abs(tip[0]) < 1e-12 and -0.25 * spec.height_m < tip[1] < 0
    # geometry scales with height_m when the relief does
    big = dataclasses.replace(
        spec,
        **{
            k: 2 * getattr(spec, k)
            for k in ("height_m", "nose_m", "brow_m", "eye_depth_m", "lip_m", "cheek_m")
        },
    )
    assert np.allclose(face_mesh(big)[0], 2 * vertices, atol=1e-15)


def test_face_relief_follows_parameters() -> None:
    flat = FaceSpec(resolution=48, nose_m=0.0, brow_m=0.0, eye_depth_m=0.0, lip_m=0.0, cheek_m=0.0)
    nosy = dataclasses.replace(flat, nose_m=0.03)
    v0, v1 = face_mesh(flat)[0], face_mesh(nosy)[0]
    bump = np.linalg.norm(v1 - v0, axis=1)
    assert bump.max() == pytest.approx(0.03, rel=0.05)


def test_brows_and_lips_are_darker() -> None:
    spec = FaceSpec(resolution=64)
    vertices, _, albedo = face_mesh(spec)
    x, y, z = (vertices / spec.height_m).T
    skin = spec.skin_albedo
    upper = (y > 0.05) & (z > 0)
    lower = (y < -0.15) & (z > 0)
    assert albedo[upper].min() == pytest.approx(spec.brow_albedo, abs=0.01)
    assert albedo[lower].min() == pytest.approx(spec.lip_albedo, abs=0.01)
    # the dark vertices are on the front, the brows off the symmetry plane, the lips across it
    brows = (albedo < skin - 0.5 * (skin - spec.brow_albedo)) & (y > 0)
    assert brows.any() and np.all(z[brows] > 0) and np.all(np.abs(x[brows]) > 0.03)
    lips = (albedo < skin - 0.5 * (skin - spec.lip_albedo)) & (y < 0)
    assert lips.any() and np.all(z[lips] > 0) and np.abs(x[lips]).min() < 0.01
    # the rest of the head is skin
    assert np.all(albedo[z < 0] == skin)
    # setting brow and lip albedo to the skin's makes the face uniform
    uniform = dataclasses.replace(spec, brow_albedo=skin, lip_albedo=skin)
    assert np.allclose(face_mesh(uniform)[2], skin)


def test_face_is_well_framed_by_default_camera(default_scene: Scene) -> None:
    gb = default_scene.gbuffer
    assert 0.2 < gb.mask.mean() < 0.8
    h, w = gb.mask.shape
    assert gb.mask[h // 2, w // 2]
    # face features are visible: brow- and lip-dark pixels exist in the image
    spec = default_scene.problem.object.face
    assert gb.albedo.min() < spec.brow_albedo + 0.05
    lower = object_frame(default_scene, gb.points)[:, 1] < 0
    assert gb.albedo[lower].min() < spec.lip_albedo + 0.05


def test_face_renders_mirror_symmetric(default_scene: Scene) -> None:
    """Light at azimuth φ vs π − φ (x_S mirrored): the images are mirror images of each other."""
    sphere = default_scene.sphere
    zenith, azimuth = 0.6, 0.4
    left = default_scene.render(sphere.position(zenith, azimuth))
    right = default_scene.render(sphere.position(zenith, np.pi - azimuth))
    assert np.array_equal(default_scene.gbuffer.mask, default_scene.gbuffer.mask[:, ::-1])
    diff = np.abs(left - right[:, ::-1])
    assert np.mean(diff < 1e-6) > 0.995
    assert np.mean(diff) < 1e-4


# ------------------------------------------------------------------ G-buffer


def test_rays_are_cast_with_embree(default_scene: Scene) -> None:
    assert isinstance(default_scene._caster, RayCaster)
    assert type(default_scene._caster._scene).__module__ == "embreex.rtcore_scene"


def _rays_at_the_face(scene: Scene, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """n rays from points on a sphere round the face towards points in a box round it: hits and misses."""
    rng = np.random.default_rng(seed)
    center = scene.sphere.center
    u = rng.normal(size=(n, 3))
    origins = center + 0.3 * u / np.linalg.norm(u, axis=1, keepdims=True)
    targets = center + rng.uniform(-0.2, 0.2, size=(n, 3))
    d = targets - origins
    return origins, d / np.linalg.norm(d, axis=1, keepdims=True)


def test_ray_caster_agrees_with_trimesh_and_with_itself_on_any_thread_count(
    default_scene: Scene, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Our Embree wrapper against trimesh's (an independent wrapper of the same library), and split
    over two threads against one."""
    from trimesh.ray.ray_pyembree import RayMeshIntersector

    origins, directions = _rays_at_the_face(default_scene, 40_000, seed=3)
    caster = RayCaster(default_scene.mesh)
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    serial = caster.first_hits(origins, directions)
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    threaded = caster.first_hits(origins, directions)
    reference = RayMeshIntersector(default_scene.mesh).intersects_first(origins, directions)
    assert 0.3 < np.mean(serial >= 0) < 0.99  # both hits and misses are tested
    np.testing.assert_array_equal(threaded, serial)
    np.testing.assert_array_equal(serial, reference)


def test_first_hit_distances_are_the_exact_distances_to_a_box() -> None:
    """Rays at the cube [−0.1, 0.1]³ (m) from z = −0.5 along +z at random x, y: through the cube the
    distance is 0.4 m, outside it inf; tilted rays through the −z face hit it at 0.4 / d_z."""
    import trimesh

    caster = RayCaster(trimesh.creation.box(extents=(0.2, 0.2, 0.2)))
    rng = np.random.default_rng(5)
    xy = rng.uniform(-0.2, 0.2, size=(2000, 2))
    origins = np.c_[xy, np.full(len(xy), -0.5)]
    inside = (np.abs(xy) < 0.0999).all(axis=1)
    outside = (np.abs(xy) > 0.1001).any(axis=1)
    t = caster.first_hit_distances(origins, np.tile([0.0, 0.0, 1.0], (len(xy), 1)))
    assert inside.sum() > 400 and outside.sum() > 400
    np.testing.assert_allclose(t[inside], 0.4, rtol=0, atol=1e-12)
    assert np.isinf(t[outside]).all()
    tilt = np.array([0.05, -0.03, 1.0]) / np.linalg.norm([0.05, -0.03, 1.0])
    aimed = np.c_[rng.uniform(-0.05, 0.05, size=(200, 2)), np.full(200, -0.5)]
    np.testing.assert_allclose(caster.first_hit_distances(aimed, np.tile(tilt, (200, 1))), 0.4 / tilt[2], atol=1e-12)


def test_any_hits_are_the_rays_through_a_box() -> None:
    """Rays from below the cube [−0.1, 0.1]³ (m), at random x, y and random upward directions: a ray
    hits it iff the slab test says so (it enters all three slabs before it leaves one, t_in < t_out,
    grazing rays within 1e-4 m left out); pointing the other way, none does."""
    import trimesh

    caster = RayCaster(trimesh.creation.box(extents=(0.2, 0.2, 0.2)))
    rng = np.random.default_rng(6)
    origins = np.c_[rng.uniform(-0.3, 0.3, size=(4000, 2)), np.full(4000, -0.5)]
    directions = np.c_[rng.uniform(-0.5, 0.5, size=(4000, 2)), np.ones(4000)]
    with np.errstate(divide="ignore"):
        near, far = ((s * 0.1 - origins) / directions for s in (-1.0, 1.0))
    t_in, t_out = np.minimum(near, far).max(axis=1), np.maximum(near, far).min(axis=1)
    length = np.linalg.norm(directions, axis=1)
    through, beside = (t_out - t_in) * length > 1e-4, (t_in - t_out) * length > 1e-4
    hits = caster.any_hits(origins, directions)
    assert through.sum() > 400 and beside.sum() > 400
    assert hits[through].all() and not hits[beside].any()
    assert not caster.any_hits(origins, -directions).any()


def test_a_pickled_scene_casts_the_same_shadows(default_scene: Scene) -> None:
    import pickle

    light = default_scene.sphere.position(0.6, 2.0)
    copy = pickle.loads(pickle.dumps(default_scene))
    shadows = default_scene.visibility(light)
    assert (shadows == 0).sum() > 100  # the light casts shadows worth comparing
    np.testing.assert_array_equal(copy.visibility(light), shadows)


@pytest.mark.parametrize("model", ["directional", "point"])
def test_a_calibrated_scene_casts_shadows_from_its_own_normals(default_scene: Scene, model: str) -> None:
    """Calibrated normals and light model (the scene's shadow origins are built once, so a
    calibrated scene must build its own): against rays cast here from p + ε n' towards the light,
    n' the calibrated normals, where n'·l > 0 (a point light's only for hits nearer than the light)."""
    from optlight.scene import SHADOW_EPSILON

    rng = np.random.default_rng(8)
    gb = default_scene.gbuffer
    tilted = gb.normals + rng.normal(scale=0.3, size=gb.normals.shape)
    tilted /= np.linalg.norm(tilted, axis=1, keepdims=True)
    light = dataclasses.replace(default_scene.light, model=model)
    calibrated = default_scene.calibrated(light, gb.albedo, tilted)
    a = default_scene.sphere.position(0.7, 2.5)
    axis = a - default_scene.sphere.center
    to_light = a - gb.points if model == "point" else np.broadcast_to(axis, gb.points.shape)
    distance = np.linalg.norm(to_light, axis=1)
    direction = to_light / distance[:, None]
    lit = np.einsum("ij,ij->i", tilted, direction) > 0
    epsilon = SHADOW_EPSILON * float(default_scene.mesh.scale)
    origins = gb.points + epsilon * tilted
    caster = RayCaster(default_scene.mesh)
    if model == "point":
        hit = caster.first_hit_distances(origins[lit], direction[lit]) < distance[lit] - epsilon
    else:
        hit = caster.any_hits(origins[lit], direction[lit])
    expected = np.ones(gb.size)
    expected[np.flatnonzero(lit)[hit]] = 0.0
    got = calibrated.visibility(a)
    assert 100 < (got == 0).sum() and (got != default_scene.visibility(a)).sum() > 10  # the normals matter
    np.testing.assert_array_equal(got, expected)


def test_gbuffer_points_lie_on_pixel_rays_and_surface(default_scene: Scene) -> None:
    gb, cam = default_scene.gbuffer, default_scene.camera
    assert (
        gb.points.shape == (gb.size, 3) and gb.normals.shape == (gb.size, 3) and gb.albedo.shape == (gb.size,)
    )
    assert np.array_equal(np.flatnonzero(gb.mask.ravel()), gb.pixel_index)
    u, v, depth = cam.project(gb.points)
    assert np.all(depth > 0)
    assert np.allclose(u, gb.pixel_index % cam.width, atol=1e-6)
    assert np.allclose(v, gb.pixel_index // cam.width, atol=1e-6)
    assert np.allclose(np.linalg.norm(gb.normals, axis=1), 1.0)
    # normals face the camera, points are on the mesh
    to_camera = cam.position - gb.points
    assert np.mean(np.einsum("ij,ij->i", gb.normals, to_camera) > 0) > 0.99
    mesh = default_scene.mesh
    for p in gb.points[::100]:
        assert on_mesh(mesh, p)


def on_mesh(mesh: trimesh.Trimesh, p: np.ndarray, tol: float = 1e-12) -> bool:
    """Is p within tol of the plane of a triangle near it, with barycentrics ≥ −tol·1e3?"""
    near = np.flatnonzero(np.linalg.norm(mesh.triangles_center - p, axis=1) < 0.01)
    a, b, c = (mesh.triangles[near][:, k] for k in range(3))
    n = np.cross(b - a, c - a)
    area2 = np.einsum("ij,ij->i", n, n)
    off_plane = np.abs(np.einsum("ij,ij->i", p - a, n)) / np.sqrt(area2)
    bary = np.stack(
        [np.einsum("ij,ij->i", np.cross(y - x, p - x), n) / area2 for x, y in ((b, c), (c, a), (a, b))]
    )
    return bool(np.any((off_plane < tol) & np.all(bary > -1e3 * tol, axis=0)))


def test_lower_resolution_scales_intrinsics() -> None:
    problem = load_problem("default")
    full = Scene.from_problem(problem)
    low = Scene.from_problem(problem, width=64)
    assert (low.camera.width, low.camera.height) == (64, 64)
    assert low.camera.fx == pytest.approx(full.camera.fx / 4)
    points = full.mesh.vertices[::997]
    u0, v0, _ = full.camera.project(points)
    u1, v1, _ = low.camera.project(points)
    assert np.allclose(u1, (u0 + 0.5) / 4 - 0.5) and np.allclose(v1, (v0 + 0.5) / 4 - 0.5)
    assert low.gbuffer.mask.mean() == pytest.approx(full.gbuffer.mask.mean(), abs=0.02)


# ------------------------------------------------------------------ sphere and meshes


def test_sphere_gbuffer_is_exact() -> None:
    problem = make_problem(object={"kind": "sphere", "radius_m": 0.1})
    scene = Scene.from_problem(problem, 64, 64)
    gb = scene.gbuffer
    center = scene.sphere.center
    assert np.allclose(np.linalg.norm(gb.points - center, axis=1), 0.1, atol=1e-12)
    assert np.allclose(gb.normals, (gb.points - center) / 0.1, atol=1e-15)
    assert np.allclose(gb.albedo, problem.object.albedo)


def write_colored_box(path: Path) -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=(0.1, 0.06, 0.04))
    colors = np.zeros((len(box.vertices), 4), np.uint8)
    colors[:, 3] = 255
    colors[box.vertices[:, 0] > 0, :3] = (200, 30, 30)
    colors[box.vertices[:, 0] <= 0, :3] = (128, 128, 128)
    box.visual.vertex_colors = colors
    box.export(path)
    return box


def srgb_to_linear(c8: np.ndarray) -> np.ndarray:
    c = c8 / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def test_mesh_file_frame_scale_and_colour_albedo(tmp_path: Path) -> None:
    path = tmp_path / "box.ply"
    write_colored_box(path)
    problem = make_problem(object={"kind": "mesh", "path": str(path), "scale": 2.0})
    scene = Scene.from_problem(problem, 48, 48)
    local = object_frame(scene, scene.mesh.vertices)
    assert np.allclose(local.max(0), (0.1, 0.06, 0.04)) and np.allclose(local.min(0), (-0.1, -0.06, -0.04))
    red = 0.2126 * srgb_to_linear(200) + 0.7152 * srgb_to_linear(30) + 0.0722 * srgb_to_linear(30)
    grey = srgb_to_linear(128)
    expected = np.where(local[:, 0] > 0, red, grey)
    assert np.allclose(scene.albedo, expected)
    # the +z face is the front: the camera sees it, at 0.04 m from O towards the camera
    front = object_frame(scene, scene.gbuffer.points)
    assert np.allclose(front[:, 2], 0.04)


def test_textured_glb_albedo_comes_from_the_texture(tmp_path: Path) -> None:
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.05)
    right = ball.vertices[:, 0] > 0
    uv = np.column_stack([np.where(right, 0.75, 0.25), np.full(len(ball.vertices), 0.5)])
    texture = Image.fromarray(np.array([[[30, 30, 30], [220, 220, 220]]], np.uint8))  # left, right texel
    ball.visual = trimesh.visual.TextureVisuals(uv=uv, image=texture)
    path = tmp_path / "ball.glb"
    ball.export(path)
    scene = Scene.from_problem(make_problem(object={"kind": "mesh", "path": str(path)}), 32, 32)
    local = object_frame(scene, scene.mesh.vertices)
    off_seam = np.abs(local[:, 0]) > 1e-9  # vertices on x = 0 carry either texel, by round-off
    expected = np.where(local[:, 0] > 0, srgb_to_linear(220), srgb_to_linear(30))
    assert off_seam.sum() > 0.8 * len(local)
    assert np.allclose(scene.albedo[off_seam], expected[off_seam])


def test_mesh_without_colours_uses_constant_albedo(tmp_path: Path) -> None:
    path = tmp_path / "ball.stl"
    trimesh.creation.icosphere(subdivisions=2, radius=0.05).export(path)
    scene = Scene.from_problem(
        make_problem(object={"kind": "mesh", "path": str(path), "albedo": 0.3}), 32, 32
    )
    assert np.all(scene.albedo == 0.3)


# ------------------------------------------------------------------ errors


def test_object_outside_light_sphere_is_a_problem_error() -> None:
    problem = make_problem(object={"face": {"height_m": 0.8}})
    with pytest.raises(ProblemError) as err:
        Scene.from_problem(problem, 16, 16)
    assert err.value.key == "light_sphere.radius_m"


def test_invisible_object_is_a_problem_error() -> None:
    problem = make_problem(object={"kind": "sphere", "radius_m": 0.001}, camera={"width": 8, "height": 8})
    with pytest.raises(ProblemError) as err:
        Scene.from_problem(problem)
    assert err.value.key == "camera"


def test_mesh_file_without_triangles_is_a_problem_error(tmp_path: Path) -> None:
    path = tmp_path / "points.obj"
    path.write_text("v 0 0 0\nv 0.01 0 0\nv 0 0.01 0\n")
    with pytest.raises(ProblemError) as err:
        Scene.from_problem(make_problem(object={"kind": "mesh", "path": str(path)}), 16, 16)
    assert err.value.key == "object.path"
