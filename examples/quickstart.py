"""Quickstart: solve a built-in problem through the Python API and write its results folder.

``optlight.solve`` runs the whole pipeline — landmarks that minimise the luminance objective, IK at
each of them, the great-circle path, the trajectory NLP, TOPPRA timing and the independent
verification — and ``Plan.save`` writes ``trajectory.csv``, ``plan.json``, ``lights.lp``, the
figures, ``preview.html`` and ``report.md``.

Run (headless; ``--view`` also serves the live Meshcat preview on 127.0.0.1)::

    .venv/bin/python examples/quickstart.py [--problem default] [--landmarks 12] [--out DIR] [--view]
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

import optlight


def main() -> None:
    """Solve, print the key numbers, save the results folder, optionally serve the preview."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--problem", default="default", help="built-in problem name or TOML file")
    parser.add_argument("--landmarks", type=int, help="number of landmarks (default: the problem's)")
    parser.add_argument("--out", type=Path, default=Path("results/examples/quickstart"))
    parser.add_argument("--view", action="store_true", help="serve the live Meshcat preview")
    args = parser.parse_args()

    problem = optlight.load_problem(args.problem)
    if args.landmarks is not None:
        problem = dataclasses.replace(
            problem, landmarks=dataclasses.replace(problem.landmarks, count=args.landmarks)
        )
    print(f"problem {problem.name}: {problem.description}")
    plan = optlight.solve(problem)

    s = plan.summary()
    print(
        f"{s['landmarks']} landmarks, mean cost {s['mean_landmark_cost']:.3g}; {s['knots']} path knots; "
        f"trajectory NLP {s['nlp_status']} in {s['nlp_iterations']} iterations, "
        f"max |h| {s['max_h_residual_m']:.1e} m"
    )
    print(
        f"joint path {s['joint_path_length_rad']:.3f} rad (per-knot IK {s['knot_ik_path_length_rad']:.3f}); "
        f"duration {s['duration_s']:.2f} s ({s['motion_time_s']:.2f} s moving); "
        f"verification {'passed' if s['verification_passed'] else 'FAILED'}"
    )
    print("time per stage: " + ", ".join(f"{k} {v:.2f} s" for k, v in plan.timings.items()))
    for i, lm in enumerate(plan.visited[:3]):
        print(
            f"  capture {i} (landmark {lm.index:2d}): zenith {np.rad2deg(lm.zenith):5.1f}°, "
            f"azimuth {np.rad2deg(lm.azimuth):5.1f}°, cost {lm.cost:.3g}"
        )
    for note in plan.warnings:
        print(f"warning: {note}")

    written = plan.save(args.out, overwrite=True)
    print(f"wrote {len(written)} files to {args.out}/ (open {args.out / 'preview.html'} in a browser)")

    if args.view:
        plan.preview().show()


if __name__ == "__main__":
    main()
