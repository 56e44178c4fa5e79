"""Work sized before it starts, paths kept inside their folder: a table of refusals through the CLI.

Each row is a bad input a user can write (a problem file, a batch spec, command-line arguments) that
used to hang, allocate without bound, or be accepted with exit status 0. Each must now be refused
before any long work: exit status 2, exactly one line on stderr that matches the row's pattern (the
file and the key, or the option, and what this machine can do), nothing written and no existing file
changed. The rows run in-process through :func:`optlight.cli.main` with this machine's available
memory fixed at :data:`MEMORY_BYTES` (the sizing refusals depend on it) and the commands' work
replaced by a function that fails the test if called (:data:`WORK`); a few rows run again as real
subprocesses. Then: the mark that lets ``render --force`` replace only its own PNGs, and the duration
bound the sizing check rests on, against real timed trajectories.
"""

from __future__ import annotations

import importlib
import json
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import reduced_problem, snapshot
from PIL import Image

import optlight
import optlight.spec.sizing
from optlight.cli import main
from optlight.errors import ProblemError
from optlight.export import STAGING_PREFIX
from optlight.setup import reach_bound
from optlight.spec.sizing import check_trajectory_samples, least_move_time
from optlight.threads import max_local_workers
from optlight.viz.images import save_gray_png, written_by_optlight

#: The memory the in-process rows see as available (bytes): the refusals' limits are computed from it.
MEMORY_BYTES = 8e9
#: The default problem shrunk so that its checks take a fraction of a second.
SMALL = {"camera": {"width": 64, "height": 64}, "landmarks": {"count": 6}}
#: Far beyond any arm's reach from the object.
FAR_BASE = {"base_position_m": [5.0, 0.0, 0.0]}


def toml_value(v: object) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    return repr(v)


def toml_text(data: dict, prefix: str = "") -> str:
    """A TOML document of tables and scalars (dotted keys quoted)."""
    lines, tables = [], []
    for k, v in data.items():
        name = json.dumps(k) if "." in k else k
        if isinstance(v, dict):
            tables.append(f"[{prefix}{name}]\n{toml_text(v, f'{prefix}{name}.')}")
        else:
            lines.append(f"{name} = {toml_value(v)}")
    return "\n".join(lines + tables) + "\n"


def small(**sections: dict) -> dict:
    """The small default problem with ``sections`` merged in, key by key."""
    out = {k: dict(v) for k, v in SMALL.items()}
    for k, v in sections.items():
        out[k] = {**out.get(k, {}), **v}
    return out


#: A batch spec whose grid is 10⁶ rows: six keys of ten valid values each.
MILLION_ROWS = {
    "problem": "small.toml",
    "grid": {
        "light.power": [0.5 + 0.05 * i for i in range(10)],
        "light.ambient": [0.01 * i for i in range(10)],
        "light.gain": [0.5 + 0.05 * i for i in range(10)],
        "landmarks.count": list(range(1, 11)),
        "trajectory.dwell_s": [0.3 + 0.1 * i for i in range(10)],
        "objective.bins": list(range(8, 18)),
    },
}

