"""Random sensible cells through the whole pipeline: how many plan and verify, how many are refused, why.

Each cell (:func:`optlight.random_cell`, seeds 0 … n − 1: a robot, an object, a camera
placement, a cap, a light-sphere radius, a task, with or without a table, a wall and the camera's
stand) is solved by the public :func:`optlight.solve` in a process of its own with a time limit
(``timeout_s``; a cell that takes longer is counted as ``timeout``), so that a hang or a crash of
one cell cannot stall the run. Each cell ends as one of:

- ``verified``: the plan passed its own verification;
- ``failed_verification``: a plan was made and failed its verification (the failing checks listed);
- ``refused``: an :class:`~optlight.errors.OptlightError`, by reason (its class and a short key:
  the problem-file key of a :class:`~optlight.errors.ProblemError`, else the message's words);
- ``crashed``: any other exception (its traceback kept) or a process that died;
- ``timeout``.

Reported: the counts overall and per robot, object, task and environment; solve times (median,
p98) of the verified cells; every refused, failed and crashed cell with its seed and message; and for
the light-set cells, the lights requested (``[lightset] count``, or the grid's directions) against
those the plan captures (a refused cell captures none), per set kind and over all.

    python benchmarks/bench_cells.py [--cells 100] [--timeout 900] [--seed0 0] [--jobs N] [--out FILE]
    optlight bench cells [--quick] --out benchmarks/results/cells     (--quick: 12 cells)
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
import traceback
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

#: Outcomes a cell can end in.
OUTCOMES = ("verified", "failed_verification", "refused", "crashed", "timeout")
#: Labels of :class:`optlight.random_cells.RandomCell` the results are grouped by.
CATEGORIES = ("robot", "object", "task", "environment")
#: A list index in a key path (``environment.boxes[0]``): left out of the reason.
_INDEX = re.compile(r"\[\d+\]")


def reason_key(error: BaseException) -> str:
    """A short key of why a cell was refused: ``Class:key`` of a ProblemError (the key it names),
    else ``Class:`` and the first words of the message, numbers and names in quotes left out."""
    name = type(error).__name__
    key = getattr(error, "key", None)
    if key:
        return f"{name}:{_INDEX.sub('[]', str(key))}"
    return f"{name}:{first_words(str(error))}"


def first_words(message: str) -> str:
    """The first six words of a message's first clause, quoted names and free-standing numbers
    left out (a robot's name such as ``ur5`` kept)."""
    words = re.sub(r"'[^']*'|\"[^\"]*\"|(?<![A-Za-z])[-+]?\d[\d.]*", "", message.split(":")[0]).split()
    return " ".join(words[:6])


def solve_one(seed: int, folder: str) -> dict[str, Any]:
    """Solve the cell of ``seed`` here and describe the outcome (JSON-safe)."""
    import warnings

    import optlight

    cell = optlight.random_cell(seed, folder)
    out: dict[str, Any] = {"seed": seed, "name": cell.name, "labels": cell.labels}
    lightset = cell.data.get("lightset")
    if lightset is not None:
        out["lights_requested"] = len(lightset["grid_deg"]) if lightset["kind"] == "grid" else lightset["count"]
        out["lights_achieved"] = 0
    start = time.perf_counter()
    try:
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            plan = optlight.solve(cell.problem)
        report = plan.verification
        out["warnings"] = [str(w.message) for w in said if not issubclass(w.category, DeprecationWarning)][:20]
        if report.passed:
            out["outcome"] = "verified"
        else:
            out["outcome"] = "failed_verification"
            out["failed_checks"] = {
                k: {"max": c.max_value, "samples": c.failing_samples}
                for k, c in report.checks.items()
                if not c.passed and k not in report.advisory
            }
            out["violations"] = [str(v) for v in report.violations[:5]]
        out["captures"] = len(plan.visited)
        if lightset is not None:
            out["lights_achieved"] = len(plan.visited) if report.passed else 0
    except optlight.OptlightError as e:
        out["outcome"] = "refused"
        out["reason"] = reason_key(e)
        out["message"] = str(e)
    except Exception as e:
        out["outcome"] = "crashed"
        out["message"] = f"{type(e).__name__}: {e}"
        out["traceback"] = traceback.format_exc()
    out["time_s"] = time.perf_counter() - start
    return out


def run_cell(seed: int, folder: str, timeout_s: float) -> dict[str, Any]:
    """:func:`solve_one` in a fresh process (``nice``d), killed after ``timeout_s``."""
    command = ["nice", "-n", "5", sys.executable, __file__, "--one", str(seed), "--folder", folder]
    start = time.perf_counter()
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return {"seed": seed, "outcome": "timeout", "time_s": time.perf_counter() - start}
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if done.returncode != 0 or not lines:
        return {
            "seed": seed,
            "outcome": "crashed",
            "message": f"process exited with status {done.returncode}",
            "traceback": done.stderr[-4000:],
            "time_s": time.perf_counter() - start,
        }
    result: dict[str, Any] = json.loads(lines[-1])
    return result


def _dist(values: list[float]) -> dict[str, float]:
    if not values:
        return {}
    v = np.asarray(values, float)
    return {"median": float(np.median(v)), "p98": float(np.percentile(v, 98))}


def summarize(cells: list[dict[str, Any]]) -> dict[str, Any]:
    """Counts overall and per category, refusal reasons, times, and the cells that did not verify."""
    counts = Counter(c["outcome"] for c in cells)
    per: dict[str, dict[str, dict[str, int]]] = {}
    for category in CATEGORIES:
        table: dict[str, dict[str, int]] = {}
        for c in cells:
            label = c.get("labels", {}).get(category, "?")
            table.setdefault(label, dict.fromkeys(OUTCOMES, 0))[c["outcome"]] += 1
        per[category] = dict(sorted(table.items()))
    n = max(1, len(cells))
    return {
        "cells": len(cells),
        "counts": {k: counts.get(k, 0) for k in OUTCOMES},
        "verified_pct": 100.0 * counts.get("verified", 0) / n,
        "refused_by_reason": dict(Counter(c["reason"] for c in cells if c["outcome"] == "refused").most_common()),
        "per_category": per,
        "lights": lights_delivered(cells),
        "solve_s": _dist([c["time_s"] for c in cells if c["outcome"] == "verified"]),
        "all_s": _dist([c["time_s"] for c in cells]),
        "not_verified": [
            {k: c.get(k) for k in ("seed", "name", "outcome", "reason", "message", "failed_checks", "violations")}
            for c in cells
            if c["outcome"] != "verified"
        ],
        "crash_tracebacks": {str(c["seed"]): c.get("traceback", "") for c in cells if c["outcome"] == "crashed"},
    }


def lights_delivered(cells: list[dict[str, Any]]) -> dict[str, dict[str, float]]:
    """Per light-set kind and ``all``: the cells, the lights requested and achieved (a verified plan's
    captures; none for a cell that did not verify) and achieved/requested in %."""
    out: dict[str, dict[str, float]] = {}
    for c in cells:
        if "lights_requested" not in c:
            continue
        for kind in (c.get("labels", {}).get("task", "?"), "all"):
            row = out.setdefault(kind, {"cells": 0, "requested": 0, "achieved": 0})
            row["cells"] += 1
            row["requested"] += c["lights_requested"]
            row["achieved"] += c["lights_achieved"]
    for row in out.values():
        row["achieved_pct"] = 100.0 * row["achieved"] / max(1, row["requested"])
    return dict(sorted(out.items()))


def run(cells: int = 100, seed0: int = 0, timeout_s: float = 900.0, jobs: int | None = None) -> dict[str, Any]:
    """Cells ``seed0`` … ``seed0 + cells − 1``, one process each, ``jobs`` at a time (default: one per
    core); the summary (:func:`summarize`) with the outcome of every cell under ``cells``."""
    jobs = jobs or os.cpu_count() or 1
    with tempfile.TemporaryDirectory(prefix="optlight_cells_") as folder, ThreadPoolExecutor(jobs) as pool:
        futures = [pool.submit(run_cell, seed, folder, timeout_s) for seed in range(seed0, seed0 + cells)]
        done = []
        for future in futures:
            done.append(future.result())
            print(json.dumps({k: done[-1].get(k) for k in ("seed", "name", "outcome", "reason", "time_s")}),
                  file=sys.stderr, flush=True)
    out = summarize(done)
    out["cells_detail"] = [{k: v for k, v in c.items() if k != "traceback"} for c in done]
    out["verified_pct"] = {"median": out["verified_pct"], "p98": out["verified_pct"]}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=100)
    parser.add_argument("--seed0", type=int, default=0)
    parser.add_argument("--timeout", type=float, default=900.0)
    parser.add_argument("--jobs", type=int, help="cells solved at a time (default: one per core)")
    parser.add_argument("--one", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--folder", help=argparse.SUPPRESS)
    parser.add_argument("--out", help="write the result as JSON here")
    args = parser.parse_args()
    if args.one is not None:
        print(json.dumps(solve_one(args.one, args.folder or tempfile.gettempdir()), default=str))
        return
    result = run(args.cells, args.seed0, args.timeout, args.jobs)
    text = json.dumps(result, indent=1, default=str)
    if args.out:
        Path(args.out).write_text(text + "\n")
    else:
        print(text)


if __name__ == "__main__":
    main()
