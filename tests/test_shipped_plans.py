"""The shipped problems' plans are the ones the committed benchmark results record.

``benchmarks/results/latest.json`` holds, for every shipped problem, the benchmark ``solve <name>``
(``benchmarks/bench_solve.py``) and, per run, the numbers of its plan: the joint path length over the
optimised knots, the motion time and the duration with the dwells, the largest light residual |h| of
the trajectory NLP and its iterations, the landmarks found and visited, the median and largest cost
of the landmarks visited, and whether the NLP converged and the plan passed verification. A solve
now must give the same numbers: the real ones to 1e-9 relative, the counts and flags exactly. The
file records no joint angles: they are compared through the path length, the timing and the costs
they determine (a landmark moved or a posture changed changes them). A change of the code that
changes a plan fails here, and the benchmark results are run again with it (``optlight bench``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import optlight

RESULTS = Path(__file__).resolve().parent.parent / "benchmarks" / "results" / "latest.json"

#: The plan's numbers the benchmark records (bench_solve's run dict), compared to 1e-9 relative.
REAL = ("joint_path_length_rad", "motion_time_s", "duration_s", "max_h_residual_m")
#: ... and compared exactly.
EXACT = ("nlp_iterations", "nlp_success", "verification_passed", "landmarks_found", "landmarks_visited")


def _recorded(problem: str) -> dict[str, Any]:
    """The first run of ``solve <problem>`` in the committed results (its runs agree: checked)."""
    results = json.loads(RESULTS.read_text())
    entry = next((b for b in results["benchmarks"] if b["name"] == f"solve {problem}"), None)
    assert entry is not None and entry["status"] == "ok", f"{RESULTS} has no run of the problem {problem!r}"
    runs = entry["result"]["runs"]
    keys = (*REAL, *EXACT, "landmark_cost")
    assert all(run[k] == runs[0][k] for run in runs for k in keys), f"the recorded runs of {problem} disagree"
    return runs[0]


def _numbers(plan: optlight.Plan) -> dict[str, Any]:
    """The numbers of ``plan`` that bench_solve records, computed the way it computes them."""
    costs = [landmark.cost for landmark in plan.visited]
    return {
        "joint_path_length_rad": plan.joint_path_length,
        "motion_time_s": plan.motion_time,
        "duration_s": plan.trajectory.duration,
        "max_h_residual_m": plan.nlp.max_h_residual,
        "nlp_iterations": plan.nlp.iterations,
        "nlp_success": bool(plan.nlp.success),
        "verification_passed": bool(plan.verification.passed),
        "landmarks_found": len(plan.landmarks),
        "landmarks_visited": len(plan.visited),
        "landmark_cost": {"median": float(np.median(costs)), "max": float(np.max(costs))},
    }


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::UserWarning")  # the plan's notes: plan.warnings
@pytest.mark.parametrize("problem", sorted(optlight.available_problems()))
def test_a_shipped_problems_plan_is_the_recorded_one(problem: str) -> None:
    recorded = _recorded(problem)
    now = _numbers(optlight.solve(problem))
    assert {k: now[k] for k in EXACT} == {k: recorded[k] for k in EXACT}
    for key in REAL:
        assert now[key] == pytest.approx(recorded[key], rel=1e-9, abs=0.0), key
    for key in ("median", "max"):
        cost = recorded["landmark_cost"][key]
        assert now["landmark_cost"][key] == pytest.approx(cost, rel=1e-9, abs=0.0), key