#: Files of the workspace: name -> problem data (written as TOML) or, for the images, their size.
PROBLEMS: dict[str, dict] = {
    "small": small(),
    "dwell": small(trajectory={"dwell_s": 1e6, "settle_s": 0.2}),
    "flying_toppra": small(trajectory={"capture": "flying", "timing": "toppra"}),
    "exposure_past_dwell": small(trajectory={"exposure_s": 0.35}),
    "acceleration": small(robot={"acceleration_limit": 1e-9}),
    "ik_iterations": small(robot=FAR_BASE, solver={"ik_max_iter": 1_000_000_000}),
    "solver_iterations": small(solver={"max_iter": 1_000_000_000}),
    "velocity": small(robot={"velocity_scale": 1e-12}),
    "sweep": small(landmarks={"sweep_step_deg": 1e-6}),
    "knots": small(trajectory={"knot_spacing_deg": 1e-6}),
    "candidates": small(lightset={"kind": "grid", "candidate_spacing_deg": 0.01}),
    "rate": small(trajectory={"rate_hz": 1e9}),
    "evil_pattern": small(trajectory={"image_pattern": "../../evil_{index}.png"}),
    "absolute_pattern": small(trajectory={"image_pattern": "/tmp/evil_{index}.png"}),
    "reference_size": small(objective={"reference": {"kind": "image", "image": "images/grey32.png"}}),
    "mask_size": small(
        objective={"reference": {"kind": "image", "image": "images/grey64.png", "mask": "images/mask32.png"}}
    ),
    "power_zero": small(world={"power_scale": 0.0}),
    "albedo_zero": small(world={"albedo_scale": 0.0}),
    "gamma_huge": small(world={"gamma": 1000.0}),
    "noise_huge": small(world={"noise_std": 50.0}),
    "offset_huge": small(world={"light_offset_m": [0.0, 0.0, 0.5]}),
    "seed_negative": small(world={"seed": -1}),
    "grid_twice": small(lightset={"kind": "grid", "grid_deg": [[0.0, 30.0], [10.0, 20.0], [0.0, 30.0]]}),
    "grid_file_twice": small(lightset={"kind": "grid", "grid_file": "twice.csv"}),
}

