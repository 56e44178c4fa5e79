"""Generalized IK on its own: put the light on the sphere, pointing at the object.

For light positions spread over the light cap of a problem, ``optlight.generalized_ik`` solves the
5-D task (light position + optical axis through the centre, roll free) with different null-space
secondary tasks — none, joint-limit avoidance, manipulability, posture, all three — and the 6-D task
(roll fixed too). Per setting it prints successes, iterations, time, the residual, an independent
check of the light pose by forward kinematics, the joint-limit margin (the distance of the closest
joint to its nearer limit, as a fraction of its range), the manipulability √det(J Jᵀ) and the
distance from the start θ_ref. The secondary tasks act only in the iterations before the primary task
converges, so their effect shows with gains above the defaults. Every solve is written to ``ik.csv``.

Run (headless; ``--view`` also serves the live Meshcat preview on 127.0.0.1)::

    .venv/bin/python examples/ik_only.py [--problem default] [--out DIR] [--view]
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path
from typing import Literal

import numpy as np

import optlight

#: A compared setting: label, primary task, null-space gains k of the secondary tasks.
Setting = tuple[str, Literal["5d", "6d"], dict[str, float]]

#: The compared settings. The k=0.05 rows use the default gain ([solver] ik_joint_limit_gain), the
#: others larger gains: the secondary tasks only act until the primary task converges (a few iterations).
SETTINGS: tuple[Setting, ...] = (
    ("5-D, no secondary task", "5d", {}),
    ("5-D + joint limits k=0.05", "5d", {"joint_limits": 0.05}),
    ("5-D + joint limits k=1", "5d", {"joint_limits": 1.0}),
    ("5-D + manipulability k=0.5", "5d", {"manipulability": 0.5}),
    ("5-D + posture k=0.2", "5d", {"posture": 0.2}),
    ("5-D + all three", "5d", {"joint_limits": 1.0, "manipulability": 0.5, "posture": 0.2}),
    ("6-D + joint limits k=0.05", "6d", {"joint_limits": 0.05}),
)


def cap_targets(sphere: optlight.LightSphere, rings: int = 3, per_ring: int = 8) -> np.ndarray:
    """(zenith, azimuth) pairs (rad): the pole and ``rings`` rings of ``per_ring`` azimuths up to the
    sphere's largest allowed zenith."""
    zeniths = np.linspace(sphere.zenith_min, sphere.zenith_max, rings + 1)
    azimuths = 2 * np.pi * np.arange(per_ring) / per_ring
    ring = [(z, a) for z in zeniths[1:] for a in azimuths]
    return np.array([(zeniths[0], 0.0), *ring])


def limit_margin(robot: optlight.Robot, theta: np.ndarray) -> float:
    """Smallest distance of a joint to its nearer limit, as a fraction of the joint's range."""
    return float(np.min(np.minimum(theta - robot.lower, robot.upper - theta) / (robot.upper - robot.lower)))


def solve_target(
    robot: optlight.Robot, sphere: optlight.LightSphere, setting: Setting, target: np.ndarray
) -> tuple[dict[str, object], np.ndarray]:
    """One generalized IK solve from θ_ref, checked by forward kinematics: its ik.csv row and θ."""
    label, task, gains = setting
    zenith, azimuth = target
    r = optlight.generalized_ik(robot, sphere, target, task=task, secondary=tuple(gains), weights=gains)
    position, rotation = robot.light_pose(r.theta)
    to_center = (sphere.center - position) / np.linalg.norm(sphere.center - position)
    jac = robot.light_jacobian(r.theta)
    row = {
        "setting": label,
        "zenith_deg": float(np.rad2deg(zenith)),
        "azimuth_deg": float(np.rad2deg(azimuth)),
        "success": r.success,
        "iterations": r.iterations,
        "restarts": r.restarts,
        "time_ms": 1e3 * r.time_s,
        "residual_m": r.residual,
        "position_error_m": float(np.linalg.norm(position - sphere.position(zenith, azimuth))),
        "axis_error_deg": float(np.rad2deg(np.arccos(np.clip(rotation[:, 2] @ to_center, -1.0, 1.0)))),
        "limit_margin": limit_margin(robot, r.theta),
        "manipulability": float(np.sqrt(max(np.linalg.det(jac @ jac.T), 0.0))),
        "distance_to_ref_rad": float(np.linalg.norm(r.theta - robot.theta_ref)),
    }
    return row, r.theta


HEADER = (
    f"{'setting':27s} {'ok':>5s} {'iter med/max':>12s} {'ms med':>6s} {'|e| max':>7s} {'FK m / deg':>15s} "
    f"{'margin min/mean':>15s} {'manip':>6s} {'|θ-θref|':>8s}"
)


def summary_line(label: str, rows: list[dict]) -> str:
    """One table line: successes, iterations, time, then the worst residual and FK errors and the
    mean margin, manipulability and distance from θ_ref over the successful solves."""
    ok = [r for r in rows if r["success"]]
    iterations = [r["iterations"] for r in rows]

    def worst(key: str) -> float:
        return max((r[key] for r in ok), default=np.nan)

    def mean(key: str) -> float:
        return float(np.mean([r[key] for r in ok])) if ok else np.nan

    return (
        f"{label:27s} {len(ok):2d}/{len(rows):<2d} {np.median(iterations):5.0f}/{max(iterations):<6d} "
        f"{np.median([r['time_ms'] for r in rows]):6.2f} {worst('residual_m'):7.1e} "
        f"{worst('position_error_m'):7.1e}/{worst('axis_error_deg'):7.1e} "
        f"{min((r['limit_margin'] for r in ok), default=np.nan):7.4f}/{mean('limit_margin'):7.4f} "
        f"{mean('manipulability'):6.4f} {mean('distance_to_ref_rad'):8.3f}"
    )


def main() -> None:
    """Run every setting on every target, print one line per setting, write ik.csv."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--problem", default="default", help="built-in problem name or TOML file (robot, sphere)"
    )
    parser.add_argument("--out", type=Path, default=Path("results/examples/ik_only"))
    parser.add_argument("--view", action="store_true", help="serve the live Meshcat preview")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    problem = optlight.load_problem(args.problem)
    robot = optlight.load_robot(problem)
    sphere = optlight.LightSphere.from_problem(problem)
    targets = cap_targets(sphere)
    print(
        f"{robot.name} ({robot.n} joints), light sphere radius {sphere.radius:g} m, {len(targets)} targets "
        f"up to zenith {np.rad2deg(sphere.zenith_max):g}°, every solve from θ_ref"
    )
    print(HEADER)
    rows: list[dict] = []
    thetas: dict[str, list[np.ndarray]] = {}
    for setting in SETTINGS:
        solved = [solve_target(robot, sphere, setting, target) for target in targets]
        rows += [row for row, _ in solved]
        thetas[setting[0]] = [theta for _, theta in solved]
        print(summary_line(setting[0], [row for row, _ in solved]))

    path = args.out / "ik.csv"
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    print(f"wrote {path} ({len(rows)} solves)")

    if args.view:
        label = SETTINGS[-2][0]
        scene = optlight.Scene.from_problem(problem)
        positions = sphere.position(targets[:, 0], targets[:, 1])
        margins = [row["limit_margin"] for row in rows if row["setting"] == label]
        preview = optlight.Preview(
            scene, robot, positions, margins, np.empty((0, 3)), theta=thetas[label][-1]
        )
        preview.show(f"targets coloured by joint-limit margin, the robot at the last target ({label})")


if __name__ == "__main__":
    main()
