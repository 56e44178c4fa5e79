"""Scaling: solve time per capture as the captures and the obstacles grow.

    python benchmarks/bench_scaling.py [--captures 12 36 ...] [--obstacles 0 3 ...] [--json PATH]

The default problem (procedural face, Franka Panda) with ``[landmarks] count`` = each of
:data:`CAPTURES` and each count of obstacles in :data:`OBSTACLES`: 0 is the problem as shipped
(``[environment]`` off: the camera's view kept clear, nothing else modelled); from 3 on,
``[environment]`` on, whose camera body and stand are two obstacles (and the robot's own links are
checked against each other), plus posts for the rest: vertical boxes 6 cm × 6 cm × 1 m on a circle
of radius :data:`POST_RADIUS_M` around the robot's base, spread over the half behind it (the object
and the camera are in front), where a stretched arm passes a few centimetres from them. The
landmarks of the default face lie on the camera's view boundary, 360°/count apart in azimuth, so
``distinct_deg`` is lowered to :data:`DISTINCT_DEG` to keep every landmark a capture (576 of them
are 0.18° apart). With the environment on, the self-collision rows leave some of the default
layout's view-boundary landmarks unreachable, so ``allow_partial`` is on and a cell plans the
captures the robot reaches (``planned_captures``; the time per capture is per planned capture).

Per cell: the solve time (s, the pipeline's ``total``) and its stages, the time per capture (ms),
whether verification passed, the motion time (s, without the dwells) per capture and the mean
landmark cost. The baseline of a cell is the 12-capture cell with the same obstacles, so a ratio
near 1 is a flat time per capture.
"""

from __future__ import annotations

import argparse
import math
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

import optlight
from optlight.export import write_json
from optlight.spec import Problem, load_problem, problem_from_dict

CAPTURES = (12, 36, 144, 576)
OBSTACLES = (0, 3, 10)
#: Landmarks closer than this are one capture (the default 0.5° would merge the 576 landmarks).
DISTINCT_DEG = 0.1
#: Radius (m) of the circle of posts around the robot's base (the panda reaches 0.855 m).
POST_RADIUS_M = 0.95


def posts(count: int) -> list[dict[str, Any]]:
    """``count`` box obstacles as ``[[environment.boxes]]`` tables, 6 × 6 × 100 cm, standing on z = 0
    on the circle of radius :data:`POST_RADIUS_M` round the base, azimuths 100°–260° (behind it)."""
    azimuths = np.radians(np.linspace(100.0, 260.0, count) if count > 1 else [180.0] * count)
    return [
        {
            "name": f"post_{i}",
            "center_m": [POST_RADIUS_M * math.cos(a), POST_RADIUS_M * math.sin(a), 0.5],
            "size_m": [0.06, 0.06, 1.0],
        }
        for i, a in enumerate(azimuths)
    ]


#: Obstacles of ``[environment]`` on before any post: the camera's body and its stand.
CAMERA_OBSTACLES = 2


def scaled_problem(captures: int, obstacles: int) -> Problem:
    """The default problem with ``captures`` landmarks and ``obstacles`` obstacles (module docstring)."""
    if 0 < obstacles < CAMERA_OBSTACLES:
        raise ValueError(f"obstacles: 0 or at least {CAMERA_OBSTACLES} (the camera's body and stand)")
    base = load_problem("default")
    data = base.to_dict()
    data["landmarks"].update(count=captures, distinct_deg=DISTINCT_DEG, allow_partial=True)
    if obstacles:
        data["environment"]["enabled"] = True
    if obstacles > CAMERA_OBSTACLES:
        data["environment"]["boxes"] = posts(obstacles - CAMERA_OBSTACLES)
    return problem_from_dict(data, source=base.source)


def run_cell(captures: int, obstacles: int) -> dict[str, Any]:
    """One solve of :func:`scaled_problem`; its numbers (a failed solve gives its error)."""
    problem = scaled_problem(captures, obstacles)
    start = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            plan = optlight.solve(problem)
    except optlight.OptlightError as e:
        return {"captures": captures, "obstacles": obstacles, "error": str(e), "time_s": time.perf_counter() - start}
    total = time.perf_counter() - start
    planned = len(plan.visited)
    return {
        "captures": captures,
        "obstacles": obstacles,
        "planned_captures": planned,
        "time_s": total,
        "ms_per_capture": 1e3 * total / planned,
        "stages_s": {k: v for k, v in plan.timings.items() if k != "total"},
        "verified": bool(plan.verification.passed),
        "motion_s_per_capture": plan.motion_time / planned,
        "mean_cost": float(np.mean([lm.cost for lm in plan.visited])),
        "nlp_iterations": plan.nlp.iterations,
    }


def run(captures: tuple[int, ...] = CAPTURES, obstacles: tuple[int, ...] = OBSTACLES) -> dict[str, Any]:
    """Every (captures, obstacles) cell, smallest first; the machine-readable results."""
    cells = []
    for m in obstacles:
        for n in captures:
            cell = run_cell(n, m)
            cells.append(cell)
            shown = (
                f"{cell['ms_per_capture']:.0f} ms/capture, verified {cell['verified']}"
                if "error" not in cell
                else f"failed: {cell['error']}"
            )
            print(f"scaling: {n} captures, {m} obstacles: {cell['time_s']:.1f} s, {shown}", flush=True)
    return {"benchmark": "scaling", "post_radius_m": POST_RADIUS_M, "distinct_deg": DISTINCT_DEG, "cells": cells}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--captures", type=int, nargs="+", default=list(CAPTURES))
    parser.add_argument("--obstacles", type=int, nargs="+", default=list(OBSTACLES))
    parser.add_argument("--json", type=Path, help="write the results here as JSON")
    args = parser.parse_args()
    result = run(tuple(args.captures), tuple(args.obstacles))
    if args.json:
        write_json(args.json, result)


if __name__ == "__main__":
    main()