#: (name, argv, pattern of the one stderr line, paths that must not exist afterwards). ``{name}`` in
#: an argument is that workspace file's path; in the pattern, that path escaped.
ROWS: list[tuple[str, list[str], str, list[str]]] = [
    # hangs
    (
        "dwell of a million seconds",
        ["check", "{dwell}"],
        r"{dwell}: trajectory\.dwell_s: expected a value ≤ [0-9.e+]+ s on this machine: .* got 1000000\.0$",
        [],
    ),
    (
        "flying captures timed by TOPPRA",
        ["solve", "{flying_toppra}", "--out", "out_flying"],
        r"{flying_toppra}: trajectory\.capture: expected \"stop\" with trajectory\.timing = \"toppra\" "
        r"\(flying captures are timed jerk-limited\), got 'flying'$",
        ["out_flying"],
    ),
    (
        "an exposure longer than the dwell after the settle time",
        ["check", "{exposure_past_dwell}"],
        r"{exposure_past_dwell}: trajectory\.exposure_s: expected an exposure that ends within the dwell "
        r"\(≤ dwell_s − settle_s = 0\.3 s\), got 0\.35$",
        [],
    ),
    (
        "acceleration limit 1e-9",
        ["check", "{acceleration}"],
        r"{acceleration}: robot\.acceleration_limit: expected limits ≥ [0-9.e+]+ × the present ones "
        r".* on this machine",
        [],
    ),
    (
        "a billion IK iterations with the base out of reach",
        ["solve", "{ik_iterations}", "--out", "out_ik"],
        r"{ik_iterations}: solver\.ik_max_iter: expected a value ≤ 10000, got 1000000000$",
        ["out_ik"],
    ),
    (
        "a billion IPOPT iterations",
        ["check", "{solver_iterations}"],
        r"{solver_iterations}: solver\.max_iter: expected a value ≤ 10000, got 1000000000$",
        [],
    ),
    (
        "a thousand workers",
        ["batch", "{million}", "--workers", "1000", "--out", "out_workers"],
        r"optlight batch: argument --workers: expected an integer number of worker processes "
        r"\(4 per usable core here\) in \[1, \d+\], got 1000",
        ["out_workers"],
    ),
    (
        "a reachability grid of millions of cells",
        ["reach", "{small}", "--zenith-step", "0.1", "--azimuth-step", "0.1", "--out", "out_reach"],
        r"--zenith-step: a grid of at most 20000 cells \(an IK solve each\): 601 zenith × 3600 azimuth cells "
        r".*--zenith-step ≥ 15 with this azimuth step$",
        ["out_reach"],
    ),
    (
        "a batch grid of a million rows",
        ["batch", "{million}", "--out", "out_batch"],
        r"{million}: grid: expected at most 10000 rows, .* got 1000000$",
        ["out_batch"],
    ),
    (
        "a sweep step of a micro-degree",
        ["check", "{sweep}"],
        r"{sweep}: landmarks\.sweep_step_deg: expected a value ≥ 0\.1 deg, got 1e-06$",
        [],
    ),
    (
        "knots a micro-degree apart",
        ["check", "{knots}"],
        r"{knots}: trajectory\.knot_spacing_deg: expected a value ≥ 0\.1 deg, got 1e-06$",
        [],
    ),
    (
        "grid candidates a hundredth of a degree apart",
        ["check", "{candidates}"],
        r"{candidates}: lightset\.candidate_spacing_deg: expected a value ≥ 0\.5 deg, got 0\.01$",
        [],
    ),
    # huge allocations
    (
        "velocity scale 1e-12",
        ["solve", "{velocity}", "--out", "out_velocity"],
        r"{velocity}: robot\.velocity_scale: expected a value ≥ [0-9.e+-]+ on this machine: "
        r".* got 1e-12$",
        ["out_velocity"],
    ),
    (
        "rate of a gigahertz",
        ["check", "{rate}"],
        r"{rate}: trajectory\.rate_hz: expected a value ≤ [0-9.e+]+ Hz on this machine: "
        r".* got 1000000000\.0$",
        [],
    ),
    # bad input that was accepted
    (
        "image pattern climbing out of the dataset",
        ["acquire", "{evil_pattern}", "--out", "out_evil"],
        r"{evil_pattern}: trajectory\.image_pattern: .*without / \\ or \.\.: '\.\./\.\./evil_0\.png'",
        ["out_evil"],
    ),
    (
        "image pattern with an absolute path",
        ["check", "{absolute_pattern}"],
        r"{absolute_pattern}: trajectory\.image_pattern: .*'/tmp/evil_0\.png'",
        [],
    ),
    (
        "reference image of another size",
        ["check", "{reference_size}"],
        r"{reference_size}: objective\.reference\.image: expected an image of the camera's size, 64 × 64 px .*"
        r"objective\.reference\.resize = true .* got 'grey32\.png of 32 × 32 px'$",
        [],
    ),
    (
        "reference mask of another size",
        ["check", "{mask_size}"],
        r"{mask_size}: objective\.reference\.mask: expected an image of the camera's size, 64 × 64 px .* "
        r"got 'mask32\.png of 32 × 32 px'$",
        [],
    ),
    (
        "world power scale 0",
        ["acquire", "{power_zero}", "--out", "out_power"],
        r"{power_zero}: world\.power_scale: expected a value > 0, got 0\.0$",
        ["out_power"],
    ),
    (
        "world albedo scale 0",
        ["check", "{albedo_zero}"],
        r"{albedo_zero}: world\.albedo_scale: expected a value > 0",
        [],
    ),
    (
        "world gamma 1000",
        ["check", "{gamma_huge}"],
        r"{gamma_huge}: world\.gamma: expected a value ≤ 10, got 1000\.0$",
        [],
    ),
    (
        "world noise above the saturation",
        ["check", "{noise_huge}"],
        r"{noise_huge}: world\.noise_std: expected a noise σ ≤ light\.saturation = 1",
        [],
    ),
    (
        "world light offset beyond the sphere",
        ["check", "{offset_huge}"],
        r"{offset_huge}: world\.light_offset_m: expected an offset shorter than the light sphere's radius",
        [],
    ),
    (
        "world seed negative",
        ["check", "{seed_negative}"],
        r"{seed_negative}: world\.seed: expected a value ≥ 0, got -1$",
        [],
    ),
    (
        "render --force over the user's own PNG",
        ["render", "{small}", "--zenith", "10", "--azimuth", "0", "--out", "photo.png", "--force"],
        r"--out: photo\.png exists and optlight did not write it; "
        r"--force replaces only a file optlight wrote$",
        [],
    ),
    (
        "a grid of two identical directions",
        ["check", "{grid_twice}"],
        r"{grid_twice}: lightset\.grid_deg: expected distinct light directions .*"
        r"grid_deg\[0\] \(A\+000E\+30\) and grid_deg\[2\] \(A\+000E\+30\) are the same direction",
        [],
    ),
    (
        "a grid file of two identical directions",
        ["check", "{grid_file_twice}"],
        r"{grid_file_twice}: lightset\.grid_file: expected distinct light directions .*"
        r"twice\.csv data row 1 \(front\) and twice\.csv data row 3 \(again\) are the same direction",
        [],
    ),
]

