"""The verification composed: the samples of a timed plan and every check run on them in one place,
the limits, the light, the controller's interpolation, the torques, the environment and the view
(the checks themselves are in the sibling modules; the package docstring lists them)."""

from __future__ import annotations

import time

import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.geometry import LightSphere
from optlight.motion import Exposure, Trajectory
from optlight.verify.blur import blur_checks
from optlight.verify.collector import Collector
from optlight.verify.environment import EnvironmentCheck, ViewCheck, environment_checks, view_checks
from optlight.verify.interpolation import ControllerPoints, interpolation_check
from optlight.verify.light import LightPose, light_checks
from optlight.verify.limits import joint_limits, limit_checks
from optlight.verify.report import Tolerances, TorqueSummary, VerificationReport
from optlight.verify.torques import TorqueModel, torque_check

Array = NDArray[np.float64]


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
    exposure: Exposure | None = None,
    exposure_windows: ArrayLike | None = None,
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
        exposure: the camera's exposure and blur tolerances, or None to skip the ``blur_angle`` and
            ``blur_distance`` checks.
        exposure_windows: (M, 2) start and end (s) of each capture's exposure
            (:meth:`Trajectory.exposure_windows`); None: centred on the capture times.
        advisory: names of checks reported without deciding the verdict.
        rate_hz: resampling rate, at least 1000 Hz; also the controller grid of the continuity check.
        tol: the tolerances.
    """
    start = time.perf_counter()
    limits = joint_limits(trajectory.dof, lower, upper, velocity_limit, acceleration_limit, jerk_limit)
    landmarks = _landmarks(landmark_positions, trajectory)
    if rate_hz < 1000.0:
        raise ValueError(f"rate_hz must be at least 1000 Hz, got {rate_hz}")

    collector, (q, qd, qdd) = _sampled(trajectory, rate_hz)

    skipped = limit_checks(collector, trajectory, (q, qd, qdd), limits, rate_hz, tol)
    skipped += light_checks(collector, trajectory, q, light_pose, sphere, landmarks, planned_path, transfers, tol)
    if waypoints is not None:
        interpolation_check(collector, waypoints, q, tol)
    else:
        skipped += ("interpolation",)
    torques: TorqueSummary | None = None
    if dynamics is not None:
        torques = torque_check(collector, dynamics, q, qd, qdd, collector.names)
    if torques is None or torques.limit_nm is None:
        skipped += ("torque",)
    if exposure is not None:
        windows = (
            trajectory.capture_times[:, None] + exposure.seconds * np.array([-0.5, 0.5])
            if exposure_windows is None
            else exposure_windows
        )
        blur_checks(collector, trajectory, np.clip(windows, 0.0, trajectory.duration), exposure, light_pose, sphere.center)
    else:
        skipped += ("blur_angle", "blur_distance")
    skipped += _surroundings_checks(collector, trajectory, q, environment, view)

    return VerificationReport(
        checks=collector.checks,
        violations=tuple(collector.violations),
        duration_s=trajectory.duration,
        samples=int(collector.t.size),
        rate_hz=float(rate_hz),
        tolerances=tol,
        skipped=skipped,
        elapsed_s=time.perf_counter() - start,
        advisory=tuple(a for a in advisory if a in collector.checks),
        torques=torques,
    )


def _sampled(trajectory: Trajectory, rate_hz: float) -> tuple[Collector, tuple[Array, Array, Array]]:
    """A collector at the verification's sample times (:func:`_verification_times`), and q, q̇, q̈ there."""
    t = _verification_times(trajectory, rate_hz)
    n = trajectory.dof
    names = list(trajectory.joint_names) if trajectory.joint_names else [f"j{i}" for i in range(n)]
    return Collector(t, names), trajectory.sample(t)


def _surroundings_checks(
    collector: Collector,
    trajectory: Trajectory,
    q: Array,
    environment: EnvironmentCheck | None,
    view: ViewCheck | None,
) -> tuple[str, ...]:
    """The environment's checks at the samples q and the view and beam checks at the captures, each
    when given. Returns the names of the checks skipped."""
    if environment is not None:
        environment_checks(collector, environment(q, collector.t, trajectory.capture_times), collector.t.size)
    if view is None:
        return ("view", "beam")
    captures = trajectory.capture_times
    view_checks(collector, view(trajectory.sample(captures)[0], captures))
    return ()


def _landmarks(landmark_positions: ArrayLike, trajectory: Trajectory) -> Array:
    """The landmark positions as (M, 3), one per dwell of the trajectory (ValueError otherwise)."""
    landmarks = np.asarray(landmark_positions, float).reshape(-1, 3)
    intervals = trajectory.landmark_intervals
    if landmarks.shape[0] != intervals.shape[0]:
        raise ValueError(
            f"{landmarks.shape[0]} landmark positions for a trajectory with {intervals.shape[0]} dwells"
        )
    return landmarks


def _verification_times(trajectory: Trajectory, rate_hz: float) -> Array:
    """Uniform samples and boundaries (from :meth:`Trajectory.sample_times`), the instants just
    before each boundary (q̈ jumps there), and the capture times."""
    base = trajectory.sample_times(rate_hz)
    before = trajectory.boundaries - 1e-7
    extra = np.concatenate([before[before > 0], trajectory.capture_times])
    return np.unique(np.concatenate([base, extra]))
