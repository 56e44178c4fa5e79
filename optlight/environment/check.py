"""Exact environment checks of sampled configurations with coal: clearance, self-collision, view cone.

:func:`check_configurations` evaluates every pair of a :class:`CollisionModel` (coal GJK/EPA on the
exact shapes; signed distance, < 0 = penetration depth) over the samples θ_k of a trajectory and
reports, per pair of bodies, the smallest distance and when, and every *episode* (a run of
consecutive samples below the pair's threshold) at its worst sample, with the point on the robot
where it happens.

Not every pair is evaluated at every sample. Between samples k and l a point of geometry g moves at
most Σ_i ρ[g, i] |θ_l,i − θ_k,i| (:attr:`CollisionModel.motion_weights`, a chain-length bound), so a
pair last evaluated at distance D is *certified* at sample l to be at least D − (bound of both
geometries). A pair is evaluated again as soon as its certified value could drop below its
threshold, or below min(its smallest distance so far, threshold + :data:`EXACT_BAND_M`). Therefore:

- every sample below a threshold is found, and evaluated exactly;
- a pair's reported minimum is exact when it is below threshold + EXACT_BAND_M; above that it is the
  smallest evaluated value, and every sample is certified above threshold + EXACT_BAND_M.

View-cone pairs are evaluated at the capture samples only (``view_cone = "capture"``) or at every
sample (``"path"``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import coal
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from optlight.environment.collision import CollisionModel, PairKind
from optlight.jsondata import json_safe

Array = NDArray[np.float64]

#: Pairs are tracked exactly while they are within this distance of their threshold (m).
EXACT_BAND_M = 0.05
#: Episodes kept per pair of bodies in :attr:`EnvironmentReport.violations`.
MAX_EPISODES = 5
#: Capture times match samples within this tolerance (s).
TIME_TOLERANCE_S = 1e-9
#: Most samples certified at once between evaluations (:func:`check_configurations`). The bound of a
#: block is one (block, pairs, joints) array: 32 samples cost ~3 µs each, 256 ~8 µs (out of cache).
_CERTIFY_BLOCK = 32


@dataclass(frozen=True)
class PairClearance:
    """Smallest distance between two bodies over the samples (m; < 0 = penetration depth).

    ``first`` is a robot body (URDF link or "light"), ``second`` an obstacle, another robot body or
    "view_cone"; ``time_s`` when the minimum happens (None if never evaluated); ``threshold_m`` the
    smallest allowed distance; ``failing_samples`` how many samples are below it."""

    kind: PairKind
    first: str
    second: str
    min_distance_m: float
    time_s: float | None
    threshold_m: float
    failing_samples: int
    evaluations: int

    @property
    def passed(self) -> bool:
        """No sample below the threshold."""
        return self.failing_samples == 0


@dataclass(frozen=True)
class EnvironmentViolation:
    """The worst sample of one episode of a pair below its threshold: time (s), distance (m),
    threshold (m), ``point_m`` the point of ``first`` (the robot body) nearest to ``second``
    (world frame, m)."""

    kind: PairKind
    first: str
    second: str
    time_s: float
    distance_m: float
    threshold_m: float
    point_m: tuple[float, float, float]
    message: str


@dataclass(frozen=True)
class EnvironmentReport:
    """Outcome of an environment check: one :class:`PairClearance` per pair of bodies, the
    violations (first :data:`MAX_EPISODES` episodes per pair), ``samples`` checked, ``view_samples``
    at which the view cone was checked, ``evaluations`` (coal distance calls), ``elapsed_s``."""

    pairs: tuple[PairClearance, ...]
    violations: tuple[EnvironmentViolation, ...]
    samples: int
    view_samples: int
    evaluations: int
    elapsed_s: float

    @property
    def passed(self) -> bool:
        """No pair below its threshold at any sample."""
        return all(p.passed for p in self.pairs)

    def minimum(self, kind: PairKind) -> PairClearance | None:
        """The pair of this kind with the smallest distance (None when there is none)."""
        pairs = [p for p in self.pairs if p.kind == kind and p.time_s is not None]
        return min(pairs, key=lambda p: p.min_distance_m) if pairs else None

    @property
    def min_clearance_m(self) -> float:
        """Smallest robot–obstacle distance over all samples (m; inf without obstacles)."""
        worst = self.minimum("obstacle")
        return worst.min_distance_m if worst is not None else math.inf

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-safe data (non-finite numbers become None)."""
        return json_safe(
            {
                "passed": self.passed,
                "samples": self.samples,
                "view_samples": self.view_samples,
                "evaluations": self.evaluations,
                "elapsed_s": self.elapsed_s,
                "min_clearance_m": self.min_clearance_m,
                "pairs": [{**json_safe(p), "passed": p.passed} for p in self.pairs],
                "violations": self.violations,
            }
        )

    def summary(self) -> str:
        """A readable account: verdict, the closest pair of each kind, the violations."""
        lines = [
            f"Environment {'PASSED' if self.passed else 'FAILED'}: {self.samples} samples "
            f"({self.view_samples} with the view cone), {self.evaluations} distance evaluations "
            f"in {self.elapsed_s:.2f} s"
        ]
        kinds: tuple[PairKind, ...] = ("obstacle", "self", "view")
        for kind in kinds:
            p = self.minimum(kind)
            if p is not None:
                lines.append(
                    f"  {'ok  ' if p.passed else 'FAIL'} {kind:<8} closest {p.first} ↔ {p.second}: "
                    f"{p.min_distance_m * 1e3:.1f} mm at t = {p.time_s:.4f} s "
                    f"(threshold {p.threshold_m * 1e3:.1f} mm)"
                )
        lines.extend(f"  {v.message}" for v in self.violations)
        return "\n".join(lines)


