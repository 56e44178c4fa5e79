"""The blur of each capture (``blur_angle``, ``blur_distance``): how far the light turns about the
object's centre and how far it travels while the camera exposes, measured on the trajectory itself
by dense sampling of each exposure window, whatever bounded the speed there."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.motion import Exposure, Trajectory
from optlight.verify.collector import Collector
from optlight.verify.light import LightPose

Array = NDArray[np.float64]

#: Samples per exposure window (the light's path within a few milliseconds is all but straight).
WINDOW_SAMPLES = 65


def exposure_blur(
    trajectory: Trajectory, windows: ArrayLike, light_pose: LightPose, center: ArrayLike
) -> tuple[Array, Array]:
    """(angle (M,) rad, distance (M,) m): per exposure window [t0, t1] of ``windows`` (M, 2), the
    light's positions p_k at :data:`WINDOW_SAMPLES` equally spaced times, the angle its direction
    from the centre O turns, Σ_k ∠(p_k − O, p_{k+1} − O), and the length of its path, Σ_k |p_{k+1} − p_k|
    (each at least the largest angle or distance between two moments of the exposure)."""
    w = np.asarray(windows, float).reshape(-1, 2)
    if w.shape[0] == 0:
        return np.zeros(0), np.zeros(0)
    times = w[:, :1] + (w[:, 1:] - w[:, :1]) * np.linspace(0.0, 1.0, WINDOW_SAMPLES)[None]
    q = trajectory.sample(times.ravel())[0]
    p = np.array([light_pose(theta)[0] for theta in q]).reshape(*times.shape, 3)
    r = p - np.asarray(center, float)
    u = r / np.linalg.norm(r, axis=2, keepdims=True)
    cross = np.linalg.norm(np.cross(u[:, :-1], u[:, 1:]), axis=2)
    angle = np.arctan2(cross, np.sum(u[:, :-1] * u[:, 1:], axis=2)).sum(axis=1)
    return angle, np.linalg.norm(np.diff(p, axis=1), axis=2).sum(axis=1)


def capture_exposures(
    trajectory: Trajectory, settle_s: float, exposure_s: float, light_pose: LightPose, center: ArrayLike
) -> tuple[Array, Array, Array]:
    """(windows (M, 2) s, angles (M,) rad, distances (M,) m): each capture's exposure window
    (:meth:`Trajectory.exposure_windows`) and the blur measured on it (:func:`exposure_blur`), as
    captures.csv gives them."""
    windows = trajectory.exposure_windows(settle_s, exposure_s)
    return (windows, *exposure_blur(trajectory, windows, light_pose, center))


def blur_checks(
    collector: Collector,
    trajectory: Trajectory,
    windows: ArrayLike,
    exposure: Exposure,
    light_pose: LightPose,
    center: ArrayLike,
) -> None:
    """``blur_angle`` ≤ exposure.blur_rad and ``blur_distance`` ≤ exposure.blur_m at every capture,
    reported at the sample of the capture's time (:attr:`Trajectory.capture_times`)."""
    angle, distance = exposure_blur(trajectory, windows, light_pose, center)
    index = np.searchsorted(collector.t, trajectory.capture_times).clip(0, collector.t.size - 1)
    for name, measure, limit, unit, what in (
        ("blur_angle", angle, exposure.blur_rad, "rad", "angle the light turns about the object's centre"),
        ("blur_distance", distance, exposure.blur_m, "m", "distance the light travels"),
    ):
        collector.scalar_check(name, f"largest {what} during an exposure", unit, measure, limit, index, _message(collector, what, unit))


def _message(collector: Collector, what: str, unit: str) -> Callable[[int, float], str]:
    """The violation message of a blur check: (sample k, value) -> text."""

    def message(k: int, value: float) -> str:
        return f"{what} during the exposure of the capture at t = {collector.t[k]:.4f} s is {value:.4g} {unit}"

    return message