#: Rows that also run as real subprocesses (their refusal does not depend on the memory available).
SUBPROCESS_ROWS = {
    "velocity scale 1e-12",
    "a batch grid of a million rows",
    "render --force over the user's own PNG",
}


def make_workspace(root: Path) -> dict[str, str]:
    """The problem files, images, grid and batch spec of the rows, and a PNG of the user's."""
    images = root / "images"
    images.mkdir()
    Image.fromarray(np.full((32, 32), 128, np.uint8)).save(images / "grey32.png")
    Image.fromarray(np.full((64, 64), 128, np.uint8)).save(images / "grey64.png")
    Image.fromarray(np.full((32, 32), 255, np.uint8)).save(images / "mask32.png")
    (root / "twice.csv").write_text("azimuth_deg,elevation_deg,name\n0,30,front\n20,10,side\n0,30,again\n")
    Image.fromarray(np.arange(64 * 64, dtype=np.uint32).reshape(64, 64).astype(np.uint8)).save(
        root / "photo.png"
    )
    files = {}
    for name, data in PROBLEMS.items():
        path = root / f"{name}.toml"
        path.write_text(toml_text({"description": name, **data}))
        files[name] = str(path)
    spec = root / "million.toml"
    spec.write_text(toml_text(MILLION_ROWS))
    files["million"] = str(spec)
    return files



@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, str]]:
    root = tmp_path_factory.mktemp("refusals")
    return root, make_workspace(root)


def argv_of(argv: list[str], files: dict[str, str]) -> list[str]:
    return [a.format(**files) if a.startswith("{") else a for a in argv]


def pattern_of(pattern: str, files: dict[str, str]) -> re.Pattern[str]:
    for name, path in files.items():
        pattern = pattern.replace("{" + name + "}", re.escape(path))
    return re.compile(r"^optlight: error: " + pattern)


#: The long work of the commands of the rows (module -> function), replaced by :func:`started`.
WORK = {
    "optlight.pipeline": "solve",
    "optlight.acquisition": "acquire",
    "optlight.batch.run": "run_tasks",
    "optlight.planning.reach": "reachability_map",
}


def started(*args: object, **kwargs: object) -> None:
    raise AssertionError("the work started before the input was refused")


def assert_refused(code: int, out: str, err: str, pattern: re.Pattern[str]) -> None:
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, (code, out, err)
    assert "Traceback" not in out + err
    assert len(lines) == 1, err
    assert pattern.search(lines[0]), lines[0]


def test_the_table_has_every_case_once() -> None:
    assert len({name for name, *_ in ROWS}) == len(ROWS)
    assert SUBPROCESS_ROWS <= {name for name, *_ in ROWS}
    assert max_local_workers() < 1000  # the row of a thousand workers is beyond this machine


@pytest.mark.parametrize(("name", "argv", "pattern", "absent"), ROWS, ids=[r[0] for r in ROWS])
def test_refused_in_process(
    name: str,
    argv: list[str],
    pattern: str,
    absent: list[str],
    workspace: tuple[Path, dict[str, str]],
    monkeypatch: pytest.MonkeyPatch,
    capfd: pytest.CaptureFixture[str],
) -> None:
    root, files = workspace
    monkeypatch.chdir(root)
    monkeypatch.setattr(optlight.spec.sizing, "available_memory", lambda: MEMORY_BYTES)
    for module, work in WORK.items():  # refused in the checks: the work itself never starts
        monkeypatch.setattr(importlib.import_module(module), work, started)
    before = snapshot(root)
    code = main(argv_of(argv, files))
    out, err = capfd.readouterr()
    assert_refused(code, out, err, pattern_of(pattern, files))
    assert snapshot(root) == before, "a file changed or an output was written"
    assert not any((root / a).exists() for a in absent)
    assert not list(root.glob(f"{STAGING_PREFIX}*"))