def _capture_mask(times: Array, capture_times: ArrayLike | None) -> NDArray[np.bool_]:
    """(T,): the samples at ``times`` (T,) (s) within :data:`TIME_TOLERANCE_S` of a capture time; each
    capture time must have one. Each capture's samples are looked for in the sorted times, among
    those twice the tolerance around it (576 captures of 70,000 samples: 0.29 s with a pass over
    every sample per capture)."""
    mask = np.zeros(times.size, bool)
    if capture_times is None:
        return mask
    order = np.argsort(times, kind="stable")
    ordered = times[order]
    for t in np.asarray(capture_times, float).ravel():
        lo, hi = np.searchsorted(ordered, [t - 2 * TIME_TOLERANCE_S, t + 2 * TIME_TOLERANCE_S])
        near = order[lo:hi]
        hit = near[np.abs(times[near] - t) <= TIME_TOLERANCE_S]
        if hit.size == 0:
            raise ValueError(f"capture time {t:.9g} s is not one of the sample times")
        mask[hit] = True
    return mask


def check_configurations(
    model: CollisionModel,
    thetas: ArrayLike,
    times: ArrayLike,
    *,
    view: str = "capture",
    capture_times: ArrayLike | None = None,
) -> EnvironmentReport:
    """Check the samples ``thetas`` (T, n) (joint angles, rad) at ``times`` (T,) (s) against every
    pair of ``model`` (module docstring). ``view``: "capture" checks the view cone at the samples
    whose time is one of ``capture_times`` (each must be a sample time), "path" at every sample,
    "off" nowhere."""
    start = time.perf_counter()
    robot = model.robot
    theta = np.asarray(thetas, float).reshape(-1, robot.n)
    t = np.asarray(times, float).ravel()
    if t.size != theta.shape[0]:
        raise ValueError(f"{theta.shape[0]} configurations for {t.size} times")
    if not np.isfinite(theta).all():
        raise ValueError("the configurations are not finite")
    if view not in ("off", "capture", "path"):
        raise ValueError(f"view must be 'off', 'capture' or 'path', got {view!r}")
    capture = _capture_mask(t, capture_times) if view == "capture" else np.full(t.size, view == "path")

    pairs = model.pairs
    n_pairs = len(pairs)
    kinds = np.array([p.kind for p in pairs])
    threshold = np.array([p.threshold for p in pairs])
    first = np.array([p.first for p in pairs], int)
    second = np.array([p.second for p in pairs], int)
    n_geom = len(model.geometry.geometryObjects)
    weights = np.zeros((n_geom, robot.n))
    weights[: model.motion_weights.shape[0]] = model.motion_weights
    pair_weights = weights[first] + weights[second]  # (P, n): obstacles and the cone do not move
    trigger_band = threshold + EXACT_BAND_M

    last_d = np.full(n_pairs, -np.inf)  # never evaluated: certified value −inf forces an evaluation
    last_theta = np.zeros((n_pairs, robot.n))
    best = np.full(n_pairs, np.inf)
    best_k = np.full(n_pairs, -1)
    evaluations = np.zeros(n_pairs, int)
    failing: list[list[tuple[int, float, Array]]] = [[] for _ in range(n_pairs)]
    is_view = kinds == "view"
    geom, gdata = model.geometry, model.geometry_data
    req, res = coal.DistanceRequest(), coal.DistanceResult()
    objects = geom.geometryObjects

    # A pair is due when its certified value drops below max(threshold, min(best, threshold + band)):
    # kept up to date where a pair's best changes rather than recomputed at every sample, and the
    # pairs' geometries as Python ints (a sixth less time on collision's check, the same evaluations).
    bound = np.maximum(threshold, np.minimum(best, trigger_band))
    first_g, second_g = first.tolist(), second.tolist()
    k, size = 0, 1
    while k < t.size:
        # The next sample with a pair due. The certificates change only where a pair is evaluated,
        # so the samples up to the next evaluation can be certified at once: a block, doubled while
        # nothing is due (long clear stretches), back to one sample after an evaluation (a pair
        # tracked exactly is due at every sample). The same samples are evaluated as one by one.
        block = slice(k, min(k + size, t.size))
        certified = last_d - np.einsum("pn,bpn->bp", pair_weights, np.abs(theta[block, None] - last_theta))
        due = (~is_view | capture[block, None]) & (certified < bound)
        rows = np.flatnonzero(due.any(axis=1))
        if rows.size == 0:
            k, size = block.stop, min(2 * size, _CERTIFY_BLOCK)
            continue
        k, size = k + int(rows[0]), 1
        todo = np.flatnonzero(due[rows[0]])
        pin.updateGeometryPlacements(robot.model, robot.data, geom, gdata, robot.to_pin(theta[k]))
        placed: dict[int, coal.Transform3s] = {}  # once per geometry and sample: most are in several pairs
        for p in todo.tolist():
            a, b = first_g[p], second_g[p]
            for g in (a, b):
                if g not in placed:
                    placed[g] = coal.Transform3s(gdata.oMg[g])  # pinocchio's converter: 0.75 µs, not 1.1
            res.clear()  # one result, cleared: a new one costs 0.8 µs
            d = coal.distance(objects[a].geometry, placed[a], objects[b].geometry, placed[b], req, res)
            evaluations[p] += 1
            last_d[p], last_theta[p] = d, theta[k]
            if d < best[p]:
                best[p], best_k[p] = d, k
                bound[p] = max(threshold[p], min(d, trigger_band[p]))
            if d < threshold[p]:
                failing[p].append((k, d, np.asarray(res.getNearestPoint1(), float).copy()))
        k += 1

    report_pairs, violations = _aggregate(model, t, best, best_k, evaluations, failing)
    return EnvironmentReport(
        pairs=report_pairs,
        violations=violations,
        samples=int(t.size),
        view_samples=int(capture.sum()) if is_view.any() else 0,
        evaluations=int(evaluations.sum()),
        elapsed_s=time.perf_counter() - start,
    )


