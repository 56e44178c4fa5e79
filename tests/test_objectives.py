"""Objectives: NumPy twin = CasADi value, CasADi gradient = finite differences of the NumPy twin,
the soft histogram against hand-computed bins, references from images (PNG, NPY) round-trip."""

from __future__ import annotations

import math
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from conftest import reduced_problem

from optlight.errors import OptlightError, ProblemError
from optlight.objectives import (
    ContrastTerm,
    FractionTerm,
    HistogramTerm,
    ImageTerm,
    MeanTerm,
    Objective,
    SoftHistogram,
    Term,
    histogram_distance_numpy,
    read_image,
    reference_from_bins,
    reference_from_pixels,
)
from optlight.scene import Scene
from optlight.spec import Problem, problem_from_dict

P = 40
HIST = SoftHistogram(bins=8, sigma_bins=1.0)


def random_u(seed: int, p: int = P) -> np.ndarray:
    return np.random.default_rng(seed).uniform(0.02, 0.98, p)


def all_terms() -> dict[str, Term]:
    ref_u = random_u(100)
    ref_h = HIST.numpy(ref_u)
    terms: dict[str, Term] = {
        f"histogram-{d}": HistogramTerm(HIST, ref_h, d) for d in ("l2", "chi2", "emd", "emd2")
    }
    terms.update(
        image=ImageTerm(ref_u),
        mean=MeanTerm(0.4),
        contrast=ContrastTerm(0.15),
        saturation=FractionTerm(0.9, 0.05, above=True),
        shadow=FractionTerm(0.1, 0.05, above=False),
    )
    return terms


TERMS = all_terms()


def casadi_value_and_gradient(term: Term, u: np.ndarray) -> tuple[float, np.ndarray]:
    x = ca.MX.sym("u", u.size)
    f = term.casadi(x)
    fun = ca.Function("f", [x], [f, ca.gradient(f, x)])
    value, grad = fun(u)
    return float(value), np.asarray(grad).ravel()


@pytest.mark.parametrize("name", sorted(TERMS))
def test_numpy_twin_equals_casadi(name: str) -> None:
    term = TERMS[name]
    for seed in range(3):
        u = random_u(seed)
        value, _ = casadi_value_and_gradient(term, u)
        assert float(term.numpy(u)) == pytest.approx(value, rel=1e-12, abs=1e-15)


@pytest.mark.parametrize("name", sorted(TERMS))
def test_casadi_gradient_matches_finite_differences_of_numpy(name: str) -> None:
    term = TERMS[name]
    u = random_u(7)
    _, grad = casadi_value_and_gradient(term, u)
    eps = 1e-6
    fd = np.empty(u.size)
    for i in range(u.size):
        e = np.zeros(u.size)
        e[i] = eps
        fd[i] = (float(term.numpy(u + e)) - float(term.numpy(u - e))) / (2 * eps)
    scale = max(np.abs(fd).max(), 1e-12)
    np.testing.assert_allclose(grad, fd, rtol=0, atol=1e-6 * scale)


def test_numpy_terms_are_batched() -> None:
    batch = np.stack([random_u(s) for s in range(4)])
    for term in TERMS.values():
        np.testing.assert_allclose(term.numpy(batch), [float(term.numpy(u)) for u in batch], rtol=1e-14)


def test_soft_histogram_of_a_tiny_image_against_hand_computed_bins() -> None:
    # 4 bins on [0, 1]: centres 1/8, 3/8, 5/8, 7/8, width 1/4, σ = ½ bin = 1/8. Pixels at 1/8, 3/8, 3/8, 1.
    hist = SoftHistogram(bins=4, sigma_bins=0.5)
    image = np.array([[0.125, 0.375], [0.375, 1.0]])
    # (u − c)/σ per pixel and bin: 1/8 -> 0, 2, 4, 6; 3/8 -> −2, 0, 2, 4; 1 -> −7, −5, −3, −1.
    k1 = [1.0, math.exp(-2), math.exp(-8), math.exp(-18)]
    k3 = [math.exp(-2), 1.0, math.exp(-2), math.exp(-8)]
    k8 = [math.exp(-24.5), math.exp(-12.5), math.exp(-4.5), math.exp(-0.5)]
    raw = np.array([a + 2 * b + c for a, b, c in zip(k1, k3, k8, strict=True)]) / 4
    np.testing.assert_allclose(hist.centres, [0.125, 0.375, 0.625, 0.875])
    np.testing.assert_allclose(hist.numpy(image.ravel()), raw / raw.sum(), rtol=1e-14)
    x = ca.MX.sym("u", 4)
    np.testing.assert_allclose(
        np.asarray(ca.Function("h", [x], [hist.casadi(x)])(image.ravel())).ravel(),
        raw / raw.sum(),
        rtol=1e-14,
    )