@pytest.mark.parametrize(
    ("name", "argv", "pattern", "absent"),
    [r for r in ROWS if r[0] in SUBPROCESS_ROWS],
    ids=[r[0] for r in ROWS if r[0] in SUBPROCESS_ROWS],
)
def test_refused_as_a_subprocess(
    name: str, argv: list[str], pattern: str, absent: list[str], workspace: tuple[Path, dict[str, str]]
) -> None:
    root, files = workspace
    before = snapshot(root)
    run = subprocess.run(
        [sys.executable, "-m", "optlight.cli", *argv_of(argv, files)],
        cwd=root,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert_refused(run.returncode, run.stdout, run.stderr, pattern_of(pattern, files))
    assert snapshot(root) == before
    assert not any((root / a).exists() for a in absent)


# --------------------------------------------------------------------------------------------
# What is accepted: a resize asked for, a PNG optlight rendered
# --------------------------------------------------------------------------------------------


def test_a_reference_of_another_size_is_resized_when_the_problem_says_so(
    workspace: tuple[Path, dict[str, str]], capfd: pytest.CaptureFixture[str]
) -> None:
    root, _ = workspace
    data = small(objective={"reference": {"kind": "image", "image": "images/grey32.png", "resize": True}})
    path = root / "resized.toml"
    path.write_text(toml_text(data))
    try:
        assert main(["check", str(path)]) == 0
        assert "valid" in capfd.readouterr().out
    finally:
        path.unlink()


def test_render_force_replaces_only_a_png_optlight_rendered(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str]
) -> None:
    """A PNG optlight rendered is replaced by --force (its mark checked by reading the file back); the
    same pixels saved by another program are not."""
    problem = tmp_path / "small.toml"
    problem.write_text(toml_text(small()))
    monkeypatch.chdir(tmp_path)
    render = ["render", str(problem), "--zenith", "10", "--azimuth", "0", "--out", "face.png"]
    assert main(render) == 0
    assert written_by_optlight(tmp_path / "face.png")
    first = (tmp_path / "face.png").read_bytes()
    assert main([*render[:-4], "--zenith", "40", "--azimuth", "90", "--out", "face.png", "--force"]) == 0
    assert (tmp_path / "face.png").read_bytes() != first  # replaced by the new light's image
    with Image.open(tmp_path / "face.png") as image:
        pixels = np.asarray(image)
    Image.fromarray(pixels).save(tmp_path / "copy.png")  # the same image, not written by optlight
    assert not written_by_optlight(tmp_path / "copy.png")
    kept = (tmp_path / "copy.png").read_bytes()
    capfd.readouterr()
    assert main([*render[:-1], "copy.png", "--force"]) == 2
    assert "optlight did not write it" in capfd.readouterr().err
    assert (tmp_path / "copy.png").read_bytes() == kept


def test_the_mark_is_a_png_text_chunk(tmp_path: Path) -> None:
    path = save_gray_png(tmp_path / "a.png", np.eye(4))
    with Image.open(path) as image:
        assert image.text == {"Software": "optlight"}
    (tmp_path / "b.png").write_bytes(b"\x89PNG not really")
    (tmp_path / "c.txt").write_text("Software optlight")
    assert not written_by_optlight(tmp_path / "b.png") and not written_by_optlight(tmp_path / "c.txt")
    assert not written_by_optlight(tmp_path / "missing.png")


