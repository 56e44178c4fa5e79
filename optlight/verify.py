"""Independent verification of a timed plan before anything is exported (docs/design.md §6).

The checks use only the trajectory's own samples and the caller's forward kinematics, never the
planner's or TOPPRA's internal data. The trajectory is resampled at ``rate_hz`` (≥ 1 kHz) plus every
dwell/motion boundary (and just before each), every capture time, and then:

- ``position``: lower_j − tol ≤ q_j ≤ upper_j + tol (rad);
- ``velocity``: |q̇_j| ≤ v_max,j (1 + limit_rel);
- ``acceleration``: |q̈_j| ≤ a_max,j (1 + limit_rel);
- at every sample of every dwell (capture time included), with (a, R) = light_pose(q):
  ``h``: |h| = |Rᵀ(O − a) − [0, 0, b]| ≤ h_m (on the sphere and aimed at O, docs/design.md §3);
  ``aim``: angle between the light axis R e_z and O − a ≤ aim_rad;
  ``landmark``: |a − p_i| ≤ landmark_m for the dwell's landmark p_i;
- ``path`` (when a planned path is given): distance from every sampled light position to the
  polyline of planned light positions ≤ path_m, from the first capture to the last except on the
  transfers (``transfers``: the segments between two captures where the light leaves the sphere);
- ``outside`` (with transfers): on them, the light's depth inside the sphere b − |a − O| ≤ path_m
  (off the sphere, never nearer the object than the captures);
- with a jerk limit: ``jerk``: |q⃛_j| ≤ j_max,j (1 + limit_rel) (the trajectory's own q⃛), and
  ``acceleration_continuity``: on the controller's grid t_k = k / rate_hz, the largest jump
  |q̈_j(t_{k+1}) − q̈_j(t_k)| relative to what the jerk limit allows in one step, j_max,j / rate_hz
  (a step of q̈, as TOPPRA's parametrization has, shows as a ratio far above 1);
- with controller waypoints (the points of joint_trajectory.yaml): ``interpolation``: at every sample,
  |q̂_j(t) − q_j(t)| ≤ interpolation_rad, q̂ the quintic Hermite interpolation of the waypoints
  (the polynomial of degree 5 per interval with the waypoints' q, q̇, q̈ at both ends, as ROS 2's
  joint_trajectory_controller interpolates them), evaluated here by its own basis functions
  (:func:`quintic_hermite`);
- with a dynamics model (:class:`optlight.robot.Dynamics`: the URDF's inertias and the lamp):
  ``torque``: |τ_j| ≤ τ_max,j at every sample, τ = M(q) q̈ + C(q, q̇) q̇ + g(q) by inverse dynamics
  (pinocchio's RNEA), τ_max the robot's published torque limits; a robot without them has its peak
  torques reported (:attr:`VerificationReport.torques`) and the check skipped;
- with a view check (:class:`optlight.environment.view.ViewCheck`, exact ray casting at the captures):
  ``view`` (camera rays to the object blocked by a robot link or the light housing) and ``beam``
  (light rays to the object blocked by a robot link), each the largest blocked fraction of a
  capture's rays (any blocked ray fails);
- with an environment check (exact coal distances, :meth:`optlight.environment.Environment.check`):
  ``clearance`` (robot to obstacles), ``self_collision`` (robot to itself) and ``view_cone`` (robot
  and light out of the camera's view of the object), each the allowed distance minus the smallest
  distance over its pairs of bodies (m; positive = too close).

Checks named in ``advisory`` are computed and reported but do not decide :attr:`VerificationReport.passed`.

A NaN anywhere (a broken trajectory or forward kinematics) fails the check it enters. A violation is
recorded per *episode* (a run of consecutive failing samples of one joint or one
quantity) at its worst sample; the report keeps the first :data:`MAX_EPISODES` per check, the count of
failing samples, and the worst value of every check.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from optlight.errors import VerificationError
from optlight.geometry import LightSphere, h_residual
from optlight.jsondata import json_safe
from optlight.motion import Trajectory

Array = NDArray[np.float64]
LightPose = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
#: (q samples (T, n), times (T,), capture times) -> an EnvironmentReport (duck-typed: ``pairs`` and
#: ``violations`` as in :mod:`optlight.environment.check`).
EnvironmentCheck = Callable[[np.ndarray, np.ndarray, np.ndarray], Any]
#: (joint angles at the captures (M, n), capture times (M,)) -> a ViewReport (duck-typed: ``captures``
#: with ``view_blocked``, ``view_body``, ``view_bodies``, ``beam_*``, ``capture``, ``time_s``).
ViewCheck = Callable[[np.ndarray, np.ndarray], Any]

#: Points a controller interpolates quintically (duck-typed, as
#: :class:`optlight.planning.waypoints.Waypoints`): ``t`` (K,) s, ``q``, ``qd``, ``qdd`` (K, n).
ControllerPoints = Any

#: Joint torques of a motion (duck-typed, as :class:`optlight.robot.Dynamics`): ``torques(q, q̇, q̈)``
#: (T, n) N·m, ``torque_limit`` (n,) N·m or None, ``torque_limit_source`` (str).
TorqueModel = Any

#: Check names of the environment pair kinds.
ENVIRONMENT_CHECKS = {"obstacle": "clearance", "self": "self_collision", "view": "view_cone"}

#: Episodes kept per check in :attr:`VerificationReport.violations`.
MAX_EPISODES = 5
#: Points per chunk in the point-to-polyline distance (bounds the memory of the near segments' lists).
_CHUNK = 50_000


@dataclass(frozen=True)
class Tolerances:
    """What counts as a violation. Units: relative (limit_rel), rad, m."""

    limit_rel: float = 1e-3
    position_rad: float = 1e-6
    h_m: float = 1e-6
    aim_rad: float = 1e-4
    landmark_m: float = 1e-6
    path_m: float = 5e-3
    interpolation_rad: float = 1e-4


@dataclass(frozen=True)
class Violation:
    """The worst sample of one episode. ``value`` and ``limit`` are physical: the joint position and
    the bound it crossed (rad), |q̇| and v_max(1 + limit_rel) (rad/s), |q̈| and its limit (rad/s²),
    |h|, the landmark or path distance (m), the aiming angle (rad)."""

    check: str
    time_s: float
    joint: str | None
    value: float
    limit: float
    message: str


@dataclass(frozen=True)
class CheckResult:
    """Worst value of one check over all its samples, in the check's measure: the largest excess
    over the position limits (rad; negative = smallest margin), the largest |q̇_j|/v_max,j or
    |q̈_j|/a_max,j (ratio), the largest |h|, landmark or path distance (m), aiming angle (rad)."""

    name: str
    measure: str
    unit: str
    max_value: float
    limit: float
    time_s: float | None
    joint: str | None
    failing_samples: int
    episodes: int
    samples: int

    @property
    def passed(self) -> bool:
        """No failing sample."""
        return self.failing_samples == 0


@dataclass(frozen=True)
class TorqueSummary:
    """The joint torques along the plan: per joint (``joints``) the peak |τ_j| (``peak_nm``, N·m) and
    when (``time_s``), the limit (``limit_nm``) and the peak's fraction of it (``fraction``), None
    for a robot without published limits; ``source`` where the limits come from."""

    joints: tuple[str, ...]
    peak_nm: tuple[float, ...]
    time_s: tuple[float, ...]
    limit_nm: tuple[float, ...] | None
    fraction: tuple[float, ...] | None
    source: str

    def lines(self) -> list[str]:
        """One line per joint: peak, limit and fraction (or that no limit is published)."""
        if self.limit_nm is None or self.fraction is None:
            head = [f"Joint torques (not checked: {self.source}):"]
            return head + [
                f"  {j}: peak |τ| = {p:.3g} N·m at t = {t:.4f} s"
                for j, p, t in zip(self.joints, self.peak_nm, self.time_s, strict=True)
            ]
        rows = zip(self.joints, self.peak_nm, self.time_s, self.limit_nm, self.fraction, strict=True)
        return [f"Joint torques (limits: {self.source}):"] + [
            f"  {j}: peak |τ| = {p:.3g} N·m at t = {t:.4f} s, {f:.1%} of {lim:.4g} N·m" for j, p, t, lim, f in rows
        ]


@dataclass(frozen=True)
class VerificationReport:
    """Outcome of :func:`verify_trajectory`."""

    checks: dict[str, CheckResult]
    violations: tuple[Violation, ...]
    duration_s: float
    samples: int
    rate_hz: float
    tolerances: Tolerances
    skipped: tuple[str, ...] = ()
    elapsed_s: float = 0.0
    advisory: tuple[str, ...] = ()
    torques: TorqueSummary | None = None

    @property
    def passed(self) -> bool:
        """Every check passed, the advisory ones aside."""
        return all(c.passed for name, c in self.checks.items() if name not in self.advisory)

    @property
    def counts(self) -> dict[str, int]:
        """Number of failing samples per check."""
        return {k: c.failing_samples for k, c in self.checks.items()}

    @property
    def maxima(self) -> dict[str, float]:
        """Worst value per check, in the check's measure (see :class:`CheckResult`)."""
        return {k: c.max_value for k, c in self.checks.items()}

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-safe data (non-finite numbers become None)."""
        return {
            "passed": self.passed,
            "duration_s": self.duration_s,
            "samples": self.samples,
            "rate_hz": self.rate_hz,
            "elapsed_s": self.elapsed_s,
            "tolerances": asdict(self.tolerances),
            "skipped": list(self.skipped),
            "advisory": list(self.advisory),
            "counts": self.counts,
            "checks": {k: {**json_safe(c), "passed": c.passed} for k, c in self.checks.items()},
            "violations": json_safe(self.violations),
            "torques": json_safe(self.torques) if self.torques is not None else None,
        }

    def summary(self) -> str:
        """A readable multi-line account: verdict, one line per check, the recorded violations."""
        verdict = "PASSED" if self.passed else "FAILED"
        lines = [
            f"Verification {verdict}: {self.duration_s:.3f} s trajectory, {self.samples} samples "
            f"(≥ {self.rate_hz:g} Hz), checked in {self.elapsed_s:.2f} s",
        ]
        width = max(len(k) for k in self.checks) if self.checks else 8
        for name, c in self.checks.items():
            where = ""
            if c.time_s is not None:
                where = f" at t = {c.time_s:.4f} s" + (f" ({c.joint})" if c.joint else "")
            unit = f" {c.unit}" if c.unit else ""
            mark = "ok  " if c.passed else ("warn" if name in self.advisory else "FAIL")
            lines.append(
                f"  {mark} {name:<{width}}  {c.measure} = {c.max_value:.6g}{unit}{where}; "
                f"limit {c.limit:.6g}{unit}; {c.failing_samples}/{c.samples} samples over in {c.episodes} episodes"
            )
        for name in self.skipped:
            lines.append(f"  skip {name:<{width}}  not checked")
        for name in self.advisory:
            if name in self.checks:
                lines.append(f"  note {name:<{width}}  reported only: it does not decide the verdict")
        if self.torques is not None:
            lines.extend(self.torques.lines())
        if self.violations:
            lines.append(f"Violations (first {MAX_EPISODES} episodes per check):")
            lines.extend(f"  {v.check}: {v.message}" for v in self.violations)
        return "\n".join(lines)


def ensure_verified(report: VerificationReport) -> None:
    """Raise :class:`VerificationError` (carrying the report) unless the report passed."""
    if not report.passed:
        raise VerificationError(report.summary(), report)


def verify_trajectory(
    trajectory: Trajectory,
    *,
    light_pose: LightPose,
    lower: ArrayLike,
    upper: ArrayLike,
    velocity_limit: ArrayLike,
    acceleration_limit: ArrayLike,
    sphere: LightSphere,
    landmark_positions: ArrayLike,
    planned_path: ArrayLike | None = None,
    transfers: ArrayLike | None = None,
    environment: EnvironmentCheck | None = None,
    jerk_limit: ArrayLike | None = None,
    view: ViewCheck | None = None,
    waypoints: ControllerPoints | None = None,
    dynamics: TorqueModel | None = None,
    advisory: tuple[str, ...] = (),
    rate_hz: float = 1000.0,
    tol: Tolerances = Tolerances(),  # noqa: B008 - frozen, immutable default
) -> VerificationReport:
    """Check a timed trajectory against the joint limits and the light constraints (module docstring).

    Args:
        trajectory: the plan; its dwells (``landmark_intervals``) are matched with the landmarks.
        light_pose: q (n,) -> (position a (3,) in m, rotation R (3, 3)) of the light frame in the
            world frame; the light emits along R e_z.
        lower, upper: (n,) joint position limits (rad; ±inf for none).
        velocity_limit, acceleration_limit: (n,) positive limits (rad/s, rad/s²).
        sphere: the light sphere (centre O, radius b).
        landmark_positions: (M, 3) light positions (m, world) of the landmarks, in visiting order.
        planned_path: (K, 3) light positions (m, world) along the planned path, or None to skip the
            path check.
        transfers: (M − 1,) True for the segments between two captures (in visiting order) where the
            light leaves the sphere, or None for none.
        environment: exact clearance / self-collision / view-cone check of the samples, or None.
        jerk_limit: (n,) positive jerk limits (rad/s³), or None to skip the jerk and acceleration
            continuity checks (a TOPPRA-timed trajectory has no bounded jerk).
        view: exact view and beam check at the captures, or None to skip it.
        waypoints: the points a controller interpolates quintically (``t``, ``q``, ``qd``, ``qdd``),
            or None to skip the ``interpolation`` check.
        dynamics: the joint torques of the motion and their limits, or None to skip the ``torque``
            check.
        advisory: names of checks reported without deciding the verdict.
        rate_hz: resampling rate, at least 1000 Hz; also the controller grid of the continuity check.
        tol: the tolerances.
    """
    start = time.perf_counter()
    n = trajectory.dof
    lo, hi = _per_joint(lower, n, "lower"), _per_joint(upper, n, "upper")
    vmax, amax = (
        _per_joint(velocity_limit, n, "velocity_limit"),
        _per_joint(acceleration_limit, n, "acceleration_limit"),
    )
    if not ((vmax > 0).all() and (amax > 0).all()):
        raise ValueError("velocity and acceleration limits must be positive")
    landmarks = np.asarray(landmark_positions, float).reshape(-1, 3)
    intervals = trajectory.landmark_intervals
    if landmarks.shape[0] != intervals.shape[0]:
        raise ValueError(
            f"{landmarks.shape[0]} landmark positions for a trajectory with {intervals.shape[0]} dwells"
        )
    if rate_hz < 1000.0:
        raise ValueError(f"rate_hz must be at least 1000 Hz, got {rate_hz}")

    t = _verification_times(trajectory, rate_hz)
    q, qd, qdd = trajectory.sample(t)
    names = list(trajectory.joint_names) if trajectory.joint_names else [f"j{i}" for i in range(n)]
    collector = _Collector(t, names)

    excess = np.maximum(lo - q, q - hi)
    collector.joint_check(
        "position",
        "largest excess over [lower, upper] (negative: margin)",
        "rad",
        excess,
        np.full(n, tol.position_rad),
        lambda j, k: (
            f"joint {names[j]}: q = {q[k, j]:.6g} rad beyond [{lo[j]:.6g}, {hi[j]:.6g}] at t = {t[k]:.4f} s"
        ),
        value=lambda j, k: q[k, j],
        limit=lambda j, k: hi[j] if q[k, j] > hi[j] else lo[j],
    )

    def rate_check(name: str, symbol: str, x: Array, lim: Array, unit: str) -> None:
        bound = lim * (1 + tol.limit_rel)
        collector.joint_check(
            name,
            f"largest |{symbol}_j| / limit_j",
            "",
            np.abs(x) / lim,
            np.full(n, 1.0 + tol.limit_rel),
            lambda j, k: (
                f"joint {names[j]}: |{symbol}| = {abs(x[k, j]):.6g} {unit} > {bound[j]:.6g} {unit} "
                f"at t = {t[k]:.4f} s"
            ),
            value=lambda j, k: abs(x[k, j]),
            limit=lambda j, k: bound[j],
        )

    rate_check("velocity", "q̇", qd, vmax, "rad/s")
    rate_check("acceleration", "q̈", qdd, amax, "rad/s²")
    skipped: tuple[str, ...] = ()
    if jerk_limit is not None:
        jmax = _per_joint(jerk_limit, n, "jerk_limit")
        if not (jmax > 0).all():
            raise ValueError("jerk limits must be positive")
        rate_check("jerk", "q⃛", trajectory.jerk(t), jmax, "rad/s³")
        _continuity_check(collector, trajectory, jmax, rate_hz, tol, names)
    else:
        skipped = ("jerk", "acceleration_continuity")

    # Light at the landmarks, throughout each dwell.
    # the last dwell starting (less 1e-12 s) at or before each sample, when the sample is also within
    # its end (plus 1e-12 s); t and the dwells are sorted
    dwell_of = np.searchsorted(intervals[:, 0] - 1e-12, t, side="right") - 1
    dwell_of[(dwell_of >= 0) & (t > intervals[np.maximum(dwell_of, 0), 1] + 1e-12)] = -1
    in_dwell = np.flatnonzero(dwell_of >= 0)
    # the planned path runs from the first capture to the last; the approach and the return (joint-space
    # transfers to and from the start configuration) are checked by the limits and the environment
    # (and so are the transfers between two captures, which must also stay outside the sphere)
    off_sphere = np.zeros(t.size, bool)
    for s in np.flatnonzero(np.zeros(len(intervals) - 1, bool) if transfers is None else transfers):
        off_sphere |= (t > intervals[s, 1] + 1e-12) & (t < intervals[s + 1, 0] - 1e-12)
    path_times = (t >= intervals[0, 0] - 1e-12) & (t <= intervals[-1, 1] + 1e-12) & ~off_sphere
    on_path, in_transfer = np.flatnonzero(path_times), np.flatnonzero(off_sphere)
    path_needed = planned_path is not None
    pose_at = np.flatnonzero((path_times if path_needed else False) | (dwell_of >= 0) | off_sphere)
    positions = np.full((t.size, 3), np.nan)
    rotations = np.full((t.size, 3, 3), np.nan)
    # a dwell's samples hold one configuration: its pose computed once (the same q, the same pose)
    changes, source = _equal_runs(q, pose_at)
    for k in changes:
        positions[k], rotations[k] = light_pose(q[k])
    positions[pose_at], rotations[pose_at] = positions[source], rotations[source]
    a, r = positions[in_dwell], rotations[in_dwell]
    h_norm = np.linalg.norm(h_residual(a, r, sphere.center, sphere.radius), axis=1)
    axis, to_center = r[:, :, 2], sphere.center - a
    aim = np.arctan2(np.linalg.norm(np.cross(axis, to_center), axis=1), np.einsum("ij,ij->i", axis, to_center))
    landmark_dist = np.linalg.norm(positions[in_dwell] - landmarks[dwell_of[in_dwell]], axis=1)

    def dwell_check(name: str, values: Array, limit: float, unit: str, what: str) -> None:
        collector.scalar_check(
            name,
            f"largest {what} during the dwells",
            unit,
            values,
            limit,
            in_dwell,
            lambda k, v: (
                f"landmark {dwell_of[k]}: {what} = {v:.3g} {unit} > {limit:.3g} {unit} at t = {t[k]:.4f} s"
            ),
        )

    dwell_check("h", h_norm, tol.h_m, "m", "|h|")
    dwell_check("aim", aim, tol.aim_rad, "rad", "aiming angle")
    dwell_check("landmark", landmark_dist, tol.landmark_m, "m", "distance to the landmark")

    if planned_path is not None:
        polyline = np.asarray(planned_path, float).reshape(-1, 3)
        if polyline.shape[0] == 0:
            raise ValueError("planned_path has no points")
        deviation = distance_to_polyline(positions[on_path], polyline)
        collector.scalar_check(
            "path",
            "largest distance to the planned path, from the first capture to the last",
            "m",
            deviation,
            tol.path_m,
            on_path,
            lambda k, v: (
                f"light {v * 1e3:.3g} mm from the planned path at t = {t[k]:.4f} s (> {tol.path_m * 1e3:.3g} mm)"
            ),
        )
    else:
        skipped += ("path",)
    if in_transfer.size:
        depth = sphere.radius - np.linalg.norm(positions[in_transfer] - sphere.center, axis=1)
        collector.scalar_check(
            "outside",
            "largest depth of the light inside the sphere on the transfers",
            "m",
            depth,
            tol.path_m,
            in_transfer,
            lambda k, v: f"light {v * 1e3:.3g} mm inside the sphere at t = {t[k]:.4f} s (> {tol.path_m * 1e3:.3g} mm)",
        )
    if waypoints is not None:
        interpolated = quintic_hermite(waypoints.t, waypoints.q, waypoints.qd, waypoints.qdd, t)
        gap = np.abs(interpolated - q)
        collector.joint_check(
            "interpolation",
            "largest |q̂_j − q_j|, q̂ the quintic interpolation of the controller waypoints",
            "rad",
            gap,
            np.full(n, tol.interpolation_rad),
            lambda j, k: (
                f"joint {names[j]}: the waypoints' quintic interpolation is {gap[k, j]:.3g} rad from the plan "
                f"at t = {t[k]:.4f} s (> {tol.interpolation_rad:.3g} rad)"
            ),
        )
    else:
        skipped += ("interpolation",)
    torques = _torque_check(collector, dynamics, q, qd, qdd, names) if dynamics is not None else None
    if torques is None or torques.limit_nm is None:
        skipped += ("torque",)
    if environment is not None:
        _environment_checks(collector, environment(q, t, trajectory.capture_times), t.size)
    if view is not None:
        captures = trajectory.capture_times
        _view_checks(collector, view(trajectory.sample(captures)[0], captures))
    else:
        skipped += ("view", "beam")

    return VerificationReport(
        checks=collector.checks,
        violations=tuple(collector.violations),
        duration_s=trajectory.duration,
        samples=int(t.size),
        rate_hz=float(rate_hz),
        tolerances=tol,
        skipped=skipped,
        elapsed_s=time.perf_counter() - start,
        advisory=tuple(a for a in advisory if a in collector.checks),
        torques=torques,
    )


def _torque_check(
    collector: _Collector, dynamics: TorqueModel, q: Array, qd: Array, qdd: Array, names: list[str]
) -> TorqueSummary:
    """``torque``: |τ_j| / τ_max,j ≤ 1 at every sample, τ = ``dynamics.torques(q, q̇, q̈)`` (N·m);
    recorded only when the robot has limits. Returns the peaks per joint either way."""
    tau = np.abs(dynamics.torques(q, qd, qdd))
    peak = _worst_per_joint(tau)
    peaks = tuple(float(tau[k, j]) for j, k in enumerate(peak))
    times = tuple(float(collector.t[k]) for k in peak)
    limit = dynamics.torque_limit
    if limit is None:
        return TorqueSummary(tuple(names), peaks, times, None, None, dynamics.torque_limit_source)
    tau_max = np.asarray(limit, float)
    ratio = tau / tau_max
    collector.joint_check(
        "torque",
        "largest |τ_j| / torque_limit_j (inverse dynamics, the lamp included)",
        "",
        ratio,
        np.ones(tau_max.size),
        lambda j, k: (
            f"joint {names[j]}: |τ| = {tau[k, j]:.4g} N·m > its limit {tau_max[j]:.4g} N·m at t = {collector.t[k]:.4f} s"
        ),
        value=lambda j, k: tau[k, j],
        limit=lambda j, k: tau_max[j],
    )
    fraction = tuple(p / float(m) for p, m in zip(peaks, tau_max, strict=True))
    return TorqueSummary(tuple(names), peaks, times, tuple(tau_max.tolist()), fraction, dynamics.torque_limit_source)


def _worst_per_joint(x: Array) -> list[int]:
    """Per column of x (T, n), the sample of its first NaN, else of its maximum."""
    return [_worst(x[:, j]) for j in range(x.shape[1])]


def _continuity_check(
    collector: _Collector, trajectory: Trajectory, jmax: Array, rate_hz: float, tol: Tolerances, names: list[str]
) -> None:
    """``acceleration_continuity`` on the controller grid t_k = k / rate_hz: the ratio of each jump
    |q̈_j(t_{k+1}) − q̈_j(t_k)| to j_max,j Δt_k (Δt_k = 1 / rate_hz but the last), recorded at t_{k+1}."""
    grid = np.arange(int(np.floor(trajectory.duration * rate_hz + 1e-9)) + 1) / rate_hz
    if grid[-1] < trajectory.duration - 1e-12:
        grid = np.append(grid, trajectory.duration)
    if grid.size < 2:
        return
    qdd = trajectory.sample(grid)[2]
    jump = np.abs(np.diff(qdd, axis=0))
    allowed = jmax * np.diff(grid)[:, None]
    ratio = jump / allowed
    sample_times, collector.t = collector.t, grid[1:]  # this check's samples are the controller grid
    collector.joint_check(
        "acceleration_continuity",
        "largest |Δq̈_j| / (jerk_limit_j Δt) between controller samples",
        "",
        ratio,
        np.full(jmax.size, 1.0 + tol.limit_rel),
        lambda j, k: (
            f"joint {names[j]}: q̈ jumps by {jump[k, j]:.6g} rad/s² between t = {grid[k]:.4f} and "
            f"{grid[k + 1]:.4f} s, {ratio[k, j]:.3g}× what jerk_limit {jmax[j]:.6g} rad/s³ allows"
        ),
        value=lambda j, k: jump[k, j],
        limit=lambda j, k: allowed[k, j] * (1 + tol.limit_rel),
    )
    collector.t = sample_times


def _view_checks(collector: _Collector, report: Any) -> None:
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


def _environment_checks(collector: _Collector, report: Any, samples: int) -> None:
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


def quintic_hermite(t_points: ArrayLike, q: ArrayLike, qd: ArrayLike, qdd: ArrayLike, t: ArrayLike) -> Array:
    """Positions (T, n) at times t (T,) of the quintic Hermite interpolation of points
    (t_k, q_k, q̇_k, q̈_k) (K,) and (K, n) each: on [t_k, t_{k+1}], h = t_{k+1} − t_k, x = (t − t_k)/h,

        q̂ = H₀ q_k + H₁ h q̇_k + H₂ h² q̈_k + H₃ q_{k+1} + H₄ h q̇_{k+1} + H₅ h² q̈_{k+1},
        H₀ = 1 − 10x³ + 15x⁴ − 6x⁵,  H₁ = x − 6x³ + 8x⁴ − 3x⁵,  H₂ = (x² − 3x³ + 3x⁴ − x⁵)/2,
        H₃ = 10x³ − 15x⁴ + 6x⁵,      H₄ = −4x³ + 7x⁴ − 3x⁵,     H₅ = (x³ − 2x⁴ + x⁵)/2,

    the basis whose values and first two derivatives at x = 0 and 1 pick out one of the six end
    values each. NaN outside [t_0, t_K] (a time the points do not cover)."""
    tp = np.asarray(t_points, float)
    q, qd, qdd = (np.asarray(a, float) for a in (q, qd, qdd))
    times = np.asarray(t, float)
    k = np.clip(np.searchsorted(tp, times, side="right") - 1, 0, tp.size - 2)
    h = (tp[k + 1] - tp[k])[:, None]
    x = (times - tp[k])[:, None] / h
    x2, x3 = x * x, x * x * x
    x4, x5 = x3 * x, x3 * x2
    basis = (
        1 - 10 * x3 + 15 * x4 - 6 * x5,
        x - 6 * x3 + 8 * x4 - 3 * x5,
        0.5 * (x2 - 3 * x3 + 3 * x4 - x5),
        10 * x3 - 15 * x4 + 6 * x5,
        -4 * x3 + 7 * x4 - 3 * x5,
        0.5 * (x3 - 2 * x4 + x5),
    )
    ends = (q[k], h * qd[k], h**2 * qdd[k], q[k + 1], h * qd[k + 1], h**2 * qdd[k + 1])
    out = sum(b * e for b, e in zip(basis, ends, strict=True))
    outside = (times < tp[0] - 1e-9) | (times > tp[-1] + 1e-9)
    return np.where(outside[:, None], np.nan, out)


def distance_to_polyline(points: ArrayLike, polyline: ArrayLike) -> Array:
    """Euclidean distance (m) from each of the points (P, 3) to the polyline through (K, 3) vertices
    (a single vertex is a point): min over segments [v_i, v_{i+1}] of |p − (v_i + c (v_{i+1} − v_i))|,
    c = clip((p − v_i)·d_i / |d_i|², 0, 1).

    Only the segments that can be nearest are measured: the nearest vertex, at r₀, bounds the
    distance, and a segment with a point within r₀ of p has its start within r₀ + max_i |d_i| of p
    (a k-d tree finds those). Exact, and O(P log K) for the even knots of a plan instead of O(P K)
    (576 captures: 30 s of the verification). The long segments (a transfer's) are first cut into
    pieces (:func:`_even_segments`), so that max_i |d_i| does not widen every point's search."""
    points = np.asarray(points, float).reshape(-1, 3)
    v = np.asarray(polyline, float).reshape(-1, 3)
    out = np.full(len(points), np.nan)  # a NaN point or vertex: NaN, which fails the check
    if len(v) == 1 or not np.isfinite(v).all():
        return np.linalg.norm(points - v[0], axis=1) if len(v) == 1 else out
    v = _even_segments(v)
    # a run of equal points (a dwell's) is measured once, at its first
    finite = np.flatnonzero(np.isfinite(points).all(axis=1))
    first, source = _equal_runs(points, finite)
    p = points[first]
    a, d = v[:-1], np.diff(v, axis=0)
    dd = np.maximum(np.einsum("ij,ij->i", d, d), 1e-300)
    bound = (cKDTree(v).query(p)[0] + math.sqrt(float(dd.max()))) * (1.0 + 1e-9) + 1e-12  # rounding
    starts = cKDTree(a)
    for s in range(0, len(p), _CHUNK):
        near = starts.query_ball_point(p[s : s + _CHUNK], bound[s : s + _CHUNK])
        counts = np.fromiter(map(len, near), np.int64, len(near))
        segment = np.concatenate(near).astype(np.int64)
        rel = np.repeat(p[s : s + _CHUNK], counts, axis=0) - a[segment]
        c = np.clip(np.einsum("ck,ck->c", rel, d[segment]) / dd[segment], 0.0, 1.0)
        distance = np.linalg.norm(rel - c[:, None] * d[segment], axis=1)
        out[first[s : s + _CHUNK]] = np.minimum.reduceat(distance, np.r_[0, np.cumsum(counts)[:-1]])
    out[finite] = out[source]
    return out


def _equal_runs(rows: Array, index: NDArray[np.intp]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """The runs of equal consecutive rows among ``rows[index]`` (``index`` increasing): the index of
    each run's first row, and for each entry of ``index`` the first row of its run."""
    if index.size == 0:
        return index, index
    first = index[np.r_[True, (rows[index[1:]] != rows[index[:-1]]).any(axis=1)]]
    return first, first[np.searchsorted(first, index, side="right") - 1]


def _even_segments(v: Array) -> Array:
    """The polyline through the vertices v (K, 3) with every segment longer than twice the median
    (of the non-zero lengths) cut into equal pieces no longer than that: the same points, so the
    same distances to it."""
    lengths = np.linalg.norm(np.diff(v, axis=0), axis=1)
    positive = lengths[lengths > 0]
    if positive.size == 0:
        return v
    pieces = np.ceil(lengths / (2.0 * float(np.median(positive)))).astype(np.int64).clip(min=1)
    if (pieces == 1).all():
        return v
    segment = np.repeat(np.arange(lengths.size), pieces)
    step = np.arange(pieces.sum()) - np.repeat(np.cumsum(pieces) - pieces, pieces)
    fraction = (step / pieces[segment])[:, None]
    return np.vstack([v[segment] + fraction * (v[segment + 1] - v[segment]), v[-1:]])


# --------------------------------------------------------------------------------------------


def _verification_times(trajectory: Trajectory, rate_hz: float) -> Array:
    """Uniform samples and boundaries (from :meth:`Trajectory.sample_times`), the instants just
    before each boundary (q̈ jumps there), and the capture times."""
    base = trajectory.sample_times(rate_hz)
    before = trajectory.boundaries - 1e-7
    extra = np.concatenate([before[before > 0], trajectory.capture_times])
    return np.unique(np.concatenate([base, extra]))


def _per_joint(value: ArrayLike, n: int, name: str) -> Array:
    x = np.asarray(value, float)
    if x.shape not in ((), (n,)) or np.isnan(x).any():
        raise ValueError(f"{name} must be one or {n} numbers, got {x}")
    return np.broadcast_to(x, (n,)).copy()


def _runs(bad: NDArray[np.bool_], index: NDArray[np.intp] | None = None) -> list[tuple[int, int]]:
    """(start, stop) ranges of the runs of True in a 1-D boolean array; with ``index`` (the sample
    numbers of the entries) a run also ends where the sample numbers are not consecutive."""
    link = bad[:-1] & bad[1:]
    if index is not None:
        link &= np.diff(index) == 1
    starts = np.flatnonzero(bad & ~np.concatenate([[False], link]))
    stops = np.flatnonzero(bad & ~np.concatenate([link, [False]])) + 1
    return list(zip(starts.tolist(), stops.tolist(), strict=True))


class _Collector:
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
            for a, b in _runs(bad[:, j]):
                episodes.append((a, a + _worst(measure[a:b, j]), j))
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
            k, j = (int(i) for i in np.unravel_index(_worst(measure.ravel()), measure.shape))
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
        runs = _runs(bad, index)
        for a, b in runs[:MAX_EPISODES]:
            w = a + _worst(measure[a:b])
            k = int(index[w])
            self.violations.append(
                Violation(
                    name, float(self.t[k]), None, float(measure[w]), threshold, message(k, float(measure[w]))
                )
            )
        w = _worst(measure) if measure.size else -1
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


def _worst(x: Array) -> int:
    """Index of the first NaN of a 1-D array, else of its maximum."""
    nan = np.flatnonzero(np.isnan(x))
    return int(nan[0]) if nan.size else int(np.argmax(x))
