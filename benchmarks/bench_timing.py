"""Timing benchmark: TOPPRA and jerk-limited timing, on a synthetic 7-DOF path and on the default problem.

    python benchmarks/bench_timing.py [--json PATH] [--repeats N]

Synthetic path: what the trajectory NLP produces, imitated: the landmarks lie on a closed loop in joint
space (q = q_c + A cos φ + B sin φ, φ = 2πi/36, the light going round the sphere once), each segment
samples the loop between two landmarks at 10 waypoints, with a small seeded ripple so that the spline
is not trivially smooth. Limits: Franka Panda's joint velocity, acceleration and jerk limits
(datasheet). Reported: wall time of :func:`time_parameterize` (TOPPRA) and of
:func:`jerk_limited_timing` (median, p98 over repeats), of sampling the result at 1 kHz, the motion
time of each, and the largest |q̇_j|/v_max,j, |q̈_j|/a_max,j (and |q⃛_j|/j_max,j, the largest jump of
q̈ between 1 kHz samples over j_max/1 kHz for the jerk-limited one) found by resampling densely, not
read from either timing's own data.

Default problem: the segments of ``optlight.solve("default")`` (its trajectory NLP's knots) timed both
ways with the panda's limits: motion time jerk-limited vs TOPPRA-only, and the cost of each.
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
from optlight.motion import Trajectory
from optlight.planning.jerk import jerk_limited_timing
from optlight.planning.timing import time_parameterize

VELOCITY_LIMIT = np.array([2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61])  # rad/s
ACCELERATION_LIMIT = np.array([15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0])  # rad/s²
JERK_LIMIT = np.full(7, 7500.0)  # rad/s³
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


def _motion(traj: Trajectory) -> float:
    return float(np.sum(np.diff(traj.segment_times, axis=1)))


def _timed(fn: Any, repeats: int) -> tuple[Trajectory, list[float]]:
    fn()  # warm-up
    seconds, traj = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        traj = fn()
        seconds.append(time.perf_counter() - start)
    assert traj is not None
    return traj, seconds


def jerk_ratios(traj: Trajectory, rate_hz: float, jerk_limit: np.ndarray) -> tuple[float, float]:
    """Largest |q⃛_j|/j_max,j over samples at ``rate_hz``, and the largest |Δq̈_j| between uniform
    1 kHz samples over j_max,j · 1 ms (continuity as a controller sees it)."""
    jerk = traj.jerk(traj.sample_times(rate_hz))
    grid = np.arange(int(traj.duration * 1000.0) + 1) / 1000.0
    jump = np.abs(np.diff(traj.sample(grid)[2], axis=0)) / (jerk_limit * 1e-3)
    return float(np.max(np.abs(jerk) / jerk_limit)), float(jump.max())


def default_problem(repeats: int) -> dict[str, Any]:
    """Motion time and cost of both timings on the segments of the default problem's plan."""
    import optlight

    plan = optlight.solve("default")
    robot, spec = plan.robot, plan.problem
    segments = [plan.nlp.theta[s] for s in plan.path.segments()]
    vmax = robot.velocity_limit * spec.robot.velocity_scale
    dwell = spec.trajectory.dwell_s
    toppra, toppra_s = _timed(
        lambda: time_parameterize(segments, vmax, robot.acceleration_limit, dwell), repeats
    )
    jerk, jerk_s = _timed(
        lambda: jerk_limited_timing(segments, vmax, robot.acceleration_limit, robot.jerk_limit, dwell), repeats
    )
    return {
        "robot": robot.name,
        "segments": len(segments),
        "motion_s": {"toppra": _motion(toppra), "jerk_limited": _motion(jerk)},
        "motion_ratio": _motion(jerk) / _motion(toppra),
        "toppra": _stats(toppra_s),
        "jerk_limited": _stats(jerk_s),
        "acceleration_jump_ratio_toppra": jerk_ratios(toppra, 1000.0, robot.jerk_limit)[1],
        "acceleration_jump_ratio_jerk_limited": jerk_ratios(jerk, 1000.0, robot.jerk_limit)[1],
    }