# --------------------------------------------------------------------------------------------
# The duration bound of the sizing check, against timed trajectories
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("timing", ["jerk_limited", "toppra"])
def test_least_move_time_bounds_every_timed_move(timing: str) -> None:
    """Every move between two captures of a solved plan (ruckig's or TOPPRA's timing, dwells at both
    ends) takes at least :func:`least_move_time` of the light's straight distance between them, and
    the light never moves faster than the bound's speed Σ v_j R (checked on the sampled motion)."""
    problem = reduced_problem(camera_px=64, landmarks={"count": 6}, trajectory={"timing": timing})
    plan = optlight.solve(problem)
    setup, trajectory = plan.setup, plan.trajectory
    limits, reach = setup.limits, reach_bound(setup.robot)
    jerk = limits.jerk if timing == "jerk_limited" else None
    dwells = trajectory.landmark_intervals
    positions = setup.robot.light_positions(trajectory.sample(dwells[:, 0])[0])
    for k in range(len(dwells) - 1):
        distance = float(np.linalg.norm(positions[k + 1] - positions[k]))
        bound, _ = least_move_time(distance, reach, limits.velocity, limits.acceleration, jerk)
        took = dwells[k + 1, 0] - dwells[k, 1]
        assert 0.0 < bound <= took + 1e-9, (k, bound, took)
    t = np.linspace(0.0, trajectory.duration, 20001)
    light = setup.robot.light_positions(trajectory.sample(t)[0])
    speed = np.linalg.norm(np.diff(light, axis=0), axis=1) / np.diff(t)
    assert speed.max() <= reach * limits.velocity.sum()


def test_a_timed_trajectory_too_long_for_the_memory_names_its_cause(monkeypatch: pytest.MonkeyPatch) -> None:
    """The check on the timed trajectory itself: a rate the trajectory's samples cannot hold names
    rate_hz with the largest rate that fits; a long motion names velocity_scale; long dwells dwell_s."""
    monkeypatch.setattr(optlight.spec.sizing, "available_memory", lambda: MEMORY_BYTES)
    budget = optlight.spec.sizing.trajectory_samples_budget(reduced_problem(camera_px=64), 7)
    assert budget is not None and budget > 0
    fast = reduced_problem(camera_px=64, trajectory={"rate_hz": 1e6})
    check_trajectory_samples(fast, 7, budget / 1e6 * 0.99, 1.0)  # fits
    with pytest.raises(ProblemError, match=r"trajectory\.rate_hz") as e:
        check_trajectory_samples(fast, 7, budget / 1e6 * 1.01, 1.0)
    largest = float(re.search(r"≤ ([0-9.e+]+) Hz", e.value.expected).group(1))
    assert math.isclose(largest, 1e6 / 1.01, rel_tol=1e-2)
    slow = reduced_problem(camera_px=64)
    with pytest.raises(ProblemError, match=r"robot\.velocity_scale"):
        check_trajectory_samples(slow, 7, budget / 1000.0 * 1.01, 1.0)
    with pytest.raises(ProblemError, match=r"trajectory\.dwell_s"):
        check_trajectory_samples(slow, 7, budget / 1000.0 * 1.01, budget / 1000.0)


def test_a_solve_whose_timed_trajectory_outgrows_the_memory_stops_before_sampling_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """With memory for ~3.5 s of samples at 1 kHz the small problem passes the estimate made before
    the work (6 dwells of 0.5 s and short moves: ~3 s), but its timed trajectory is longer: the solve
    stops with a refusal that names the key, and the trajectory is never sampled (the verification
    does not run)."""
    import optlight.pipeline

    problem = reduced_problem(camera_px=64, landmarks={"count": 6})
    per_sample = optlight.spec.sizing.SAMPLE_BYTES_PER_JOINT * 7
    memory = (optlight.spec.sizing.estimated_peak_memory(problem) + 3500 * per_sample) / optlight.spec.sizing.MEMORY_SAFETY
    monkeypatch.setattr(optlight.spec.sizing, "available_memory", lambda: memory)
    monkeypatch.setattr(optlight.pipeline, "verify_knots", started)
    cause = r"(robot\.velocity_scale|trajectory\.dwell_s): .*the timed trajectory lasts"
    with pytest.raises(ProblemError, match=cause):
        optlight.solve(problem)
