"""What the robot meets: ``clearance``, ``self_collision`` and ``view_cone`` from an exact environment
check of the samples, ``view`` and ``beam`` from exact ray casting at the captures (docs/design.md §8, §9).
Both checks come from the caller, duck-typed; here their reports become check results."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from optlight.verify.collector import Collector
from optlight.verify.report import MAX_EPISODES, CheckResult, Violation

#: (q samples (T, n), times (T,), capture times) -> an EnvironmentReport (duck-typed: ``pairs`` and
#: ``violations`` as in :mod:`optlight.environment.check`).
EnvironmentCheck = Callable[[np.ndarray, np.ndarray, np.ndarray], Any]
#: (joint angles at the captures (M, n), capture times (M,)) -> a ViewReport (duck-typed: ``captures``
#: with ``view_blocked``, ``view_body``, ``view_bodies``, ``beam_*``, ``capture``, ``time_s``).
ViewCheck = Callable[[np.ndarray, np.ndarray], Any]

#: Check names of the environment pair kinds.
ENVIRONMENT_CHECKS = {"obstacle": "clearance", "self": "self_collision", "view": "view_cone"}


def view_checks(collector: Collector, report: Any) -> None:
    """``view`` and ``beam``: the largest blocked fraction of a capture's rays (limit 0); every
    blocked capture is a violation naming the capture, the first blocking body and the time."""
    for name, what in (("view", "the camera's rays to the object"), ("beam", "the light's rays to the object")):
        fractions = [getattr(c, f"{name}_blocked") for c in report.captures]
        blocked = [c for c in report.captures if getattr(c, f"{name}_blocked") > 0]
        worst = max(report.captures, key=lambda c: getattr(c, f"{name}_blocked"), default=None)
        collector.checks[name] = CheckResult(
            name=name,
            measure=f"largest blocked fraction of {what} at a capture",
            unit="",
            max_value=max(fractions, default=0.0),
            limit=0.0,
            time_s=worst.time_s if worst is not None else None,
            joint=getattr(worst, f"{name}_body") if worst is not None else None,
            failing_samples=len(blocked),
            episodes=len(blocked),
            samples=len(fractions),
        )
        for c in blocked[:MAX_EPISODES]:
            bodies = getattr(c, f"{name}_bodies")
            others = f" (also {', '.join(bodies[1:])})" if len(bodies) > 1 else ""
            fraction = getattr(c, f"{name}_blocked")
            collector.violations.append(
                Violation(
                    name,
                    c.time_s,
                    bodies[0],
                    fraction,
                    0.0,
                    f"capture {c.capture} at t = {c.time_s:.4f} s: {fraction:.1%} of {what} blocked, "
                    f"first by {bodies[0]}{others}",
                )
            )


def environment_checks(collector: Collector, report: Any, samples: int) -> None:
    """One check per pair kind of an environment report: the allowed distance minus its worst pair's
    distance (m), failing samples summed over the pairs; the report's episodes become violations."""
    for kind, name in ENVIRONMENT_CHECKS.items():
        pairs = [p for p in report.pairs if p.kind == kind]
        if not pairs:
            continue
        worst = min(pairs, key=lambda p: p.min_distance_m - p.threshold_m)
        collector.checks[name] = CheckResult(
            name=name,
            measure="allowed distance minus the smallest distance (positive: too close)",
            unit="m",
            max_value=-(worst.min_distance_m - worst.threshold_m),
            limit=0.0,
            time_s=worst.time_s,
            joint=f"{worst.first} ↔ {worst.second}",
            failing_samples=sum(p.failing_samples for p in pairs),
            episodes=sum(1 for v in report.violations if v.kind == kind),
            samples=samples,
        )
        collector.violations.extend(
            Violation(name, v.time_s, f"{v.first} ↔ {v.second}", v.distance_m, v.threshold_m, v.message)
            for v in report.violations
            if v.kind == kind
        )

