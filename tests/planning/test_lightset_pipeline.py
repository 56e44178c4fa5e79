"""Light sets through the whole job: a set designed on the allowed cap is placed, planned,
verified and exported in the DiLiGenT layout; a grid reports the lights it had to replace."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest
from conftest import reacher_of, reduced_problem

import optlight
from optlight.datasets import read_diligent
from optlight.errors import OutOfReachError
from optlight.photometric_stereo import gbuffer_normal_map
from optlight.pipeline import choose_captures, place_captures
from optlight.plan import PHOTOMETRIC_STEREO_FOLDER, Plan
from optlight.planning.set_landmarks import CLEAR_MARGIN, SetReplacement, directions_of
from optlight.setup import Setup


@pytest.fixture(scope="module")
def ps_plan() -> Plan:
    """photometric_stereo.toml with 5 lights, 2 starts and a 48² camera."""
    return optlight.solve(
        reduced_problem("photometric_stereo", camera_px=48, lightset={"count": 5, "starts": 2})
    )


@pytest.fixture(scope="module")
def ps_folder(ps_plan: Plan, tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("ps") / "out"
    ps_plan.save(folder, preview=False)
    return folder


def _directions_world(plan: Plan) -> np.ndarray:
    sphere = plan.setup.sphere
    d = np.array([lm.position for lm in plan.visited]) - sphere.center
    return d / np.linalg.norm(d, axis=1, keepdims=True)


@pytest.mark.slow
def test_set_solve_passes_verification_and_reports_requested_vs_achieved(ps_plan: Plan) -> None:
    assert ps_plan.verification.passed
    report = ps_plan.lightset
    assert report is not None and report["kind"] == "photometric_stereo"
    assert report["requested"] == 5
    assert report["achieved"] == len(ps_plan.visited) == 5 - len(report["dropped"])
    # every captured light lies on the allowed cap, outside the camera's view
    zenith = np.array([lm.zenith for lm in ps_plan.visited])
    assert np.all(zenith >= ps_plan.setup.view_zenith - 1e-6)
    assert np.all(zenith <= ps_plan.setup.sphere.zenith_max + 1e-6)
    # a light the placement did not move is where the design put it, so an unmoved set keeps its cost
    if not report["moved_by_placement"] and not report["dropped"]:
        assert report["set_cost_achieved"] == pytest.approx(report["set_cost_requested"], rel=1e-6)
    assert {lm.status for lm in ps_plan.visited} <= {"set", "placed"}
    travel = report["order_joint_travel_rad"]
    assert travel["tour"] <= travel["azimuth"] + 1e-9  # the tour is no longer than azimuth order


def test_diligent_folder_reads_back_with_the_achieved_lights(ps_plan: Plan, ps_folder: Path) -> None:
    folder = read_diligent(ps_folder / PHOTOMETRIC_STEREO_FOLDER)
    # DiLiGenT axes from the camera's rotation directly: OpenCV (x right, y down, z forward) -> (x, −y, −z)
    camera = ps_plan.scene.camera.rotation.T @ _directions_world(ps_plan).T
    expected = (camera * np.array([[1.0], [-1.0], [-1.0]])).T
    np.testing.assert_allclose(folder.directions, expected, atol=1e-6)
    assert folder.images.shape == (len(ps_plan.visited), 48, 48)
    # one naming and one frame across the exports: filenames.txt and light_directions.txt are
    # captures.csv's image column and light directions, and lights.lp's rows
    with (ps_folder / "captures.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    lp = [line.split() for line in (ps_folder / "lights.lp").read_text().splitlines()[1:]]
    assert list(folder.names) == [r["image"] for r in rows] == [line[0] for line in lp]
    columns = ("light_dir_right", "light_dir_up", "light_dir_to_camera")
    np.testing.assert_allclose([[float(r[c]) for c in columns] for r in rows], folder.directions, atol=1e-9)
    np.testing.assert_allclose([[float(x) for x in line[1:]] for line in lp], folder.directions, atol=1e-9)
    np.testing.assert_array_equal(folder.mask, ps_plan.scene.gbuffer.mask)
    for name in ("normal_map.png", "normal_error.png", "lightset_reach.png", "plan.json", "report.md"):
        assert (ps_folder / name).is_file()
    report = (ps_folder / "report.md").read_text()
    assert "## Light set" in report and "reachability map (`lightset_reach.png`)" in report


def test_recovered_normals_match_the_model(ps_plan: Plan, ps_folder: Path) -> None:
    """The model's images are Lambertian with the ambient subtracted and shadowed or saturated lights
    rejected per pixel, so where three or more lights remain the least-squares normal is exact up to
    the renderer's float rounding; the bound (mean 0.1°, the noiseless bound) leaves room for the few pixels at a shadow's
    edge, where a light is half in (the G-buffer normal is the pixel centre's, the image the
    pixel's). The statistics in plan.json are those of normals.npy."""
    import json

    normals = np.load(ps_folder / PHOTOMETRIC_STEREO_FOLDER / "normals.npy")
    recovered = np.linalg.norm(normals, axis=2) > 0.5
    assert recovered.sum() > 0.5 * ps_plan.scene.gbuffer.mask.sum()
    reference = (
        gbuffer_normal_map(ps_plan.scene) @ ps_plan.scene.camera.rotation * np.array([1.0, -1.0, -1.0])
    )
    error = np.degrees(np.arccos(np.clip(np.sum(normals * reference, axis=2), -1.0, 1.0)))[recovered]
    assert error.mean() < 0.1
    stats = json.loads((ps_folder / "plan.json").read_text())["summary"]["lightset"]["recovery"]
    assert stats["mean_deg"] == pytest.approx(error.mean(), abs=1e-6)
    assert stats["p95_deg"] == pytest.approx(np.percentile(error, 95), abs=1e-6)


@pytest.mark.slow
def test_grid_replaces_the_lights_in_the_camera_view() -> None:
    """A grid with the frontal light (azimuth 0, elevation 0: the camera's axis, zenith 0) cannot be
    captured with the lamp out of the view: it is replaced on the allowed cap and reported."""
    grid = [[0.0, 0.0], [25.0, 0.0], [-25.0, 0.0], [0.0, 25.0], [0.0, -25.0]]
    problem = reduced_problem(
        "photometric_stereo", camera_px=48, lightset={"kind": "grid", "grid_deg": grid, "count": 5}
    )
    with pytest.warns(UserWarning, match="grid lights lie outside the allowed cap"):
        plan = optlight.solve(problem)
    assert plan.verification.passed
    report = plan.lightset
    assert report is not None and report["requested"] == 5
    replaced = report["grid"]["replaced"]
    assert [r["name"] for r in replaced] == ["A+000E+00"]
    # moved at least to the view's edge: the lamp enters the view below zenith view_zenith
    assert replaced[0]["moved_deg"] >= math.degrees(plan.setup.view_zenith) - 1e-6
    assert any("grid lights lie outside the allowed cap" in w for w in plan.warnings)  # in plan.json too


@pytest.mark.parametrize("kind", ["rti", "grid"])
def test_a_light_is_replaced_by_the_reachable_one_that_best_keeps_the_set(kind: str) -> None:
    """SetReplacement against brute force: every candidate near the light that scores better than the
    replacement (a lower set cost with the other lights fixed; for a grid, nearer the requested
    direction) is one the robot does not reach clear or one on another light of the set (within
    ``[landmarks] distinct_deg``), and the replacement's joint angles put the light there
    (pinocchio) with every environment row clear."""
    sections: dict = {"count": 8, "starts": 1, "design_over": "cap"}  # the rule alone, without the map
    if kind == "grid":
        sections = {
            "kind": "grid",
            "grid_deg": [[20.0 * i, 30.0] for i in range(8)],
            "count": 8,
            "design_over": "cap",
        }
    setup = Setup.from_problem(reduced_problem("rti_dome", camera_px=32, lightset=sections))
    _, design, captures, _ = choose_captures(setup)
    assert design is not None
    reacher = reacher_of(setup)
    rule = SetReplacement(reacher, design, captures, setup.lightset_spec, setup.landmark_spec)
    light = captures[3]
    here = rule.directions[light.index]
    others = np.array([d for i, d in rule.directions.items() if i != light.index])
    attempts = [reacher.attempt(light.position, setup.robot.theta_ref)]
    found = rule(light, attempts, setup.robot.theta_ref)
    assert not isinstance(found, str), found
    replacement, theta, note = found
    sphere = setup.sphere
    position, _ = setup.robot.light_pose(theta)
    np.testing.assert_allclose(position, replacement.position, atol=1e-6)
    assert setup.environment is not None
    assert setup.environment.worst_sphere_row(setup.robot, theta)[0] >= 0.0
    assert replacement.status == "placed" and "best keeps the set" in note

    def score(direction: np.ndarray) -> float:
        if design.cost is None:
            return -float(direction @ design.requested[light.index])
        return design.cost.numpy(np.vstack([others, direction]))

    chosen = (replacement.position - sphere.center) @ sphere.rotation / sphere.radius
    nearest = rule.lattice[np.argsort(-(rule.lattice @ here))[:40]]
    apart = math.cos(math.radians(setup.landmark_spec.distinct_deg))
    better = [d for d in nearest if score(d) < score(chosen) - 1e-12 and (others @ d).max() < apart]
    # the rule keeps the previous light's IK branch (here θ_ref's) when it can, and restarts otherwise
    start = setup.robot.theta_ref
    direct = reacher.attempt(replacement.position, start, restarts=False).theta is not None
    for d in better:
        position = sphere.center + sphere.radius * sphere.rotation @ d
        assert reacher.attempt(position, start, restarts=False).theta is None, (
            "a better light was passed over"
        )
        if not direct:
            assert reacher.attempt(position, start).theta is None, "a better light was passed over"


def test_a_grid_light_is_not_replaced_onto_another_light_of_the_set() -> None:
    """Two grid lights the robot cannot reach must not share a replacement (yale_grid once captured
    64 images at 61 lights): with another light of the set standing where the rule would put the
    replaced one, the rule picks a light at least ``[landmarks] distinct_deg`` from every other."""
    grid = {
        "kind": "grid",
        "grid_deg": [[20.0 * i, 30.0] for i in range(8)],
        "count": 8,
        "design_over": "cap",
    }
    setup = Setup.from_problem(reduced_problem("rti_dome", camera_px=32, lightset=grid))
    _, design, captures, _ = choose_captures(setup)
    assert design is not None
    reacher = reacher_of(setup)
    light, other = captures[3], captures[4]
    attempts = [reacher.attempt(light.position, setup.robot.theta_ref)]
    sphere = setup.sphere

    def replaced_direction(rule: SetReplacement) -> np.ndarray:
        found = rule(light, attempts, setup.robot.theta_ref)
        assert not isinstance(found, str), found
        return (found[0].position - sphere.center) @ sphere.rotation / sphere.radius

    alone = replaced_direction(
        SetReplacement(reacher, design, captures, setup.lightset_spec, setup.landmark_spec)
    )
    rule = SetReplacement(reacher, design, captures, setup.lightset_spec, setup.landmark_spec)
    rule.directions[other.index] = alone  # another light of the set where the replacement would go
    apart = replaced_direction(rule)
    others = np.array([d for i, d in rule.directions.items() if i != light.index])
    closest = math.degrees(math.acos(float(np.clip((others @ apart).max(), -1.0, 1.0))))
    assert closest >= setup.landmark_spec.distinct_deg


@pytest.mark.slow
def test_a_set_designed_over_the_reachable_lights_is_placed_where_it_was_designed() -> None:
    """rti_dome, 8 lights. Designed on the cap alone, the placement has to replace 3 of them (the arm
    reaches them only across the camera's view cone). Designed over the reachability map, every light
    lies on the clear side of the map's field, and the placement puts every one where the design did:
    its joint angles hold the light there (pinocchio, to the IK's tolerance) with every environment
    row clear."""
    placed = {}
    for over in ("cap", "reachable"):
        setup = Setup.from_problem(
            reduced_problem("rti_dome", camera_px=32, lightset={"count": 8, "starts": 1, "design_over": over})
        )
        _, design, captures, _ = choose_captures(setup)
        assert design is not None and (design.reach is not None) == (over == "reachable")
        placement = place_captures(setup, captures, design)
        achieved = directions_of(setup.sphere, placement.landmarks)
        requested = design.requested[[lm.index for lm in placement.landmarks]]
        placed[over] = (len(placement.landmarks), int(np.sum(np.sum(achieved * requested, axis=1) < 1 - 1e-12)))
    assert placed["cap"][1] >= 2  # replaced
    assert placed["reachable"] == (8, 0)
    assert design.reach is not None and design.field is not None
    assert np.all(design.field.numpy(design.requested) >= CLEAR_MARGIN - 1e-6)
    env = setup.environment
    assert env is not None
    ik_tol = math.sqrt(setup.problem.solver.ik_tol)  # the IK converges at |e|² < ik_tol
    for lm, theta in zip(placement.landmarks, placement.thetas, strict=True):
        assert np.linalg.norm(setup.robot.light_pose(theta)[0] - lm.position) <= ik_tol
        assert env.worst_sphere_row(setup.robot, theta)[0] >= 0.0


def test_a_set_the_robot_reaches_nowhere_is_refused_after_the_map() -> None:
    """The Panda 3 m from the object reaches no cell of the cap: the set stage says so, naming the
    map and what to change, before any design or placement NLP."""
    problem = reduced_problem(
        "rti_dome",
        camera_px=32,
        robot={"base_position_m": [3.0, 0.0, 0.0]},
        lightset={"count": 4, "starts": 1, "reach_step_deg": 20.0},
    )
    with pytest.raises(OutOfReachError, match=r"reaches no light of the cap clear .*reachability map, 27 cells, 0 %"):
        choose_captures(Setup.from_problem(problem))
