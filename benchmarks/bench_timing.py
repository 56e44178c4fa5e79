"""Timing benchmark: TOPPRA on a 7-DOF path through 37 landmarks (36 segments × 10 waypoints).

    python benchmarks/bench_timing.py [--json PATH] [--repeats N]

The path imitates what the trajectory NLP produces: the landmarks lie on a closed loop in joint space
(q = q_c + A cos φ + B sin φ, φ = 2πi/36, the light going round the sphere once), each segment samples
the loop between two landmarks at 10 waypoints, with a small seeded ripple so that the spline is not
trivially smooth. Limits: Franka Panda's joint velocity and acceleration limits (datasheet). Reported:
wall time of :func:`time_parameterize` (median, p98 over repeats), of sampling the result at 1 kHz,
the trajectory's duration, and the largest |q̇_j|/v_max,j and |q̈_j|/a_max,j found by resampling
densely (every TOPPRA interval sampled many times), not read from TOPPRA's output.
:func:`run` returns the same numbers as a dict for a benchmark runner.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import os
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np

from optlight.export import write_json
from optlight.planning.timing import Trajectory, time_parameterize

VELOCITY_LIMIT = np.array([2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61])  # rad/s
ACCELERATION_LIMIT = np.array([15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0])  # rad/s²
SEGMENTS = 36
WAYPOINTS = 10
DWELL_S = 0.5


def benchmark_path(seed: int = 0) -> list[np.ndarray]:
    """36 segments of 10 waypoints (rad) on a rippled closed loop in the joint space of a 7-DOF arm."""
    rng = np.random.default_rng(seed)
    center = np.array([0.0, -0.3, 0.0, -2.0, 0.0, 1.9, 0.8])
    a, b = rng.uniform(-0.6, 0.6, 7), rng.uniform(-0.6, 0.6, 7)
    segments = []
    for i in range(SEGMENTS):
        phi = 2 * np.pi * (i + np.linspace(0.0, 1.0, WAYPOINTS)) / SEGMENTS
        q = center + np.outer(np.cos(phi), a) + np.outer(np.sin(phi), b)
        ripple = np.sin(np.pi * np.linspace(0.0, 1.0, WAYPOINTS))[:, None] * rng.normal(0.0, 0.03, 7)
        segments.append(q + ripple)
    return segments


def dense_ratios(traj: Trajectory, rate_hz: float) -> tuple[float, float, int]:
    """Largest |q̇_j|/v_max,j and |q̈_j|/a_max,j over samples at ``rate_hz`` plus the boundaries."""
    t = traj.sample_times(rate_hz)
    _, qd, qdd = traj.sample(t)
    return (
        float(np.max(np.abs(qd) / VELOCITY_LIMIT)),
        float(np.max(np.abs(qdd) / ACCELERATION_LIMIT)),
        int(t.size),
    )


def _stats(seconds: list[float]) -> dict[str, float]:
    ms = 1e3 * np.asarray(seconds)
    return {"median_ms": float(np.median(ms)), "p98_ms": float(np.percentile(ms, 98)), "repeats": len(ms)}


def run(repeats: int = 15) -> dict[str, Any]:
    """Time the benchmark path; returns {"toppra": {...}, "sample_1khz": {...}, "limits": {...}, "meta": {...}}."""
    segments = benchmark_path()
    time_parameterize(segments, VELOCITY_LIMIT, ACCELERATION_LIMIT, DWELL_S)  # warm-up
    toppra_s, sample_s = [], []
    traj = None
    for _ in range(repeats):
        start = time.perf_counter()
        traj = time_parameterize(segments, VELOCITY_LIMIT, ACCELERATION_LIMIT, DWELL_S)
        toppra_s.append(time.perf_counter() - start)
        t = traj.sample_times(1000.0)
        start = time.perf_counter()
        traj.sample(t)
        sample_s.append(time.perf_counter() - start)
    assert traj is not None
    # 20 kHz: the TOPPRA intervals last ~1.3 ms (median) here, so each is sampled ~25 times
    v_ratio, a_ratio, samples = dense_ratios(traj, 20_000.0)
    motion = float(np.sum(np.diff(traj.segment_times, axis=1)))
    return {
        "toppra": {**_stats(toppra_s), "per_segment_ms": float(np.median(toppra_s)) * 1e3 / SEGMENTS},
        "sample_1khz": {**_stats(sample_s), "samples": int(traj.sample_times(1000.0).size)},
        "limits": {
            "max_velocity_ratio": v_ratio,
            "max_acceleration_ratio": a_ratio,
            "dense_samples": samples,
            "verification_tolerance": 1e-3,
        },
        "trajectory": {
            "duration_s": traj.duration,
            "motion_s": motion,
            "dwell_s": DWELL_S,
            "landmarks": SEGMENTS + 1,
        },
        "meta": {
            "segments": SEGMENTS,
            "waypoints_per_segment": WAYPOINTS,
            "dof": 7,
            "python": platform.python_version(),
            "machine": platform.machine(),
            "cpus": os.cpu_count(),
            "toppra": importlib.metadata.version("toppra"),
            "numpy": importlib.metadata.version("numpy"),
        },
    }


def _print(results: dict[str, Any]) -> None:
    lim, tr, meta = results["limits"], results["trajectory"], results["meta"]
    caption = (
        f"{meta['dof']}-DOF, {meta['segments']} segments × {meta['waypoints_per_segment']} waypoints; "
        f"trajectory {tr['duration_s']:.2f} s ({tr['motion_s']:.2f} s moving); toppra {meta['toppra']}"
    )
    rows = [
        ("time_parameterize (36 segments)", results["toppra"]),
        ("sample at 1 kHz", results["sample_1khz"]),
    ]
    limit_rows = [
        ("max |q̇|/v_max (dense)", lim["max_velocity_ratio"]),
        ("max |q̈|/a_max (dense)", lim["max_acceleration_ratio"]),
    ]
    try:
        from rich.console import Console
        from rich.table import Table
    except ImportError:
        print(caption)
        for name, r in rows:
            print(f"{name:34s} {r['median_ms']:9.2f} ms {r['p98_ms']:9.2f} ms")
        for name, v in limit_rows:
            print(f"{name:34s} {v:.6f}")
        return
    table = Table(title="optlight timing (TOPPRA)", caption=caption)
    for col in ("operation", "median ms", "p98 ms", "repeats"):
        table.add_column(col, justify="left" if col == "operation" else "right")
    for name, r in rows:
        table.add_row(name, f"{r['median_ms']:.2f}", f"{r['p98_ms']:.2f}", str(r["repeats"]))
    limits = Table(title=f"limits by dense resampling ({lim['dense_samples']} samples)")
    limits.add_column("quantity")
    limits.add_column("value", justify="right")
    limits.add_column("verification allows", justify="right")
    for name, v in limit_rows:
        limits.add_row(name, f"{v:.6f}", f"≤ {1 + lim['verification_tolerance']:g}")
    console = Console()
    console.print(table)
    console.print(limits)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", type=Path, help="write the results to this file")
    parser.add_argument("--repeats", type=int, default=15, help="repetitions of the timing")
    args = parser.parse_args()
    results = run(args.repeats)
    _print(results)
    if args.json:
        write_json(args.json, results)


if __name__ == "__main__":
    main()
