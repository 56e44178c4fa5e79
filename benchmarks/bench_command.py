"""The whole command a user runs: ``optlight solve default --out DIR``, wall time and what it writes.

    python benchmarks/bench_command.py [--repeats N] [--json PATH]

Each repeat runs the command in a fresh interpreter (imports included) into a new temporary folder
and times it from start to exit. Reported: the wall time (s, median / p98), the solve's own time
(the pipeline's ``total`` from ``plan.json``) and so the time spent outside it (imports, the problem
check, writing the results), the size of ``preview.html`` and of the whole folder (bytes).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from optlight.export import write_json

#: Repeats of the command in a full run.
REPEATS = 3


def _dist(values: list[float]) -> dict[str, float]:
    return {"median": float(np.median(values)), "p98": float(np.percentile(values, 98))}


def run_once(problem: str = "default") -> dict[str, float]:
    """One ``optlight solve PROBLEM --out DIR`` in a fresh interpreter; its times (s) and sizes (bytes)."""
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "out"
        start = time.perf_counter()
        subprocess.run(
            [sys.executable, "-m", "optlight.cli", "solve", problem, "--out", str(out)],
            check=True,
            capture_output=True,
        )
        wall = time.perf_counter() - start
        solve = json.loads((out / "plan.json").read_text())["summary"]["timings_s"]["total"]
        return {
            "wall_s": wall,
            "solve_s": float(solve),
            "outside_solve_s": wall - float(solve),
            "preview_bytes": float((out / "preview.html").stat().st_size),
            "folder_bytes": float(sum(p.stat().st_size for p in out.iterdir())),
        }


def run(repeats: int = REPEATS, problem: str = "default") -> dict[str, Any]:
    """``repeats`` runs of the command; the machine-readable results."""
    runs = [run_once(problem) for _ in range(repeats)]
    return {
        "benchmark": "command",
        "problem": problem,
        "repeats": repeats,
        **{key: _dist([r[key] for r in runs]) for key in runs[0]},
        "runs": runs,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=REPEATS)
    parser.add_argument("--json", type=Path, help="write the results here as JSON")
    args = parser.parse_args()
    result = run(args.repeats)
    for key, value in result.items():
        if isinstance(value, dict):
            print(f"{key}: median {value['median']:.4g}, p98 {value['p98']:.4g}")
    if args.json:
        write_json(args.json, result)


if __name__ == "__main__":
    main()
