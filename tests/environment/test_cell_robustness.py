"""Cells the project never shipped: the collision model against the robot's own geometry (coal against
brute force, the spheres against coal, the SRDF's pairs), the start when none is given, refusals that
say what to change, and a few random cells through the whole solve."""

from __future__ import annotations

import re
import warnings

import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.distance import cdist

import optlight
from optlight.environment import Environment
from optlight.environment.check import check_configurations
from optlight.environment.shapes import SMOOTHING_M
from optlight.errors import ProblemError
from optlight.random_cells import random_cell
from optlight.robot.loading import load_robot
from optlight.setup import Setup
from optlight.spec import ROBOT_NAMES, problem_from_dict

#: Random configurations per robot.
CONFIGURATIONS = 50


def _model(name: str, **environment):
    """The robot with the environment on, the object and the camera out of its reach (beside it)."""
    problem = problem_from_dict(
        {
            "object": {"center_m": [0.0, -1.2, 0.4]},
            "camera": {"position_m": [0.0, -2.0, 0.4]},
            "robot": {"name": name},
            "environment": {"enabled": True, **environment},
            "view": {"mode": "off"},
        }
    )
    robot = load_robot(problem)
    env = Environment.from_problem(problem)
    return robot, env, env.collision_model(robot)


def _configurations(robot, count: int, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    lower, upper = np.maximum(robot.lower, -np.pi), np.minimum(robot.upper, np.pi)
    return [robot.theta_ref.copy()] + [rng.uniform(lower, upper) for _ in range(count)]


def _world_points(cm, g: int) -> np.ndarray:
    m = cm.geometry_data.oMg[g]
    return np.asarray(cm.geometry.geometryObjects[g].geometry.points(), float) @ m.rotation.T + m.translation


@pytest.mark.parametrize("name", ["ur10", "panda", "kinova"])
def test_coal_link_distances_are_at_most_the_closest_vertices(name: str) -> None:
    """coal's distance between two links' hulls is at most the distance between their closest hull
    vertices (brute force), which bounds it from above; it was 465 mm between UR10 links whose
    vertices are 19 mm apart when the hulls kept the mesh's interior vertices."""
    robot, _, cm = _model(name)
    hulls = {g for g, o in enumerate(cm.geometry.geometryObjects) if hasattr(o.geometry, "points")}
    pairs = [p for p in cm.pairs if p.kind == "self" and {p.first, p.second} <= hulls]
    assert len(pairs) >= 5
    for theta in _configurations(robot, 10):
        pin.updateGeometryPlacements(robot.model, robot.data, cm.geometry, cm.geometry_data, robot.to_pin(theta))
        for p in pairs:
            exact = cm.distance(p.first, p.second)
            vertices = float(cdist(_world_points(cm, p.first), _world_points(cm, p.second)).min())
            assert exact <= vertices + 1e-5, (name, p.first_body, p.second_name, exact, vertices)  # GJK: µm


def test_ur10_self_pairs_follow_the_ur_srdf() -> None:
    """The UR10's base_link and upper_arm_link do not touch (the shoulder offset keeps them apart):
    the UR SRDF disables the pair, so it is no self pair, and coal agrees wherever the upper arm is
    at or above the horizontal (shoulder_lift in [−π, 0]; below it, the arm points into the floor the
    base stands on, and its hull can reach the base's cable outlet)."""
    robot, _, cm = _model("ur10")
    pairs = {(p.first_body, p.second_name) for p in cm.pairs if p.kind == "self"}
    assert ("base_link", "upper_arm_link") not in pairs and ("upper_arm_link", "base_link") not in pairs
    base = [g for g, o in enumerate(cm.geometry.geometryObjects) if o.name.startswith("base_link")]
    arm = [g for g, o in enumerate(cm.geometry.geometryObjects) if o.name.startswith("upper_arm_link")]
    for theta in _configurations(robot, CONFIGURATIONS):
        theta[1] = -abs(theta[1])
        pin.updateGeometryPlacements(robot.model, robot.data, cm.geometry, cm.geometry_data, robot.to_pin(theta))
        assert min(cm.distance(a, b) for a in base for b in arm) > cm.self_margin


@pytest.mark.parametrize("name", ROBOT_NAMES)
def test_spheres_against_coal_per_robot(name: str) -> None:
    """Per built-in robot, with the environment on: at the reference configuration no sphere row
    (obstacles and self) is below 0 and coal finds it clear; at random configurations the spheres of
    every self pair are never farther apart than coal's exact distance (they contain the hulls), so
    the rows report every pair coal finds too close."""
    robot, env, cm = _model(name, table_height_m=-0.02)
    clearance, _ = env.sphere_clearance(robot, robot.theta_ref)
    assert clearance.min() >= 0.0, env.clearance_labels(robot)[int(np.argmin(clearance))]
    report = check_configurations(cm, robot.theta_ref[None], np.zeros(1), view="off")
    assert report.passed
    sp = cm.spheres
    index = {b.name: i for i, b in enumerate(cm.bodies)}
    self_pairs = [p for p in cm.pairs if p.kind == "self"]
    for theta in _configurations(robot, CONFIGURATIONS):
        q = robot.to_pin(theta)
        pin.updateGeometryPlacements(robot.model, robot.data, cm.geometry, cm.geometry_data, q)
        centers = sp.world_centers(robot.model, robot.data, q)
        for p in self_pairs:
            a, b = np.flatnonzero(sp.body == index[p.first_body]), np.flatnonzero(sp.body == index[p.second_name])
            gap = np.sqrt(cdist(centers[a], centers[b]) ** 2 + SMOOTHING_M**2) - sp.radii[a][:, None] - sp.radii[b][None]
            assert gap.min() <= cm.distance(p.first, p.second) + 1e-9, (name, p.first_body, p.second_name)


@pytest.mark.parametrize("name", ["ur5", "ur10", "kinova"])
def test_pairs_that_never_come_close_have_no_sphere_rows(name: str) -> None:
    """A self pair proven never within the margin (the joints between swept by branch and bound) gets
    no sphere rows, and coal agrees at random configurations (sampled here, not swept); on the UR5
    the lamp's housing and the first wrist link, whose two spheres break the margin at every posture,
    are such a pair, and the housing and the forearm, which can touch, are not."""
    robot, _, cm = _model(name)
    never = set(cm.never_close_pairs)
    if name == "ur5":
        assert ("light", "wrist_1_link") in never and ("forearm_link", "light") not in never
    assert never
    names = [b.name for b in cm.spheres.bodies]
    row_pairs = {tuple(sorted((names[cm.spheres.body[s]], names[cm.spheres.body[t]]))) for s, t in cm.self_rows}
    assert not never & row_pairs
    pairs = [p for p in cm.pairs if p.kind == "self" and tuple(sorted((p.first_body, p.second_name))) in never]
    rng = np.random.default_rng(7)
    for _ in range(300):
        theta = rng.uniform(-np.pi, np.pi, robot.n)
        pin.updateGeometryPlacements(robot.model, robot.data, cm.geometry, cm.geometry_data, robot.to_pin(theta))
        for p in pairs:
            assert cm.distance(p.first, p.second) > cm.self_margin, (p.first_body, p.second_name)


@pytest.mark.slow
def test_ur5_cap_is_clear_where_coal_says_so(tmp_path) -> None:
    """A UR5 cell (random cell 19: a mesh, an RTI set, a table, a wall and the camera's stand) whose
    every reached light the spheres of the housing and the first wrist link took away: its
    reachability map now has clear lights, and coal finds the map's postures there clear of
    everything and out of the view."""
    from optlight.planning.policy import Reacher
    from optlight.planning.reach import reachability_map

    setup = Setup.from_problem(random_cell(19, tmp_path).problem)
    reach = reachability_map(Reacher(setup.workcell, setup.solver, setup.image_costs), 10.0, 20.0)
    assert reach.clear_fraction > 0.3
    assert setup.environment is not None
    thetas = reach.theta[reach.clear]
    report = setup.environment.check(setup.robot, thetas, np.arange(len(thetas)), capture_times=np.arange(len(thetas)))
    assert report.passed, report.summary()


@pytest.mark.slow
def test_a_cell_the_arm_cannot_reach_names_a_base_that_reaches_it(tmp_path) -> None:
    """A Z1 cell (random cell 4, every landmark asked for) whose cap the arm reaches clear almost
    nowhere (its wrist cannot turn the lamp far enough sideways): the refusal names a base position,
    and there, the generalized IK from random starts and coal's exact check (not the map the
    suggestion was made with) find clear lights."""
    from optlight.robot import generalized_ik

    cell = random_cell(4, tmp_path)
    asked = {**cell.data, "landmarks": {**cell.data["landmarks"], "allow_partial": False}}
    with pytest.raises(optlight.UnreachableError, match=r"move the robot base: \[robot\] base_position_m = \[") as e:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            optlight.solve(problem_from_dict(asked))
    named = re.search(r"base_position_m = (\[[^\]]*\]) reaches (\d+) of", str(e.value))
    assert named is not None and int(named.group(2)) >= 1
    data = {**asked, "robot": {**cell.data["robot"], "base_position_m": eval(named.group(1))}}
    moved = Setup.from_problem(problem_from_dict(data))
    assert moved.environment is not None
    sphere, robot, rng = moved.sphere, moved.robot, np.random.default_rng(3)
    clear = 0
    for zenith in np.radians(np.arange(np.degrees(sphere.zenith_min), np.degrees(sphere.zenith_max) + 1e-9, 10.0)):
        for azimuth in np.radians(np.arange(0.0, 360.0, 20.0)):
            for start in [robot.theta_ref, *robot.random_configuration(rng, 8)]:
                ik = generalized_ik(robot, sphere, sphere.position(zenith, azimuth), start, restarts=False, **moved.ik)
                if ik.success and moved.environment.check(robot, ik.theta[None], [0.0], capture_times=[0.0]).passed:
                    clear += 1
                    break
    assert clear >= 1


def _ur5_cell(**robot) -> dict:
    """A UR5 with a face 0.5 m in front of its base at the height of its reference tool position, the
    camera to its left, a table at the base: the reference configuration reaches into the face."""
    return {
        "object": {"kind": "face", "center_m": [0.5, 0.0, 0.4]},
        "camera": {"position_m": [0.15, 0.6, 0.55], "width": 64, "height": 64},
        "robot": {"name": "ur5", **robot},
        "environment": {"enabled": True, "table_height_m": 0.0},
    }


def test_ur5_reference_inside_the_object_starts_at_a_clear_configuration() -> None:
    """Unset start, the reference configuration inside the object: the start is a clear configuration
    (coal, and the NLPs' rows), and the setup says which; the same configuration given as start is
    refused, naming a start that is clear."""
    problem = problem_from_dict(_ur5_cell())
    robot = load_robot(problem)
    env = Environment.from_problem(problem)
    assert env.sphere_clearance(robot, robot.theta_ref)[0].min() < 0.0  # the case: not clear
    setup = Setup.from_problem(problem)
    assert not np.allclose(setup.start, setup.robot.theta_ref)
    assert setup.start_note is not None and "reference configuration of ur5 is not clear" in setup.start_note
    assert setup.environment is not None
    assert setup.environment.sphere_clearance(setup.robot, setup.start)[0].min() >= 0.0
    cm = setup.environment.collision_model(setup.robot)
    assert check_configurations(cm, setup.start[None], np.zeros(1), view="off").passed
    written = re.search(r"\[robot\] start = (\[[^\]]*\])", setup.start_note)
    assert written is not None and np.allclose(eval(written.group(1)), setup.start, atol=5e-4)

    with pytest.raises(ProblemError) as refused:
        Setup.from_problem(problem_from_dict(_ur5_cell(start=[float(t) for t in robot.theta_ref])))
    assert refused.value.key == "robot.start" and "[robot] start = [" in str(refused.value)


def test_ur10_with_the_environment_starts_at_its_reference() -> None:
    """A UR10 with the environment on and the object out of its way starts at its own reference
    configuration: no self pair of links that cannot touch refuses it."""
    cell = {
        "object": {"kind": "sphere", "radius_m": 0.08, "center_m": [0.55, -0.3, 0.35]},
        "camera": {"position_m": [0.2, -1.0, 0.5], "width": 64, "height": 64},
        "robot": {"name": "ur10"},
        "environment": {"enabled": True, "table_height_m": 0.0},
    }
    setup = Setup.from_problem(problem_from_dict(cell))
    assert setup.start_note is None and np.array_equal(setup.start, setup.robot.theta_ref)


def test_a_table_above_a_turning_shoulder_names_the_height_that_works() -> None:
    """A table top the UR5's shoulder (turning about the vertical) is always too close to: refused on
    environment.table_height_m with the highest table that works, and that table is accepted."""
    cell = _ur5_cell()
    cell["environment"]["table_height_m"] = 0.02
    with pytest.raises(ProblemError) as refused:
        Setup.from_problem(problem_from_dict(cell))
    assert refused.value.key == "environment.table_height_m"
    height = float(re.search(r"at most (-?[\d.]+) m", str(refused.value)).group(1))
    assert height < 0.02
    cell["environment"]["table_height_m"] = height
    Setup.from_problem(problem_from_dict(cell))  # accepted


#: Random cells solved end to end (seeds whose cells plan on the current planner).
SOLVED_SEEDS = (1, 6, 20)


@pytest.mark.slow
@pytest.mark.parametrize("seed", SOLVED_SEEDS)
def test_random_cells_plan_or_say_why(seed: int, tmp_path) -> None:
    """A random cell ends in a verified plan or a refusal (an OptlightError) that names the key to
    change; never a traceback, never a plan that fails its own verification."""
    cell = random_cell(seed, tmp_path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            plan = optlight.solve(cell.problem)
    except optlight.OptlightError as e:
        assert re.search(r"\[\w+\]|\b\w+\.\w+\b", str(e)), str(e)
        return
    assert plan.verification.passed, (cell.name, plan.verification.counts)


def test_a_window_with_one_capture_has_no_unfollowed_segment() -> None:
    """A stretch of the path with a single capture (a light set cut to one light) has no segment:
    with obstacles the check of the IK's clearance along segments gives an empty boolean array
    (it raised TypeError, a traceback, in a random cell)."""
    from conftest import reduced_problem

    from optlight.planning.path import build_path
    from optlight.planning.trajectory.windows import unfollowed_segments

    setup = Setup.from_problem(reduced_problem("collision", camera_px=32))
    assert setup.environment is not None and setup.environment.collisions
    position = setup.sphere.center + setup.sphere.radius * setup.sphere.direction(0.5, 1.0)
    path = build_path(setup.sphere, position[None], [0], np.radians(2.0))
    warm = np.repeat(setup.start[None], path.n_knots, axis=0)
    out = unfollowed_segments(setup.workcell, setup.trajectory_spec, path, warm, np.zeros(0, dtype=np.int64))
    assert out.shape == (0,) and out.dtype == bool
