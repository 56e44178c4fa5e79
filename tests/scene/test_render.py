"""NumPy renderer against analytic truth: sphere (Lambert), plane (1/r²), box on a plane (shadow)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.ndimage import binary_dilation, binary_erosion

from optlight.scene import Scene
from optlight.spec import Problem, problem_from_dict

EXACT_LIGHT = {"ambient": 0.0, "gain": 1.0, "power": 1.0, "saturation": 100.0, "cast_shadows": False}


def make_problem(**sections: dict) -> Problem:
    return problem_from_dict(sections)


def pixel_rays(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Origin and unit direction (world) of the ray through each object pixel's centre,
    from the pinhole model: d ∝ R_WC (K⁻¹ [u, v, 1])."""
    cam = scene.camera
    idx = scene.gbuffer.pixel_index
    u, v = idx % cam.width, idx // cam.width
    d = np.stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones(len(idx))], -1) @ cam.rotation.T
    return np.broadcast_to(cam.position, d.shape), d / np.linalg.norm(d, axis=1, keepdims=True)


def to_sphere_frame(scene: Scene, world: np.ndarray) -> np.ndarray:
    return (world - scene.sphere.center) @ scene.sphere.rotation


def plane_hits(scene: Scene, origins: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Ray parameter of the hit with the plane z_S = 0 through O."""
    z = scene.sphere.rotation[:, 2]
    return ((scene.sphere.center - origins) @ z) / (dirs @ z)


def export(mesh: trimesh.Trimesh, path: Path) -> str:
    """Write a mesh given in sphere-frame coordinates (the object frame of a mesh file)."""
    mesh.export(path)
    return str(path)


def plane_mesh(half: float) -> trimesh.Trimesh:
    v = np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]], float)
    return trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False)


# ------------------------------------------------------------------ sphere, directional


def test_sphere_directional_is_lambert() -> None:
    problem = make_problem(object={"kind": "sphere", "radius_m": 0.1, "albedo": 0.7}, light=EXACT_LIGHT)
    scene = Scene.from_problem(problem, 96, 96)
    origins, dirs = pixel_rays(scene)
    center, r = scene.sphere.center, 0.1
    # analytic ray–sphere hit: |o + t d − c|² = r²
    oc = origins - center
    half_b = np.einsum("ij,ij->i", dirs, oc)
    disc = half_b**2 - (np.einsum("ij,ij->i", oc, oc) - r**2)
    assert np.all(disc >= 0)
    p = origins + (-half_b - np.sqrt(disc))[:, None] * dirs
    n = (p - center) / r
    for zenith, azimuth in [(0.0, 0.0), (0.5, 1.0), (1.2, 4.0)]:
        a = scene.sphere.position(zenith, azimuth)
        light_dir = (a - center) / scene.sphere.radius
        expected = 0.7 * np.maximum(0.0, n @ light_dir)
        assert np.allclose(scene.pixels(a), expected, rtol=0, atol=1e-6)
    # the mask is the sphere's disc, less at most a ring of silhouette pixels (the mesh is inscribed)
    cam = scene.camera
    o_all, d_all = cam.rays()
    oc = o_all - center
    half_b = np.einsum("ij,ij->i", d_all, oc)
    analytic = (half_b**2 - (np.einsum("ij,ij->i", oc, oc) - r**2) > 0).reshape(cam.height, cam.width)
    mask = scene.gbuffer.mask
    assert not np.any(mask & ~analytic)
    assert np.all(mask[binary_erosion(analytic)])


# ------------------------------------------------------------------ plane, point light


def test_plane_point_light_falls_off_as_inverse_square(tmp_path: Path) -> None:
    path = export(plane_mesh(0.15), tmp_path / "plane.ply")
    problem = make_problem(
        object={"kind": "mesh", "path": path, "albedo": 0.6},
        light={**EXACT_LIGHT, "model": "point", "power": 2.0},
    )
    scene = Scene.from_problem(problem, 80, 80)
    assert scene.gbuffer.mask.mean() > 0.9
    origins, dirs = pixel_rays(scene)
    p = origins + plane_hits(scene, origins, dirs)[:, None] * dirs
    normal = scene.sphere.rotation[:, 2]
    b = scene.sphere.radius
    for zenith, azimuth in [(0.0, 0.0), (0.6, 2.0), (1.0, 5.0)]:
        a = scene.sphere.position(zenith, azimuth)
        to_light = a - p
        r = np.linalg.norm(to_light, axis=1)
        cos = (to_light @ normal) / r
        assert np.all(cos > 0)
        got = scene.pixels(a)
        assert np.allclose(got * r**2 / (0.6 * 2.0 * cos * b**2), 1.0, rtol=1e-9, atol=0)
        # the falloff is real: the value varies across the plane beyond the cosine term alone
        assert np.ptp(got / cos) > 0.1 * got.max()


# ------------------------------------------------------------------ box on a plane, cast shadow


@pytest.mark.parametrize("model", ["directional", "point"])
def test_box_on_plane_casts_the_predicted_shadow(tmp_path: Path, model: str) -> None:
    half, edge = 0.15, 0.06
    box = trimesh.creation.box(extents=(edge, edge, edge))
    box.apply_translation((0, 0, edge / 2))  # [−e/2, e/2]² × [0, e] in the sphere frame
    path = export(trimesh.util.concatenate([plane_mesh(half), box]), tmp_path / "box.ply")
    problem = make_problem(object={"kind": "mesh", "path": path}, light={"cast_shadows": True, "model": model})
    scene = Scene.from_problem(problem, 96, 96)
    origins, dirs = pixel_rays(scene)
    lo, hi = np.array([-edge / 2, -edge / 2, 0.0]), np.array([edge / 2, edge / 2, edge])

    def hits_box(o_s: np.ndarray, d_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Slab test in the sphere frame: (hit?, entry parameter)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (lo - o_s) / d_s, (hi - o_s) / d_s
        t_in = np.nanmax(np.minimum(t1, t2), axis=1)
        t_out = np.nanmin(np.maximum(t1, t2), axis=1)
        return (t_in < t_out) & (t_out > 0), t_in

    o_s = to_sphere_frame(scene, origins)
    d_s = dirs @ scene.sphere.rotation
    t_plane = plane_hits(scene, origins, dirs)
    q = o_s + t_plane[:, None] * d_s
    box_hit, t_box = hits_box(o_s, d_s)
    on_plane = (np.abs(q[:, :2]).max(1) < half) & ~(box_hit & (t_box < t_plane))

    def image(flags: np.ndarray) -> np.ndarray:
        return scene.to_image(flags.astype(float)).astype(bool)

    lights = scene.sphere.position(np.array([0.8, 0.6]), np.array([0.5, 3.5]))
    masks = scene.visibility(lights)  # both lights' rays in one call
    assert masks.shape == (2, scene.gbuffer.size)
    for a, mask in zip(lights, masks, strict=True):
        a_s = to_sphere_frame(scene, a)  # the box lies between the plane and the light: any hit shadows
        towards = np.broadcast_to(a_s, q.shape) - q if model == "point" else np.broadcast_to(a_s, q.shape)
        in_shadow, _ = hits_box(q, towards / np.linalg.norm(towards, axis=1, keepdims=True))
        expected = image(on_plane & in_shadow)
        got = image(on_plane & (mask == 0))
        assert np.array_equal(mask, scene.visibility(a))
        assert expected.sum() > 100  # a real shadow, not a few pixels
        boundary = binary_dilation(expected) & ~binary_erosion(expected)
        boundary |= binary_dilation(~image(on_plane)) & image(on_plane)  # next to the box or the edge
        assert not np.any((expected != got) & ~boundary)
        assert np.mean(expected[boundary] == got[boundary]) > 0.8
        # shadowed plane pixels show only the ambient term
        pixels = scene.pixels(a)
        rho, light = scene.gbuffer.albedo, scene.light
        shadowed = on_plane & (scene.visibility(a) == 0)
        assert np.allclose(pixels[shadowed], light.gain * rho[shadowed] * light.ambient)


# ------------------------------------------------------------------ image plumbing, clip, noise


@pytest.fixture(scope="module")
def face_scene() -> Scene:
    return Scene.from_problem(make_problem(light={"noise_std": 0.05, "saturation": 0.5}), 64, 64)


def test_render_places_pixels_and_clips(face_scene: Scene) -> None:
    a = face_scene.sphere.position(0.3, 1.0)
    pixels = face_scene.pixels(a)
    image = face_scene.render(a)
    assert image.shape == (64, 64)
    assert np.array_equal(image[face_scene.gbuffer.mask], pixels)
    assert np.all(image[~face_scene.gbuffer.mask] == 0)
    assert pixels.max() == 0.5 and pixels.min() > 0  # saturated somewhere, ambient everywhere


def test_noise_is_gaussian_seeded_and_only_on_request(face_scene: Scene) -> None:
    a = face_scene.sphere.position(0.3, 1.0)
    v = face_scene.visibility(a)
    clean = face_scene.pixels(a, v)
    noisy = face_scene.pixels(a, v, noise=True)
    assert np.array_equal(noisy, face_scene.pixels(a, v, noise=True))  # same seed, same noise
    inside = (clean > 0.15) & (clean < 0.35)  # far from both clip levels
    residual = noisy[inside] - clean[inside]
    assert residual.std() == pytest.approx(0.05, rel=0.15)
    assert abs(residual.mean()) < 0.02
    assert np.all((noisy >= 0) & (noisy <= 0.5))
    rng = np.random.default_rng(7)
    assert not np.array_equal(face_scene.pixels(a, v, noise=rng), face_scene.pixels(a, v, noise=rng))
