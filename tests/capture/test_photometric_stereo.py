"""Normal recovery on the analytic sphere (exact without noise; the error the trace predicts with
noise), the shadow and saturation rejection against G-buffer geometry, the DiLiGenT export read back
with PIL and NumPy, and bad input."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from optlight.datasets import diligent_files, files_writer, read_diligent, recovery_files, to_uint16
from optlight.errors import OptlightError, ProblemError
from optlight.photometric_stereo import (
    ambient_image,
    error_map_figure,
    gbuffer_normal_map,
    normal_map_figure,
    recover_from_scene,
    recover_normals,
    recovery_report,
    render_set,
)
from optlight.planning.lightsets import ring_directions
from optlight.scene import Scene
from optlight.spec import problem_from_dict

SPHERE = {"kind": "sphere", "center_m": [0.45, 0.1, 0.30], "radius_m": 0.08, "albedo": 0.8}
CAMERA = {"position_m": [0.45, -0.7, 0.30], "width": 64, "height": 64, "fov_deg": 20.0}


def sphere_scene(**light: float) -> Scene:
    problem = problem_from_dict(
        {"object": SPHERE, "camera": CAMERA, "light_sphere": {"radius_m": 0.3}, "light": light}
    )
    return Scene.from_problem(problem)


def test_noise_free_sphere_is_recovered_exactly() -> None:
    scene = sphere_scene(ambient=0.0, power=0.9, gain=1.1)
    directions = ring_directions(5, math.radians(25.0))
    recovery = recover_from_scene(scene, directions, render_set(scene, directions))
    reference = gbuffer_normal_map(scene)
    stats = recovery.error_stats(reference)
    assert stats["mean_deg"] < 0.1 and stats["recovered_pct"] > 95.0
    # where all 5 lights light the pixel, the albedo is the sphere's 0.8 (strengths gain · power given)
    everywhere = recovery.count == 5
    assert np.allclose(recovery.albedo[everywhere], 0.8, atol=1e-6)
    assert np.allclose(np.linalg.norm(recovery.normals[recovery.valid], axis=1), 1.0)
    assert np.all(recovery.normals[~recovery.valid] == 0)


def test_a_calibrated_scenes_images_are_linearised_by_its_response() -> None:
    """A calibrated model renders through the camera's response (γ 2.2): its images are recovered as
    exactly as a linear scene's (the plan of a light set re-planned in the camera loop exports them)."""
    linear = sphere_scene(ambient=0.05, power=0.9)
    scene = linear.calibrated(linear.light, linear.gbuffer.albedo, response_gamma=2.2)
    directions = ring_directions(5, math.radians(25.0))
    images = render_set(scene, directions)
    assert not np.allclose(images, render_set(linear, directions))  # the response is in the images
    recovery = recover_from_scene(scene, directions, images)
    stats = recovery.error_stats(gbuffer_normal_map(scene))
    assert stats["mean_deg"] < 0.1 and stats["recovered_pct"] > 95.0


def test_ambient_is_subtracted_and_saturated_pixels_are_rejected() -> None:
    scene = sphere_scene(ambient=0.05, power=1.3, saturation=1.0)
    directions = ring_directions(6, math.radians(30.0))
    images = render_set(scene, directions)
    assert (images >= 1.0).any()  # the bright side saturates under power 1.3
    recovery = recover_from_scene(scene, directions, images)
    assert recovery.error_stats(gbuffer_normal_map(scene))["mean_deg"] < 0.1
    # without removing the ambient the estimate is biased: the ambient is what the test exercises
    biased = recover_normals(
        images, directions @ scene.sphere.rotation.T, np.full(6, 1.3), mask=scene.gbuffer.mask
    )
    assert biased.error_stats(gbuffer_normal_map(scene))["mean_deg"] > 0.5
    # the usable-light count equals, per pixel, the lights that neither saturate nor fall below the
    # dark level, computed from the G-buffer normals
    world = directions @ scene.sphere.rotation.T
    cos = scene.gbuffer.normals @ world.T
    lit = 1.3 * scene.gbuffer.albedo[:, None] * np.maximum(cos, 0.0)
    total = lit + 0.05 * scene.gbuffer.albedo[:, None]
    expected = ((lit > 0.02) & (total < 0.98)).sum(axis=1)
    margin = (np.abs(lit - 0.02).min(axis=1) > 1e-9) & (np.abs(total - 0.98).min(axis=1) > 1e-9)
    counts = recovery.count.ravel()[scene.gbuffer.pixel_index]
    assert np.array_equal(counts[margin], expected[margin])
    assert (expected < 6).any() and (expected == 6).any()


