"""Batch benchmark: many plans on the Dask engine, and the cell search's throughput.

    python benchmarks/bench_batch.py [--plans N] [--repeats N] [--json PATH]

Batch: ``plans`` small problems (the default problem with a 48² camera and 3 landmarks, the robot's
base moved 0–7 cm along x), each ``optlight.solve`` + ``plan.save`` (no preview), run by
:func:`optlight.run_batch` into a fresh folder: serially in this process (the baseline, same run), on
a local cluster of 1 worker and of 2 workers (this machine's cores), each started by the batch
("cold": the cluster's start and the workers' imports of optlight, CasADi and pinocchio included, as
a user of ``optlight batch`` sees them) and started and warmed before the clock starts (the
steady state of a long batch, or of several batches on one cluster through ``client=``). Reported:
wall time per configuration (median, p98 over ``repeats``), the speed-ups of 2 workers over 1 (warm
and cold) and over the serial run, the time of one row on a worker, Dask's own per-task overhead
here (the wall time of 400 empty tasks on a warm 2-worker cluster, per task), and the 1-minute load
average before and after (the machine is shared: other processes take cores from the workers).

Cell: :func:`optlight.design_cell` on a 6 × 6 grid of base placements (x, y ∈ [−0.15, 0.15] m)
scored against 6 lights, serially (baseline) and on 2 workers warmed by scoring one placement each:
placements scored per minute of the scoring's wall time (the final full solve excluded).

Per-plan cost at full size: one row of the default problem itself (256² camera, 36 landmarks,
no preview) solved and saved serially, for the README's projection to a cluster.
:func:`run` returns the numbers as a dict for the benchmark runner.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from optlight.batch import run_batch, solve_row
from optlight.cell import design_cell, evaluate_placement, load_cell_spec, problem_toml
from optlight.engine import dask_client
from optlight.spec import load_problem, problem_from_dict

if TYPE_CHECKING:
    from distributed import Client

#: Empty tasks timed for Dask's per-task overhead.
OVERHEAD_TASKS = 400
#: Batch configurations: serial (the baseline); local clusters started by the batch ("cold": start-up
#: and the workers' imports included); clusters started and warmed before the clock starts.
CONFIGS = ("serial", "1 worker, cold", "2 workers, cold", "1 worker", "2 workers")


def _dist(values: list[float]) -> dict[str, float]:
    return {"median": float(np.median(values)), "p98": float(np.percentile(values, 98))}


def _write_inputs(folder: Path, plans: int) -> tuple[Path, Path]:
    """The small base problem, a batch spec of ``plans`` base placements and a 6 × 6 cell spec."""
    data = load_problem("default").to_dict()
    data["camera"].update(width=48, height=48)
    data["landmarks"]["count"] = 3
    base = problem_from_dict(data)
    (folder / "small.toml").write_text(problem_toml(base))
    placements = [[round(0.01 * i, 3), 0.0, 0.0] for i in range(plans)]
    batch = folder / "batch.toml"
    batch.write_text(f'problem = "small.toml"\n[grid]\n"robot.base_position_m" = {json.dumps(placements)}\n')
    lights = [[40.0, 60.0 * k] for k in range(6)]
    cell = folder / "cell.toml"
    cell.write_text(
        f'problem = "small.toml"\nlights = {json.dumps(lights)}\nsteps = 6\ntop = 1\n'
        "[search]\nbase_x_m = [-0.15, 0.15]\nbase_y_m = [-0.15, 0.15]\n"
    )
    return batch, cell


def dask_overhead_ms(workers: int, tasks: int) -> float:
    """Wall time per empty task (ms) submitted to a warm local cluster of ``workers`` processes."""
    with dask_client(workers=workers) as client:
        # abs: a builtin, so the workers unpickle it by name
        client.gather(client.map(abs, range(workers * 4)))  # warm
        start = time.perf_counter()
        client.gather(client.map(abs, range(workers * 4, workers * 4 + tasks)))
        return 1e3 * (time.perf_counter() - start) / tasks


def _warm(client: Client) -> None:
    """Import optlight's planning modules on every worker (a cold worker spends seconds on it)."""
    client.run(importlib.import_module, "optlight.cell")


def _batch_walls(
    batch: Path, folder: Path, repeats: int
) -> tuple[dict[str, list[float]], list[float], list[float]]:
    """Wall times of the batch per configuration, the rows' times on workers, success % per run."""
    walls: dict[str, list[float]] = {k: [] for k in CONFIGS}
    row_s: list[float] = []
    ok: list[float] = []
    for r in range(repeats):
        for label in CONFIGS:
            out = folder / f"out-{label}-{r}"
            workers = int(label[0]) if label[0].isdigit() else 0
            if label == "serial":
                result = run_batch(batch, out, serial=True, progress=False)
            elif label.endswith("cold"):
                result = run_batch(batch, out, workers=workers, progress=False)
            else:
                with dask_client(workers=workers) as client:
                    _warm(client)
                    result = run_batch(batch, out, client=client, shared_out=True, progress=False)
            walls[label].append(result.elapsed_s)
            ok.append(100.0 * result.ok / len(result.records))
            if label != "serial":
                row_s += [rec.solve_s for rec in result.records]
    return walls, row_s, ok


def run(plans: int = 8, repeats: int = 1) -> dict[str, Any]:
    """The batch serially, on 1 and 2 workers (cold and warm), the cell search serially and on 2 warm
    workers, Dask's per-task overhead and one full-size default plan; see the module docstring."""
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="optlight-bench-batch-") as tmp:
        folder = Path(tmp)
        batch, cell = _write_inputs(folder, plans)
        walls, row_s, ok = _batch_walls(batch, folder, repeats)
        cells = {}
        for label in ("serial", "2 workers"):
            if label == "serial":
                found = design_cell(cell, folder / "cell-serial", serial=True, progress=False)
            else:
                with dask_client(workers=2) as client:
                    _warm(client)
                    spec = load_cell_spec(cell)
                    lights = np.asarray(spec.lights)
                    client.run(evaluate_placement, spec.base, lights)  # each worker's first placement
                    found = design_cell(cell, folder / "cell-2", client=client, progress=False)
            cells[label] = {
                "placements": len(found.candidates),
                "search_s": found.search_s,
                "placements_per_min": found.throughput_per_min,
                "best": dict(found.best.values),
            }
        full = solve_row(load_problem("default"))
    median = {k: float(np.median(v)) for k, v in walls.items()}
    return {
        "plans": plans,
        "repeats": repeats,
        "cores": os.cpu_count(),
        "load_average_1min": {"before": load_before, "after": os.getloadavg()[0]},
        "batch_wall_s": {k: {**_dist(v), "success_pct": float(np.mean(ok))} for k, v in walls.items()},
        "speedup_2_over_1_workers_warm": median["1 worker"] / median["2 workers"],
        "speedup_2_over_1_workers_cold": median["1 worker, cold"] / median["2 workers, cold"],
        "speedup_2_workers_over_serial": median["serial"] / median["2 workers"],
        "row_on_worker_s": _dist(row_s),
        "dask_overhead_per_task_ms": dask_overhead_ms(2, OVERHEAD_TASKS),
        "cell": cells,
        "default_plan_s": full["solve_s"],
        "default_plan_status": full["status"],
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--plans", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--json", type=Path, help="write the result here")
    args = parser.parse_args(argv)
    result = run(args.plans, args.repeats)
    text = json.dumps(result, indent=2)
    print(text)
    if args.json:
        args.json.write_text(text + "\n")


if __name__ == "__main__":
    main()
