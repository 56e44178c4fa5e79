"""The random cell generator: valid problems, sensible by construction, seeded."""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest

from optlight.random_cells import (
    CAMERA_AHEAD_M,
    CAMERA_BESIDE_M,
    MIN_SCALE,
    OBJECTS,
    REACH_M,
    REFERENCE_REACH_M,
    TASKS,
    random_cell,
    to_toml,
)
from optlight.scene.objects import build_object
from optlight.spec import ROBOT_NAMES, load_problem

SEEDS = range(20)


@pytest.fixture(scope="module")
def cells(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cells")
    return [random_cell(seed, folder) for seed in SEEDS]


def _scale(cell) -> float:
    robot = cell.labels["robot"].removeprefix("urdf:")
    return min(1.0, max(MIN_SCALE, REACH_M[robot] / REFERENCE_REACH_M))


def test_cells_are_valid_problem_files(cells, tmp_path):
    """Each cell written as TOML reads back to the same data and loads as a problem file."""
    for cell in cells:
        text = to_toml(cell.data)
        assert tomllib.loads(text) == cell.data
        path = tmp_path / f"{cell.name}.toml"
        path.write_text(text)
        problem = load_problem(path)
        assert problem == cell.problem


def test_cells_are_seeded(tmp_path):
    assert random_cell(7, tmp_path).data == random_cell(7, tmp_path).data
    assert random_cell(7, tmp_path).data != random_cell(8, tmp_path).data


def test_cells_are_sensible(cells):
    """Object in front of the base, camera on the robot's side of it, beside the base and not behind
    it, the object inside the light sphere with room for the housing, the table under the object and
    the camera, the object's bound as the built mesh has it."""
    for cell in cells:
        p = cell.problem
        s = _scale(cell)
        center, eye = np.array(p.object.center_m), np.array(p.camera.position_m)
        reach_out = float(np.hypot(center[0], center[1]))
        assert 0.45 * s - 1e-3 <= reach_out <= 0.60 * s + 1e-3, cell.name
        assert 0.25 * s - 1e-3 <= center[2] <= 0.50 * s + 1e-3, cell.name
        forward = np.array([center[0], center[1], 0.0]) / reach_out
        assert abs(math.degrees(math.atan2(forward[1], forward[0]))) <= 30.0 + 1e-6
        distance = float(np.linalg.norm(eye - center))
        assert 0.6 * s - 1e-3 <= distance <= 1.0 * s + 1e-3, cell.name
        # the robot's side: the camera nearer the base than the object is, along the base → object line
        along = float(eye @ forward)
        assert CAMERA_AHEAD_M - 1e-3 <= along <= reach_out + 1e-3, cell.name
        assert float(np.hypot(eye[0], eye[1])) >= CAMERA_BESIDE_M * s - 1e-3, cell.name
        assert eye[2] >= center[2] - 1e-9
        bound = float(np.max(np.linalg.norm(build_object(p).mesh.vertices - center, axis=1)))
        assert bound <= cell.object_radius + 1e-6 <= 1.25 * bound, cell.name  # OBJ text: µm
        ls = p.light_sphere
        assert ls.radius_m >= bound + p.light.housing_length_m
        assert distance > ls.radius_m
        assert 40.0 <= ls.zenith_max_deg <= 70.0 and ls.zenith_min_deg <= 20.0
        assert p.landmarks.allow_partial, cell.name  # the landmarks or lights the arm reaches are planned
        if p.environment.enabled:
            table = p.environment.table_height_m
            assert table is not None and -0.03 - 1e-9 <= table <= 0.0
            assert center[2] - bound > table and eye[2] > table
            for box in p.environment.boxes:  # a wall behind the base
                assert float(np.array(box.center_m) @ forward) < -0.3


def test_cells_cover_every_kind(tmp_path):
    """Over 80 seeds: every built-in robot and a user URDF, every object and task, with and without
    the environment."""
    drawn = [random_cell(seed, tmp_path).labels for seed in range(80)]
    robots = {d["robot"] for d in drawn}
    assert set(ROBOT_NAMES) <= robots and any(r.startswith("urdf:") for r in robots)
    assert {d["object"] for d in drawn} == set(OBJECTS)
    assert {d["task"] for d in drawn} == set(TASKS)
    assert {d["environment"] for d in drawn} == {"none", "table", "table+wall"}
