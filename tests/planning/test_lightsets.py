"""Light sets: the classical photometric-stereo optimum (9/N, the 54.7356° ring), the per-pixel term
against a brute-force loop with np.linalg.inv, every set term's gradient against finite differences,
RTI coverage, the Yale B grid and its mapping onto allowed lights, and bad input."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from optlight.errors import OptlightError, ProblemError
from optlight.geometry import direction_in_sphere_frame
from optlight.objectives import Objective
from optlight.planning.lightsets import (
    CLASSICAL_SLANT,
    Cap,
    ImageSetTerm,
    LightSetDesigner,
    PhotometricStereoTerm,
    RieszEnergy,
    SetCost,
    SetTerm,
    UnshadowedTrace,
    angles_of,
    camera_axis_direction,
    coverage,
    design_light_set,
    design_ring,
    grid_from_degrees,
    grid_from_problem,
    map_grid,
    min_separation,
    read_grid_file,
    ring_directions,
    set_cost_from_problem,
    yale_b_grid,
)
from optlight.scene import Scene
from optlight.spec import LightSpec, problem_from_dict

WIDE_CAP = Cap(0.0, math.radians(85.0))
SPHERE = {"kind": "sphere", "center_m": [0.45, 0.1, 0.30], "radius_m": 0.08, "albedo": 0.8}
SPHERE_CAMERA = {"position_m": [0.45, -0.7, 0.30], "width": 40, "height": 40, "fov_deg": 20.0}


@pytest.fixture(scope="module")
def face() -> tuple[Scene, Objective]:
    """A small face with cast shadows and a low saturation level, so every weight factor is active."""
    problem = problem_from_dict({"object": {"face": {"resolution": 64}}, "light": {"saturation": 0.7}})
    scene = Scene.from_problem(problem, 24, 24)
    return scene, Objective.from_problem(problem, scene)


@pytest.fixture(scope="module")
def sphere() -> Scene:
    light = {"saturation": 0.6, "power": 1.2, "gain": 1.1, "ambient": 0.05}
    problem = problem_from_dict(
        {"object": SPHERE, "camera": SPHERE_CAMERA, "light_sphere": {"radius_m": 0.3}, "light": light}
    )
    return Scene.from_problem(problem)


# ------------------------------------------------------------------ the classical optimum


@pytest.mark.parametrize("n", range(3, 13))
def test_unshadowed_design_reaches_nine_over_n(n: int) -> None:
    result = design_light_set(UnshadowedTrace(), n, WIDE_CAP, starts=3, seed=n)
    assert result.success
    assert 9.0 / n * (1 - 1e-9) <= result.cost <= 9.0 / n * 1.005
    gram = result.directions.T @ result.directions
    assert np.allclose(gram, n / 3 * np.eye(3), atol=0.05 * n / 3)  # the optimum's LᵀL = (N/3) I
    assert np.allclose(np.linalg.norm(result.directions, axis=1), 1.0)
    assert np.all(result.zenith <= WIDE_CAP.zenith_max + 1e-9)
    assert len(result.start_costs) == 3


@pytest.mark.parametrize("n", [3, 4, 7, 12])
def test_ring_design_finds_the_classical_slant(n: int) -> None:
    result = design_ring(UnshadowedTrace(), n, WIDE_CAP)
    assert abs(math.degrees(result.zenith[0]) - 54.7356103) < 0.1
    assert result.cost == pytest.approx(9.0 / n, rel=1e-6)
    assert math.degrees(CLASSICAL_SLANT) == pytest.approx(54.7356103, abs=1e-6)
    # analytic check of the ring at the classical slant: LᵀL = diag(N/2 sin², N/2 sin², N cos²) = N/3 I
    d = ring_directions(n, CLASSICAL_SLANT)
    assert np.allclose(d.T @ d, n / 3 * np.eye(3), atol=1e-12)


def test_ring_slant_is_capped_when_the_cap_is_narrow() -> None:
    cap = Cap(0.0, math.radians(40.0))
    result = design_ring(UnshadowedTrace(), 6, cap)
    assert math.degrees(result.zenith[0]) == pytest.approx(40.0, abs=1e-4)  # cost decreases up to 54.7°


# ------------------------------------------------------------------ the per-pixel term


def brute_force(term: PhotometricStereoTerm, directions: np.ndarray, masks: np.ndarray) -> float:
    """The per-pixel expected error by a loop over pixels and lights, scalar math and np.linalg.inv."""
    light = term.light
    beta = light.softplus_sharpness
    total = 0.0
    for p in range(term.pixels):
        m = term.regularization * np.eye(3)
        for i, d in enumerate(directions):
            c = float(term.normals[p] @ d)
            softplus = math.log1p(math.exp(beta * c)) / beta
            u = light.gain * term.albedo[p] * (light.power * masks[p, i] * softplus + light.ambient)
            u /= light.saturation
            attached = 1.0 / (1.0 + math.exp(-beta * c))
            unsaturated = 1.0 / (1.0 + math.exp(-(term.saturation_level - u) / term.softness))
            m += masks[p, i] * attached * unsaturated * np.outer(d, d)
        total += float(np.trace(np.linalg.inv(m)))
    return total / term.pixels


def casadi_value(term: SetTerm, directions: np.ndarray, parameters: np.ndarray) -> float:
    zenith, azimuth = angles_of(directions)
    designer = LightSetDesigner(term, len(directions), Cap(0.0, math.pi))
    return float(designer.cost_gradient(np.r_[zenith, azimuth], parameters)[0])


def test_per_pixel_term_matches_brute_force_on_a_sphere(sphere: Scene) -> None:
    term = PhotometricStereoTerm.from_scene(sphere)
    rng = np.random.default_rng(4)
    directions = Cap(0.0, math.radians(60.0)).random(5, rng)
    parameters = term.parameters(directions)
    masks = parameters.reshape(term.pixels, 5, order="F")
    assert masks.min() == 1.0  # a convex sphere casts no shadow on itself
    masks = masks.copy()
    masks[rng.random(masks.shape) < 0.2] = 0.0  # a made-up cast-shadow mask exercises the v factor
    parameters = masks.ravel(order="F")
    weights = term.weights(directions, parameters)
    assert (weights < 0.01).any() and (weights > 0.99).any() and ((weights > 0.1) & (weights < 0.9)).any()
    expected = brute_force(term, directions, masks)
    assert term.numpy(directions, parameters) == pytest.approx(expected, rel=1e-10)
    assert casadi_value(term, directions, parameters) == pytest.approx(expected, rel=1e-10)


def test_per_pixel_term_counts_the_lights_that_light_each_pixel(sphere: Scene) -> None:
    """With a sharp attached-shadow weight and no saturation, a pixel's value is tr((L_pᵀL_p + εI)⁻¹)
    over exactly the lights with n·l > 0."""
    sharp = LightSpec(softplus_sharpness=1e5, saturation=100.0)  # no pixel saturates
    term = PhotometricStereoTerm(
        sphere.gbuffer.normals @ sphere.sphere.rotation, sphere.gbuffer.albedo, sharp
    )
    directions = ring_directions(6, math.radians(50.0))
    cos = term.normals @ directions.T
    keep = np.abs(cos).min(axis=1) > 1e-3  # away from the terminator, where the weight is 0 or 1
    for p in np.flatnonzero(keep)[::37]:
        lit = directions[cos[p] > 0]
        expected = np.trace(np.linalg.inv(lit.T @ lit + term.regularization * np.eye(3)))
        assert term.per_pixel(directions)[p] == pytest.approx(expected, rel=1e-6)


# ------------------------------------------------------------------ gradients


def all_terms(face: tuple[Scene, Objective]) -> dict[str, SetTerm]:
    scene, objective = face
    ps = PhotometricStereoTerm.from_scene(scene)
    return {
        "unshadowed": UnshadowedTrace(),
        "photometric_stereo": ps,
        "riesz": RieszEnergy(),
        "riesz_s1": RieszEnergy(1.0),
        "image": ImageSetTerm(objective, scene),
        "combined": SetCost([(1.0, ps), (2.0, RieszEnergy()), (50.0, ImageSetTerm(objective, scene))]),
    }


@pytest.mark.parametrize(
    "name", ["unshadowed", "photometric_stereo", "riesz", "riesz_s1", "image", "combined"]
)
def test_gradient_matches_finite_differences(face: tuple[Scene, Objective], name: str) -> None:
    term = all_terms(face)[name]
    cap = Cap.from_sphere(face[0].sphere)
    directions = cap.random(4, np.random.default_rng(11))
    zenith, azimuth = angles_of(directions)
    x = np.r_[zenith, azimuth]
    p = term.parameters(directions)
    assert p.size == term.parameter_size(4)
    designer = LightSetDesigner(term, 4, cap)
    value, gradient = designer.cost_gradient(x, p)
    gradient = np.asarray(gradient).ravel()
    h = 1e-6
    if name in ("image", "combined"):
        # the image term's NumPy twin is the exact renderer: differentiate the CasADi value itself
        def f(y: np.ndarray) -> float:
            return float(designer.cost_gradient(y, p)[0])
    else:

        def f(y: np.ndarray) -> float:
            return term.numpy(direction_in_sphere_frame(y[:4], y[4:]), p)

        assert term.numpy(directions, p) == pytest.approx(float(value), rel=1e-11)
    fd = np.array([(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(8)])
    assert np.allclose(gradient, fd, rtol=1e-5, atol=1e-6 * max(1.0, np.abs(fd).max()))
    assert np.abs(gradient).max() > 0


def test_image_term_numpy_twin_is_the_exact_renderer(face: tuple[Scene, Objective]) -> None:
    scene, objective = face
    term = ImageSetTerm(objective, scene)
    directions = Cap.from_sphere(scene.sphere).random(3, np.random.default_rng(2))
    p = term.parameters(directions)
    exact = np.mean([objective.numpy(scene.pixels(a)) for a in term.positions(directions)])
    assert term.numpy(directions, p) == pytest.approx(exact, rel=1e-12)
    # the smooth model (β = 60, smooth clip) stays within a few per cent of the exact one here
    assert casadi_value(term, directions, p) == pytest.approx(exact, rel=0.1)


# ------------------------------------------------------------------ design


def test_designed_set_beats_the_classical_ring_on_the_face(face: tuple[Scene, Objective]) -> None:
    scene, _ = face
    term = PhotometricStereoTerm.from_scene(scene)
    cap = Cap.from_sphere(scene.sphere)
    ring = ring_directions(6, min(CLASSICAL_SLANT, cap.zenith_max))
    result = design_light_set(term, 6, cap, starts=2, seed=1)
    assert result.success
    assert result.cost < term.numpy(ring)
    assert result.cost == pytest.approx(term.numpy(result.directions), rel=1e-12)  # masks at the solution
    assert np.all(cap.contains(result.directions))


def test_allowed_hook_constrains_the_design() -> None:
    def left_half(d: ca.MX) -> ca.MX:
        return d[:, 0] + 0.1  # x_S ≤ −0.1 for every light

    result = design_light_set(UnshadowedTrace(), 4, WIDE_CAP, starts=2, allowed=left_half)
    assert result.success
    assert np.all(result.directions[:, 0] <= -0.1 + 1e-6)
    assert result.cost > 9.0 / 4  # the free optimum needs lights on both sides


def test_designer_is_reused_and_must_match() -> None:
    designer = LightSetDesigner(UnshadowedTrace(), 5, WIDE_CAP)
    a = design_light_set(designer.objective, 5, WIDE_CAP, starts=1, seed=1, designer=designer)
    b = design_light_set(designer.objective, 5, WIDE_CAP, starts=1, seed=2, designer=designer)
    assert a.cost == pytest.approx(9 / 5, rel=1e-6) and b.cost == pytest.approx(9 / 5, rel=1e-6)
    with pytest.raises(OptlightError, match="another"):
        design_light_set(designer.objective, 6, WIDE_CAP, designer=designer)


def test_rti_design_spreads_lights_evenly() -> None:
    cap = Cap(0.0, math.radians(60.0))
    result = design_light_set(RieszEnergy(), 12, cap, starts=2)
    designed = coverage(result.directions, cap)
    lattice = coverage(cap.lattice(12), cap)
    rng_set = coverage(cap.random(12, np.random.default_rng(0)), cap)
    assert result.cost < RieszEnergy().numpy(cap.lattice(12))
    assert designed["min_separation_deg"] > lattice["min_separation_deg"] > rng_set["min_separation_deg"]
    assert designed["covering_radius_deg"] < rng_set["covering_radius_deg"]
    # every pair at least 30° apart: on a 60° cap of area π·(1 − cos 60°)·2 = π, 12 disks of radius 15°
    assert math.degrees(min_separation(result.directions)) > 30.0


def test_start_outside_the_cap_names_the_key() -> None:
    cap = Cap(0.0, math.radians(60.0))
    start = ring_directions(4, math.radians(70.0))
    with pytest.raises(ProblemError, match=r"start: expected directions inside the cap .*zenith 70\.000°"):
        design_light_set(UnshadowedTrace(), 4, cap, start=start)


# ------------------------------------------------------------------ grids


def test_yale_b_grid() -> None:
    grid = yale_b_grid()
    assert len(grid.names) == 64 == len(set(grid.names))
    assert np.allclose(np.linalg.norm(grid.directions, axis=1), 1.0)
    by_name = dict(zip(grid.names, grid.directions, strict=True))
    assert np.allclose(by_name["A+000E+00"], [0, 0, 1])  # frontal: towards the camera
    assert np.allclose(by_name["A+000E+90"], [0, 1, 0])  # straight above
    assert by_name["A+050E+00"][0] < 0  # to the subject's right: the image's left
    for name, d in by_name.items():
        a, e = math.radians(int(name[1:5])), math.radians(int(name[6:]))
        # the angle to the camera axis of a light at azimuth A, elevation E: cos = cos A cos E
        assert angles_of(d)[0] == pytest.approx(math.acos(math.cos(a) * math.cos(e)), abs=1e-12)
        mirrored = f"A{-int(name[1:5]):+04d}E{name[6:]}" if int(name[1:5]) else name
        assert np.allclose(by_name[mirrored] * [-1, 1, 1], d)  # mirror-symmetric


def test_map_grid_keeps_allowed_directions_and_replaces_the_rest() -> None:
    grid = yale_b_grid()
    cap = Cap(0.0, math.radians(60.0))

    def reachable(d: np.ndarray) -> np.ndarray:
        return d[:, 1] > -0.3  # e.g. lights low under the object are out of reach

    mapping = map_grid(grid, cap, reachable)
    inside = cap.contains(grid.directions) & reachable(grid.directions)
    assert np.array_equal(mapping.replaced, ~inside)
    assert np.allclose(mapping.achieved[inside], grid.directions[inside])
    assert np.all(reachable(mapping.achieved)) and np.all(cap.contains(mapping.achieved))
    assert len({tuple(np.round(d, 12)) for d in mapping.achieved}) == 64  # distinct lights
    assert np.allclose(np.cos(mapping.moved), np.sum(mapping.requested * mapping.achieved, axis=1))
    report = mapping.report()
    assert report["requested"] == 64 and report["achieved_exactly"] == int(inside.sum())
    assert len(report["replaced"]) == mapping.replaced_count > 0


def test_map_grid_nearest_matches_brute_force_over_a_mask() -> None:
    grid = grid_from_degrees([[0, 0], [30, 10], [-80, 0], [0, -50]])
    cap = Cap(0.0, math.radians(60.0))
    candidates = cap.lattice(500)
    allowed = candidates[:, 0] < 0.2
    mapping = map_grid(grid, cap, allowed, candidates, distinct=False)
    for requested, achieved in zip(grid.directions, mapping.achieved, strict=True):
        best = max(candidates[allowed], key=lambda c: float(c @ requested))
        assert np.allclose(achieved, best)


def test_grid_outside_the_cap_can_be_refused() -> None:
    with pytest.raises(
        ProblemError,
        match=r"lightset.grid: expected grid directions inside the cap .*A\+000E\+90 at zenith 90.0°",
    ):
        map_grid(yale_b_grid(), Cap(0.0, math.radians(60.0)), outside_cap="error")


def test_camera_axis_direction_is_unit_and_matches_angles() -> None:
    d = camera_axis_direction(math.radians(35.0), math.radians(40.0))
    assert np.linalg.norm(d) == pytest.approx(1.0)
    assert math.degrees(math.asin(d[1])) == pytest.approx(40.0)  # elevation above the horizon


@pytest.mark.parametrize(
    "text, where",
    [
        ("azimuth_deg,elevation_deg\n10,20\n10,abc\n", "line 3: '10,abc'"),
        ("azimuth_deg,elevation_deg\n10\n", "line 2: '10'"),
        ("# comment\nazimuth_deg,elevation_deg\n10,95\n", "line 3: '10,95'"),
        ("a,b\n1,2\n", "header 'a,b'"),
    ],
)
def test_malformed_grid_file_names_the_key_and_line(tmp_path: Path, text: str, where: str) -> None:
    path = tmp_path / "grid.csv"
    path.write_text(text)
    with pytest.raises(ProblemError) as err:
        read_grid_file(path, "problem.toml")
    message = str(err.value)
    assert message.startswith("problem.toml: lightset.grid_file: expected") and where in message
    assert "\n" not in message


def test_grid_file_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "grid.csv"
    path.write_text("# two lights\nname,azimuth_deg,elevation_deg\nleft,-30,0\ntop,0,45\n")
    grid = read_grid_file(path)
    assert grid.names == ("left", "top")
    assert np.allclose(grid.directions, grid_from_degrees([[-30, 0], [0, 45]]).directions)


# ------------------------------------------------------------------ problem files


def test_lightset_keys_are_validated(tmp_path: Path) -> None:
    with pytest.raises(ProblemError, match="lightset.count: expected at least 3 lights"):
        problem_from_dict({"lightset": {"kind": "photometric_stereo", "count": 2}})
    with pytest.raises(ProblemError, match="lightset.count: expected at least 2 lights"):
        problem_from_dict({"lightset": {"kind": "rti", "count": 1}})
    with pytest.raises(ProblemError, match=r"lightset.grid_deg\[1\]\[1\]: expected an elevation"):
        problem_from_dict({"lightset": {"kind": "grid", "grid_deg": [[0, 0], [10, 91]]}})
    with pytest.raises(ProblemError, match="lightset.grid_file: expected an existing CSV file"):
        problem_from_dict({"lightset": {"kind": "grid", "grid_file": str(tmp_path / "none.csv")}})
    with pytest.raises(ProblemError, match="lightset.kind: expected one of"):
        problem_from_dict({"lightset": {"kind": "dome"}})


def test_problem_builds_set_costs_and_grids(face: tuple[Scene, Objective], tmp_path: Path) -> None:
    scene, objective = face
    problem = problem_from_dict({"lightset": {"kind": "photometric_stereo", "count": 8, "image_weight": 2.0}})
    cost = set_cost_from_problem(problem, scene, objective)
    assert [type(t).__name__ for _, t in cost.terms] == ["PhotometricStereoTerm", "ImageSetTerm"]
    assert [w for w, _ in cost.terms] == [1.0, 2.0]
    rti = set_cost_from_problem(problem_from_dict({"lightset": {"kind": "rti", "riesz_exponent": 3}}), scene)
    assert isinstance(rti.terms[0][1], RieszEnergy) and rti.terms[0][1].exponent == 3.0
    with pytest.raises(ProblemError, match="lightset.kind"):
        set_cost_from_problem(problem_from_dict({"lightset": {"kind": "grid"}}), scene)
    assert len(grid_from_problem(problem_from_dict({"lightset": {"kind": "grid"}})).names) == 64
    table = problem_from_dict({"lightset": {"kind": "grid", "grid_deg": [[0, 0], [20, 10]]}})
    assert grid_from_problem(table).directions.shape == (2, 3)
    (tmp_path / "g.csv").write_text("azimuth_deg,elevation_deg\n0,0\n")
    (tmp_path / "p.toml").write_text('[lightset]\nkind = "grid"\ngrid_file = "g.csv"\n')
    from optlight.spec import load_problem

    assert len(grid_from_problem(load_problem(tmp_path / "p.toml")).names) == 1


def test_riesz_energy_of_two_coincident_lights_is_infinite_without_a_warning() -> None:
    lights = Cap(0.0, math.radians(60.0)).lattice(5)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning (division by zero, a NaN power) fails
        pole = np.array([[0.0, 0.0, 1.0]])  # 2 − 2 d·d is exactly 0
        assert RieszEnergy().numpy(np.vstack([lights, pole, pole])) == math.inf
        assert RieszEnergy().numpy(np.vstack([lights, lights[2]])) > 1e20  # inf, or 1e30 by rounding
        assert math.isfinite(RieszEnergy().numpy(lights))