def noise_ratios(sigma: float, seed: int) -> tuple[float, float, float]:
    """Observed / predicted mean squared error of b̂/ρ and of n̂ over pixels where every light is
    usable with a margin of 6σ, and the standard deviation of the first ratio's estimate."""
    scene = sphere_scene(ambient=0.0, power=1.0, gain=1.0, saturation=1.0, noise_std=sigma)
    directions = ring_directions(5, math.radians(35.0))
    world = directions @ scene.sphere.rotation.T
    rng = np.random.default_rng(seed)
    normals = scene.gbuffer.normals
    albedo = scene.gbuffer.albedo
    signal = albedo[:, None] * (normals @ world.T)
    clean = (signal.min(axis=1) > 0.02 + 6 * sigma) & (signal.max(axis=1) < 0.98 - 6 * sigma)
    inverse = np.linalg.inv(world.T @ world)
    b_err, n_err, b_pred, n_pred = [], [], [], []
    for _ in range(4):
        recovery = recover_from_scene(scene, directions, render_set(scene, directions, noise=rng))
        flat_n = recovery.normals.reshape(-1, 3)[scene.gbuffer.pixel_index]
        flat_rho = recovery.albedo.ravel()[scene.gbuffer.pixel_index]
        b = flat_n * flat_rho[:, None]
        b_err.append(np.sum((b / albedo[:, None] - normals) ** 2, axis=1)[clean])
        n_err.append(np.sum((flat_n - normals) ** 2, axis=1)[clean])
        scale = (sigma / albedo[clean]) ** 2
        b_pred.append(scale * np.trace(inverse))
        projector = np.eye(3) - normals[clean, :, None] * normals[clean, None, :]
        n_pred.append(scale * np.einsum("pij,ji->p", projector, inverse))
    b_ratio = float(np.mean(np.concatenate(b_err) / np.concatenate(b_pred)))
    n_ratio = float(np.mean(np.concatenate(n_err) / np.concatenate(n_pred)))
    # each term |δ|²/E|δ|² has variance 2 tr(C²)/tr(C)², C ∝ (LᵀL)⁻¹ (a weighted χ² with 3 degrees)
    samples = sum(e.size for e in b_err)
    std = math.sqrt(2 * np.trace(inverse @ inverse) / np.trace(inverse) ** 2 / samples)
    return b_ratio, n_ratio, std


@pytest.mark.parametrize("sigma", [0.002, 0.006])
def test_noise_error_grows_as_the_trace_predicts(sigma: float) -> None:
    b_ratio, n_ratio, std = noise_ratios(sigma, seed=int(sigma * 1e4))
    assert std < 0.03  # thousands of pixel samples
    assert abs(b_ratio - 1.0) < 5 * std  # exact: b̂ is linear in the noise
    assert abs(n_ratio - 1.0) < 5 * std + 0.02  # first order in σ


def test_fewer_than_three_lights_names_the_key() -> None:
    images = np.zeros((2, 4, 4))
    with pytest.raises(
        ProblemError,
        match=r"^<api>: lightset.count: expected at least 3 lights for photometric stereo, got 2$",
    ):
        recover_normals(images, np.eye(3)[:2])
    with pytest.raises(OptlightError, match="images"):
        recover_normals(np.zeros((3, 4)), np.eye(3))
    with pytest.raises(OptlightError, match="unit"):
        recover_normals(np.zeros((3, 4, 4)), 2 * np.eye(3))


def test_figures_and_report(tmp_path: Path) -> None:
    scene = sphere_scene(ambient=0.0)
    directions = ring_directions(4, math.radians(30.0))
    recovery = recover_from_scene(scene, directions, render_set(scene, directions))
    reference = gbuffer_normal_map(scene)
    report = recovery_report(recovery, reference)
    assert report["usable_lights"]["max"] == 4 and report["mean_deg"] < 0.1
    for name, figure in {
        "normals": normal_map_figure(recovery.normals, recovery.valid),
        "error": error_map_figure(recovery.angular_error(reference)),
    }.items():
        path = tmp_path / f"{name}.png"
        figure.savefig(path, dpi=50)
        with Image.open(path) as im:
            assert im.size[0] > 100 and im.size[1] > 100


# ------------------------------------------------------------------ DiLiGenT export


