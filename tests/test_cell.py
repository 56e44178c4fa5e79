"""Robot-cell design (optlight.cell): the spec, the search grid, the score of a placement against
geometric facts, the chosen placement written as a problem file that loads back, and the same search
on a 2-worker local Dask cluster."""

from __future__ import annotations

import csv
import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from conftest import REACH_ONLY, reduced_problem
from PIL import Image

from optlight.cell import (
    PATH_KEYS,
    cell_spec_from_dict,
    design_cell,
    evaluate_placement,
    level_grid,
    load_cell_spec,
    placement_problem,
    problem_toml,
)
from optlight.cli import main
from optlight.errors import ProblemError
from optlight.export import MANIFEST
from optlight.spec import available_problems, load_problem

#: Lights of the tests (zenith, azimuth in degrees): three the panda reaches at the base problem's
#: placement.
LIGHTS = [[40.0, 0.0], [40.0, 120.0], [40.0, 240.0]]


def write_base(folder: Path, **sections: dict) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "small.toml"
    path.write_text(problem_toml(reduced_problem(camera_px=48, landmarks={"count": 3}, **sections)))
    return path


def write_spec(folder: Path, body: str, **sections: dict) -> Path:
    write_base(folder, **sections)
    spec = folder / "cell.toml"
    spec.write_text(f'problem = "small.toml"\nlights = {json.dumps(LIGHTS)}\n{body}')
    return spec


def _resolved(problem_dict: dict, problem: object) -> dict:
    """``problem_dict`` with its file paths made absolute against ``problem``'s file."""
    for dotted in PATH_KEYS:
        *parents, name = dotted.split(".")
        node = problem_dict
        for part in parents:
            node = node.get(part, {})
        if name in node:
            node[name] = str(problem.resolve(node[name]))  # type: ignore[attr-defined]
    return problem_dict


@pytest.mark.parametrize("name", sorted(available_problems()))
def test_problem_toml_loads_back_as_the_same_problem_from_another_folder(tmp_path: Path, name: str) -> None:
    problem = load_problem(name)
    path = tmp_path / "elsewhere" / f"{name}.toml"
    path.parent.mkdir()
    path.write_text(problem_toml(problem))
    again = load_problem(path)
    assert again.source == path.resolve()
    assert _resolved(again.to_dict(), again) == _resolved(problem.to_dict(), problem)


def test_problem_toml_writes_what_tomllib_reads() -> None:
    """Strings with quotes and backslashes, lists of lists, arrays of tables, nested tables."""
    import tomllib

    problem = dataclasses.replace(
        reduced_problem(
            "default",
            lightset={"kind": "grid", "grid_deg": [[0.0, 10.0], [90.0, 20.5]]},
            environment={"boxes": [{"name": "a", "size_m": [0.1, 0.2, 0.3]}, {"name": "b"}]},
        ),
        description='a "quoted" \\ back\tslash — ü\u0001',
    )
    data = tomllib.loads(problem_toml(problem))
    assert data == problem.to_dict()


def test_level_grid_zooms_around_the_best_within_the_ranges(tmp_path: Path) -> None:
    write_base(tmp_path)
    spec = cell_spec_from_dict(
        {
            "problem": "small.toml",
            "method": "coarse_to_fine",
            "steps": 5,
            "search": {"base_x_m": [-0.2, 0.2], "base_y_m": [0.0, 0.4], "base_z_m": [0.1, 0.1]},
        },
        source=tmp_path / "c.toml",
    )
    first = level_grid(spec, 0, None)
    assert len(first) == 25 and {p["base_z_m"] for p in first} == {0.1}
    assert sorted({p["base_x_m"] for p in first}) == pytest.approx([-0.2, -0.1, 0.0, 0.1, 0.2])
    # level 1: a window half the range wide around the centre, shifted inside the range
    second = level_grid(spec, 1, {"base_x_m": 0.2, "base_y_m": 0.1, "base_z_m": 0.1})
    assert sorted({p["base_x_m"] for p in second}) == pytest.approx([0.0, 0.05, 0.1, 0.15, 0.2])
    assert sorted({p["base_y_m"] for p in second}) == pytest.approx([0.0, 0.05, 0.1, 0.15, 0.2])
    # level 2: a quarter of the range
    third = level_grid(spec, 2, {"base_x_m": 0.0, "base_y_m": 0.2, "base_z_m": 0.1})
    assert sorted({p["base_x_m"] for p in third}) == pytest.approx([-0.05, -0.025, 0.0, 0.025, 0.05])
    assert sorted({p["base_y_m"] for p in third}) == pytest.approx([0.15, 0.175, 0.2, 0.225, 0.25])


