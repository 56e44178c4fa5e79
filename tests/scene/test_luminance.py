"""CasADi luminance against the NumPy renderer (values) and finite differences (gradients)."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from optlight.scene import Scene
from optlight.scene.render import cosine_and_falloff
from optlight.spec import problem_from_dict

LIGHTS = [(0.3, 0.5), (0.7, 2.5), (1.0, 4.5)]


@pytest.fixture(scope="module", params=["directional", "point"])
def scene(request: pytest.FixtureRequest) -> Scene:
    # saturation 0.6 and ambient 0.05: both clip levels and shadows are exercised
    light = {"model": request.param, "saturation": 0.6, "power": 1.2, "gain": 1.1, "cast_shadows": True}
    return Scene.from_problem(
        problem_from_dict({"light": light, "object": {"face": {"resolution": 96}}}), 48, 48
    )


def evaluate(f: ca.Function, a: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.asarray(f(a, v)).ravel()


def cosine(scene: Scene, a: np.ndarray) -> np.ndarray:
    gb = scene.gbuffer
    return cosine_and_falloff(gb.points, gb.normals, a, scene.light.model, scene.sphere.center, scene.sphere.radius)[0]


def test_function_signature(scene: Scene) -> None:
    f = scene.luminance()
    assert f.name_in() == ["a", "v"] and f.name_out() == ["I"]
    assert f.size_in(0) == (3, 1) and f.size_in(1) == (scene.gbuffer.size, 1)
    assert f.size_out(0) == (scene.gbuffer.size, 1)
    assert scene.luminance() is f and scene.luminance(smooth=False) is not f  # cached per flag
    assert f.is_a("MXFunction")


@pytest.mark.parametrize("zenith, azimuth", LIGHTS)
def test_hard_model_equals_numpy_renderer(scene: Scene, zenith: float, azimuth: float) -> None:
    a = scene.sphere.position(zenith, azimuth)
    v = scene.visibility(a)
    assert 0 < v.sum() < len(v) or zenith < 0.5  # oblique lights cast shadows on the face
    hard = evaluate(scene.luminance(smooth=False), a, v)
    reference = scene.pixels(a, v)
    away = np.abs(cosine(scene, a)) > 0.05
    assert np.allclose(hard[away], reference[away], rtol=0, atol=1e-9)
    assert np.sum(reference == scene.light.saturation) > 0  # the clip is exercised


@pytest.mark.parametrize("zenith, azimuth", LIGHTS)
def test_smooth_model_is_close_to_hard_away_from_kinks(scene: Scene, zenith: float, azimuth: float) -> None:
    a = scene.sphere.position(zenith, azimuth)
    v = scene.visibility(a)
    smooth = evaluate(scene.luminance(), a, v)
    hard = evaluate(scene.luminance(smooth=False), a, v)
    away = (np.abs(cosine(scene, a)) > 0.1) & (np.abs(hard - scene.light.saturation) > 0.1)
    assert away.sum() > 0.15 * len(v)
    # softplus_β(x) − max(x, 0) = log(1 + e^{−β|x|})/β ≤ e^{−6}/60 at |x| > 0.1, β = 60
    assert np.max(np.abs(smooth[away] - hard[away])) < 2e-4
    assert np.all(smooth <= scene.light.saturation) and np.all(smooth > -1e-12)


@pytest.mark.parametrize("zenith, azimuth", LIGHTS)
def test_smooth_gradient_matches_finite_differences(scene: Scene, zenith: float, azimuth: float) -> None:
    """Jacobian dI/da (P×3) by AD against central differences of the same Function, v fixed."""
    a = scene.sphere.position(zenith, azimuth)
    v = scene.visibility(a)
    f = scene.luminance()
    a_sym = ca.MX.sym("a", 3)
    jac = ca.Function("dIda", [a_sym], [ca.jacobian(f(a_sym, ca.DM(v)), a_sym)])
    analytic = np.asarray(jac(a))
    h = 1e-6
    numeric = np.column_stack(
        [(evaluate(f, a + h * e, v) - evaluate(f, a - h * e, v)) / (2 * h) for e in np.eye(3)]
    )
    scale = np.abs(analytic).max()
    assert scale > 1.0  # the image does depend on the light
    assert np.allclose(analytic, numeric, rtol=1e-5, atol=1e-6 * scale)


def test_shadows_are_a_fixed_mask(scene: Scene) -> None:
    """v enters multiplicatively: v = 0 leaves the ambient term, as in the NumPy renderer."""
    a = scene.sphere.position(0.4, 1.0)
    zero = np.zeros(scene.gbuffer.size)
    ambient = scene.light.gain * scene.gbuffer.albedo * scene.light.ambient
    assert np.allclose(evaluate(scene.luminance(smooth=False), a, zero), ambient, atol=1e-15)
    assert np.allclose(evaluate(scene.luminance(), a, zero), ambient, atol=1e-12)


def test_no_cast_shadows_means_full_visibility() -> None:
    scene = Scene.from_problem(problem_from_dict({"light": {"cast_shadows": False}}), 32, 32)
    assert np.array_equal(scene.visibility(scene.sphere.position(1.0, 0.0)), np.ones(scene.gbuffer.size))
