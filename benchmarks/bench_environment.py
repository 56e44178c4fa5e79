"""Environment benchmark: constrained against unconstrained plans on the obstacle problems.

    python benchmarks/bench_environment.py [PROBLEM ...] [--repeats N] [--json PATH]

For each problem (default: ``collision`` and ``table_wall``), ``repeats`` times and interleaved:
``optlight.solve(problem)`` (constrained: ``[environment] enabled``, clearance and view-cone rows in
the placement and trajectory NLPs) and ``optlight.solve`` of the same problem with ``enabled = false``
(unconstrained). Per plan: the solve time (s, the pipeline's ``total``), the NLP time (s, its ``nlp``
stage; with the environment the free solve and the constrained one from it), the motion time (s,
without the dwells), and the exact environment checks of the verification (coal distances on the
trajectory resampled at ≥ 1 kHz, :meth:`optlight.environment.Environment.check`): the unconstrained
plan, which its own verification does not check, is verified afterwards in the problem's environment
exactly as the constrained one is. Per check (``clearance``: robot to obstacles, ``self_collision``,
``view_cone``): the smallest distance of its worst pair of bodies (m; < 0 = penetration depth) and
the slack over the allowed distance (m; < 0 = violation), which pair and when.
:func:`run` returns the numbers as a dict (median / p98 over repeats) for the benchmark runner.
"""

from __future__ import annotations

import argparse
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

import optlight
from optlight.environment import Environment
from optlight.export import write_json
from optlight.spec import Problem, load_problem, problem_from_dict
from optlight.verify import ENVIRONMENT_CHECKS, VerificationReport, verify_trajectory

#: The built-in problems with an environment.
PROBLEMS = ("collision", "table_wall")
PLANS = ("constrained", "unconstrained")


def _dist(values: Sequence[float]) -> dict[str, float]:
    return {"median": float(np.median(values)), "p98": float(np.percentile(values, 98))}


def unconstrained(problem: Problem) -> Problem:
    """The same problem planned without its environment (``[environment] enabled = false``)."""
    data = problem.to_dict()
    data["environment"]["enabled"] = False
    return problem_from_dict(data, source=problem.source)


def verify_in_environment(plan: optlight.Plan, environment: Environment) -> VerificationReport:
    """The pipeline's verification of ``plan``'s trajectory, with ``environment``'s exact checks."""
    robot = plan.robot
    return verify_trajectory(
        plan.trajectory,
        light_pose=robot.light_pose,
        lower=robot.lower,
        upper=robot.upper,
        velocity_limit=plan.setup.limits.velocity,
        acceleration_limit=robot.acceleration_limit,
        sphere=plan.scene.sphere,
        landmark_positions=np.array([lm.position for lm in plan.visited]),
        planned_path=robot.light_positions(plan.nlp.theta),
        transfers=plan.path.transfers,
        environment=lambda q, t, captures: environment.check(robot, q, t, capture_times=captures),
    )


def _checks(report: VerificationReport, environment: Environment) -> dict[str, dict[str, Any]]:
    """Per environment check: smallest distance (m), slack over the allowed distance (m), worst pair,
    time (s), failing samples."""
    allowed = {"clearance": environment.margin, "self_collision": environment.self_margin, "view_cone": 0.0}
    out = {}
    for name in ENVIRONMENT_CHECKS.values():
        check = report.checks.get(name)
        if check is None:
            continue
        slack = -check.max_value
        out[name] = {
            "min_distance_m": allowed[name] + slack,
            "slack_m": slack,
            "pair": check.joint,
            "time_s": check.time_s,
            "failing_samples": check.failing_samples,
        }
    return out


def _solve_once(problem: Problem, environment: Environment, constrained: bool) -> dict[str, Any]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the placement's notes; kept in plan.warnings
        plan = optlight.solve(problem if constrained else unconstrained(problem))
    report = plan.verification if constrained else verify_in_environment(plan, environment)
    return {
        "solve_time_s": plan.timings["total"],
        "nlp_time_s": plan.timings["nlp"],
        "motion_time_s": plan.motion_time,
        "nlp_iterations": plan.nlp.iterations,
        "landmarks": len(plan.visited),
        "passed": bool(report.passed),
        "own_verification_passed": bool(plan.verification.passed),
        "checks": _checks(report, environment),
        "warnings": list(plan.warnings),
    }


def _summary(runs: list[dict[str, Any]]) -> dict[str, Any]:
    checks = list(dict.fromkeys(name for r in runs for name in r["checks"]))
    return {
        **{key: _dist([r[key] for r in runs]) for key in ("solve_time_s", "nlp_time_s", "motion_time_s")},
        "passed_pct": 100.0 * float(np.mean([r["passed"] for r in runs])),
        "checks": {
            name: {
                "min_distance_m": _dist([r["checks"][name]["min_distance_m"] for r in runs]),
                "slack_m": _dist([r["checks"][name]["slack_m"] for r in runs]),
                "passed_pct": 100.0
                * float(np.mean([r["checks"][name]["failing_samples"] == 0 for r in runs])),
            }
            for name in checks
        },
    }


def run(problems: Sequence[str] = PROBLEMS, repeats: int = 3) -> dict[str, Any]:
    """Constrained and unconstrained plans of each problem (name or path), ``repeats`` of each,
    interleaved; per problem and plan the runs and their median / p98 (module docstring)."""
    results: dict[str, Any] = {}
    for name in problems:
        problem = load_problem(name)
        environment = Environment.from_problem(problem)
        runs: dict[str, list[dict[str, Any]]] = {plan: [] for plan in PLANS}
        for _ in range(repeats):
            for plan in PLANS:
                runs[plan].append(_solve_once(problem, environment, plan == "constrained"))
        results[problem.name] = {
            "robot": problem.robot.name,
            "landmarks": problem.landmarks.count,
            "view": problem.view.mode,
            "margin_m": environment.margin,
            "self_margin_m": environment.self_margin,
            **{plan: _summary(runs[plan]) for plan in PLANS},
            "runs": runs,
        }
    return {"benchmark": "environment", "repeats": repeats, "problems": results}


def _print(result: dict[str, Any]) -> None:
    print(f"environment: constrained vs unconstrained plans, {result['repeats']} repeat(s), medians")
    header = (
        f"{'problem':12s} {'plan':14s} {'solve [s]':>10s} {'NLP [s]':>9s} {'motion [s]':>11s} {'passed':>7s}"
    )
    print(f"{header}  closest (distance, slack over the allowed one)")
    for name, r in result["problems"].items():
        for plan in PLANS:
            s = r[plan]
            closest = "; ".join(
                f"{check} {c['min_distance_m']['median'] * 1e3:.1f} mm ({c['slack_m']['median'] * 1e3:+.1f})"
                for check, c in s["checks"].items()
            )
            print(
                f"{name:12s} {plan:14s} {s['solve_time_s']['median']:10.2f} {s['nlp_time_s']['median']:9.2f} "
                f"{s['motion_time_s']['median']:11.2f} {s['passed_pct']:6.0f}%  {closest}"
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("problems", nargs="*", default=list(PROBLEMS), help="problem names or paths")
    parser.add_argument("--repeats", type=int, default=3, help="plans of each kind per problem")
    parser.add_argument("--json", type=Path, help="write the results here as JSON")
    args = parser.parse_args()
    result = run(args.problems, args.repeats)
    _print(result)
    if args.json:
        write_json(args.json, result)


if __name__ == "__main__":
    main()
