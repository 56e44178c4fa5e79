"""Landmark search: the reference light is found again, mirror-symmetric object -> mirror-symmetric
landmarks, never worse than the sweep, NLP built once, free mode keeps its separation, figures."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import pytest
from conftest import reduced_problem, search_landmarks

from optlight.errors import ProblemError
from optlight.objectives import Objective
from optlight.planning import landmarks as lm_module
from optlight.planning.landmarks import exact_cost, local_minima, zenith_grid
from optlight.scene import Scene
from optlight.setup import Setup
from optlight.spec import Problem
from optlight.viz.figures import contact_sheet_images, landmark_figures, save_landmark_figures

REF_ZENITH_DEG = 31.3  # off the sweep grid, so only the refinement can land on it; out of the camera's view


def small_problem(**landmarks: Any) -> Problem:
    """The default face at 64×64 px, searched at 40 px, reference light off the sweep grid."""
    return reduced_problem(
        camera_px=64,
        object={"face": {"resolution": 64}},
        objective={"reference": {"kind": "light", "zenith_deg": REF_ZENITH_DEG, "azimuth_deg": 0.0}},
        landmarks={"count": 8, "resolution": 40, **landmarks},
    )


@pytest.fixture(scope="module")
def problem() -> Problem:
    return small_problem()


@pytest.fixture(scope="module")
def setup(problem: Problem) -> Setup:
    return Setup.from_problem(problem)


@pytest.fixture(scope="module")
def scene(setup: Setup) -> Scene:
    return setup.scene


@pytest.fixture(scope="module")
def result(setup: Setup) -> lm_module.LandmarkSet:
    return search_landmarks(setup)


def test_distance_vanishes_at_the_reference_light(problem: Problem, scene: Scene) -> None:
    objective = Objective.from_problem(problem, scene)
    ref = scene.sphere.position(math.radians(REF_ZENITH_DEG), 0.0)
    assert exact_cost(scene, objective, ref) == pytest.approx(0.0, abs=1e-15)
    assert exact_cost(scene, objective, scene.sphere.position(math.radians(25.0), 0.0)) > 1e-5


def test_reference_azimuth_returns_the_reference_zenith(result: lm_module.LandmarkSet) -> None:
    first = result.landmarks[0]
    assert first.azimuth == 0.0
    assert math.degrees(first.zenith) == pytest.approx(REF_ZENITH_DEG, abs=0.05)
    assert first.cost < 1e-8


def test_mirror_symmetric_face_gives_mirror_symmetric_landmarks(result: lm_module.LandmarkSet) -> None:
    # The face is symmetric about the vertical plane x_S = 0 (y_S up), which maps φ to π − φ.
    m = len(result)
    for j, lm in enumerate(result.landmarks):
        mirror = result.landmarks[(m // 2 - j) % m]
        assert math.isclose(np.mod(np.pi - lm.azimuth, 2 * np.pi), mirror.azimuth, abs_tol=1e-9)
        assert math.degrees(lm.zenith) == pytest.approx(math.degrees(mirror.zenith), abs=0.05)
        assert lm.cost == pytest.approx(mirror.cost, rel=1e-3, abs=1e-12)


def test_never_worse_than_the_sweep(
    problem: Problem, setup: Setup, scene: Scene, result: lm_module.LandmarkSet
) -> None:
    objective = Objective.from_problem(problem, scene)
    grid = result.sweep
    assert grid.cost.shape == (len(result), grid.zenith.size)
    allowed = grid.zenith >= setup.sphere.zenith_min - 1e-12  # the samples out of the camera's view
    assert allowed.sum() < grid.zenith.size  # the sweep also covers the view, to report what it costs
    for lm, row in zip(result.landmarks, grid.cost, strict=True):
        best_sample = grid.zenith[allowed][np.argmin(row[allowed])]
        sample_cost = exact_cost(scene, objective, scene.sphere.position(best_sample, lm.azimuth))
        assert lm.cost <= sample_cost + 1e-15
        assert setup.sphere.zenith_min <= lm.zenith <= setup.sphere.zenith_max
        np.testing.assert_allclose(lm.position, scene.sphere.position(lm.zenith, lm.azimuth))
    assert result.resolution == (40, 40)
    assert result.histograms.shape == (len(result), problem.objective.bins)


def test_every_sweep_sample_is_the_cost_of_its_own_light(setup: Setup, result: lm_module.LandmarkSet) -> None:
    # The pole (zenith 0), the one light every azimuth shares, is rendered by the first azimuth's
    # sweep only: each row must still hold its cost, as it holds every other sample's. Both sweeps,
    # azimuth mode's and free mode's (sweep_costs), against one render per light.
    search, objective = setup.search_scene, setup.search_objective
    grid = result.sweep
    assert grid.zenith[0] == 0.0

    def one_by_one(zenith: np.ndarray, azimuth: np.ndarray) -> np.ndarray:
        return np.array([[exact_cost(search, objective, search.sphere.position(z, a)) for z in zenith] for a in azimuth])

    np.testing.assert_allclose(grid.cost, one_by_one(grid.zenith, grid.azimuth), rtol=1e-12, atol=1e-16)
    zenith, azimuth = grid.zenith[::3], np.radians([10.0, 100.0, 250.0])
    np.testing.assert_allclose(
        lm_module.sweep_costs(search, objective, zenith, azimuth),
        one_by_one(zenith, azimuth),
        rtol=1e-12,
        atol=1e-16,
    )


def test_azimuth_mode_builds_no_nlp_and_reports_progress(problem: Problem, monkeypatch) -> None:
    built = []
    real = ca.nlpsol

    def counting(*args: Any, **kwargs: Any) -> Any:
        built.append(args[0])
        return real(*args, **kwargs)

    monkeypatch.setattr(ca, "nlpsol", counting)
    calls: list[tuple[int, int]] = []
    small = small_problem(count=3, seeds=2)
    out = search_landmarks(
        Setup.from_problem(small), progress=lambda done, total: calls.append((done, total))
    )
    assert built == []  # the zenith search is a 1-D Brent search on the NumPy objective
    assert calls == [(1, 3), (2, 3), (3, 3)]
    assert out.iterations > 0  # objective evaluations of the zenith searches
    free = search_landmarks(Setup.from_problem(small_problem(mode="free", count=2, min_separation_deg=20.0)))
    assert built == ["cap_refiner"] and len(free) == 2  # free mode's 2-D NLP, built once for both


def test_zenith_search_finds_a_minimum_off_the_sweep_grid(setup: Setup) -> None:
    """The refinement alone, against a dense scan of the same fixed-mask objective on its bracket."""
    search = lm_module.ZenithSearch(setup.search_scene, setup.search_objective, setup.sphere)
    azimuth, lo, hi = 0.0, math.radians(REF_ZENITH_DEG - 2.0), math.radians(REF_ZENITH_DEG + 1.0)
    mask = setup.search_scene.visibility(setup.sphere.position(math.radians(REF_ZENITH_DEG), azimuth))
    solved = search.solve(azimuth, mask, (lo, hi))
    assert solved.success and solved.status == "converged" and 5 <= solved.iterations <= 40
    scan = np.linspace(lo, hi, 301)
    costs = setup.search_objective.numpy_batch(
        np.stack([setup.search_scene.pixels(a, mask) for a in setup.sphere.position(scan, azimuth)])
    )
    assert abs(solved.x[0] - scan[np.argmin(costs)]) <= lm_module.REFINE_TOL + (hi - lo) / 300


def test_a_seed_on_the_views_boundary_the_objective_rises_from_is_not_searched(
    small_setup: Setup, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The default face's landmarks lie on the view's boundary, the smallest allowed zenith: each
    azimuth's seed there is an end of the allowed zeniths the objective rises from, so one
    evaluation inside replaces its zenith search, and the landmarks are the ones the searches give."""
    probed = search_landmarks(small_setup)
    lo = small_setup.sphere.zenith_min
    assert all(lm.zenith == lo for lm in probed.landmarks)  # the case
    monkeypatch.setattr(lm_module.ZenithSearch, "rises_from_end", lambda *args: False)
    searched = search_landmarks(small_setup)
    assert [(lm.zenith, lm.azimuth, lm.cost, lm.status) for lm in probed.landmarks] == [
        (lm.zenith, lm.azimuth, lm.cost, lm.status) for lm in searched.landmarks
    ]
    assert probed.iterations < searched.iterations / 2

    monkeypatch.undo()
    scene, objective, sphere = small_setup.search_scene, small_setup.search_objective, small_setup.sphere
    search = lm_module.ZenithSearch(scene, objective, sphere)
    mask = scene.visibility(sphere.position(lo, 0.0))
    inside = float(objective.numpy(scene.pixels(sphere.position(lo + lm_module.REFINE_TOL, 0.0), mask)))
    assert search.rises_from_end(0.0, lo, inside - 1e-9, mask)
    assert not search.rises_from_end(0.0, lo, inside + 1e-9, mask)  # falls into the allowed zeniths
    assert not search.rises_from_end(0.0, lo + 0.01, -math.inf, mask)  # not an end


