"""The light: on the sphere and aimed at the object throughout every dwell (``h``, ``aim``,
``landmark``, docs/design.md §3), along the planned path between the captures (``path``) and off the
sphere on the transfers (``outside``)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.geometry import LightSphere, h_residual
from optlight.motion import Trajectory
from optlight.verify.collector import Collector
from optlight.verify.polyline import distance_to_polyline, equal_runs
from optlight.verify.report import Tolerances

Array = NDArray[np.float64]
LightPose = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class LightSamples:
    """Where each sample stands in the plan: ``dwell_of`` (T,) the dwell's index or −1, and the sample
    indices in a dwell (``in_dwell``), on the planned path (``on_path``: from the first capture to the
    last, the transfers aside) and on a transfer (``in_transfer``); ``pose_at`` the samples whose light
    pose a check needs."""

    dwell_of: NDArray[np.intp]
    in_dwell: NDArray[np.intp]
    on_path: NDArray[np.intp]
    in_transfer: NDArray[np.intp]
    pose_at: NDArray[np.intp]


def light_checks(
    collector: Collector,
    trajectory: Trajectory,
    q: Array,
    light_pose: LightPose,
    sphere: LightSphere,
    landmarks: Array,
    planned_path: ArrayLike | None,
    transfers: ArrayLike | None,
    tol: Tolerances,
) -> tuple[str, ...]:
    """``h``, ``aim`` and ``landmark`` during the dwells, ``path`` when a planned path is given and
    ``outside`` on the transfers. Returns the names of the checks skipped."""
    samples = light_samples(collector.t, trajectory.landmark_intervals, transfers, planned_path is not None)
    positions, rotations = light_poses(q, light_pose, samples.pose_at)
    dwell_checks(collector, positions, rotations, samples, sphere, landmarks, tol)
    skipped: tuple[str, ...] = ()
    if planned_path is not None:
        path_check(collector, positions, samples.on_path, planned_path, tol)
    else:
        skipped += ("path",)
    if samples.in_transfer.size:
        outside_check(collector, positions, samples.in_transfer, sphere, tol)
    return skipped


def light_samples(t: Array, intervals: Array, transfers: ArrayLike | None, path_needed: bool) -> LightSamples:
    """Classify the samples t (sorted) by the dwells ``intervals`` (M, 2) and the transfers (M − 1,).

    The planned path runs from the first capture to the last; the approach and the return (joint-space
    transfers to and from the start configuration) are checked by the limits and the environment (and so
    are the transfers between two captures, which must also stay outside the sphere)."""
    # the last dwell starting (less 1e-12 s) at or before each sample, when the sample is also within
    # its end (plus 1e-12 s); t and the dwells are sorted
    dwell_of = np.searchsorted(intervals[:, 0] - 1e-12, t, side="right") - 1
    dwell_of[(dwell_of >= 0) & (t > intervals[np.maximum(dwell_of, 0), 1] + 1e-12)] = -1
    off_sphere = np.zeros(t.size, bool)
    for s in np.flatnonzero(np.zeros(len(intervals) - 1, bool) if transfers is None else transfers):
        off_sphere |= (t > intervals[s, 1] + 1e-12) & (t < intervals[s + 1, 0] - 1e-12)
    path_times = (t >= intervals[0, 0] - 1e-12) & (t <= intervals[-1, 1] + 1e-12) & ~off_sphere
    return LightSamples(
        dwell_of=dwell_of,
        in_dwell=np.flatnonzero(dwell_of >= 0),
        on_path=np.flatnonzero(path_times),
        in_transfer=np.flatnonzero(off_sphere),
        pose_at=np.flatnonzero((path_times if path_needed else False) | (dwell_of >= 0) | off_sphere),
    )


def light_poses(q: Array, light_pose: LightPose, pose_at: NDArray[np.intp]) -> tuple[Array, Array]:
    """Light positions (T, 3) and rotations (T, 3, 3) at the samples ``pose_at`` (NaN elsewhere)."""
    positions = np.full((q.shape[0], 3), np.nan)
    rotations = np.full((q.shape[0], 3, 3), np.nan)
    # a dwell's samples hold one configuration: its pose computed once (the same q, the same pose)
    changes, source = equal_runs(q, pose_at)
    for k in changes:
        positions[k], rotations[k] = light_pose(q[k])
    positions[pose_at], rotations[pose_at] = positions[source], rotations[source]
    return positions, rotations


def dwell_checks(
    collector: Collector,
    positions: Array,
    rotations: Array,
    samples: LightSamples,
    sphere: LightSphere,
    landmarks: Array,
    tol: Tolerances,
) -> None:
    """At every dwell sample, with (a, R) the light's pose: ``h`` |Rᵀ(O − a) − [0, 0, b]| ≤ h_m,
    ``aim`` the angle between R e_z and O − a ≤ aim_rad, ``landmark`` |a − p_i| ≤ landmark_m."""
    in_dwell, dwell_of, t = samples.in_dwell, samples.dwell_of, collector.t
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


def path_check(
    collector: Collector, positions: Array, on_path: NDArray[np.intp], planned_path: ArrayLike, tol: Tolerances
) -> None:
    """``path``: the distance from every light position on the path to the polyline of planned light
    positions ≤ path_m."""
    t = collector.t
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


def outside_check(
    collector: Collector, positions: Array, in_transfer: NDArray[np.intp], sphere: LightSphere, tol: Tolerances
) -> None:
    """``outside``: on the transfers, the light's depth inside the sphere b − |a − O| ≤ path_m."""
    t = collector.t
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
