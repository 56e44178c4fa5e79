"""IK benchmark: generalized IK (ours) against a plain pinocchio CLIK on the same light poses.

    python benchmarks/bench_ik.py [--n N] [--robots panda,ur5,xarm7] [--json PATH]

Per robot, ``n`` seeded random reachable light poses: a joint configuration drawn uniformly within the
limits, its light pose (a, R) by forward kinematics, and the object centre O = a + b·z_L (b = 0.4 m)
on the light's axis. Every solver starts from the robot's reference configuration θ_ref.

- ``ours 5-D``: :func:`optlight.robot.generalized_ik`, default settings (task: a on a*, optical axis
  through O, roll free; joint-limit avoidance in the null space; random restarts when stuck; tolerance
  |e|² < 1e-9, i.e. |e| < 3.2e-5 m with the pointing rows weighted by b).
- ``ours 6-D``: the same solver with the full pose R* = R as the task.
- ``clik dt=0.1``: pinocchio's inverse-kinematics example on the 6-D pose (log6 error in the light
  frame, J = −Jlog6·J_LOCAL, damped least squares with damp = 1e-12, q ← integrate(q, 0.1·v),
  |log6| < 1e-4, 1000 iterations), unchanged but for the frame.
- ``clik dt=1``: the same with full Gauss–Newton steps (dt = 1).

Success = converged *and* within the joint limits (CLIK does not clip; ``converged`` counts it either
way). Every success of ours is re-checked here: |a − a*| < 1e-4 m, |h| < 1e-4 m, θ within limits.
Times are wall-clock around each call (ms); the methods run interleaved pose by pose, so that a change
of machine load affects them alike. :func:`run` returns the numbers as a dict.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import os
import platform
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from optlight.export import write_json
from optlight.geometry import LightSphere, h_residual, sphere_frame
from optlight.robot import Robot, generalized_ik, load_robot

Array = NDArray[np.float64]

RADIUS_M = 0.4


@dataclass(frozen=True)
class Poses:
    """``n`` light poses reached by configurations ``theta`` (n, dof): positions (n, 3), rotations
    (n, 3, 3) and the light spheres (centre on the light's axis, radius b)."""

    theta: Array
    position: Array
    rotation: Array
    spheres: list[LightSphere]


def make_poses(robot: Robot, n: int, seed: int = 0) -> Poses:
    """Seeded random reachable light poses (see the module docstring)."""
    rng = np.random.default_rng(seed)
    thetas = robot.random_configuration(rng, n)
    positions, rotations, spheres = [], [], []
    for theta in thetas:
        p, rot = robot.light_pose(theta)
        centre = p + RADIUS_M * rot[:, 2]
        positions.append(p)
        rotations.append(rot)
        spheres.append(LightSphere(centre, RADIUS_M, sphere_frame(centre, p)))
    return Poses(thetas, np.array(positions), np.array(rotations), spheres)


def clik(
    robot: Robot,
    target: pin.SE3,
    q0: Array,
    *,
    dt: float = 0.1,
    eps: float = 1e-4,
    it_max: int = 1000,
    damp: float = 1e-12,
) -> tuple[Array, bool, int]:
    """Pinocchio's CLIK example on the light frame: returns (θ, converged, iterations)."""
    model, data, fid = robot.model, robot.data, robot.light_frame_id
    q = q0.copy()
    eye = np.eye(6)
    for i in range(it_max + 1):
        pin.forwardKinematics(model, data, q)
        i_m_d = pin.updateFramePlacement(model, data, fid).actInv(target)
        err = pin.log(i_m_d).vector
        if np.linalg.norm(err) < eps:
            return robot.from_pin(q), True, i
        if i == it_max:
            break
        jac = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL)
        jac = -np.dot(pin.Jlog6(i_m_d.inverse()), jac)
        v = -jac.T.dot(np.linalg.solve(jac.dot(jac.T) + damp * eye, err))
        q = pin.integrate(model, q, v * dt)
    return robot.from_pin(q), False, it_max


def _stats(ms: Array) -> dict[str, float]:
    return {
        "mean_ms": float(ms.mean()),
        "median_ms": float(np.median(ms)),
        "p98_ms": float(np.percentile(ms, 98)),
        "max_ms": float(ms.max()),
    }


def _verified(robot: Robot, theta: Array, target: Array, sphere: LightSphere) -> bool:
    a, rot = robot.light_pose(theta)
    return bool(
        robot.within_limits(theta, tol=0.0)
        and np.linalg.norm(a - target) < 1e-4
        and np.abs(h_residual(a, rot, sphere.center, sphere.radius)).max() < 1e-4
    )


Solver = Callable[[int], tuple[Array, bool, bool, int, int]]


