"""Pipeline benchmark: the whole :func:`optlight.solve` on one problem, against the paper's pipeline.

    python benchmarks/bench_solve.py [PROBLEM] [--repeats N] [--json PATH]

Ours: ``optlight.solve(problem)`` (scene, landmarks or light set, placement, path, trajectory NLP,
timing, verification), repeated; reported per repeat and as median / p98: its own stage timings, the joint
path length Σ|Δθ| over the knots, the motion time (without dwells), the duration with dwells, the
largest light residual |h| of the NLP, its iterations, the costs of the landmarks visited, and
whether the NLP converged and the plan passed verification (success %). Baseline, in the same run
and as many times: ``baselines.per_knot_ik_plan(problem)`` (the paper's per-knot generalized IK through the
same stages, timed the same way),
when ``baselines.py`` has it; otherwise the result says the baseline is missing.
:func:`run` returns the numbers as a dict for the benchmark runner.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import baselines  # noqa: E402

import optlight  # noqa: E402
from optlight.export import write_json  # noqa: E402
from optlight.spec import load_problem, problem_from_dict  # noqa: E402

#: The per-knot IK baseline in ``baselines.py``: ``per_knot_ik_plan(problem) -> dict``.
BASELINE = "per_knot_ik_plan"
#: Quantities of our plans only: the moving time's rest-to-rest lower bound and their ratio.
PLAN_KEYS = ("duration_s", "rest_to_rest_s", "motion_bound_ratio", "nlp_iterations")
#: ... and, with flying captures, the bound of a motion that does not stop and the ratio to it.
FLYING_KEYS = ("flying_bound_s", "flying_bound_ratio")
#: Quantities compared with the baseline: our name -> the baseline dict's key.
BASELINE_KEYS = {
    "time_s": "time_s",
    "joint_path_length_rad": "joint_path_length",
    "motion_time_s": "motion_time",
    "max_h_residual_m": "max_h_residual",
}


def _dist(values: Sequence[float]) -> dict[str, float]:
    return {"median": float(np.median(values)), "p98": float(np.percentile(values, 98))}


def _solve_once(problem: optlight.Problem) -> dict[str, Any]:
    plan = optlight.solve(problem)
    costs = [landmark.cost for landmark in plan.visited]
    bound = plan.motion_bound()
    return {
        "time_s": plan.timings["total"],
        "stages_s": dict(plan.timings),
        "joint_path_length_rad": plan.joint_path_length,
        "motion_time_s": plan.motion_time,
        "duration_s": plan.trajectory.duration,
        "rest_to_rest_s": bound["rest_to_rest_s"],
        "motion_bound_ratio": bound["ratio"],
        **({"flying_bound_s": bound["flying_s"], "flying_bound_ratio": bound["flying_ratio"]} if "flying_s" in bound else {}),
        "max_h_residual_m": plan.nlp.max_h_residual,
        "nlp_iterations": plan.nlp.iterations,
        "nlp_success": bool(plan.nlp.success),
        "verification_passed": bool(plan.verification.passed),
        "landmarks_found": len(plan.landmarks),
        "landmarks_visited": len(plan.visited),
        "landmark_cost": {"median": float(np.median(costs)), "max": float(np.max(costs))},
        "warnings": list(plan.warnings),
    }


def run(problem: str, repeats: int = 1, capture: str | None = None) -> dict[str, Any]:
    """``repeats`` solves of ``problem`` (name or path) and as many baseline plans; returns the
    machine-readable results (per repeat under ``runs``, median/p98 under ``plan`` and ``baseline``).
    ``capture`` ("stop" or "flying") replaces the problem's ``[trajectory] capture``; the problem is
    then named with it, e.g. ``default (flying)``."""
    spec = load_problem(problem)
    label = spec.name
    if capture is not None:
        data = spec.to_dict()
        data["trajectory"]["capture"] = capture
        spec, label = problem_from_dict(data, source=spec.source), f"{spec.name} ({capture})"
    runs = [_solve_once(spec) for _ in range(repeats)]
    plan: dict[str, Any] = {key: _dist([r[key] for r in runs]) for key in _plan_keys(runs)}
    stages = list(dict.fromkeys(stage for r in runs for stage in r["stages_s"]))  # in pipeline order
    plan["stages_s"] = {s: _dist([r["stages_s"][s] for r in runs if s in r["stages_s"]]) for s in stages}

    per_knot = getattr(baselines, BASELINE, None)
    baseline_runs = [] if per_knot is None else [per_knot(spec) for _ in range(repeats)]
    baseline = (
        {ours: _dist([float(b[theirs]) for b in baseline_runs]) for ours, theirs in BASELINE_KEYS.items()}
        if baseline_runs
        else None
    )
    return {
        "benchmark": "solve",
        "problem": label,
        "robot": spec.robot.name,
        "captures": int(np.median([r["landmarks_visited"] for r in runs])),
        "repeats": repeats,
        "success_pct": 100.0 * float(np.mean([r["nlp_success"] and r["verification_passed"] for r in runs])),
        "plan": plan,
        "runs": runs,
        "baseline": baseline,
        "baseline_runs": baseline_runs,
        "baseline_missing": None if per_knot is not None else f"benchmarks/baselines.py has no {BASELINE}()",
    }


def _plan_keys(runs: Sequence[dict[str, Any]]) -> tuple[str, ...]:
    """The quantities every run has: the compared ones, ours, and the flying bound when flying."""
    return (*BASELINE_KEYS, *PLAN_KEYS, *(k for k in FLYING_KEYS if all(k in r for r in runs)))


def _print(result: dict[str, Any]) -> None:
    plan, baseline = result["plan"], result["baseline"]
    print(
        f"solve {result['problem']} ({result['robot']}, {result['captures']} captures), "
        f"{result['repeats']} repeat(s), success {result['success_pct']:.0f} %"
    )
    print(f"{'quantity':24s} {'median':>12s} {'p98':>12s} {'baseline':>12s}")
    for key in _plan_keys(result["runs"]):
        theirs = (
            f"{baseline[key]['median']:12.4g}" if baseline is not None and key in baseline else f"{'–':>12s}"
        )
        print(f"{key:24s} {plan[key]['median']:12.4g} {plan[key]['p98']:12.4g} {theirs}")
    for stage, d in plan["stages_s"].items():
        print(f"{'stage ' + stage + ' [s]':24s} {d['median']:12.4g} {d['p98']:12.4g}")
    if result["baseline_missing"]:
        print(f"baseline missing: {result['baseline_missing']}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("problem", nargs="?", default="default", help="built-in problem name or path")
    parser.add_argument("--repeats", type=int, default=1, help="solves (and baseline plans) per problem")
    parser.add_argument("--json", type=Path, help="write the results here as JSON")
    parser.add_argument("--capture", choices=("stop", "flying"), help="replace the problem's [trajectory] capture")
    args = parser.parse_args()
    result = run(args.problem, args.repeats, args.capture)
    _print(result)
    if args.json:
        write_json(args.json, result)


if __name__ == "__main__":
    main()
