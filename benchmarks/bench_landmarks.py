"""Landmark search against the paper's fine sweep, in the same run.

Ours: :func:`optlight.planning.landmarks.find_landmarks` (coarse sweep at the search resolution,
a bounded 1-D search from the best seeds, a parabolic polish at the camera's resolution), on
:data:`PROBLEMS`: the default face, whose landmarks all lie on the camera's view boundary (its 10°
reference is inside the view), and the UR5 face, whose landmarks are refined inside the cap. Baseline:
:func:`baselines.paper_sweep`, the zenith swept in 0.5° steps along each azimuth at the camera's
resolution with shadow rays at every sample, over the same lights as ours (the cap less the
lights whose housing would enter the camera's view, ``Setup.sphere``). Both costs per azimuth are
evaluated by the same function (:func:`optlight.planning.landmarks.exact_cost`, camera resolution, shadow rays), so equal
zeniths give bit-identical costs.

Reported per problem: the worst per-azimuth cost ratio ours/sweep (azimuths where the sweep reaches
0 are checked as ours ≤ 1e-15 instead), total times and their ratio, per-azimuth time and objective
evaluations of the refinement (median, p98), hardware and versions.

    python benchmarks/bench_landmarks.py [--problem NAME] [--json PATH]
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

import casadi
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from baselines import paper_sweep  # noqa: E402

from optlight.export import write_json  # noqa: E402
from optlight.planning.landmarks import exact_cost, find_landmarks  # noqa: E402
from optlight.setup import Setup
from optlight.spec import load_problem  # noqa: E402

#: Costs at or below this count as zero (the reference light reproduced exactly).
ZERO_COST = 1e-15
SWEEP_STEP_DEG = 0.5
PROBLEMS = ("default", "face_ur5")


def _dist(values: np.ndarray) -> dict[str, float]:
    return {"median": float(np.median(values)), "p98": float(np.percentile(values, 98))}


def run(problems: tuple[str, ...] = PROBLEMS) -> dict[str, Any]:
    """Both searches on each of ``problems``; the machine-readable results (angles in degrees)."""
    return {
        "benchmark": "landmarks",
        "problems": {name: run_problem(name) for name in problems},
        "environment": {
            "python": platform.python_version(),
            "numpy": np.__version__,
            "casadi": casadi.__version__,
            "machine": platform.machine(),
            "processor": platform.processor() or platform.machine(),
            "cpus": os.cpu_count(),
        },
    }


def run_problem(problem: str) -> dict[str, Any]:
    """Both searches on ``problem``; its machine-readable results (angles in degrees)."""
    spec = load_problem(problem)
    setup = Setup.from_problem(spec)
    scene, objective = setup.scene, setup.objective

    t0 = time.perf_counter()
    ours = find_landmarks(setup.workcell, setup.image_costs, setup.landmark_spec, setup.solver, setup.file)
    ours_time = time.perf_counter() - t0

    t0 = time.perf_counter()
    sweep = paper_sweep(spec, scene, SWEEP_STEP_DEG, objective, sphere=setup.sphere)
    sweep_time = time.perf_counter() - t0

    rows = []
    for lm, zenith, azimuth, t_sweep in zip(
        ours.landmarks, sweep.zenith, sweep.azimuth, sweep.time_s, strict=True
    ):
        sweep_cost = exact_cost(scene, objective, scene.sphere.position(zenith, azimuth))
        rows.append(
            {
                "azimuth_deg": math.degrees(lm.azimuth),
                "zenith_deg": math.degrees(lm.zenith),
                "cost": lm.cost,
                "status": lm.status,
                "iterations": lm.iterations,
                "time_s": lm.time_s,
                "sweep_zenith_deg": math.degrees(zenith),
                "sweep_cost": sweep_cost,
                "sweep_time_s": float(t_sweep),
                "ratio": lm.cost / sweep_cost if sweep_cost > ZERO_COST else None,
                "not_worse": bool(
                    lm.cost <= sweep_cost or (sweep_cost <= ZERO_COST and lm.cost <= ZERO_COST)
                ),
            }
        )
    ratios = [r["ratio"] for r in rows if r["ratio"] is not None]
    times = np.array([r["time_s"] for r in rows])
    iterations = np.array([r["iterations"] for r in rows])
    return {
        "problem": spec.name,
        "landmarks": len(ours),
        "camera_px": [scene.camera.width, scene.camera.height],
        "search_px": list(ours.resolution),
        "sweep_step_deg": SWEEP_STEP_DEG,
        "coarse_step_deg": spec.landmarks.sweep_step_deg,
        "seeds": spec.landmarks.seeds,
        "worst_ratio": max(ratios) if ratios else None,
        "not_worse_everywhere": all(r["not_worse"] for r in rows),
        "time_s": {"ours": ours_time, "sweep": sweep_time, "ratio": ours_time / sweep_time},
        "time_per_azimuth_s": {"ours": _dist(times), "sweep": _dist(sweep.time_s)},
        "evaluations_per_azimuth": _dist(iterations),
        "status_counts": {s: sum(r["status"] == s for r in rows) for s in ("refined", "polished", "sweep")},
        "per_azimuth": rows,
    }


def print_table(result: dict[str, Any]) -> None:
    """The per-azimuth table and the summary of one problem's result, plain text."""
    print(
        f"landmarks: {result['problem']}, {result['landmarks']} azimuths, camera "
        f"{result['camera_px'][0]}×{result['camera_px'][1]} px, search {result['search_px'][0]}×"
        f"{result['search_px'][1]} px, coarse step {result['coarse_step_deg']:g}°, sweep step "
        f"{result['sweep_step_deg']:g}°"
    )
    print(
        f"{'azim°':>6} {'zenith°':>8} {'cost':>11} {'status':>9} {'it':>4} {'ms':>7} | "
        f"{'sweep°':>7} {'sweep cost':>11} {'ms':>7} | {'ratio':>9}"
    )
    for r in result["per_azimuth"]:
        ratio = "0 = 0" if r["ratio"] is None else f"{r['ratio']:.6f}"
        print(
            f"{r['azimuth_deg']:6.1f} {r['zenith_deg']:8.3f} {r['cost']:11.4e} {r['status']:>9} "
            f"{r['iterations']:4d} {1e3 * r['time_s']:7.1f} | {r['sweep_zenith_deg']:7.2f} "
            f"{r['sweep_cost']:11.4e} {1e3 * r['sweep_time_s']:7.1f} | {ratio:>9}"
        )
    t, pa, it = result["time_s"], result["time_per_azimuth_s"], result["evaluations_per_azimuth"]
    print(
        f"worst cost ratio ours/sweep: {result['worst_ratio']:.6f}; not worse at every azimuth: "
        f"{result['not_worse_everywhere']}"
    )
    print(
        f"total time: ours {t['ours']:.2f} s, sweep {t['sweep']:.2f} s, ratio {t['ratio']:.3f} (1/{1 / t['ratio']:.1f})"
    )
    print(
        f"per azimuth: ours median {1e3 * pa['ours']['median']:.1f} ms, p98 {1e3 * pa['ours']['p98']:.1f} ms; "
        f"sweep median {1e3 * pa['sweep']['median']:.1f} ms, p98 {1e3 * pa['sweep']['p98']:.1f} ms"
    )
    print(
        f"refinement evaluations per azimuth: median {it['median']:.0f}, p98 {it['p98']:.0f}; "
        f"winners {result['status_counts']}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--problem", action="append", help="built-in problem name or path (repeatable)")
    parser.add_argument("--json", type=Path, help="write the results here as JSON")
    args = parser.parse_args()
    result = run(tuple(args.problem) if args.problem else PROBLEMS)
    for problem in result["problems"].values():
        print_table(problem)
    if args.json:
        write_json(args.json, result)


if __name__ == "__main__":
    main()
