"""Benchmark runner: every component benchmark, then the whole pipeline on every problem.

    python benchmarks/run.py [--quick] [NAME ...] [--out DIR]
    optlight bench [NAME ...] [--quick] [--out DIR]

A NAME is a component benchmark (a ``bench_<name>.py`` module next to this file, e.g. ``scene``,
``timing``, ``landmarks``) or a problem (a name in ``problems/`` or a path) for the pipeline benchmark
(``bench_solve.py``); a component name wins over a problem of the same name (pass the problem's path
then). Without NAME every component and every problem in ``problems/`` runs.

Each benchmark's ``run(...)`` is called with its own defaults, or in ``--quick`` mode with the sizes of
:data:`QUICK_SIZES` for the parameters its signature has (a component without a size parameter runs
as is). A benchmark that raises is recorded as failed with its error and the run continues; the exit
status is then 1. Printed: one table (benchmark / metric: median, p98, success %, the baseline's median
measured in the same run, ratio median / baseline median). Written to ``--out`` (default
``benchmarks/results/``): ``latest.json`` (machine, versions, timestamp, every benchmark's full result
or error, the table rows) and ``latest.md`` (the table in markdown, with the machine line).

``benchmarks/README.md`` is rendered from the latest results (:func:`readme`): the full run's
``results/latest.json`` and every sub-run's ``results/<name>/latest.json`` (``--out
benchmarks/results/<name>``), each with the date and machine it records. A run whose ``--out`` is
``benchmarks/results`` or a folder in it renders it again at the end;
``python benchmarks/run.py --readme-only`` renders it from the results as they are, running nothing.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import importlib.metadata
import importlib.util
import inspect
import json
import math
import os
import platform
import re
import subprocess
import sys
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
from rich.console import Console
from rich.measure import Measurement
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    SpinnerColumn,
    TextColumn,
    TimeElapsedColumn,
)
from rich.table import Table
from rich.text import Text

from optlight.errors import OptlightError, ProblemError
from optlight.spec import available_problems, resolve_problem_path

BENCH_DIR = Path(__file__).resolve().parent
RESULTS_DIR = BENCH_DIR / "results"
#: The benchmarks' README, rendered from :data:`RESULTS_DIR` by :func:`readme`.
README = BENCH_DIR / "README.md"
#: Module of the whole-pipeline benchmark, ``run(problem, repeats)``; every other ``bench_*.py`` is a component.
PIPELINE_MODULE = "bench_solve"
#: Problems the pipeline benchmark also solves with flying captures (``solve-flying``).
FLYING_PROBLEMS = ("default", "yale_grid")
#: ``--quick`` sizes, passed to a benchmark's ``run`` only for the parameters it has.
QUICK_SIZES: dict[str, Any] = {"n": 300, "repeats": 1, "cells": 12}
#: Solves per problem in a full run (a component runs with its own defaults).
PIPELINE_REPEATS = 3
#: Distributions whose versions are recorded (import names differ: ``pin`` is ``pinocchio``).
VERSIONED = (
    "numpy",
    "scipy",
    "casadi",
    "pin",
    "example-robot-data",
    "toppra",
    "meshcat",
    "trimesh",
    "embreex",
    "rich",
    "optlight",
)
#: Statistic key suffixes a component may use, with the unit they denote.
UNIT_SUFFIXES = {"_ms": "ms", "_s": "s"}
MS_PER_S = 1e3
MM_PER_M = 1e3
#: The IK baseline in ``bench_ik``: pinocchio's CLIK example, unchanged but for the frame.
IK_BASELINE = "clik dt=0.1"
COLUMNS = ("benchmark", "metric", "median", "p98", "success %", "baseline median", "ratio")

Result = dict[str, Any]


@dataclass(frozen=True)
class Row:
    """One line of the table. ``ratio`` is median / baseline median (both measured in the same run)."""

    benchmark: str
    metric: str
    median: float | None
    p98: float | None = None
    success_pct: float | None = None
    baseline_median: float | None = None

    @property
    def ratio(self) -> float | None:
        if self.median is None or not self.baseline_median:
            return None
        return self.median / self.baseline_median

    def cells(self) -> list[str]:
        """The row as text, in the order of :data:`COLUMNS`."""
        numbers = (self.median, self.p98, self.success_pct, self.baseline_median, self.ratio)
        return [self.benchmark, self.metric, *(_number(x) for x in numbers)]

    def to_dict(self) -> dict[str, Any]:
        return {**dataclasses.asdict(self), "ratio": self.ratio}


RowsFn = Callable[[str, Result], list[Row]]


@dataclass(frozen=True)
class Benchmark:
    """One entry of a run. ``load()`` imports the module and returns its ``run`` function (so that an
    import error is that benchmark's failure); it is called with ``args`` and the ``sizes`` its
    signature accepts; ``rows(name, result)`` turns the result into table rows."""

    name: str
    load: Callable[[], Callable[..., Result]]
    rows: RowsFn
    args: tuple[Any, ...] = ()
    sizes: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Outcome:
    """What one benchmark produced: its result and rows, or the error it raised."""

    name: str
    kwargs: dict[str, Any]
    wall_s: float
    result: Result | None = None
    rows: list[Row] = field(default_factory=list)
    error: str | None = None
    traceback: str | None = None

    @property
    def failed(self) -> bool:
        return self.error is not None


@dataclass(frozen=True)
class Report:
    """A whole run: when, where, in which mode, and every benchmark's outcome."""

    timestamp: str
    quick: bool
    machine: dict[str, Any]
    outcomes: list[Outcome]

    @property
    def rows(self) -> list[Row]:
        return [row for outcome in self.outcomes for row in outcome.rows]

    @property
    def failed(self) -> list[Outcome]:
        return [outcome for outcome in self.outcomes if outcome.failed]

    @property
    def notes(self) -> list[str]:
        """Why a baseline is missing, for each result that says so under ``baseline_missing``."""
        return [
            f"{o.name}: baseline missing ({o.result['baseline_missing']})"
            for o in self.outcomes
            if o.result is not None and o.result.get("baseline_missing")
        ]

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Report:
        """The report a ``latest.json`` holds (:meth:`to_dict`'s output read back)."""
        keys = ("benchmark", "metric", "median", "p98", "success_pct", "baseline_median")
        outcomes = [
            Outcome(
                name=b["name"],
                kwargs=b["kwargs"],
                wall_s=b["wall_s"],
                result=b["result"],
                rows=[Row(**{k: row[k] for k in keys}) for row in b["rows"]],
                error=b["error"],
                traceback=b["traceback"],
            )
            for b in data["benchmarks"]
        ]
        return cls(data["timestamp"], data["quick"], data["machine"], outcomes)

    def to_dict(self) -> dict[str, Any]:
        return {
            "timestamp": self.timestamp,
            "quick": self.quick,
            "machine": self.machine,
            "columns": list(COLUMNS),
            "benchmarks": [
                {
                    "name": o.name,
                    "status": "failed" if o.failed else "ok",
                    "kwargs": o.kwargs,
                    "wall_s": o.wall_s,
                    "error": o.error,
                    "traceback": o.traceback,
                    "rows": [row.to_dict() for row in o.rows],
                    "result": o.result,
                }
                for o in self.outcomes
            ],
            "failed": [o.name for o in self.failed],
            "notes": self.notes,
        }


# --------------------------------------------------------------------------------------------
# Machine and versions
# --------------------------------------------------------------------------------------------


def machine_info() -> dict[str, Any]:
    """CPU model, cores (all and usable by this process), RAM, OS, Python, library versions, git commit."""
    return {
        "cpu": _cpu_model(),
        "cores": os.cpu_count(),
        "cores_usable": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
        "ram_gb": _ram_gb(),
        "os": platform.platform(),
        "python": platform.python_version(),
        "versions": {name: _version(name) for name in VERSIONED},
        "git": _git_state(),
    }


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "model name":
                return value.strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _ram_gb() -> float | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            key, _, value = line.partition(":")
            if key == "MemTotal":
                kib = float(value.split()[0])
                return round(kib / 2**20, 1)
    except (OSError, ValueError, IndexError):
        pass
    return None


def _version(distribution: str) -> str | None:
    try:
        return importlib.metadata.version(distribution)
    except importlib.metadata.PackageNotFoundError:
        return None


def _git_state() -> dict[str, Any] | None:
    """The checkout's commit and whether tracked files differ from it; None outside a git checkout."""

    def git(*args: str) -> str:
        done = subprocess.run(
            ["git", "-C", str(BENCH_DIR.parent), *args],
            capture_output=True,
            text=True,
            check=True,
            timeout=10,
        )
        return done.stdout.strip()

    try:
        commit = git("rev-parse", "HEAD")
        dirty = bool(git("status", "--porcelain", "--untracked-files=no"))
    except (OSError, subprocess.SubprocessError):
        return None
    return {"commit": commit, "dirty": dirty}


def machine_line(machine: dict[str, Any], commit: bool = True) -> str:
    """The machine in one line: CPU, cores, RAM, OS, Python, library versions, and (``commit``) the
    git commit."""
    cores = f"{machine['cores']} cores"
    if machine["cores_usable"] != machine["cores"]:
        cores += f" ({machine['cores_usable']} usable)"
    ram = f", {machine['ram_gb']:g} GB RAM" if machine["ram_gb"] is not None else ""
    versions = ", ".join(f"{k} {v}" for k, v in machine["versions"].items() if v is not None)
    git = machine["git"] if commit else None
    revision = (
        "" if git is None else f"; git {git['commit'][:10]}{' + uncommitted changes' if git['dirty'] else ''}"
    )
    return f"{machine['cpu']}, {cores}{ram}; {machine['os']}; Python {machine['python']}; {versions}{revision}"


# --------------------------------------------------------------------------------------------
# Results -> rows
# --------------------------------------------------------------------------------------------


def _distribution(stats: dict[str, Any]) -> tuple[float, float, str] | None:
    """(median, p98, unit) if ``stats`` holds ``median``/``p98`` (bare or with a unit suffix)."""
    for suffix in ("", *UNIT_SUFFIXES):
        median, p98 = stats.get(f"median{suffix}"), stats.get(f"p98{suffix}")
        if isinstance(median, int | float) and isinstance(p98, int | float):
            return float(median), float(p98), UNIT_SUFFIXES.get(suffix, "")
    return None


def _unit_of(key: str) -> str:
    return next((unit for suffix, unit in UNIT_SUFFIXES.items() if key.endswith(suffix)), "")


def distribution_rows(name: str, result: Result) -> list[Row]:
    """Every distribution in ``result`` (a dict with ``median``/``p98``, or ``median_ms``/``p98_ms`` …,
    at any depth) as a row named by its key path, with ``success_pct`` when the dict has one."""
    rows: list[Row] = []

    def walk(node: dict[str, Any], path: tuple[str, ...], unit: str) -> None:
        for key, value in node.items():
            if not isinstance(value, dict):
                continue
            found = _distribution(value)
            if found is None:
                walk(value, (*path, key), _unit_of(key) or unit)
                continue
            median, p98, own_unit = found
            label = "/".join((*path, key))
            shown_unit = own_unit or _unit_of(key) or unit
            success = value.get("success_pct")
            rows.append(
                Row(
                    name,
                    f"{label} [{shown_unit}]" if shown_unit else label,
                    median,
                    p98,
                    float(success) if isinstance(success, int | float) else None,
                )
            )

    walk(result, (), "")
    return rows


def landmark_rows(name: str, result: Result) -> list[Row]:
    """``bench_landmarks``: ours against the paper's fine sweep on each problem, per azimuth and in
    total; success % is the share of azimuths where ours is not worse than the sweep."""
    rows = []
    for problem in result["problems"].values():
        per_azimuth = problem["per_azimuth"]
        label = f"{name} {problem['problem']}"
        times = problem["time_per_azimuth_s"]
        costs = np.array([r["cost"] for r in per_azimuth])
        sweep_costs = np.array([r["sweep_cost"] for r in per_azimuth])
        evaluations = problem["evaluations_per_azimuth"]
        rows += [
            Row(
                label,
                "time per azimuth [ms]",
                MS_PER_S * times["ours"]["median"],
                MS_PER_S * times["ours"]["p98"],
                baseline_median=MS_PER_S * times["sweep"]["median"],
            ),
            Row(label, "total time [s]", problem["time_s"]["ours"], baseline_median=problem["time_s"]["sweep"]),
            Row(
                label,
                "cost per azimuth",
                float(np.median(costs)),
                float(np.percentile(costs, 98)),
                100.0 * float(np.mean([r["not_worse"] for r in per_azimuth])),
                float(np.median(sweep_costs)),
            ),
            Row(label, "refinement evaluations per azimuth", evaluations["median"], evaluations["p98"]),
        ]
    return rows


def scaling_rows(name: str, result: Result) -> list[Row]:
    """``bench_scaling``: per (captures, obstacles) cell one solve's time per capture, against the
    smallest cell with the same obstacles (a ratio near 1: flat); success % is whether it verified;
    beside it the motion time per capture and the mean landmark cost."""
    cells = result["cells"]
    smallest = {}
    for cell in cells:
        if "error" not in cell:
            smallest.setdefault(cell["obstacles"], cell["ms_per_capture"])
    rows = []
    for cell in cells:
        label = f"{name} {cell['captures']} captures, {cell['obstacles']} obstacles"
        if "error" in cell:
            rows.append(Row(label, "time per capture [ms]", None, success_pct=0.0))
            continue
        rows += [
            Row(
                label,
                "time per capture [ms]",
                cell["ms_per_capture"],
                success_pct=100.0 * cell["verified"],
                baseline_median=smallest[cell["obstacles"]],
            ),
            Row(label, "solve time [s]", cell["time_s"]),
            Row(label, "motion time per capture [s]", cell["motion_s_per_capture"]),
            Row(label, "mean landmark cost", cell["mean_cost"]),
        ]
    return rows


def ik_rows(name: str, result: Result) -> list[Row]:
    """``bench_ik``: time per pose of every method on every robot; our methods (``ours …``) against
    :data:`IK_BASELINE` on the same poses; success % is the share of poses whose solution was re-checked
    (``verified_pct``)."""
    rows = []
    for robot, methods in result["robots"].items():
        baseline = methods.get(IK_BASELINE)
        for method, stats in methods.items():
            paired = baseline is not None and method.startswith("ours")
            rows.append(
                Row(
                    f"{name} {robot}",
                    f"{method} [ms]",
                    stats["median_ms"],
                    stats["p98_ms"],
                    stats["verified_pct"],
                    baseline["median_ms"] if paired else None,
                )
            )
    return rows


def solve_rows(name: str, result: Result) -> list[Row]:
    """``bench_solve``: the whole pipeline against the paper's per-knot IK plan (when it exists);
    success % is the share of solves whose NLP converged and whose plan passed verification."""
    label = f"{name} {result['problem']}"
    ours, baseline = result["plan"], result["baseline"]

    def base(key: str) -> float | None:
        return None if baseline is None or key not in baseline else float(baseline[key]["median"])

    def row(metric: str, key: str, success_pct: float | None = None) -> Row:
        return Row(label, metric, ours[key]["median"], ours[key]["p98"], success_pct, base(key))

    return [
        row("time [s]", "time_s", result["success_pct"]),
        row("joint path length [rad]", "joint_path_length_rad"),
        row("motion time [s]", "motion_time_s"),
        *(
            [row("rest-to-rest bound [s]", "rest_to_rest_s"), row("motion time / rest-to-rest bound", "motion_bound_ratio")]
            if "motion_bound_ratio" in ours
            else []
        ),
        *(
            [
                row("duration [s]", "duration_s"),
                row("flying bound [s]", "flying_bound_s"),
                row("motion time / flying bound", "flying_bound_ratio"),
            ]
            if "flying_bound_ratio" in ours
            else []
        ),
        row("max |h| [m]", "max_h_residual_m"),
        Row(label, "NLP iterations", ours["nlp_iterations"]["median"], ours["nlp_iterations"]["p98"]),
    ]


def environment_rows(name: str, result: Result) -> list[Row]:
    """``bench_environment``: per problem, the constrained plan's solve, NLP and motion times against
    the unconstrained plan's (the baseline, same run); then the smallest distance of each exact
    environment check for both plans (mm; < 0 = penetration). Success % is the share of plans that
    pass verification in the environment (on a check's rows: that pass that check)."""
    rows = []
    for problem, r in result["problems"].items():
        label = f"{name} {problem}"
        ours, theirs = r["constrained"], r["unconstrained"]
        for metric, key in (("solve time [s]", "solve_time_s"), ("NLP time [s]", "nlp_time_s")):
            rows.append(
                Row(
                    label,
                    metric,
                    ours[key]["median"],
                    ours[key]["p98"],
                    ours["passed_pct"],
                    theirs[key]["median"],
                )
            )
        key = "motion_time_s"
        rows.append(
            Row(label, "motion time [s]", ours[key]["median"], ours[key]["p98"], None, theirs[key]["median"])
        )
        for plan in ("constrained", "unconstrained"):
            for check, c in r[plan]["checks"].items():
                d = c["min_distance_m"]
                rows.append(
                    Row(
                        label,
                        f"{plan}: min {check} distance [mm]",
                        MM_PER_M * d["median"],
                        MM_PER_M * d["p98"],
                        c["passed_pct"],
                    )
                )
    return rows


def batch_rows(name: str, result: Result) -> list[Row]:
    """``bench_batch``: the batch's wall time on 1 and 2 workers against the serial run (the baseline,
    same run; success % = rows solved), the speed-ups, one row's time on a worker, Dask's per-task
    overhead here, and the cell search's placements per minute on 2 workers against the serial search."""
    label = f"{name} {result['plans']} plans"
    walls = result["batch_wall_s"]
    serial = walls["serial"]["median"]
    rows = [
        Row(
            label,
            f"wall time, {k} [s]",
            v["median"],
            v["p98"],
            v["success_pct"],
            None if k == "serial" else serial,
        )
        for k, v in walls.items()
    ]
    rows += [
        Row(label, "speed-up, 2 over 1 workers (warm)", result["speedup_2_over_1_workers_warm"]),
        Row(label, "speed-up, 2 over 1 workers (cold)", result["speedup_2_over_1_workers_cold"]),
        Row(label, "speed-up, 2 warm workers over serial", result["speedup_2_workers_over_serial"]),
        Row(
            label,
            "one row on a worker [s]",
            result["row_on_worker_s"]["median"],
            result["row_on_worker_s"]["p98"],
        ),
        Row(label, "Dask overhead per task [ms]", result["dask_overhead_per_task_ms"]),
        Row(f"{name} default problem", "one row, serial [s]", result["default_plan_s"]),
        Row(name, "load average (1 min), before", result["load_average_1min"]["before"]),
        Row(name, "load average (1 min), after", result["load_average_1min"]["after"]),
    ]
    cell = result["cell"]
    per_min = "placements per minute"
    rows.append(
        Row(
            f"{name} cell",
            f"{per_min}, 2 workers",
            cell["2 workers"]["placements_per_min"],
            baseline_median=cell["serial"]["placements_per_min"],
        )
    )
    return rows


def cell_rows(name: str, result: Result) -> list[Row]:
    """``bench_cells``: the share of random cells verified (success %), each outcome's count, the
    refusals by reason, the light-set cells' lights achieved of those requested (per kind and all),
    the solve time of the verified cells, and the verified share per robot, object, task and
    environment."""
    cells = result["cells"]
    rows = [Row(name, f"{cells} random cells verified [%]", result["verified_pct"]["median"])]
    rows += [Row(name, f"{outcome} [cells]", count) for outcome, count in result["counts"].items()]
    rows += [Row(name, f"refused: {reason} [cells]", count) for reason, count in result["refused_by_reason"].items()]
    for kind, lights in result.get("lights", {}).items():
        rows.append(
            Row(name, f"lights {kind}: achieved of {int(lights['requested'])} requested", lights["achieved"],
                success_pct=lights["achieved_pct"])
        )
    if result["solve_s"]:
        rows.append(Row(name, "solve, verified cells [s]", result["solve_s"]["median"], result["solve_s"]["p98"]))
    for category, table in result["per_category"].items():
        for label, counts in table.items():
            total = sum(counts.values())
            rows.append(
                Row(name, f"{category} {label}: verified of {total}", counts["verified"],
                    success_pct=100.0 * counts["verified"] / max(1, total))
            )
    return rows


def lightset_plan_rows(name: str, result: Result) -> list[Row]:
    """``bench_lightset_plans``: every distribution (:func:`distribution_rows`); where the set was
    also designed on the cap alone, its rows carry that design's median as the baseline (same run)."""
    rows: list[Row] = []
    for problem, figures in result.items():
        if problem == "meta":
            continue
        cap = figures.get("designed_on_cap", {})
        shipped = {k: v for k, v in figures.items() if k != "designed_on_cap"}
        for row in distribution_rows(name, {problem: shipped}):
            key = row.metric.removeprefix(f"{problem}/").split(" [")[0].split("/")
            node: Any = cap
            for part in key:
                node = node.get(part, {}) if isinstance(node, dict) else {}
            baseline = node.get("median") if isinstance(node, dict) else None
            rows.append(dataclasses.replace(row, baseline_median=baseline))
    return rows


#: Components whose results need their own reading (a baseline to pair); the rest are read generically.
COMPONENT_ROWS: dict[str, RowsFn] = {
    "batch": batch_rows,
    "cells": cell_rows,
    "environment": environment_rows,
    "ik": ik_rows,
    "landmarks": landmark_rows,
    "lightset_plans": lightset_plan_rows,
    "scaling": scaling_rows,
}


# --------------------------------------------------------------------------------------------
# Selecting and running
# --------------------------------------------------------------------------------------------


@functools.cache
def load_module(path: Path) -> ModuleType:
    """Import a benchmark module from its file (once per path)."""
    module_name = f"optlight_benchmarks.{path.stem}"
    spec = importlib.util.spec_from_file_location(module_name, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot import {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[module_name]
        raise
    return module


def _runner(path: Path) -> Callable[[], Callable[..., Result]]:
    def load() -> Callable[..., Result]:
        run: Callable[..., Result] = load_module(path).run
        return run

    return load


def components(bench_dir: Path = BENCH_DIR) -> dict[str, Path]:
    """The component benchmarks in ``bench_dir``: ``bench_<name>.py`` files except the pipeline's."""
    return {
        path.stem.removeprefix("bench_"): path
        for path in sorted(bench_dir.glob("bench_*.py"))
        if path.stem != PIPELINE_MODULE
    }


def select(names: Sequence[str], quick: bool, bench_dir: Path = BENCH_DIR) -> list[Benchmark]:
    """The benchmarks to run for ``names`` (see the module docstring), components first."""
    found = components(bench_dir)
    if names:
        chosen = [n for n in names if n in found]
        problems = [n for n in names if n not in found]
        for name in problems:
            try:
                resolve_problem_path(name)
            except ProblemError:
                raise OptlightError(
                    f"unknown benchmark {name!r}: expected a component ({', '.join(found) or 'none'}), "
                    f"a problem name ({', '.join(available_problems()) or 'none'}) or a problem file"
                ) from None
    else:
        chosen, problems = list(found), list(available_problems())
    sizes = QUICK_SIZES if quick else {}
    benchmarks = [
        Benchmark(name, _runner(found[name]), COMPONENT_ROWS.get(name, distribution_rows), sizes=dict(sizes))
        for name in chosen
    ]
    solve = _runner(bench_dir / f"{PIPELINE_MODULE}.py")
    repeats = QUICK_SIZES["repeats"] if quick else PIPELINE_REPEATS
    benchmarks += [
        Benchmark("solve", solve, solve_rows, (problem,), {"repeats": repeats}) for problem in problems
    ]
    benchmarks += [
        Benchmark("solve-flying", solve, solve_rows, (problem,), {"repeats": repeats, "capture": "flying"})
        for problem in problems
        if problem in FLYING_PROBLEMS
    ]
    return benchmarks


def run_one(benchmark: Benchmark) -> Outcome:
    """Run one benchmark; any exception it raises is caught and recorded as its failure."""
    kwargs: dict[str, Any] = {}
    start = time.perf_counter()
    try:
        run = benchmark.load()
        accepted = inspect.signature(run).parameters
        kwargs = {k: v for k, v in benchmark.sizes.items() if k in accepted}
        result = run(*benchmark.args, **kwargs)
        rows = benchmark.rows(benchmark.name, result)
    except Exception as e:
        return Outcome(
            _title(benchmark),
            kwargs,
            time.perf_counter() - start,
            error=f"{type(e).__name__}: {e}",
            traceback=traceback.format_exc(),
        )
    return Outcome(_title(benchmark), kwargs, time.perf_counter() - start, result, rows)


def _title(benchmark: Benchmark) -> str:
    return " ".join([benchmark.name, *(str(a) for a in benchmark.args)])


def run_all(benchmarks: Sequence[Benchmark], quick: bool, console: Console | None = None) -> Report:
    """Run ``benchmarks`` in order with a progress bar on ``console`` (stderr by default)."""
    machine = machine_info()
    timestamp = datetime.now(UTC).isoformat(timespec="seconds")
    outcomes = []
    columns = (
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
    )
    with Progress(*columns, console=console or Console(stderr=True)) as progress:
        task = progress.add_task("benchmarks", total=len(benchmarks))
        for benchmark in benchmarks:
            progress.update(task, description=_title(benchmark))
            outcome = run_one(benchmark)
            outcomes.append(outcome)
            if outcome.failed:
                progress.console.print(Text(f"failed: {outcome.name}: {outcome.error}", style="red"))
            progress.advance(task)
        progress.update(task, description="benchmarks")
    return Report(timestamp, quick, machine, outcomes)


# --------------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------------


def _number(x: float | None) -> str:
    return "–" if x is None or not math.isfinite(x) else f"{x:.4g}"


def _title_line(report: Report) -> str:
    mode = "quick" if report.quick else "full"
    return f"optlight benchmarks ({mode} run, {report.timestamp})"


def table(report: Report) -> Table:
    """The rows as a rich table, failed benchmarks at the end, the machine line as caption."""
    out = Table(title=_title_line(report), caption=machine_line(report.machine))
    for name in COLUMNS:
        out.add_column(name, justify="left" if name in ("benchmark", "metric") else "right", no_wrap=True)
    for row in report.rows:
        out.add_row(*(Text(cell) for cell in row.cells()))
    for outcome in report.failed:
        out.add_row(Text(outcome.name), Text("FAILED", style="bold red"), *[""] * (len(COLUMNS) - 2))
    return out


def markdown(report: Report, commit: bool = True) -> str:
    """The same table in markdown, preceded by the title and machine line (with the git commit when
    ``commit``), failures listed after it."""

    def line(cells: Sequence[str]) -> str:
        return "| " + " | ".join(cell.replace("|", "\\|") for cell in cells) + " |"

    lines = [
        f"**{_title_line(report)}**",
        "",
        f"Machine: {machine_line(report.machine, commit)}",
        "",
        line(COLUMNS),
        "|" + "|".join("---" if name in ("benchmark", "metric") else "---:" for name in COLUMNS) + "|",
        *(line(row.cells()) for row in report.rows),
    ]
    if report.notes:
        lines += ["", "Notes:", ""]
        lines += [f"- {note}" for note in report.notes]
    if report.failed:
        lines += ["", "Failed:", ""]
        lines += [f"- `{outcome.name}`: {outcome.error}" for outcome in report.failed]
    return "\n".join(lines) + "\n"


def _plain(value: Any) -> Any:
    """``value`` as JSON data: NumPy scalars and arrays, paths and dataclasses converted, non-finite
    floats as null; anything else that JSON cannot hold as its ``str``."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return _plain(value.item())
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if value is None or isinstance(value, str | int | bool):
        return value
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return _plain(dataclasses.asdict(value))
    return str(value)


def write(report: Report, out_dir: Path) -> tuple[Path, Path]:
    """Write ``latest.json`` and ``latest.md`` into ``out_dir``; returns their paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    json_path, md_path = out_dir / "latest.json", out_dir / "latest.md"
    json_path.write_text(json.dumps(_plain(report.to_dict()), indent=2, allow_nan=False) + "\n")
    md_path.write_text(markdown(report))
    return json_path, md_path


#: The README's text above the tables.
README_INTRO = """# Benchmarks

Generated by `python benchmarks/run.py --readme-only` from the latest results in `results/`; do not
edit by hand.

`optlight bench` (or `make bench`) runs every component benchmark (`bench_<name>.py`) and the whole
pipeline on every problem in `problems/`, prints one table and writes `results/latest.json` (machine,
library versions, every benchmark's full result) and `results/latest.md`. `optlight bench NAME --out
benchmarks/results/NAME` runs one benchmark on its own into a folder of `results/`. `--quick` runs
reduced sizes.

Columns: the median and 98th percentile of a metric over its repeats, the success rate, and the
*baseline* measured in the same run (the paper's sweep for the landmark search, pinocchio's CLIK for
the IK, the paper's per-knot IK pipeline for the solve, the unconstrained plan for the environment,
the design on the cap alone for the light sets, the open loop for the camera loop); ratio = median /
baseline median. A shared machine's speed drifts between runs: compare a time with its baseline,
measured beside it, rather than with another run's numbers.
"""


def _first_paragraph(path: Path) -> str:
    """The first paragraph of a module's docstring, on one line (the module is not imported)."""
    import ast

    doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
    text = " ".join(doc.split("\n\n")[0].split())
    return re.sub(r":\w+:`", "`", text).replace("``", "`")  # reST roles and literals as markdown code


def readme(results_dir: Path = RESULTS_DIR, bench_dir: Path = BENCH_DIR) -> str:
    """benchmarks/README.md from the latest results: the full run (``results_dir/latest.json``), then
    every sub-run (``results_dir/<name>/latest.json``), each with its date, its machine (without the
    commit) and its table; the benchmarks of each described by their module's first paragraph."""
    described = components(bench_dir)
    described.setdefault(PIPELINE_MODULE.removeprefix("bench_"), bench_dir / f"{PIPELINE_MODULE}.py")

    def section(heading: str, path: Path) -> list[str]:
        report = Report.from_dict(json.loads(path.read_text(encoding="utf-8")))
        names = sorted({o.name.split()[0] for o in report.outcomes})
        about = {n: _first_paragraph(described[n]) for n in names if described.get(n, Path()).is_file()}
        items = [f"- `{n}`: {text}" for n, text in about.items() if text]
        return [heading, "", *items, *([""] if items else []), markdown(report, commit=False)]

    parts = [README_INTRO]
    if (results_dir / "latest.json").is_file():
        parts += section("## Full run", results_dir / "latest.json")
    for path in sorted(results_dir.glob("*/latest.json")):
        parts += section(f"## `{path.parent.name}`", path)
    return "\n".join(parts)


def write_readme(results_dir: Path = RESULTS_DIR, path: Path = README) -> Path:
    """Render :func:`readme` from ``results_dir`` into ``path``; returns the path."""
    path.write_text(readme(results_dir))
    return path


def _in_results(out: Path) -> bool:
    """Whether ``out`` is :data:`RESULTS_DIR` or a folder in it (the results the README shows)."""
    out = out.resolve()
    return out == RESULTS_DIR or out.parent == RESULTS_DIR


def bench(
    names: Sequence[str] = (), quick: bool = False, out: Path | None = None, bench_dir: Path = BENCH_DIR
) -> int:
    """Select (from ``bench_dir``), run, print and write to ``out`` (default ``benchmarks/results``);
    returns the exit status, 1 if any benchmark failed."""
    benchmarks = select(names, quick, bench_dir)
    report = run_all(benchmarks, quick)
    printed = table(report)
    console = Console()
    # At its natural width even where the terminal (or a CI log's default of 80 columns) is narrower:
    # numbers and metric names cut short with an ellipsis would be worse than long lines.
    unbounded = console.options.update_width(sys.maxsize)
    console.width = max(console.width, Measurement.get(console, unbounded, printed).maximum)
    console.print(printed)
    for note in report.notes:
        console.print(Text(f"note: {note}"))
    out_dir = out if out is not None else RESULTS_DIR
    json_path, md_path = write(report, out_dir)
    console.print(Text(f"wrote {json_path} and {md_path}"))
    if _in_results(out_dir):
        console.print(Text(f"wrote {write_readme()}"))
    if report.failed:
        errors = Console(stderr=True)
        for outcome in report.failed:
            errors.print(Text(f"FAILED {outcome.name}: {outcome.error}", style="red"))
        return 1
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python benchmarks/run.py``: returns the exit status (2 for an unknown NAME)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "names",
        nargs="*",
        metavar="NAME",
        help="component benchmark (e.g. scene, timing, landmarks) or problem name/file; default: all",
    )
    parser.add_argument("--quick", action="store_true", help="reduced sizes and one solve per problem (CI)")
    parser.add_argument("--out", type=Path, help=f"output folder (default {RESULTS_DIR})")
    parser.add_argument(
        "--readme-only", action="store_true", help=f"render {README} from the latest results, run nothing"
    )
    args = parser.parse_args(argv)
    if args.readme_only:
        print(f"wrote {write_readme()}")
        return 0
    try:
        return bench(args.names, args.quick, args.out)
    except OptlightError as e:
        print(f"run.py: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