def _aggregate(
    model: CollisionModel,
    t: Array,
    best: Array,
    best_k: NDArray[np.int64],
    evaluations: NDArray[np.int64],
    failing: Sequence[list[tuple[int, float, Array]]],
) -> tuple[tuple[PairClearance, ...], tuple[EnvironmentViolation, ...]]:
    """Geometry pairs → body pairs: minimum, failing samples (union over the body pair's geometry
    pairs) and episodes at their worst sample."""
    groups: dict[tuple[PairKind, str, str], list[int]] = {}
    for p, pair in enumerate(model.pairs):
        groups.setdefault((pair.kind, pair.first_body, pair.second_name), []).append(p)
    out, violations = [], []
    for (kind, first, second), members in groups.items():
        threshold = model.pairs[members[0]].threshold
        m = min(members, key=lambda p: best[p])
        worst_at: dict[int, tuple[float, Array]] = {}
        for p in members:
            for k, d, point in failing[p]:
                if k not in worst_at or d < worst_at[k][0]:
                    worst_at[k] = (d, point)
        out.append(
            PairClearance(
                kind=kind,
                first=first,
                second=second,
                min_distance_m=float(best[m]),
                time_s=float(t[best_k[m]]) if best_k[m] >= 0 else None,
                threshold_m=threshold,
                failing_samples=len(worst_at),
                evaluations=int(sum(evaluations[p] for p in members)),
            )
        )
        ks = sorted(worst_at)
        runs: list[list[int]] = []
        for k in ks:
            if runs and k == runs[-1][-1] + 1:
                runs[-1].append(k)
            else:
                runs.append([k])
        for run in runs[:MAX_EPISODES]:
            k = min(run, key=lambda i: worst_at[i][0])
            d, point = worst_at[k]
            what = (
                f"{-d * 1e3:.1f} mm inside the camera's view cone"
                if kind == "view"
                else f"{d * 1e3:.1f} mm from {second}"
            )
            violations.append(
                EnvironmentViolation(
                    kind=kind,
                    first=first,
                    second=second,
                    time_s=float(t[k]),
                    distance_m=float(d),
                    threshold_m=threshold,
                    point_m=(float(point[0]), float(point[1]), float(point[2])),
                    message=(
                        f"{kind}: {first} {what} (threshold {threshold * 1e3:.1f} mm) at t = {t[k]:.4f} s, "
                        f"near ({point[0]:.3f}, {point[1]:.3f}, {point[2]:.3f}) m; "
                        f"{len(run)} samples in this episode"
                    ),
                )
            )
    out.sort(key=lambda p: (p.kind, p.min_distance_m))
    violations.sort(key=lambda v: v.time_s)
    return tuple(out), tuple(violations)
