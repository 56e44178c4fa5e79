"""The bookkeeping of the checks: :class:`Collector` turns a measure and its threshold into a
:class:`~optlight.verify.report.CheckResult` and the first episodes of violations (a run of consecutive
failing samples, recorded at its worst sample)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from optlight.verify.report import MAX_EPISODES, CheckResult, Violation

Array = NDArray[np.float64]


def failing_runs(bad: NDArray[np.bool_], index: NDArray[np.intp] | None = None) -> list[tuple[int, int]]:
    """(start, stop) ranges of the runs of True in a 1-D boolean array; with ``index`` (the sample
    numbers of the entries) a run also ends where the sample numbers are not consecutive."""
    link = bad[:-1] & bad[1:]
    if index is not None:
        link &= np.diff(index) == 1
    starts = np.flatnonzero(bad & ~np.concatenate([[False], link]))
    stops = np.flatnonzero(bad & ~np.concatenate([link, [False]])) + 1
    return list(zip(starts.tolist(), stops.tolist(), strict=True))


class Collector:
    """Accumulates the check results and the first episodes of each check. A NaN measure fails."""

    def __init__(self, t: Array, names: list[str]) -> None:
        self.t = t
        self.names = names
        self.checks: dict[str, CheckResult] = {}
        self.violations: list[Violation] = []

    def joint_check(
        self,
        name: str,
        measure_name: str,
        unit: str,
        measure: Array,
        threshold: Array,
        message: Callable[[int, int], str],
        value: Callable[[int, int], float] | None = None,
        limit: Callable[[int, int], float] | None = None,
    ) -> None:
        """A check of every joint at every sample: fails where measure[k, j] > threshold[j].
        ``message``, ``value`` and ``limit`` take (joint j, sample k)."""
        bad = ~(measure <= threshold)
        episodes = []
        for j in range(measure.shape[1]):
            for a, b in failing_runs(bad[:, j]):
                episodes.append((a, a + worst_index(measure[a:b, j]), j))
        episodes.sort()
        for _, k, j in episodes[:MAX_EPISODES]:
            self.violations.append(
                Violation(
                    check=name,
                    time_s=float(self.t[k]),
                    joint=self.names[j],
                    value=float(value(j, k) if value else measure[k, j]),
                    limit=float(limit(j, k) if limit else threshold[j]),
                    message=message(j, k),
                )
            )
        if measure.size:
            k, j = (int(i) for i in np.unravel_index(worst_index(measure.ravel()), measure.shape))
            worst, time_s, joint = float(measure[k, j]), float(self.t[k]), self.names[j]
        else:
            worst, time_s, joint = math.nan, None, None
        self.checks[name] = CheckResult(
            name=name,
            measure=measure_name,
            unit=unit,
            max_value=worst,
            limit=float(np.max(threshold)) if threshold.size else math.nan,
            time_s=time_s,
            joint=joint,
            failing_samples=int(bad.any(axis=1).sum()),
            episodes=len(episodes),
            samples=int(measure.shape[0]),
        )

    def scalar_check(
        self,
        name: str,
        measure_name: str,
        unit: str,
        measure: Array,
        threshold: float,
        index: NDArray[np.intp],
        message: Callable[[int, float], str],
    ) -> None:
        """A check of one quantity at the samples ``index``: fails where measure > threshold.
        ``message`` takes (sample k, value)."""
        bad = ~(measure <= threshold)
        runs = failing_runs(bad, index)
        for a, b in runs[:MAX_EPISODES]:
            w = a + worst_index(measure[a:b])
            k = int(index[w])
            self.violations.append(
                Violation(
                    name, float(self.t[k]), None, float(measure[w]), threshold, message(k, float(measure[w]))
                )
            )
        w = worst_index(measure) if measure.size else -1
        self.checks[name] = CheckResult(
            name=name,
            measure=measure_name,
            unit=unit,
            max_value=float(measure[w]) if w >= 0 else math.nan,
            limit=threshold,
            time_s=float(self.t[index[w]]) if w >= 0 else None,
            joint=None,
            failing_samples=int(bad.sum()),
            episodes=len(runs),
            samples=int(measure.size),
        )


def worst_index(x: Array) -> int:
    """Index of the first NaN of a 1-D array, else of its maximum."""
    nan = np.flatnonzero(np.isnan(x))
    return int(nan[0]) if nan.size else int(np.argmax(x))


def worst_per_joint(x: Array) -> list[int]:
    """Per column of x (T, n), the sample of its first NaN, else of its maximum."""
    return [worst_index(x[:, j]) for j in range(x.shape[1])]