def test_diligent_round_trip(tmp_path: Path) -> None:
    scene = sphere_scene(ambient=0.05, saturation=0.9)
    directions = ring_directions(4, math.radians(40.0), phase=math.pi / 2)  # the first light is above
    images = render_set(scene, directions)
    camera_dirs = scene.camera.to_camera_frame(directions @ scene.sphere.rotation.T)
    files = diligent_files(images, camera_dirs, np.full(4, 1.0), scene.gbuffer.mask, saturation=0.9)
    recovery = recover_from_scene(scene, directions, images)
    camera_normals = scene.camera.to_camera_frame(recovery.normals.reshape(-1, 3)).reshape(
        recovery.normals.shape
    )
    files.update(recovery_files(camera_normals, recovery.albedo, recovery.valid))
    written = files_writer(files, "diligent")(tmp_path)
    folder = tmp_path / "diligent"
    assert sorted(p.name for p in written) == sorted(files)

    names = (folder / "filenames.txt").read_text().split()
    assert names == ["001.png", "002.png", "003.png", "004.png"]
    lights = np.loadtxt(folder / "light_directions.txt")
    assert np.allclose(lights, camera_dirs * [1, -1, -1], atol=1e-9)
    assert lights[0, 1] > 0.5 and np.all(lights[:, 2] > 0)  # above: y up; in front: z towards the camera
    assert np.allclose(np.loadtxt(folder / "light_intensities.txt"), 1 / 0.9)
    with Image.open(folder / "mask.png") as im:
        assert im.mode == "L" and np.array_equal(np.asarray(im) == 255, scene.gbuffer.mask)
    for name, image in zip(names, images, strict=True):
        with Image.open(folder / name) as im:
            assert im.mode == "I;16"
            pixels = np.asarray(im)
        assert np.array_equal(pixels, to_uint16(image, 0.9)) and pixels.max() > 255
    normals = np.load(folder / "normals.npy")
    assert normals.shape == (*scene.gbuffer.mask.shape, 3)
    assert np.all(normals[~recovery.valid] == 0)
    centre = normals[32, 32]
    assert centre[2] > 0.99  # the sphere's front faces the camera: +z
    assert np.allclose(np.load(folder / "albedo.npy")[recovery.valid], recovery.albedo[recovery.valid])

    back = read_diligent(folder)
    assert back.names == tuple(names) and np.allclose(back.directions, lights)
    assert np.allclose(back.images * 0.9, images, atol=0.9 / 65535)


def test_diligent_bad_input(tmp_path: Path) -> None:
    mask = np.ones((4, 4), bool)
    with pytest.raises(OptlightError, match="images"):
        diligent_files(np.zeros((2, 4, 4)), np.eye(3), np.ones(3), mask)
    with pytest.raises(OptlightError, match="names"):
        diligent_files(np.zeros((3, 4, 4)), np.eye(3), np.ones(3), mask, names=["a.png"] * 3)
    with pytest.raises(OptlightError, match="relative"):
        files_writer({"../x.txt": b""})
    with pytest.raises(OptlightError, match="DiLiGenT"):
        read_diligent(tmp_path)


def test_ambient_image_is_the_light_off_render() -> None:
    scene = sphere_scene(ambient=0.07, gain=1.3)
    off = scene.to_image(
        scene.pixels(scene.sphere.position(0.3, 0.0), visibility=np.zeros(scene.gbuffer.size))
    )
    assert np.allclose(ambient_image(scene), off)


def test_diligent_writer_plugs_into_write_results(tmp_path: Path) -> None:
    from test_export import NAMES, directions, plan  # a small verified plan with three captures

    from optlight.export import write_results

    trajectory, report = plan()
    images = np.linspace(0.0, 1.0, 3 * 4 * 5).reshape(3, 4, 5)
    files = diligent_files(images, directions(), np.ones(3), np.ones((4, 5), bool))
    out = tmp_path / "run"
    written = write_results(
        out,
        trajectory=trajectory,
        report=report,
        plan_dict={},
        joint_names=NAMES,
        light_directions_camera=directions(),
        image_pattern="{index:03d}.png",
        writers=[files_writer(files, "diligent")],
    )
    assert {f"diligent/{name}" for name in files} <= {str(p.relative_to(out)) for p in written}
    # the DiLiGenT directions and relight's lights.lp agree: both are (x, −y, −z) of the camera frame
    lp = np.array(
        [[float(x) for x in line.split()[1:]] for line in (out / "lights.lp").read_text().splitlines()[1:]]
    )
    assert np.allclose(np.loadtxt(out / "diligent" / "light_directions.txt"), lp, atol=1e-8)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no staging folder left
