"""Problem files: every built-in file loads; bad files raise ProblemError naming file and key."""

from __future__ import annotations

import copy
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from optlight.errors import ProblemError
from optlight.setup import Setup
from optlight.spec import (
    PROBLEMS_DIR,
    available_problems,
    load_problem,
    problem_from_dict,
    reference_markdown,
)

ROOT = Path(__file__).resolve().parent.parent


def default_dict() -> dict:
    with (PROBLEMS_DIR / "default.toml").open("rb") as f:
        return tomllib.load(f)


def write_toml(path: Path, data: dict) -> Path:
    """A minimal TOML writer for the value types problem files use."""

    def value(v: object) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        if isinstance(v, dict):
            return "{" + ", ".join(f'"{k}" = {value(x)}' for k, x in v.items()) + "}"
        return repr(v)

    path.write_text("\n".join(f'"{k}" = {value(v)}' for k, v in data.items()) + "\n")
    return path


@pytest.mark.parametrize("name", sorted(available_problems()))
def test_builtin_problems_load(name: str) -> None:
    problem = load_problem(name)
    assert problem.name == name
    assert problem.description, "every built-in problem has a one-line description"


def test_defaults_fill_missing_keys(tmp_path: Path) -> None:
    problem = load_problem(write_toml(tmp_path / "p.toml", {"description": "only this"}))
    assert problem.light_sphere.radius_m == 0.40
    assert problem.objective.terms[0].kind == "histogram"


@pytest.mark.parametrize(
    ("mutate", "key", "fragment"),
    [
        (lambda d: d["light_sphere"].update(radius_m=-0.1), "light_sphere.radius_m", "> 0"),
        (lambda d: d["light_sphere"].update(zenith_max_deg=120.0), "light_sphere.zenith_max_deg", "≤ 90"),
        (
            lambda d: d["light_sphere"].update(zenith_min_deg=50.0, zenith_max_deg=40.0),
            "light_sphere.zenith_max_deg",
            "> zenith_min_deg",
        ),
        (lambda d: d["camera"].update(width=0), "camera.width", "≥ 1"),
        (
            lambda d: d["camera"].update(position_m=[0.45, -0.3, 0.35]),
            "camera.position_m",
            "outside the light sphere",
        ),
        (lambda d: d["camera"].update(look_at_m=[0.45, -2.0, 0.35]), "camera.look_at_m", "sees the object"),
        (lambda d: d["light"].update(model="laser"), "light.model", "'directional', 'point'"),
        (lambda d: d["light"].update(power="bright"), "light.power", "a finite number"),
        (lambda d: d["camera"].update(fov_deg=True), "camera.fov_deg", "a finite number"),
        (lambda d: d["object"].update(center_m=[0.0, 1.0]), "object.center_m", "list of 3"),
        (lambda d: d["object"].update(colour="red"), "object.colour", "unknown key"),
        (lambda d: d.update(extra={}), "extra", "unknown key"),
        (lambda d: d["object"].update(kind="mesh"), "object.path", "mesh file path"),
        (lambda d: d["objective"]["terms"][0].update(kind="mean"), "objective.terms[0].target", "target"),
        (lambda d: d["robot"].update(urdf="nowhere.urdf", frame="tool0"), "robot.urdf", "existing URDF"),
        (lambda d: d["robot"].update(name="ur99"), "robot.name", "panda, ur3"),
        (lambda d: d["trajectory"].update(settle_s=0.5), "trajectory.settle_s", "shorter than the dwell"),
        (lambda d: d["trajectory"].update(settle_s=0.7), "trajectory.settle_s", "dwell_s = 0.5 s"),
        (lambda d: d["light"].update(housing_radius_m=0.4), "light.housing_radius_m", "smaller than the light"),
        (lambda d: d["light"].update(housing_length_m=0.5), "light.housing_length_m", "shorter than the light"),
        (lambda d: d["light"].update(housing="cube"), "light.housing", "'cylinder', 'sphere'"),
        (lambda d: d["robot"].update(jerk_limit=[100.0, -1.0]), "robot.jerk_limit[1]", "> 0"),
        (lambda d: d["robot"].update(jerk_limit="fast"), "robot.jerk_limit", "a finite number"),
        (lambda d: d["trajectory"].update(rate_hz=0.0), "trajectory.rate_hz", "> 0"),
        (lambda d: d["trajectory"].update(timing="fast"), "trajectory.timing", "'jerk_limited', 'toppra'"),
        (lambda d: d["trajectory"].update(capture="sometimes"), "trajectory.capture", "'stop', 'flying'"),
        (
            lambda d: d["trajectory"].update(capture="flying", timing="toppra"),
            "trajectory.capture",
            "flying captures are timed jerk-limited",
        ),
        (lambda d: d["trajectory"].update(exposure_s=0.0), "trajectory.exposure_s", "> 0"),
        (lambda d: d["trajectory"].update(exposure_s=0.4), "trajectory.exposure_s", "ends within the dwell"),
        (lambda d: d["trajectory"].update(blur_deg=-0.1), "trajectory.blur_deg", "> 0"),
        (lambda d: d["trajectory"].update(blur_mm=0.0), "trajectory.blur_mm", "> 0"),
    ],
)
def test_bad_values_name_file_and_key(tmp_path: Path, mutate, key: str, fragment: str) -> None:
    data = default_dict()
    mutate(data)
    path = write_toml(tmp_path / "bad.toml", data)
    with pytest.raises(ProblemError) as err:
        Setup.from_problem(path)  # loading checks the file, building what needs the built scene
    message = str(err.value)
    assert err.value.key == key
    assert str(path) in message and key in message and fragment in message