def run(repeats: int = 15) -> dict[str, Any]:
    """Time the benchmark path and the default problem's segments; returns {"toppra": {...},
    "jerk_limited": {...}, "sample_1khz": {...}, "limits": {...}, "trajectory": {...},
    "default_problem": {...}, "meta": {...}}."""
    segments = benchmark_path()
    traj, toppra_s = _timed(
        lambda: time_parameterize(segments, VELOCITY_LIMIT, ACCELERATION_LIMIT, DWELL_S), repeats
    )
    jerk, jerk_s = _timed(
        lambda: jerk_limited_timing(segments, VELOCITY_LIMIT, ACCELERATION_LIMIT, JERK_LIMIT, DWELL_S), repeats
    )
    sample_s = []
    for _ in range(repeats):
        t = traj.sample_times(1000.0)
        start = time.perf_counter()
        traj.sample(t)
        sample_s.append(time.perf_counter() - start)
    # 20 kHz: the TOPPRA intervals last ~1.3 ms (median) here, so each is sampled ~25 times
    v_ratio, a_ratio, samples = dense_ratios(traj, 20_000.0)
    jv_ratio, ja_ratio, _ = dense_ratios(jerk, 20_000.0)
    j_ratio, jump_ratio = jerk_ratios(jerk, 20_000.0, JERK_LIMIT)
    return {
        "toppra": {**_stats(toppra_s), "per_segment_ms": float(np.median(toppra_s)) * 1e3 / SEGMENTS},
        "jerk_limited": {**_stats(jerk_s), "per_segment_ms": float(np.median(jerk_s)) * 1e3 / SEGMENTS},
        "sample_1khz": {**_stats(sample_s), "samples": int(traj.sample_times(1000.0).size)},
        "limits": {
            "max_velocity_ratio": v_ratio,
            "max_acceleration_ratio": a_ratio,
            "jerk_limited_max_velocity_ratio": jv_ratio,
            "jerk_limited_max_acceleration_ratio": ja_ratio,
            "jerk_limited_max_jerk_ratio": j_ratio,
            "jerk_limited_max_acceleration_jump_ratio": jump_ratio,
            "toppra_max_acceleration_jump_ratio": jerk_ratios(traj, 1000.0, JERK_LIMIT)[1],
            "dense_samples": samples,
            "verification_tolerance": 1e-3,
        },
        "trajectory": {
            "duration_s": traj.duration,
            "motion_s": _motion(traj),
            "jerk_limited_motion_s": _motion(jerk),
            "dwell_s": DWELL_S,
            "landmarks": SEGMENTS + 1,
        },
        "default_problem": default_problem(repeats),
        "meta": {
            "segments": SEGMENTS,
            "waypoints_per_segment": WAYPOINTS,
            "dof": 7,
            "python": platform.python_version(),
            "machine": platform.machine(),
            "cpus": os.cpu_count(),
            "toppra": importlib.metadata.version("toppra"),
            "ruckig": importlib.metadata.version("ruckig"),
            "numpy": importlib.metadata.version("numpy"),
        },
    }


def _print(results: dict[str, Any]) -> None:
    lim, tr, meta, dp = results["limits"], results["trajectory"], results["meta"], results["default_problem"]
    caption = (
        f"{meta['dof']}-DOF, {meta['segments']} segments × {meta['waypoints_per_segment']} waypoints; "
        f"moving {tr['motion_s']:.2f} s (TOPPRA) / {tr['jerk_limited_motion_s']:.2f} s (jerk-limited); "
        f"toppra {meta['toppra']}, ruckig {meta['ruckig']}"
    )
    rows = [
        ("time_parameterize (TOPPRA)", results["toppra"]),
        ("jerk_limited_timing", results["jerk_limited"]),
        ("sample at 1 kHz", results["sample_1khz"]),
        (f"default problem: TOPPRA ({dp['segments']} segments)", dp["toppra"]),
        ("default problem: jerk-limited", dp["jerk_limited"]),
    ]
    limit_rows = [
        ("TOPPRA max |q̇|/v_max (dense)", lim["max_velocity_ratio"]),
        ("TOPPRA max |q̈|/a_max (dense)", lim["max_acceleration_ratio"]),
        ("TOPPRA max |Δq̈|/(j_max·1 ms)", lim["toppra_max_acceleration_jump_ratio"]),
        ("jerk-limited max |q̇|/v_max", lim["jerk_limited_max_velocity_ratio"]),
        ("jerk-limited max |q̈|/a_max", lim["jerk_limited_max_acceleration_ratio"]),
        ("jerk-limited max |q⃛|/j_max", lim["jerk_limited_max_jerk_ratio"]),
        ("jerk-limited max |Δq̈|/(j_max·Δt)", lim["jerk_limited_max_acceleration_jump_ratio"]),
        ("default problem motion TOPPRA (s)", dp["motion_s"]["toppra"]),
        ("default problem motion jerk-limited (s)", dp["motion_s"]["jerk_limited"]),
    ]
    try:
        from rich.console import Console
        from rich.table import Table
    except ImportError:
        print(caption)
        for name, r in rows:
            print(f"{name:42s} {r['median_ms']:9.2f} ms {r['p98_ms']:9.2f} ms")
        for name, v in limit_rows:
            print(f"{name:42s} {v:.6f}")
        return
    table = Table(title="optlight timing (TOPPRA and jerk-limited)", caption=caption)
    for col in ("operation", "median ms", "p98 ms", "repeats"):
        table.add_column(col, justify="left" if col == "operation" else "right")
    for name, r in rows:
        table.add_row(name, f"{r['median_ms']:.2f}", f"{r['p98_ms']:.2f}", str(r["repeats"]))
    limits = Table(title=f"limits by dense resampling ({lim['dense_samples']} samples), motion times")
    limits.add_column("quantity")
    limits.add_column("value", justify="right")
    for name, v in limit_rows:
        limits.add_row(name, f"{v:.6f}")
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
