"""The benchmark runner on synthetic components (the real benchmarks are only imported): discovery, quick sizes,
rows, the rich table, markdown and JSON, failures recorded with a non-zero exit status, the CLI."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path
from types import ModuleType

import pytest
from rich.console import Console

from optlight import cli
from optlight.errors import OptlightError

RUNNER = Path(__file__).resolve().parent.parent / "benchmarks" / "run.py"

FAKE = """
def run(n: int = 10000, seed: int = 0) -> dict:
    return {
        "solve": {"median_ms": 1.5, "p98_ms": 2.25, "success_pct": 97.5, "n": n},
        "sweep_s": {"coarse": {"median": 0.125, "p98": 0.5}},
        "meta": {"n": n, "seed": seed},
        "baseline_missing": "no baseline in this fake",
    }
"""

BROKEN = """
def run() -> dict:
    raise ValueError("broken on purpose")
"""


def load_runner() -> ModuleType:
    spec = importlib.util.spec_from_file_location("test_bench_runner_run", RUNNER)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def runner() -> ModuleType:
    return load_runner()


@pytest.fixture
def bench_dir(tmp_path: Path) -> Path:
    folder = tmp_path / "benchmarks"
    folder.mkdir()
    (folder / "bench_fake.py").write_text(FAKE)
    (folder / "bench_broken.py").write_text(BROKEN)
    return folder


def test_discovery_and_default_selection(runner: ModuleType, bench_dir: Path) -> None:
    (bench_dir / f"{runner.PIPELINE_MODULE}.py").write_text("")
    assert list(runner.components(bench_dir)) == ["broken", "fake"]
    selected = runner.select([], quick=False, bench_dir=bench_dir)
    problems = list(runner.available_problems())
    flying = [p for p in problems if p in runner.FLYING_PROBLEMS]
    assert flying == list(runner.FLYING_PROBLEMS)  # every problem solved flying is shipped
    solves = 2 + len(problems)
    assert [b.name for b in selected] == ["broken", "fake", *["solve"] * len(problems), *["solve-flying"] * len(flying)]
    assert [b.args for b in selected[2:]] == [(p,) for p in (*problems, *flying)]
    assert all(b.sizes == {"repeats": runner.PIPELINE_REPEATS} for b in selected[2:solves])
    assert all(b.sizes == {"repeats": runner.PIPELINE_REPEATS, "capture": "flying"} for b in selected[solves:])
    assert all(b.sizes == {} for b in selected[:2])


def test_unknown_name(runner: ModuleType, bench_dir: Path) -> None:
    with pytest.raises(OptlightError, match="unknown benchmark 'nope'.*broken, fake"):
        runner.select(["nope"], quick=True, bench_dir=bench_dir)


def test_quick_sizes_rows_and_writers(runner: ModuleType, bench_dir: Path, tmp_path: Path) -> None:
    report = runner.run_all(runner.select(["fake"], quick=True, bench_dir=bench_dir), quick=True)
    (outcome,) = report.outcomes
    assert not outcome.failed
    assert outcome.kwargs == {"n": runner.QUICK_SIZES["n"]}  # only the sizes run() accepts
    assert outcome.result["meta"] == {"n": runner.QUICK_SIZES["n"], "seed": 0}
    assert [(r.metric, r.median, r.p98, r.success_pct) for r in report.rows] == [
        ("solve [ms]", 1.5, 2.25, 97.5),
        ("sweep_s/coarse [s]", 0.125, 0.5, None),
    ]

    console = Console(record=True, width=200)
    console.print(runner.table(report))
    text = console.export_text()
    assert "solve [ms]" in text and "sweep_s/coarse [s]" in text and "97.5" in text
    assert report.machine["python"] in text

    json_path, md_path = runner.write(report, tmp_path / "results")
    data = json.loads(json_path.read_text())
    assert data["quick"] is True and data["failed"] == [] and data["timestamp"] == report.timestamp
    assert data["notes"] == ["fake: baseline missing (no baseline in this fake)"]
    machine = data["machine"]
    assert {"cpu", "cores", "ram_gb", "os", "python", "versions", "git"} <= set(machine)
    assert {"numpy", "casadi", "pin", "toppra", "meshcat", "trimesh", "embreex", "optlight"} <= set(
        machine["versions"]
    )
    (bench,) = data["benchmarks"]
    assert bench["status"] == "ok" and bench["result"]["solve"]["n"] == runner.QUICK_SIZES["n"]
    assert bench["rows"][0] == {
        "benchmark": "fake",
        "metric": "solve [ms]",
        "median": 1.5,
        "p98": 2.25,
        "success_pct": 97.5,
        "baseline_median": None,
        "ratio": None,
    }

    md = md_path.read_text()
    assert "| benchmark | metric | median | p98 | success % | baseline median | ratio |" in md
    assert "| fake | solve [ms] | 1.5 | 2.25 | 97.5 | – | – |" in md
    assert f"Python {report.machine['python']}" in md
    assert "- fake: baseline missing (no baseline in this fake)" in md


def test_failure_recorded_and_exit_status(runner: ModuleType, bench_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "results"
    status = runner.bench(["broken", "fake"], quick=True, out=out, bench_dir=bench_dir)
    assert status == 1
    data = json.loads((out / "latest.json").read_text())
    assert data["failed"] == ["broken"]
    broken, fake = data["benchmarks"]
    assert broken["status"] == "failed" and broken["error"] == "ValueError: broken on purpose"
    assert "raise ValueError" in broken["traceback"] and broken["result"] is None
    assert fake["status"] == "ok" and fake["rows"]  # the run went on after the failure
    assert "- `broken`: ValueError: broken on purpose" in (out / "latest.md").read_text()
    assert runner.bench(["fake"], quick=True, out=out, bench_dir=bench_dir) == 0


def test_baseline_pairing(runner: ModuleType) -> None:
    dist = {"median": 2.0, "p98": 3.0}
    plan = {
        key: dist
        for key in ("time_s", "joint_path_length_rad", "motion_time_s", "max_h_residual_m", "nlp_iterations")
    }
    result = {"problem": "p", "success_pct": 100.0, "plan": plan, "baseline": None}
    rows = runner.solve_rows("solve", result)
    assert rows[0].cells() == ["solve p", "time [s]", "2", "3", "100", "–", "–"]
    result["baseline"] = {key: {"median": 8.0, "p98": 9.0} for key in plan}
    rows = runner.solve_rows("solve", result)
    assert [r.ratio for r in rows] == [0.25, 0.25, 0.25, 0.25, None]

    ik = {"robots": {"ur5": {"ours 5-D": {"median_ms": 0.5, "p98_ms": 1.0, "verified_pct": 99.0}}}}
    ik["robots"]["ur5"][runner.IK_BASELINE] = {"median_ms": 2.0, "p98_ms": 4.0, "verified_pct": 80.0}
    ours, clik = runner.ik_rows("ik", ik)
    assert (ours.benchmark, ours.ratio, ours.success_pct) == ("ik ur5", 0.25, 99.0)
    assert clik.ratio is None


def test_environment_rows(runner: ModuleType) -> None:
    def plan(seconds: float, passed: float, distance_m: float) -> dict:
        dist = {"median": seconds, "p98": seconds}
        check = {"min_distance_m": {"median": distance_m, "p98": distance_m}, "passed_pct": passed}
        times = {key: dist for key in ("solve_time_s", "nlp_time_s", "motion_time_s")}
        return {**times, "passed_pct": passed, "checks": {"clearance": check}}

    result = {
        "problems": {"p": {"constrained": plan(4.0, 100.0, 0.02), "unconstrained": plan(2.0, 0.0, -0.01)}}
    }
    solve, nlp, motion, ours, theirs = runner.environment_rows("environment", result)
    assert solve.cells() == ["environment p", "solve time [s]", "4", "4", "100", "2", "2"]
    assert nlp.ratio == motion.ratio == 2.0 and motion.success_pct is None
    assert (ours.metric, ours.median, ours.success_pct) == (
        "constrained: min clearance distance [mm]",
        20.0,
        100.0,
    )
    assert (theirs.median, theirs.success_pct, theirs.ratio) == (-10.0, 0.0, None)


def test_lightset_plan_rows_pair_the_cap_design(runner: ModuleType) -> None:
    def dist(x: float) -> dict:
        return {"median": x, "p98": x}

    result = {
        "rti": {
            "achieved_pct": dist(100.0),
            "solve_s": dist(10.0),
            "joint_travel_rad": {"tour": dist(20.0)},
            "designed_on_cap": {"achieved_pct": dist(80.0), "solve_s": dist(20.0), "joint_travel_rad": {"tour": dist(40.0)}},
        },
        "grid": {"achieved_pct": dist(100.0)},
        "meta": {"lightbot_s_per_pose": 6.3},
    }
    rows = {(r.metric): r for r in runner.lightset_plan_rows("lightset_plans", result)}
    assert set(rows) == {"rti/achieved_pct", "rti/solve_s [s]", "rti/joint_travel_rad/tour", "grid/achieved_pct"}
    assert rows["rti/achieved_pct"].ratio == 1.25 and rows["rti/solve_s [s]"].baseline_median == 20.0
    assert rows["rti/joint_travel_rad/tour"].ratio == 0.5
    assert rows["grid/achieved_pct"].baseline_median is None


def test_json_safe(runner: ModuleType) -> None:
    import numpy as np

    plain = runner._plain({"a": np.float64(1.5), "b": np.arange(2), "c": float("nan"), "d": (Path("x"),)})
    assert json.dumps(plain, allow_nan=False) == '{"a": 1.5, "b": [0, 1], "c": null, "d": ["x"]}'


def test_cli_help(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["bench", "--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    assert "--quick" in out and "--out" in out and "PROBLEM" in out


def test_cli_unknown_name(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["bench", "no_such_benchmark_or_problem"]) == 2
    assert "unknown benchmark 'no_such_benchmark_or_problem'" in capsys.readouterr().err


def test_every_real_benchmark_imports_and_has_a_run(runner: ModuleType) -> None:
    """Imports only (no benchmark runs): a renamed library function must fail here, not in the full
    run an hour later (the scene benchmark once imported a function that had been renamed)."""
    modules = {name: runner.load_module(path) for name, path in runner.components().items()}
    modules["solve"] = runner.load_module(runner.BENCH_DIR / f"{runner.PIPELINE_MODULE}.py")
    assert {"scene", "landmarks", "environment", "scaling", "command"} <= set(modules)
    assert all(callable(getattr(m, "run", None)) for m in modules.values())


def test_readme_is_rendered_from_the_committed_results(runner: ModuleType) -> None:
    """benchmarks/README.md is what the renderer makes of the latest results in the repository, so
    its tables cannot drift from them (``python benchmarks/run.py --readme-only`` renders it)."""
    assert runner.README.read_text() == runner.readme()


def test_readme_shows_every_results_folder_with_its_date_and_machine(
    runner: ModuleType, bench_dir: Path, tmp_path: Path
) -> None:
    results = tmp_path / "results"
    readme_before = runner.README.read_bytes()
    assert runner.bench(["fake"], quick=True, out=results, bench_dir=bench_dir) == 0
    assert runner.bench(["fake"], quick=True, out=results / "fake_alone", bench_dir=bench_dir) == 0
    assert runner.README.read_bytes() == readme_before  # results outside benchmarks/results: untouched
    full = json.loads((results / "latest.json").read_text())
    alone = json.loads((results / "fake_alone" / "latest.json").read_text())

    text = runner.readme(results, bench_dir)
    assert text.startswith(runner.README_INTRO)
    assert text.index("## Full run") < text.index("## `fake_alone`")
    for data in (full, alone):
        assert data["timestamp"] in text
    machine = runner.machine_line(full["machine"], commit=False)
    assert text.count(f"Machine: {machine}") == 2 and "; git " not in text
    assert text.count("| fake | solve [ms] | 1.5 | 2.25 | 97.5 | – | – |") == 2
    assert "- `fake`:" not in text  # the fake module has no docstring to describe it
    (bench_dir / "bench_fake.py").write_text('"""A fake: ``run`` returns fixed numbers.\n\nMore."""\n' + FAKE)
    assert "- `fake`: A fake: `run` returns fixed numbers." in runner.readme(results, bench_dir)


def test_cell_benchmark_counts_outcomes_and_reasons(runner: ModuleType) -> None:
    """bench_cells' summary of synthetic outcomes: counts per outcome and category, refusals by reason
    (a ProblemError by its key, list indices left out), the verified share, and the runner's rows."""
    cells_bench = runner.load_module(runner.BENCH_DIR / "bench_cells.py")
    from optlight.errors import ProblemError, UnreachableError

    assert cells_bench.reason_key(ProblemError("f", "environment.boxes[3].name", "x")) == (
        "ProblemError:environment.boxes[].name"
    )
    assert cells_bench.reason_key(UnreachableError("landmark 4 (zenith 26.0°) is out of reach")) == (
        "UnreachableError:landmark (zenith °) is out of"  # the first six words
    )
    labels = {"robot": "ur5", "object": "face", "task": "rti", "environment": "none"}
    outcomes = [
        {"seed": 0, "outcome": "verified", "time_s": 2.0, "labels": labels, "lights_requested": 12, "lights_achieved": 9},
        {"seed": 1, "outcome": "verified", "time_s": 4.0, "labels": {**labels, "robot": "panda"}},
        {"seed": 2, "outcome": "refused", "reason": "ProblemError:robot.start", "time_s": 1.0, "labels": labels,
         "lights_requested": 8, "lights_achieved": 0},
        {"seed": 3, "outcome": "crashed", "traceback": "Traceback ...", "time_s": 1.0, "labels": labels},
    ]
    summary = cells_bench.summarize(outcomes)
    assert summary["counts"] == {
        "verified": 2, "failed_verification": 0, "refused": 1, "crashed": 1, "timeout": 0
    }
    assert summary["verified_pct"] == 50.0
    assert summary["refused_by_reason"] == {"ProblemError:robot.start": 1}
    assert summary["per_category"]["robot"]["ur5"]["verified"] == 1
    assert summary["solve_s"]["median"] == 3.0
    assert [c["seed"] for c in summary["not_verified"]] == [2, 3]
    assert summary["lights"]["rti"] == {"cells": 2, "requested": 20, "achieved": 9, "achieved_pct": 45.0}
    assert summary["lights"]["all"]["achieved"] == 9
    summary["verified_pct"] = {"median": 50.0, "p98": 50.0}
    rows = runner.cell_rows("cells", summary)
    assert rows[0].median == 50.0
    assert any(r.metric == "refused: ProblemError:robot.start [cells]" and r.median == 1 for r in rows)
    assert any(r.metric == "lights rti: achieved of 20 requested" and r.median == 9 for r in rows)


def test_a_plan_metric_the_baseline_lacks_has_no_baseline(runner: ModuleType) -> None:
    """The rest-to-rest bound is the plan's own: the paper's per-knot IK baseline does not measure it."""
    dist = {"median": 2.0, "p98": 3.0}
    keys = ("time_s", "joint_path_length_rad", "motion_time_s", "max_h_residual_m", "nlp_iterations")
    plan = {key: dist for key in (*keys, "rest_to_rest_s", "motion_bound_ratio")}
    baseline = {key: {"median": 8.0, "p98": 9.0} for key in keys}
    rows = runner.solve_rows("solve", {"problem": "p", "success_pct": 100.0, "plan": plan, "baseline": baseline})
    bound = next(r for r in rows if r.metric == "rest-to-rest bound [s]")
    assert bound.ratio is None and rows[0].ratio == 0.25