def test_level_grid_values_are_the_decimals_of_the_ranges(tmp_path: Path) -> None:
    """The example cell's ranges (±0.15 m, 5 steps): the window around the level-0 point 0.075 m
    holds 0 and 0.1125 exactly, not −1.4e-17 and 0.11249999999999996 (floating-point steps), so
    ``best_problem.toml`` and the command's report print the placement as it was searched."""
    write_base(tmp_path)
    ranges = {"base_x_m": [-0.15, 0.15], "base_y_m": [-0.15, 0.15]}
    spec = cell_spec_from_dict(
        {"problem": "small.toml", "method": "coarse_to_fine", "steps": 5, "search": ranges},
        source=tmp_path / "c.toml",
    )
    best = next(p for p in level_grid(spec, 0, None) if p["base_x_m"] > 0.07 and p["base_y_m"] > 0.07)
    second = level_grid(spec, 1, best)
    for axis in ranges:
        values = sorted({p[axis] for p in second})
        assert values == [0.0, 0.0375, 0.075, 0.1125, 0.15]
        assert not math.copysign(1.0, values[0]) < 0  # 0.0, not −0.0
    assert "-1.38" not in problem_toml(placement_problem(spec, second[0]))


@pytest.mark.parametrize(
    ("body", "key"),
    [
        ("[search]\nbase_x_m = [0.2, -0.2]\n", "search.base_x_m"),
        ("[search]\nbase_w_m = [0.0, 1.0]\n", "search.base_w_m"),
        ("[search]\nbase_x_m = [0.1, 0.1]\n", "search"),
        ("", "search"),
        ('method = "random"\n[search]\nbase_x_m = [0.0, 1.0]\n', "method"),
        ("steps = 1\n[search]\nbase_x_m = [0.0, 1.0]\n", "steps"),
        ("top = 0\n[search]\nbase_x_m = [0.0, 1.0]\n", "top"),
        ("colour = 1\n[search]\nbase_x_m = [0.0, 1.0]\n", "colour"),
    ],
)
def test_a_malformed_cell_spec_is_one_line_naming_the_file_and_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], body: str, key: str
) -> None:
    spec = write_spec(tmp_path, body)
    with pytest.raises(ProblemError) as caught:
        load_cell_spec(spec)
    assert caught.value.file == str(spec.resolve()) and caught.value.key == key
    assert main(["cell", str(spec), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(spec.resolve()) in err and key in err
    assert not (tmp_path / "out").exists()


def test_lights_out_of_the_cap_name_the_light(tmp_path: Path) -> None:
    write_base(tmp_path)
    with pytest.raises(ProblemError, match=r"lights\[1\]\[0\]"):
        cell_spec_from_dict(
            {
                "problem": "small.toml",
                "lights": [[10.0, 0.0], [75.0, 0.0]],
                "search": {"base_x_m": [0.0, 1.0]},
            },
            source=tmp_path / "c.toml",
        )


def test_a_light_on_the_camera_axis_is_reached_but_never_clear() -> None:
    """The light at zenith 0 sits on the segment from the camera to the object: the panda reaches it,
    and the light itself blocks the centre of the view (exact geometry, whatever the posture)."""
    problem = reduced_problem(camera_px=48, **REACH_ONLY)  # a layout where the panda reaches the pole
    outcome = evaluate_placement(problem, np.deg2rad([[0.0, 0.0]]))
    assert (outcome["lights"], outcome["reached"], outcome["clear"]) == (1, 1, 0)
    assert outcome["blocked_by"]


def test_a_base_out_of_reach_reaches_nothing() -> None:
    """The panda reaches 0.855 m from its shoulder: from 2 m behind its usual place no light on a
    0.4 m sphere around the object is nearer than 1.5 m."""
    problem = reduced_problem(camera_px=48, robot={"base_position_m": [-2.0, 0.0, 0.0]})
    outcome = evaluate_placement(problem, np.deg2rad(np.array(LIGHTS)))
    assert (outcome["reached"], outcome["clear"], outcome["error"]) == (0, 0, None)


@pytest.mark.slow
def test_design_cell_picks_the_reachable_placement_and_writes_a_ready_problem(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, "top = 1\n[search]\nbase_x_m = [-2.0, 0.0]\n")
    result = design_cell(spec, tmp_path / "out", serial=True, progress=False)
    xs = [c.values["base_x_m"] for c in result.candidates]
    assert xs == pytest.approx(np.linspace(-2.0, 0.0, 5))
    assert all(c.clear <= c.robot_clear <= c.reached <= c.lights for c in result.candidates)
    far = [c for c in result.candidates if c.values["base_x_m"] <= -1.5]
    assert far and all(c.reached == 0 and c.fraction == 0.0 for c in far)
    best = result.best
    assert best.fraction == max(c.fraction for c in result.candidates) > 0.0
    assert best.verified and 0.0 < best.duration_s < np.inf
    # the written problem is the base problem with the best base position, and loads from its file
    written = load_problem(result.files["problem"])
    assert written.robot.base_position_m == (best.values["base_x_m"], 0.0, 0.0)
    base = load_problem(tmp_path / "small.toml").to_dict()
    base["robot"]["base_position_m"] = list(written.robot.base_position_m)
    base["description"] = written.description
    assert written.to_dict() == base
    assert (result.files["plan"] / "plan.json").is_file()
    with Image.open(result.files["heatmap"]) as image:
        assert image.size[0] > 300 and image.size[1] > 300
    with result.files["candidates"].open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(result.candidates) and rows[0].keys() >= {"base_x_m", "fraction", "reached"}
    summary = json.loads(result.files["summary"].read_text())
    assert summary["best"]["values"]["base_x_m"] == best.values["base_x_m"]


@pytest.mark.slow
def test_an_invalid_camera_placement_scores_zero_with_its_error(tmp_path: Path) -> None:
    """A camera on the light sphere (0.4 m from the object centre) is refused by the problem's own check;
    the placement is recorded with that error, naming the search axis that put it there (the paper's
    layout: its camera moves along x through the object)."""
    spec = write_spec(tmp_path, "steps = 2\ntop = 1\n[search]\ncamera_x_m = [-0.343, 0.35]\n", **REACH_ONLY)
    result = design_cell(spec, tmp_path / "out", serial=True, progress=False)
    valid, invalid = result.candidates
    assert valid.error is None and valid.reached == 3
    assert invalid.fraction == 0.0 and invalid.error is not None
    assert "search.camera_x_m" in invalid.error and "outside the light sphere" in invalid.error
    assert result.best is not invalid


@pytest.mark.slow
def test_the_cluster_search_gives_the_serial_one(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Coarse to fine over base x and y, on 2 workers through the command line and here: the same
    placements, the same scores, the same best; files written by the command."""
    body = 'method = "coarse_to_fine"\nsteps = 2\nlevels = 2\ntop = 1\n[search]\nbase_x_m = [-0.1, 0.1]\nbase_y_m = [0.0, 0.2]\n'
    spec = write_spec(tmp_path, body)
    assert main(["cell", str(spec), "--out", str(tmp_path / "cluster"), "--workers", "2"]) == 0
    serial = design_cell(spec, tmp_path / "serial", serial=True, progress=False)
    with (tmp_path / "cluster" / "candidates.csv").open() as f:
        cluster = list(csv.DictReader(f))
    assert len(cluster) == len(serial.candidates) > 4  # the second level added placements
    for row, c in zip(cluster, serial.candidates, strict=True):
        assert float(row["base_x_m"]) == pytest.approx(c.values["base_x_m"])
        assert float(row["base_y_m"]) == pytest.approx(c.values["base_y_m"])
        assert (int(row["reached"]), int(row["clear"])) == (c.reached, c.clear)
    summary = json.loads((tmp_path / "cluster" / "cell.json").read_text())
    assert summary["best"]["values"] == serial.best.values
    assert summary["best"]["duration_s"] == pytest.approx(serial.best.duration_s, rel=1e-8)
    assert (tmp_path / "cluster" / "best_problem.toml").read_text() == serial.files["problem"].read_text()
    # written whole with a manifest; an earlier output is refused before any work without --force
    listed = json.loads((tmp_path / "cluster" / MANIFEST).read_text())["files"]
    assert "cell.json" in listed and "best_plan/plan.json" in listed
    assert main(["cell", str(spec), "--out", str(tmp_path / "cluster"), "--workers", "2"]) == 2
    assert "--force" in capsys.readouterr().err


def test_the_example_spec_is_valid() -> None:
    spec = load_cell_spec(Path(__file__).resolve().parents[1] / "examples" / "cell_panda.toml")
    assert spec.searched == ("base_x_m", "base_y_m") and spec.lights is None and spec.levels == 2


def test_a_placement_whose_evaluation_fails_scores_zero_with_the_error(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from optlight.planning import policy

    def broken(*args: object, **kwargs: object) -> None:
        raise RuntimeError("IK exploded")

    monkeypatch.setattr(policy.Reacher, "attempt", broken)
    outcome = evaluate_placement(reduced_problem(camera_px=48), np.deg2rad(np.array(LIGHTS)))
    assert (outcome["reached"], outcome["clear"]) == (0, 0)
    assert outcome["error"] == "RuntimeError: IK exploded"