def test_the_kept_visibility_is_each_landmarks_own_shadow_rays(result: lm_module.LandmarkSet, scene: Scene) -> None:
    """The masks the search keeps are the shadow rays cast afresh at each landmark's light, and the
    contact sheet's images from them are the renders at those lights."""
    kept = result.visibility(scene.gbuffer.size)
    assert kept is not None
    np.testing.assert_array_equal(kept, scene.visibility(result.positions))
    assert (kept == 0.0).any()  # some pixels in cast shadow: the comparison discriminates
    images = contact_sheet_images(result, scene)
    for image, position in zip(images, result.positions, strict=True):
        np.testing.assert_allclose(image, scene.render(position), rtol=1e-6, atol=1e-7)  # float32


def test_free_mode_keeps_the_separation(scene: Scene) -> None:
    free = small_problem(mode="free", count=4, min_separation_deg=8.0, sweep_step_deg=6.0, resolution=32)
    out = search_landmarks(Setup.from_problem(free))
    assert len(out) == 4
    np.testing.assert_array_equal(out.visibility(scene.gbuffer.size), scene.visibility(out.positions))
    d = (out.positions - scene.sphere.center) / scene.sphere.radius
    angles = np.degrees(np.arccos(np.clip(d @ d.T, -1, 1)))
    np.fill_diagonal(angles, np.inf)
    assert angles.min() >= 8.0 - 1e-6
    # The best position on the cap is the reference light itself (or its mirror image).
    assert out.landmarks[0].cost < 1e-6
    assert math.degrees(out.landmarks[0].zenith) == pytest.approx(REF_ZENITH_DEG, abs=0.5)