def test_unknown_problem_lists_builtins() -> None:
    with pytest.raises(ProblemError, match="default"):
        load_problem("no_such_problem")


def test_invalid_toml_is_a_problem_error(tmp_path: Path) -> None:
    path = tmp_path / "broken.toml"
    path.write_text("[object\nkind = ")
    with pytest.raises(ProblemError, match="valid TOML"):
        load_problem(path)


def test_docs_reference_is_up_to_date() -> None:
    """docs/problems.md is generated from the declarations; `make docs` refreshes it."""
    assert (ROOT / "docs" / "problems.md").read_text() == reference_markdown()


def test_round_trip_through_plain_data() -> None:
    problem = load_problem("default")
    again = problem_from_dict(problem.to_dict(), source=problem.source)
    assert again == problem


def test_cli_prints_one_line_without_traceback(tmp_path: Path) -> None:
    data = default_dict()
    data["light_sphere"]["radius_m"] = -1.0
    path = write_toml(tmp_path / "bad.toml", data)
    run = subprocess.run(
        [sys.executable, "-m", "optlight.cli", "check", str(path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode != 0
    assert "Traceback" not in run.stderr + run.stdout
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "light_sphere.radius_m" in lines[0]


# --- mutation fuzzing: any mutation of a valid file gives a valid load or a clean ProblemError ---

LEAVES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**6), 10**6),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8),
    st.lists(st.floats(-2, 2, allow_nan=False), max_size=4),
    st.just({}),
)


def _paths(data: object, prefix: tuple = ()) -> list[tuple]:
    out = [prefix] if prefix else []
    if isinstance(data, dict):
        for k, v in data.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(data, list):
        for i, v in enumerate(data):
            out += _paths(v, (*prefix, i))
    return out


