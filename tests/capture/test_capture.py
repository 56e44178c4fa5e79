"""The cameras in the loop and the calibration (optlight.capture).

Mitsuba is a test dependency (``make test`` installs the ``mitsuba`` extra): it is imported at the top,
so a missing Mitsuba fails this module instead of skipping it.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import casadi as ca
import mitsuba  # noqa: F401 - a missing Mitsuba must fail these tests, never skip them
import numpy as np
import pytest
from PIL import Image
from scipy.ndimage import binary_erosion

from optlight.capture import ModelCamera, calibration, write_capture_png
from optlight.capture.calibration import calibrate, calibrated_setup
from optlight.capture.folder import FolderCamera, MissingCaptureError
from optlight.capture.mitsuba import MitsubaCamera
from optlight.errors import ProblemError
from optlight.scene import Scene
from optlight.scene.render import cosine_and_falloff, lambertian
from optlight.scene.response import linearise, respond
from optlight.setup import Setup
from optlight.spec import LightSpec, LoopSpec, WorldSpec, problem_from_dict

#: Lights (zenith, azimuth in degrees) of the calibration captures.
LIGHTS_DEG = [(20, 0), (35, 60), (50, 120), (30, 180), (45, 240), (25, 300), (55, 30), (40, 90)]


def sphere_problem(model: str, **world: object):
    return problem_from_dict(
        {
            "object": {"kind": "sphere", "radius_m": 0.1, "albedo": 0.6},
            "camera": {"width": 64, "height": 48, "cx_px": 30.0, "cy_px": 20.0},
            "light": {"model": model, "ambient": 0.05},
            "world": {"spp": 256, **world},
        }
    )


@pytest.fixture(scope="module")
def face_scene() -> Scene:
    return Scene.from_problem(problem_from_dict({"object": {"face": {"resolution": 64}}, "camera": {"width": 96, "height": 96}}))


def captures_of(camera, scene: Scene, lights=LIGHTS_DEG):
    return [
        camera.capture(scene.sphere.position(np.deg2rad(z), np.deg2rad(a)), i) for i, (z, a) in enumerate(lights)
    ]


#: Sub-pixels per side of the model's image averaged over each pixel's footprint, as Mitsuba's box filter does.
FOOTPRINT = 4


def footprint_image(problem, light) -> tuple[np.ndarray, np.ndarray]:
    """The model camera's image averaged over each pixel's footprint (:data:`FOOTPRINT`² sub-pixel
    centres of the same pinhole camera), and where a pixel holds a saturated sub-pixel (there
    Mitsuba's camera clips the footprint's mean radiance, not each sub-pixel's)."""
    cam, s = Scene.from_problem(problem).camera, FOOTPRINT
    data = problem.to_dict()
    data["camera"].update(
        width=s * cam.width,
        height=s * cam.height,
        fx_px=s * cam.fx,
        fy_px=s * cam.fy,
        cx_px=s * (cam.cx + 0.5) - 0.5,
        cy_px=s * (cam.cy + 0.5) - 0.5,
    )
    fine = problem_from_dict(data)
    blocks = ModelCamera(Scene.from_problem(fine), fine.world).capture(light).image.reshape(cam.height, s, cam.width, s)
    return blocks.mean(axis=(1, 3)), blocks.max(axis=(1, 3)) >= 1.0


@pytest.mark.parametrize("model", ["point", "directional"])
def test_mitsuba_lambertian_sphere_agrees_with_the_renderer_within_its_noise(model: str) -> None:
    """[world] equal to the model: 256 spp, pixels ≥ 3 px inside the silhouette and away from the
    terminator (|n·l| > 0.15), an off-centre principal point. Mitsuba's box filter integrates each
    pixel's footprint, so the renderer's image is averaged over it too (at the pixel centre alone, the
    means differed by 0.05 % and the scalar variant's worst pixel by 6.6σ). σ is the Monte Carlo noise
    measured from two independent renders; every pixel agrees within 6σ plus 0.2 % of its value and the
    mean within 0.1 %. The 0.2 %: single pixels differ by up to 0.1 % after 16 renders (not a
    sub-pixel shift of the image, fitted below 0.001 px, nor a scale: the means agree to 0.03 %);
    over 10 seeds of both variants the worst pixel used 89 % of this tolerance."""
    problem = sphere_problem(model)
    scene = Scene.from_problem(problem)
    light = scene.sphere.position(0.6, 1.2)
    camera = MitsubaCamera(scene, problem.world)
    first, second = camera.capture(light).image, camera.capture(light).image
    ours, saturated = footprint_image(problem, light)
    gb = scene.gbuffer
    cos, _ = cosine_and_falloff(gb.points, gb.normals, light, model, scene.sphere.center, scene.sphere.radius)
    smooth = scene.to_image(np.abs(cos) > 0.15) > 0
    inside = binary_erosion(gb.mask, iterations=3) & smooth & ~saturated
    sigma = float(np.std((first - second)[inside]) / np.sqrt(2))
    diff = (first - ours)[inside]
    assert inside.sum() > 300
    assert 0 < sigma < 0.01
    assert np.all(np.abs(diff) < 6 * sigma + 0.002 * ours[inside])
    assert abs(diff.mean()) < 0.001 * ours[inside].mean()
    # the silhouette: the same object pixels (ambient lights the whole sphere), to the boundary ring
    lit = first > 0.5 * 0.6 * 0.05
    assert np.mean(lit != gb.mask) < 0.02


def test_model_camera_applies_the_world() -> None:
    """Power, ambient, albedo scale, light offset and response against the model's own renderer."""
    problem = sphere_problem("point")
    scene = Scene.from_problem(problem)
    world = WorldSpec(power_scale=1.5, ambient=0.1, albedo_scale=0.8, gamma=2.0, light_offset_m=(0.0, 0.02, 0.0))
    a = scene.sphere.position(0.4, 2.0)
    got = ModelCamera(scene, world).capture(a).image
    real = a + np.array([0.0, 0.02, 0.0])
    gb = scene.gbuffer
    light = dataclasses.replace(problem.light, power=1.5, ambient=0.1)
    linear = lambertian(
        gb.points, gb.normals, 0.8 * gb.albedo, real, light, scene.sphere.center, scene.sphere.radius, scene.visibility(real)
    )
    expected = scene.to_image(np.clip(linear, 0, 1) ** 0.5)
    np.testing.assert_allclose(got, expected, atol=1e-5)
    np.testing.assert_allclose(linearise(respond(linear, 1.0, 2.0), 1.0, 2.0), np.clip(linear, 0, 1), atol=1e-12)


def test_calibration_recovers_power_ambient_and_gamma_to_2_percent(face_scene: Scene) -> None:
    world = WorldSpec(power_scale=1.3, ambient=0.08, gamma=2.2, noise_std=0.005, albedo_texture=0.3, seed=3)
    calibration = calibrate(face_scene, captures_of(ModelCamera(face_scene, world), face_scene), LoopSpec())
    assert calibration.power == pytest.approx(1.3, rel=0.02)
    assert calibration.ambient == pytest.approx(0.08, rel=0.02)
    assert calibration.gamma == pytest.approx(2.2, rel=0.02)
    assert not calibration.rejected
    # the texture is recovered as the per-pixel albedo factor (normalised to a median of 1)
    gb = face_scene.gbuffer
    x = 2 * np.pi * gb.points / world.texture_period_m
    texture = 1 + 0.3 * np.sin(x[:, 0]) * np.sin(x[:, 1]) * np.sin(x[:, 2])
    ok = calibration.albedo_calibrated
    truth = texture / np.median(texture[ok])
    assert ok.mean() > 0.8
    assert np.median(np.abs(calibration.albedo_factor[ok] / truth[ok] - 1)) < 0.01
    # photometric stereo's normals where ≥ 3 lights light a pixel, close to the mesh's
    assert calibration.normals_valid is not None and calibration.normals_valid.mean() > 0.5
    assert calibration.normal_deviation_deg is not None and calibration.normal_deviation_deg < 3.0


@pytest.mark.parametrize(("world_model", "model"), [("point", "directional"), ("directional", "point")])
def test_calibration_chooses_the_light_model_the_captures_follow(face_scene: Scene, world_model: str, model: str) -> None:
    """Captures of a world whose light falls off as the other model's: the calibration of the model
    scene switches its light model, and then recovers power and γ as with the right one."""
    light = face_scene.light
    scene = face_scene.calibrated(dataclasses.replace(light, model=model), face_scene.gbuffer.albedo)
    world_scene = face_scene.calibrated(dataclasses.replace(light, model=world_model), face_scene.gbuffer.albedo)
    world = WorldSpec(power_scale=1.3, ambient=0.08, gamma=2.2, noise_std=0.005, seed=3)
    calibration = calibrate(scene, captures_of(ModelCamera(world_scene, world), scene), LoopSpec())
    assert calibration.light_model == world_model
    assert calibration.model_residual_rms[world_model] < 0.5 * calibration.model_residual_rms[model]
    assert calibration.power == pytest.approx(1.3, rel=0.02)
    assert calibration.gamma == pytest.approx(2.2, rel=0.02)
    assert calibration.light(scene.light).model == world_model


def test_calibration_takes_a_small_mitsuba_lamp_for_a_point_light() -> None:
    """A 1 cm sphere lamp rendered by Mitsuba (32 spp) falls off as 1/r²: the directional model's
    calibration chooses the point model, and its γ stays the linear camera's (the directional fit
    bends γ to absorb the falloff)."""
    problem = sphere_problem("directional", light_radius_m=0.01, spp=32)
    scene = Scene.from_problem(problem)
    calibration = calibrate(scene, captures_of(MitsubaCamera(scene, problem.world), scene), LoopSpec())
    assert calibration.light_model == "point"
    assert calibration.gamma == pytest.approx(1.0, abs=0.05)
    assert calibration.power == pytest.approx(1.0, rel=0.05)


def test_saturated_and_black_captures_are_reported_and_left_out(face_scene: Scene) -> None:
    world = WorldSpec(power_scale=1.3, ambient=0.08, gamma=1.5)
    good = captures_of(ModelCamera(face_scene, world), face_scene)
    glare = ModelCamera(face_scene, dataclasses.replace(world, power_scale=40.0)).capture(good[0].light_position, 8)
    dark = ModelCamera(face_scene, dataclasses.replace(world, power_scale=0.0, ambient=0.0)).capture(
        good[1].light_position, 9
    )
    calibration = calibrate(face_scene, [*good[:4], glare, *good[4:], dark], LoopSpec())
    assert set(calibration.rejected) == {4, 9}
    assert calibration.rejected[4].startswith("saturated")
    assert calibration.rejected[9].startswith("black")
    assert 4 not in calibration.used and 9 not in calibration.used
    assert calibration.power == pytest.approx(1.3, rel=0.02)
    assert calibration.gamma == pytest.approx(1.5, rel=0.02)


def test_calibrated_model_predicts_the_captures(small_setup: Setup) -> None:
    """The calibrated setup renders what the camera recorded at a light it never saw, in NumPy and in
    CasADi (hard max and clip: the same model), the response included."""
    world = WorldSpec(power_scale=0.7, ambient=0.12, gamma=1.8, albedo_scale=0.9)
    camera = ModelCamera(small_setup.scene, world)
    calibration = calibrate(small_setup.scene, captures_of(camera, small_setup.scene), LoopSpec())
    model = calibrated_setup(small_setup, calibration)
    a = small_setup.sphere.position(np.deg2rad(33), np.deg2rad(200))
    recorded = camera.capture(a).image.ravel()[model.scene.gbuffer.pixel_index]
    predicted = model.scene.pixels(a)
    assert np.median(np.abs(predicted - recorded)) < 2e-3
    v = model.scene.visibility(a)
    casadi = np.asarray(model.scene.luminance(smooth=False)(a, v)).ravel()
    np.testing.assert_allclose(casadi, predicted, atol=1e-9)
    # the search scene follows, and the objectives keep their references
    assert model.search_scene.response_gamma == pytest.approx(calibration.gamma)
    assert model.objective.reference is small_setup.objective.reference
    search = small_setup.search_scene
    recorded = ModelCamera(search, world).capture(a).image.ravel()[search.gbuffer.pixel_index]
    assert np.median(np.abs(model.search_scene.pixels(a) - recorded)) < 2e-3


def test_folder_camera_reads_16_bit_png_and_8_bit_tiff(tmp_path: Path, small_setup: Setup) -> None:
    scene = small_setup.scene
    camera = ModelCamera(scene, WorldSpec())
    a0, a1 = scene.sphere.position(0.3, 1.0), scene.sphere.position(0.5, 3.0)
    images = [camera.capture(a).image for a in (a0, a1)]
    write_capture_png(tmp_path / "a.png", images[0], 1.0)
    gamma = 2.2
    encoded = np.round(respond(images[1], 1.0, gamma) * 255).astype(np.uint8)
    Image.fromarray(encoded).save(tmp_path / "b.tif")
    write_csv(tmp_path, [("a.png", a0), ("b.tif", a1)])
    folder = FolderCamera(tmp_path, scene.camera, 1.0, response_gamma=1.0)
    np.testing.assert_allclose(folder.capture(a0).image, images[0], atol=1 / 65535)
    folder = FolderCamera(tmp_path, scene.camera, 1.0, response_gamma=gamma)
    got = folder.capture(a1 + 1e-4).image  # within the 1 mm tolerance
    assert np.abs(got - np.clip(images[1], 0, 1)).max() < 0.02  # 8-bit steps, linearised
    with pytest.raises(MissingCaptureError, match="no image of capture 7"):
        folder.capture(scene.sphere.position(0.9, 0.0), 7)


def write_csv(folder: Path, rows) -> None:
    lines = ["capture,image,light_position_x_m,light_position_y_m,light_position_z_m"]
    lines += [f"{i},{name},{a[0]:.12g},{a[1]:.12g},{a[2]:.12g}" for i, (name, a) in enumerate(rows)]
    (folder / "captures.csv").write_text("\n".join(lines) + "\n")


def test_folder_camera_refuses_a_missing_or_wrong_sized_image(tmp_path: Path, small_setup: Setup) -> None:
    scene = small_setup.scene
    a, b = scene.sphere.position(0.3, 1.0), scene.sphere.position(0.5, 3.0)
    write_capture_png(tmp_path / "ok.png", np.zeros((scene.camera.height, scene.camera.width)), 1.0)
    write_capture_png(tmp_path / "small.png", np.zeros((10, 12)), 1.0)
    write_csv(tmp_path, [("ok.png", a), ("gone.png", b)])
    with pytest.raises(ProblemError) as missing:
        FolderCamera(tmp_path, scene.camera)
    message = str(missing.value)
    assert "gone.png" in message and "\n" not in message
    write_csv(tmp_path, [("ok.png", a), ("small.png", b)])
    with pytest.raises(ProblemError) as wrong:
        FolderCamera(tmp_path, scene.camera)
    message = str(wrong.value)
    assert "small.png" in message and "12×10" in message and "\n" not in message
    (tmp_path / "captures.csv").unlink()
    with pytest.raises(ProblemError, match="captures.csv"):
        FolderCamera(tmp_path, scene.camera)


def test_folder_camera_refuses_rows_a_capture_cannot_be_matched_to(tmp_path: Path, small_setup: Setup) -> None:
    """Two rows naming one image (they wrecked a calibration when accepted), two rows with the light
    at one place (a capture there would match either): one line naming captures.csv and the rows."""
    scene = small_setup.scene
    a, b = scene.sphere.position(0.3, 1.0), scene.sphere.position(0.5, 3.0)
    for name in ("x.png", "y.png"):
        write_capture_png(tmp_path / name, np.zeros((scene.camera.height, scene.camera.width)), 1.0)
    write_csv(tmp_path, [("x.png", a), ("y.png", b)])
    FolderCamera(tmp_path, scene.camera)  # distinct names and lights: accepted
    write_csv(tmp_path, [("x.png", a), ("y.png", b), ("x.png", scene.sphere.position(0.6, 2.0))])
    with pytest.raises(ProblemError) as duplicate:
        FolderCamera(tmp_path, scene.camera)
    message = str(duplicate.value)
    assert "captures.csv" in message and "x.png on rows 0 and 2" in message and "\n" not in message
    write_csv(tmp_path, [("x.png", a), ("y.png", a + [1.5e-3, 0.0, 0.0])])  # a light 0.75 mm from both
    with pytest.raises(ProblemError) as ambiguous:
        FolderCamera(tmp_path, scene.camera)
    message = str(ambiguous.value)
    assert "captures.csv" in message and "rows 0 and 1 1.5 mm apart" in message and "\n" not in message
    write_csv(tmp_path, [("x.png", a), ("", b)])
    with pytest.raises(ProblemError, match="an image file name on row 1"):
        FolderCamera(tmp_path, scene.camera)
    inner = tmp_path / "inner"  # a row naming a file outside the images' folder, which exists there
    inner.mkdir()
    write_capture_png(inner / "x.png", np.zeros((scene.camera.height, scene.camera.width)), 1.0)
    write_csv(inner, [("x.png", a), ("../y.png", b)])
    outside = r"captures\.csv: image: expected a file name in the images' folder on row 1"
    with pytest.raises(ProblemError, match=outside):
        FolderCamera(inner, scene.camera)


def test_mitsuba_specular_highlights_are_left_out_of_the_fit() -> None:
    """A glossy roughplastic sphere (Mitsuba, 32 spp): the entries the calibration leaves out as specular
    are highlights, where the half-vector h = (l + v)/|l + v| is close to the normal."""
    problem = problem_from_dict(
        {
            "object": {"kind": "sphere", "radius_m": 0.1, "albedo": 0.5},
            "camera": {"width": 48, "height": 48},
            "light": {"model": "point", "ambient": 0.05},
            "world": {"spp": 32, "bsdf": "roughplastic", "roughness": 0.15, "specular": 1.0},
        }
    )
    scene = Scene.from_problem(problem)
    calibration = calibrate(scene, captures_of(MitsubaCamera(scene, problem.world), scene), LoopSpec())
    assert calibration.entries["specular"] > 0
    gb = scene.gbuffer
    view = scene.camera.position - gb.points
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    specular, lit = [], []
    for k, mask in zip(calibration.used, calibration.specular, strict=True):
        light = scene.sphere.position(*np.deg2rad(LIGHTS_DEG[k])) - gb.points
        light /= np.linalg.norm(light, axis=1, keepdims=True)
        half = light + view
        half /= np.linalg.norm(half, axis=1, keepdims=True)
        angle = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", half, gb.normals), -1, 1)))
        specular.append(angle[mask])
        lit.append(angle[np.einsum("ij,ij->i", light, gb.normals) > 0.1])
    assert np.median(np.concatenate(specular)) < 15.0
    assert np.median(np.concatenate(specular)) < 0.5 * np.median(np.concatenate(lit))


def test_world_spec_errors_name_the_key() -> None:
    with pytest.raises(ProblemError, match="world.light_radius_m"):
        problem_from_dict({"world": {"light_profile": "spot", "light_radius_m": 0.01}})
    with pytest.raises(ProblemError, match="world.gamma"):
        problem_from_dict({"world": {"gamma": 0}})
    with pytest.raises(ProblemError, match="loop.normals"):
        problem_from_dict({"loop": {"normals": "guess"}})


def test_mitsuba_refuses_non_square_pixels() -> None:
    problem = problem_from_dict({"object": {"kind": "sphere"}, "camera": {"width": 32, "height": 32, "fx_px": 80.0}})
    with pytest.raises(ProblemError, match="camera.fy_px"):
        MitsubaCamera(Scene.from_problem(problem), problem.world)


def test_scene_response_has_the_finite_difference_gradient() -> None:
    """The calibrated scene's CasADi luminance (response included) against central differences."""
    problem = sphere_problem("point")
    scene = Scene.from_problem(problem)
    calibrated = scene.calibrated(problem.light, scene.gbuffer.albedo * 1.1, response_gamma=2.2)
    a0 = scene.sphere.position(0.5, 1.0)
    v = calibrated.visibility(a0)
    f = calibrated.luminance(smooth=True)
    a = ca.MX.sym("a", 3)
    jac = ca.Function("j", [a], [ca.jacobian(f(a, v), a)])
    analytic = np.asarray(jac(a0))
    h = 1e-6
    numeric = np.column_stack(
        [(np.asarray(f(a0 + h * e, v)) - np.asarray(f(a0 - h * e, v))).ravel() / (2 * h) for e in np.eye(3)]
    )
    np.testing.assert_allclose(analytic, numeric, rtol=1e-5, atol=1e-6)


def test_the_fit_at_a_gamma_is_the_least_squares_of_every_used_entry() -> None:
    """The calibration's fit at one γ sums per pixel over the captures once (``_Entries``) instead of
    over every entry at every sweep. Against the alternating least squares written entry by entry
    (c_p from Σ_k over pixel p's used entries, then (A, B) by least squares over all of them,
    renormalised), on random shading with left-out entries, a pixel never lit and one never used:
    the same A, B, c, prediction and cost."""
    rng = np.random.default_rng(3)
    k, p, s = 7, 300, 1.0
    light = LightSpec(power=0.9, ambient=0.04)
    shade = np.clip(rng.normal(0.5, 0.35, (k, p)), 0.0, None)
    shade[:, 0] = 0.0  # never lit: not calibrated, its factor stays 1
    rho = rng.uniform(0.3, 0.9, p)
    truth = rng.uniform(0.7, 1.3, p) * rho * (0.8 * shade + 0.05)
    y = respond(truth * (1 + 0.01 * rng.normal(size=(k, p))), s, 1.7)
    weights = rng.uniform(size=(k, p)) > 0.2
    weights[:, 1] = False  # never used
    fit = calibration._fit(y, calibration._Entries.of(weights, shade), rho, 1.7, s, light.gain, light)

    w, linear = weights.astype(float), linearise(y, s, 1.7)
    calibrated = (weights.sum(axis=0) >= 2) & ((weights & (shade > 0)).sum(axis=0) >= 1)
    a, b = light.gain * light.power, light.gain * light.ambient
    for _ in range(calibration.SWEEPS):
        m = rho * (a * shade + b)
        c = np.where(calibrated, (w * linear * m).sum(axis=0) / np.maximum((w * m * m).sum(axis=0), 1e-300), 1.0)
        design = np.stack([(c * rho * shade)[weights], np.broadcast_to(c * rho, shade.shape)[weights]], axis=1)
        a, b = np.linalg.lstsq(design, linear[weights], rcond=None)[0]
        scale = np.median(c[calibrated])
        c, a, b = np.where(calibrated, c / scale, 1.0), a * scale, b * scale
    prediction = c * rho * (a * shade + b)
    cost = float((w * (y - respond(prediction, s, 1.7)) ** 2).sum())
    assert (fit.a, fit.b, fit.cost) == pytest.approx((a, b, cost), rel=1e-9)
    np.testing.assert_allclose(fit.c, c, rtol=1e-9)
    np.testing.assert_allclose(fit.prediction, prediction, rtol=1e-9, atol=1e-12)
    assert fit.c[0] == fit.c[1] == 1.0 and not fit.calibrated[:2].any()