def test_free_mode_too_many_landmarks_is_a_problem_error() -> None:
    crowded = small_problem(mode="free", count=6, min_separation_deg=60.0, sweep_step_deg=10.0, resolution=24)
    with pytest.raises(ProblemError, match="landmarks.count"):
        search_landmarks(Setup.from_problem(crowded))


def test_helpers() -> None:
    np.testing.assert_array_equal(local_minima([3.0, 1.0, 2.0, 0.5, 0.5, 4.0, 0.1]), [6, 3, 1])
    sphere = Scene.from_problem(small_problem()).sphere
    grid = zenith_grid(sphere, math.radians(7.0))
    assert grid[0] == sphere.zenith_min and grid[-1] == sphere.zenith_max
    assert np.diff(grid).max() <= math.radians(7.0) + 1e-12


def test_search_scene_keeps_the_aspect(setup: Setup) -> None:
    low = setup.search_scene
    assert (low.camera.width, low.camera.height) == (40, 40)
    assert low.object is setup.scene.object  # one object, two resolutions
    same = Setup.from_problem(small_problem(resolution=64))
    assert same.search_scene is same.scene and same.search_objective is same.objective


def test_landmark_figures(result: lm_module.LandmarkSet, scene: Scene, tmp_path: Path) -> None:
    paths = save_landmark_figures(result, scene, tmp_path / "figs")
    assert [p.name for p in paths] == [
        "landmarks_polar.png",
        "landmarks_histograms.png",
        "landmarks_images.png",
        "landmarks_cost.png",
    ]
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_landmark_figures_draw_a_moved_capture_where_it_is_captured(
    result: lm_module.LandmarkSet, scene: Scene
) -> None:
    """A capture the placement moved 12° down its azimuth: the polar plot and the cost map draw it
    there, joined to its landmark; the contact sheet shows the camera image there (its shadow rays
    cast afresh), labelled with both zeniths; the other captures keep their landmarks' images."""
    landmark = result.landmarks[1]
    zenith = landmark.zenith + math.radians(12.0)
    moved = dataclasses.replace(
        landmark, zenith=zenith, position=scene.sphere.position(zenith, landmark.azimuth), status="placed"
    )
    captures = [moved if c is landmark else c for c in result.landmarks]
    jobs = landmark_figures(result, scene, captures)
    for stem in ("landmarks_polar", "landmarks_cost"):
        axes = jobs[stem].build(*jobs[stem].args).axes[0]
        marker = [line for line in axes.lines if line.get_marker() == "D"]
        assert len(marker) == 1, stem
        np.testing.assert_allclose(np.ravel(marker[0].get_xydata()), [moved.azimuth, math.degrees(zenith)])
        joined = [line for line in axes.lines if line.get_marker() in ("None", None) and len(line.get_xdata()) == 2]
        assert any(
            np.allclose(line.get_ydata(), np.degrees([landmark.zenith, zenith])) for line in joined
        ), stem
    sheet = jobs["landmarks_images"]
    images = sheet.args[1]
    np.testing.assert_allclose(images[1], scene.render(moved.position), rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(images[0], scene.render(result.landmarks[0].position), rtol=1e-6, atol=1e-7)
    assert not np.allclose(images[1], scene.render(landmark.position), atol=1e-3)  # the move shows
    labels = [text.get_text() for text in sheet.build(*sheet.args).axes[0].texts]
    azimuth, before, after = (math.degrees(a) for a in (landmark.azimuth, landmark.zenith, zenith))
    assert labels[1] == f"#{landmark.index} θ {before:.1f}→{after:.1f}° φ {azimuth:.0f}°"
    assert "→" not in labels[0]
