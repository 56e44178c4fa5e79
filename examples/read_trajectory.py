"""Read a results folder back: ``trajectory.csv`` and ``plan.json`` as a robot controller would.

``trajectory.csv`` holds t, q, q̇, q̈ of every joint; it does not record the dwells, which
``plan.json`` does (``timing.landmark_intervals_s``, ``timing.capture_times_s``), together with the
landmarks (``landmarks[i].position_m``, in capture order) and the ``[robot]`` table the plan was
solved with. The example reads both with ``optlight.Trajectory.from_csv``, resamples the trajectory
at another rate (``trajectory_<rate>hz.csv``), rebuilds the robot, recomputes the light position by
forward kinematics at every capture time and compares it with the landmark; it also checks that the
light is still during each dwell and that the joint speeds stay within the limits in plan.json.

Without ``--results`` it first solves a reduced default problem into ``OUT/plan``.

Run (headless; ``--view`` also serves the live Meshcat preview of the trajectory read back)::

    .venv/bin/python examples/read_trajectory.py [--results DIR] [--landmarks 6] [--rate 50] \
        [--out DIR] [--view]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np

import optlight


def solve_into(folder: Path, landmarks: int) -> None:
    """Solve the default problem with ``landmarks`` landmarks and save its results folder."""
    problem = optlight.load_problem("default")
    problem = dataclasses.replace(problem, landmarks=dataclasses.replace(problem.landmarks, count=landmarks))
    plan = optlight.solve(problem)
    plan.save(folder, overwrite=True, preview=False)
    print(f"solved {problem.name} with {landmarks} landmarks into {folder}/ in {plan.timings['total']:.1f} s")


def problem_of(doc: dict[str, Any]) -> optlight.Problem:
    """The problem file plan.json names (the defaults when the plan had none), with the ``[robot]``
    table the plan was solved with, as plan.json records it (unset keys left out, so they start from
    the defaults). The robot is exactly the plan's; the object and camera (for ``--view``) are the
    file's. A relative URDF path is resolved against the problem file."""
    base = optlight.load_problem(doc["problem_file"]) if doc["problem_file"] else optlight.Problem()
    robot = dataclasses.replace(optlight.Problem().robot, **doc["problem"]["robot"])
    return dataclasses.replace(base, robot=robot)


def main() -> None:
    """Read the results folder, resample, check the light at the captures and the dwells."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, help="an existing results folder (default: solve one)")
    parser.add_argument(
        "--landmarks", type=int, default=6, help="landmarks of the problem solved without --results"
    )
    parser.add_argument("--rate", type=float, default=50.0, help="resampling rate (Hz)")
    parser.add_argument("--out", type=Path, default=Path("results/examples/read_trajectory"))
    parser.add_argument("--view", action="store_true", help="serve the live Meshcat preview")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    results = args.results
    if results is None:
        results = args.out / "plan"
        solve_into(results, args.landmarks)
    doc = json.loads((results / "plan.json").read_text())
    timing = doc["timing"]
    trajectory = optlight.Trajectory.from_csv(
        results / "trajectory.csv", landmark_intervals=timing["landmark_intervals_s"]
    )
    print(
        f"read {results / 'trajectory.csv'}: {trajectory.dof} joints, {trajectory.duration:.2f} s, "
        f"{len(trajectory.capture_times)} captures"
    )
    resampled = trajectory.to_csv(args.out / f"trajectory_{args.rate:g}hz.csv", rate_hz=args.rate)
    print(
        f"wrote {resampled} ({len(trajectory.sample_times(args.rate))} rows: "
        f"{args.rate:g} Hz plus the dwell and motion boundaries)"
    )

    problem = problem_of(doc)
    robot = optlight.load_robot(problem)
    if trajectory.joint_names is not None and list(trajectory.joint_names) != robot.joint_names:
        raise SystemExit(
            f"the CSV's joints {trajectory.joint_names} are not {robot.name}'s {robot.joint_names}"
        )

    # the light at each capture, by forward kinematics, against the landmark plan.json records there
    captures = np.asarray(timing["capture_times_s"])
    q_capture = trajectory.sample(captures)[0]
    light = np.array([robot.light_pose(q)[0] for q in q_capture])
    landmarks = np.array([lm["position_m"] for lm in doc["landmarks"]])
    deviation = np.linalg.norm(light - landmarks, axis=1)
    worst = int(np.argmax(deviation))
    print(
        f"light at the {len(captures)} capture times vs plan.json's landmarks: max deviation "
        f"{deviation.max():.2e} m (capture {worst}, t = {captures[worst]:.3f} s)"
    )

    # the light is still during every dwell, and the joint speeds stay within the recorded limits
    drift = 0.0
    for start, end in trajectory.landmark_intervals:
        q = trajectory.sample(np.linspace(start, end, 11))[0]
        positions = np.array([robot.light_pose(qk)[0] for qk in q])
        drift = max(drift, float(np.linalg.norm(positions - positions[0], axis=1).max()))
    t = trajectory.sample_times(args.rate)
    _, qd, qdd = trajectory.sample(t)
    speed = float(np.max(np.abs(qd) / np.asarray(doc["robot"]["velocity_limit"])))
    acceleration = float(np.max(np.abs(qdd) / np.asarray(doc["robot"]["acceleration_limit"])))
    print(
        f"largest light motion during a dwell {drift:.2e} m; peak joint speed {100 * speed:.1f}% and "
        f"acceleration {100 * acceleration:.1f}% of the limits"
    )

    if args.view:
        scene = optlight.Scene.from_problem(problem)
        path = np.array([robot.light_pose(q)[0] for q in trajectory.sample(t)[0]])
        costs = [lm["cost"] for lm in doc["landmarks"]]
        preview = optlight.Preview(
            scene, robot, landmarks, costs, path, trajectory, light_position=landmarks[0]
        )
        preview.show("the trajectory read back")


if __name__ == "__main__":
    main()
