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
- with the camera's exposure (:class:`optlight.motion.Exposure`, the windows of the captures'
  exposures): ``blur_angle`` and ``blur_distance``, the angle (rad) the light turns about the sphere's
  centre and the distance (m) it travels during each exposure, measured on 65 samples of the window
  (:func:`exposure_blur`), against the exposure's blur tolerances;
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

from optlight.verify.blur import capture_exposures, exposure_blur
from optlight.verify.checks import verify_trajectory
from optlight.verify.environment import ENVIRONMENT_CHECKS, EnvironmentCheck, ViewCheck
from optlight.verify.interpolation import quintic_hermite
from optlight.verify.polyline import distance_to_polyline
from optlight.verify.report import (
    MAX_EPISODES,
    CheckResult,
    Tolerances,
    TorqueSummary,
    VerificationReport,
    Violation,
    ensure_verified,
)

__all__ = [
    "ENVIRONMENT_CHECKS",
    "MAX_EPISODES",
    "CheckResult",
    "EnvironmentCheck",
    "Tolerances",
    "TorqueSummary",
    "VerificationReport",
    "ViewCheck",
    "Violation",
    "capture_exposures",
    "distance_to_polyline",
    "ensure_verified",
    "exposure_blur",
    "quintic_hermite",
    "verify_trajectory",
]