def _run_methods(robot: Robot, poses: Poses, methods: dict[str, Solver]) -> dict[str, dict[str, Any]]:
    """Every method on every pose, interleaved pose by pose (so that a change of machine load hits all
    methods alike); per method the statistics of :func:`run`."""
    n, m = len(poses.spheres), len(methods)
    ms, success, converged, iterations, restarts, verified = (np.zeros((m, n)) for _ in range(6))
    for k in range(n):
        for i, solve in enumerate(methods.values()):
            start = time.perf_counter()
            theta, conv, ok, its, rs = solve(k)
            ms[i, k] = 1e3 * (time.perf_counter() - start)
            converged[i, k], success[i, k], iterations[i, k], restarts[i, k] = conv, ok, its, rs
            verified[i, k] = ok and _verified(robot, theta, poses.position[k], poses.spheres[k])
    return {
        name: {
            "success_pct": 100.0 * float(success[i].mean()),
            "verified_pct": 100.0 * float(verified[i].mean()),
            "converged_pct": 100.0 * float(converged[i].mean()),
            **_stats(ms[i]),
            "success_mean_ms": float(ms[i][success[i] > 0].mean()) if success[i].any() else float("nan"),
            "iterations_mean": float(iterations[i].mean()),
            "iterations_median": float(np.median(iterations[i])),
            "restarted_pct": 100.0 * float((restarts[i] > 0).mean()),
        }
        for i, name in enumerate(methods)
    }


def bench_robot(robot: Robot, n: int, seed: int = 0) -> dict[str, Any]:
    """All methods on ``n`` poses of one robot."""
    poses = make_poses(robot, n, seed)
    q_ref = robot.to_pin(robot.theta_ref)
    targets = [pin.SE3(rot, p) for p, rot in zip(poses.position, poses.rotation, strict=True)]
    within = robot.within_limits

    def ours(task: str) -> Solver:
        def solve(k: int) -> tuple[Array, bool, bool, int, int]:
            res = generalized_ik(
                robot,
                poses.spheres[k],
                poses.position[k],
                task=task,  # type: ignore[arg-type]
                rotation=poses.rotation[k] if task == "6d" else None,
            )
            return res.theta, res.residual**2 < 1e-9, res.success, res.iterations, res.restarts

        return solve

    def baseline(dt: float) -> Solver:
        def solve(k: int) -> tuple[Array, bool, bool, int, int]:
            theta, conv, its = clik(robot, targets[k], q_ref, dt=dt)
            return theta, conv, conv and within(theta, tol=0.0), its, 0

        return solve

    generalized_ik(robot, poses.spheres[0], poses.position[0])  # warm-up (imports, caches)
    methods = {
        "ours 5-D": ours("5d"),
        "ours 6-D": ours("6d"),
        "clik dt=0.1": baseline(0.1),
        "clik dt=1": baseline(1.0),
    }
    return _run_methods(robot, poses, methods)


def run(n: int = 10000, robots: Sequence[str] = ("panda", "ur5", "xarm7"), seed: int = 0) -> dict[str, Any]:
    """The benchmark; returns {"robots": {robot: {method: stats}}, "targets": {...}, "meta": {...}}."""
    load_before = os.getloadavg()[0]
    results = {name: bench_robot(load_robot(name), n, seed) for name in robots}
    targets: dict[str, Any] = {}
    if "panda" in results:
        ours, base = results["panda"]["ours 5-D"], results["panda"]
        targets = {
            "panda_success_ge_99.7": ours["verified_pct"] >= 99.7,
            "panda_mean_le_0.5ms": ours["mean_ms"] <= 0.5,
            "panda_faster_than_clik": all(
                ours["mean_ms"] < base[m]["mean_ms"] for m in ("clik dt=0.1", "clik dt=1")
            ),
        }
    return {
        "benchmark": "ik",
        "poses_per_robot": n,
        "seed": seed,
        "radius_m": RADIUS_M,
        "robots": results,
        "targets": targets,
        "meta": {
            "python": platform.python_version(),
            "machine": platform.machine(),
            "processor": platform.processor(),
            "cpus": os.cpu_count(),
            "load_avg_1min": [load_before, os.getloadavg()[0]],
            "pin": importlib.metadata.version("pin"),
            "numpy": importlib.metadata.version("numpy"),
            "scipy": importlib.metadata.version("scipy"),
        },
    }


def _print(results: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    meta = results["meta"]
    table = Table(
        title=f"optlight IK: {results['poses_per_robot']} random reachable light poses per robot, from θ_ref",
        caption=f"pin {meta['pin']}, numpy {meta['numpy']}, Python {meta['python']}, {meta['cpus']} CPUs, "
        f"load average {meta['load_avg_1min'][0]:.2f} → {meta['load_avg_1min'][1]:.2f}",
    )
    for col in (
        "robot",
        "method",
        "success %",
        "converged %",
        "mean ms",
        "median ms",
        "p98 ms",
        "iters",
        "restarted %",
    ):
        table.add_column(col, justify="left" if col in ("robot", "method") else "right")
    for robot, methods in results["robots"].items():
        for name, r in methods.items():
            table.add_row(
                robot,
                name,
                f"{r['verified_pct']:.2f}",
                f"{r['converged_pct']:.2f}",
                f"{r['mean_ms']:.3f}",
                f"{r['median_ms']:.3f}",
                f"{r['p98_ms']:.3f}",
                f"{r['iterations_mean']:.1f}",
                f"{r['restarted_pct']:.1f}",
            )
        table.add_section()
    console = Console(width=max(Console().width, 120))
    console.print(table)
    for name, ok in results["targets"].items():
        console.print(f"target {name}: {'met' if ok else 'NOT met'}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=10000, help="poses per robot")
    parser.add_argument("--robots", default="panda,ur5,xarm7", help="comma-separated robot names")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", type=Path, help="write the results to this file")
    args = parser.parse_args()
    results = run(args.n, tuple(args.robots.split(",")), args.seed)
    _print(results)
    if args.json:
        write_json(args.json, results)


if __name__ == "__main__":
    main()