def kernel_matrix(hist: SoftHistogram, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The P×K matrix exp(−d²/2), d = (u_p − c_k)/σ, of pixels ``u`` (..., P), and d."""
    d = (u[..., None] - hist.centres) / hist.sigma
    return np.exp(-0.5 * d * d), d


@pytest.mark.parametrize(
    ("bins", "sigma_bins"),
    [(32, 1.0), (200, 3.0), (64, 0.3), (32, 0.1), (128, 0.049), (16, 0.001), (2, 1.0)],
)
def test_soft_histogram_agrees_with_the_kernel_matrix(bins: int, sigma_bins: float) -> None:
    # The factorised sums against Σ_p exp(−(u_p − c_k)²/2σ²) over the whole P×K matrix: one image
    # larger than a piece (split by pixels) and a batch split by rows with a short last piece, with
    # luminances a little outside [0, 1]; windows of W = 27, 9, 3 and 1 bins each side of a pixel's
    # nearest bin, one that reaches every bin (2 bins) and the nearest bin alone (σ < 0.05 bin: W = 0).
    hist = SoftHistogram(bins=bins, sigma_bins=sigma_bins)
    rng = np.random.default_rng(5)
    for shape in [(40_000,), (13, 3_000)]:
        u = rng.uniform(-0.05, 1.05, shape)
        kernel = kernel_matrix(hist, u)[0].sum(axis=-2)
        np.testing.assert_allclose(
            hist.numpy(u), kernel / kernel.sum(axis=-1, keepdims=True), rtol=1e-11, atol=1e-15
        )


@pytest.mark.parametrize(
    ("bins", "sigma_bins"),
    [(32, 1.0), (200, 3.0), (64, 0.3), (2, 1.0), (1000, 20.0), (32, 0.1), (16, 0.001)],
)
def test_casadi_histogram_and_its_gradient_agree_with_the_kernel_matrix(bins: int, sigma_bins: float) -> None:
    # The chained kernel sums (segments of 16, 50, 6, 2 and 334 bins along products, |x| bounded
    # there) and the per-bin exponentials (σ < 0.12 bin) against the P×K matrix and its analytic
    # gradient, luminances a little outside [0, 1]: at 64 bins of σ = 0.3 bin a pixel lies up to 158
    # units of x from a segment's first bin, where R⁵ would overflow unbounded (NaN gradients).
    hist = SoftHistogram(bins=bins, sigma_bins=sigma_bins)
    rng = np.random.default_rng(5)
    u = rng.uniform(-0.05, 1.05, 3_000)
    weights = rng.uniform(0.0, 1.0, bins)
    x = ca.MX.sym("u", u.size)
    h = hist.casadi(x)
    values, gradient = (
        np.asarray(v).ravel() for v in ca.Function("h", [x], [h, ca.gradient(ca.dot(ca.DM(weights), h), x)])(u)
    )
    kernel, d = kernel_matrix(hist, u)
    s = kernel.sum(axis=0)
    np.testing.assert_allclose(values, s / s.sum(), rtol=1e-11, atol=1e-15)
    ds = -kernel * d / hist.sigma  # ∂s_k/∂u_i
    expected = ds @ weights / s.sum() - ds.sum(axis=1) * (weights @ s) / s.sum() ** 2
    np.testing.assert_allclose(gradient, expected, rtol=0, atol=1e-11 * np.abs(expected).max())


def test_distances_vanish_at_the_reference_and_emd_is_the_cdf_l1() -> None:
    u = random_u(3)
    h = HIST.numpy(u)
    for d in ("l2", "chi2", "emd", "emd2"):
        assert float(HistogramTerm(HIST, h, d).numpy(u)) == pytest.approx(0.0, abs=1e-15)
    # Two point masses one bin apart: the CDFs differ by 1 on one bin, so EMD ≈ w = 1/K.
    a, b = np.zeros(8), np.zeros(8)
    a[2], b[3] = 1.0, 1.0
    assert float(histogram_distance_numpy("emd", a, b)) == pytest.approx(1 / 8, rel=1e-3)
    assert float(histogram_distance_numpy("emd2", a, b)) == pytest.approx(1 / 8)


def test_objective_weights_selection_and_twins() -> None:
    ref_pixels = random_u(11, 60)
    selection = np.arange(0, 60, 3)
    reference = reference_from_pixels(HIST, ref_pixels, selection, "synthetic")
    terms = [(2.0, HistogramTerm(HIST, reference.histogram, "emd2")), (0.5, MeanTerm(0.3))]
    objective = Objective(terms, reference, HIST, saturation=2.0)
    pixels = 2.0 * random_u(12, 60)
    u = pixels[selection] / 2.0
    expected = 2.0 * float(terms[0][1].numpy(u)) + 0.5 * (u.mean() - 0.3) ** 2
    assert objective.numpy(pixels) == pytest.approx(expected, rel=1e-14)
    x = ca.MX.sym("I", 60)
    assert float(ca.Function("f", [x], [objective(x)])(pixels)) == pytest.approx(expected, rel=1e-12)
    # At the reference pixels the histogram term vanishes and only the mean term is left.
    at_reference = 0.5 * (ref_pixels[selection].mean() - 0.3) ** 2
    assert objective.numpy(2.0 * ref_pixels) == pytest.approx(at_reference, rel=1e-12)
    with pytest.raises(OptlightError):
        _ = objective.function  # no luminance model was given


def test_evaluate_gives_the_cost_and_the_histogram_it_shares_with_its_terms() -> None:
    # One histogram term on the objective's own histogram (its distance taken from the shared
    # histogram), one on another histogram (computed by the term itself), one mean term.
    ref_pixels, pixels = random_u(21, 50), random_u(22, 50)
    reference = reference_from_pixels(HIST, ref_pixels, None, "synthetic")
    other = SoftHistogram(bins=16, sigma_bins=2.0)
    terms = [
        (2.0, HistogramTerm(HIST, reference.histogram, "chi2")),
        (3.0, HistogramTerm(other, other.numpy(ref_pixels), "emd")),
        (0.5, MeanTerm(0.3)),
    ]
    cost, histogram = Objective(terms, reference, HIST).evaluate(pixels)
    expected = sum(w * float(t.numpy(pixels)) for w, t in terms)
    assert cost == pytest.approx(expected, rel=1e-14)
    assert cost == Objective(terms, reference, HIST).numpy(pixels)
    np.testing.assert_array_equal(histogram, HIST.numpy(pixels))


def test_reference_bins_are_renormalised() -> None:
    ref = reference_from_bins([1.0, 3.0, 0.0, 4.0])
    np.testing.assert_allclose(ref.histogram, [0.125, 0.375, 0.0, 0.5])
    with pytest.raises(OptlightError):
        reference_from_bins([0.0, 0.0])


def test_read_image_png_npy_and_errors(tmp_path: Path) -> None:
    from PIL import Image

    values = np.linspace(0, 1, 12).reshape(3, 4)
    Image.fromarray(np.round(values * 65535).astype(np.uint16)).save(tmp_path / "a16.png")
    Image.fromarray(np.round(values * 255).astype(np.uint8)).save(tmp_path / "a8.png")
    np.save(tmp_path / "a.npy", 2.0 * values)
    Image.fromarray(values > 0.5).save(tmp_path / "bilevel.png")
    np.testing.assert_allclose(read_image(tmp_path / "a16.png", 1.0), values, atol=1e-5)
    np.testing.assert_allclose(read_image(tmp_path / "a8.png", 1.0), values, atol=3e-3)
    np.testing.assert_allclose(read_image(tmp_path / "a.npy", 2.0), values)
    np.testing.assert_array_equal(read_image(tmp_path / "bilevel.png", 1.0), values > 0.5)
    (tmp_path / "bad.png").write_text("not an image")
    with pytest.raises(ProblemError, match="objective.reference.image"):
        read_image(tmp_path / "bad.png", 1.0, "p.toml", "objective.reference.image")
    np.save(tmp_path / "cube.npy", np.zeros((2, 2, 2)))
    with pytest.raises(ProblemError, match="shape"):
        read_image(tmp_path / "cube.npy", 1.0, "p.toml", "objective.reference.image")


# --------------------------------------------------------------------------------------------
# With a scene: references from image files, the composed CasADi function
# --------------------------------------------------------------------------------------------


def face_problem(tmp_path: Path, reference: dict, terms: list[dict] | None = None) -> Problem:
    """The default face at 48×48 px with the given [objective.reference] (and terms), written to
    ``tmp_path`` so that relative image paths resolve there."""
    data = reduced_problem(camera_px=48, object={"face": {"resolution": 48}}).to_dict()
    data["objective"]["reference"] = reference
    if terms is not None:
        data["objective"]["terms"] = terms
    return problem_from_dict(data, source=tmp_path / "p.toml")


@pytest.fixture(scope="module")
def face_scene() -> Scene:
    return Scene.from_problem(face_problem(Path("."), {"kind": "light"}))


LIGHT = (math.radians(23.0), math.radians(130.0))


def test_reference_image_round_trips_png_and_npy(tmp_path: Path, face_scene: Scene) -> None:
    from PIL import Image

    a = face_scene.sphere.position(*LIGHT)
    image = face_scene.render(a)
    np.save(tmp_path / "ref.npy", image)
    Image.fromarray(np.round(image / face_scene.light.saturation * 65535).astype(np.uint16)).save(
        tmp_path / "ref.png"
    )
    other = face_scene.sphere.position(math.radians(40.0), 0.0)
    terms = [{"kind": "histogram", "distance": "emd2"}, {"kind": "image", "weight": 0.5}]
    for name in ("ref.npy", "ref.png"):
        problem = face_problem(tmp_path, {"kind": "image", "image": name}, terms)
        objective = Objective.from_problem(problem, face_scene)
        at_light = objective.numpy(face_scene.pixels(a))
        assert at_light == pytest.approx(0.0, abs=1e-9), name
        assert objective.numpy(face_scene.pixels(other)) > 1e3 * max(at_light, 1e-12)


def test_reference_image_of_another_size_and_mask(tmp_path: Path, face_scene: Scene) -> None:
    from PIL import Image

    a = face_scene.sphere.position(*LIGHT)
    big = Scene.from_problem(face_problem(tmp_path, {"kind": "light"}), width=96, height=96)
    np.save(tmp_path / "big.npy", big.render(a))
    mask = np.zeros((48, 48), np.uint8)
    mask[:, :24] = 255
    Image.fromarray(mask).save(tmp_path / "mask.png")
    refused = face_problem(tmp_path, {"kind": "image", "image": "big.npy", "mask": "mask.png"})
    both_sizes = r"objective\.reference\.image: .* 48 × 48 px .*big\.npy of 96 × 96 px"
    with pytest.raises(ProblemError, match=both_sizes):
        Objective.from_problem(refused, face_scene)  # stretched only when the problem says so
    problem = face_problem(tmp_path, {"kind": "image", "image": "big.npy", "mask": "mask.png", "resize": True})
    objective = Objective.from_problem(problem, face_scene)
    assert objective.selection is not None
    columns = face_scene.gbuffer.pixel_index[objective.selection] % 48
    assert columns.max() < 24 and objective.selection.size > 100
    # Resampled from 96² the reference is close to, not equal to, the 48² render at the same light.
    at_light = objective.numpy(face_scene.pixels(a))
    assert at_light < 0.05 * objective.numpy(face_scene.pixels(face_scene.sphere.position(0.7, 4.0)))


def test_bad_reference_image_names_the_key(tmp_path: Path, face_scene: Scene) -> None:
    (tmp_path / "bad.png").write_bytes(b"\x89PNG broken")
    problem = face_problem(tmp_path, {"kind": "image", "image": "bad.png"})
    with pytest.raises(ProblemError, match="objective.reference.image"):
        Objective.from_problem(problem, face_scene)
    bins = face_problem(tmp_path, {"kind": "bins", "bins": [1.0] * 32}, [{"kind": "image"}])
    with pytest.raises(ProblemError, match=r"objective.terms\[0\].kind"):
        Objective.from_problem(bins, face_scene)


def test_objective_function_is_the_casadi_twin_through_the_smooth_model(
    tmp_path: Path, face_scene: Scene
) -> None:
    terms = [
        {"kind": "histogram", "distance": "chi2"},
        {"kind": "contrast", "target": 0.2, "weight": 2.0},
        {"kind": "saturation", "weight": 0.3},
        {"kind": "shadow", "weight": 0.3, "level": 0.1},
    ]
    objective = Objective.from_problem(face_problem(tmp_path, {"kind": "light"}, terms), face_scene)
    a = face_scene.sphere.position(*LIGHT)
    v = face_scene.visibility(a)
    smooth = np.asarray(face_scene.luminance(smooth=True)(a, v)).ravel()
    assert float(objective.function(a, v)) == pytest.approx(objective.numpy(smooth), rel=1e-10)
    # Gradient with respect to the light position against central differences of the function.
    x = ca.MX.sym("a", 3)
    grad = np.asarray(ca.Function("g", [x], [ca.gradient(objective.function(x, v), x)])(a)).ravel()
    eps = 1e-6
    fd = [
        (float(objective.function(a + e, v)) - float(objective.function(a - e, v))) / (2 * eps)
        for e in np.eye(3) * eps
    ]
    np.testing.assert_allclose(grad, fd, rtol=1e-5, atol=1e-9 * np.abs(fd).max())