@settings(max_examples=300, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_mutated_problem_files_fail_cleanly(data: st.DataObject) -> None:
    problem = default_dict()
    mutated = copy.deepcopy(problem)
    for _ in range(data.draw(st.integers(1, 3))):
        paths = _paths(mutated)
        path = data.draw(st.sampled_from(paths))
        parent = mutated
        for k in path[:-1]:
            parent = parent[k]
        action = data.draw(st.sampled_from(["replace", "delete", "add"]))
        if action == "delete" and isinstance(parent, dict):
            del parent[path[-1]]
        elif action == "add" and isinstance(parent, dict):
            parent[data.draw(st.text(min_size=1, max_size=6))] = data.draw(LEAVES)
        else:
            leaf = data.draw(LEAVES)
            if leaf is None:  # TOML has no null: None stands for an empty table
                leaf = {}
            parent[path[-1]] = leaf
    try:
        problem_from_dict(mutated)
    except ProblemError as e:
        assert e.key is not None and str(e)


def test_limits_take_one_value_or_one_per_joint() -> None:
    data = load_problem("default").to_dict()
    data["robot"].update(jerk_limit=[100.0, 200, 300, 400, 500, 600, 700], acceleration_limit=4.0)
    robot = problem_from_dict(data).robot
    assert robot.jerk_limit == (100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0)
    assert robot.acceleration_limit == 4.0
    assert problem_from_dict(problem_from_dict(data).to_dict()).robot == robot


# --- what a run needs: memory, image names; values echoed as written ---

_GROWTH = """
import sys
from optlight.planning.landmarks import find_landmarks
from optlight.setup import Setup
from optlight.spec import load_problem, problem_from_dict

def status(key):
    with open("/proc/self/status") as f:
        return next(1024 * int(line.split()[1]) for line in f if line.startswith(key))

n, bins = int(sys.argv[1]), int(sys.argv[2])
data = load_problem("default").to_dict()
data["camera"].update(width=n, height=n)
data["landmarks"].update(count=2)
data["objective"]["bins"] = bins
problem = problem_from_dict(data, source=load_problem("default").source)
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")  # reset the peak resident size (VmHWM) to the current one
before = status("VmRSS:")
setup = Setup.from_problem(problem)
find_landmarks(setup.workcell, setup.image_costs, setup.landmark_spec, setup.solver, setup.file)
print(status("VmHWM:") - before)
"""


@pytest.mark.slow
def test_memory_estimate_bounds_the_measured_growth() -> None:
    """The estimate's per-pixel rate bounds that of the Setup (camera-resolution scene and
    objective) and the landmark search (its search renders, the reported costs at the camera's
    resolution), measured as its peak resident memory above what the process held before it (Linux:
    VmHWM reset through /proc/self/clear_refs), in fresh processes at two sizes; and more histogram
    bins cost next to nothing per pixel (the NumPy kernel is chunked)."""
    from optlight.spec.sizing import MEMORY_BYTES_PER_PIXEL

    def growth(n: int, bins: int) -> float:
        run = subprocess.run(
            [sys.executable, "-c", _GROWTH, str(n), str(bins)], capture_output=True, text=True, timeout=300
        )
        assert run.returncode == 0, run.stderr
        return float(run.stdout.split()[-1])

    small, large, many_bins = growth(128, 32), growth(320, 32), growth(320, 128)
    per_pixel = (large - small) / (320**2 - 128**2)
    assert 0 < per_pixel <= MEMORY_BYTES_PER_PIXEL, (small, large, many_bins)
    assert (many_bins - large) / (96 * 320**2) <= 2.0  # bytes per pixel and bin (was ~72 unchunked)


def test_a_camera_whose_solve_does_not_fit_names_the_key(monkeypatch: pytest.MonkeyPatch) -> None:
    """Checked where the problem is built (this machine's memory), not when the file is loaded."""
    import optlight.spec.sizing as sizing

    problem = problem_from_dict(default_dict())
    need = sizing.estimated_peak_memory(problem)
    monkeypatch.setattr(sizing, "available_memory", lambda: need / sizing.MEMORY_SAFETY * 0.99)
    problem_from_dict(default_dict())  # loading is not refused
    with pytest.raises(ProblemError) as err:
        sizing.check_memory(problem)
    assert err.value.key == "camera.width" and "camera.height" in str(err.value) and "GB" in str(err.value)
    with pytest.raises(ProblemError, match="camera.width"):
        Setup.from_problem(problem)  # refused before it builds anything
    monkeypatch.setattr(sizing, "available_memory", lambda: need / sizing.MEMORY_SAFETY * 1.01)
    sizing.check_memory(problem)
    monkeypatch.setattr(sizing, "available_memory", lambda: None)  # unknown: not checked
    sizing.check_memory(problem)


def test_values_are_echoed_as_written() -> None:
    from optlight.errors import plain

    assert plain(np.float64(1.5)) == "1.5" and plain([np.int64(3), np.float32(0.5)]) == "[3, 0.5]"
    assert plain(np.array([1.0, 2.0])) == "[1.0, 2.0]" and plain("x") == "'x'"
    data = default_dict()
    data["landmarks"]["count"] = 100000
    with pytest.raises(ProblemError, match=r"got 100000$"):
        problem_from_dict(data)


@pytest.mark.parametrize(
    ("pattern", "fragment"),
    [
        ("img_{foo}.png", "only {index}"),
        ("img.png", "repeated"),
        ("a {index}.png", "whitespace"),
        ("{0}", "only"),
    ],
)
def test_image_patterns_are_checked_with_the_problem(pattern: str, fragment: str) -> None:
    data = default_dict()
    data["trajectory"]["image_pattern"] = pattern
    with pytest.raises(ProblemError, match=re.escape(fragment)) as err:
        problem_from_dict(data)
    assert err.value.key == "trajectory.image_pattern"


def test_a_user_urdf_is_named_by_its_file_unless_the_problem_names_it(tmp_path: Path) -> None:
    """Reports and errors name a user's arm, not the default robot's name."""
    urdf = tmp_path / "my_arm.urdf"
    urdf.write_text("<robot name='x'/>")
    unnamed = problem_from_dict({"robot": {"urdf": str(urdf), "frame": "tool0"}})
    named = problem_from_dict({"robot": {"urdf": str(urdf), "frame": "tool0", "name": "cell 3"}})
    assert (unnamed.robot.name, named.robot.name) == ("my_arm", "cell 3")
