"""The keyframes of the preview's animation: of the poses at ``fps`` frames per second, only those the
viewer's interpolation (positions linearly, orientations by slerp) needs to stay within
:data:`KEY_TOLERANCE_M` and :data:`KEY_TOLERANCE_RAD` of every frame (:func:`select_keyframes`)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

#: How far (m) and how much (rad) the viewer's interpolation between the kept keyframes may move a
#: link or the light from its pose at any frame: well below a pixel at the preview's scale.
KEY_TOLERANCE_M = 5e-4
KEY_TOLERANCE_RAD = np.radians(0.1)


def animation_times(duration: float, fps: float) -> Array:
    """Frame times 0, 1/fps, 2/fps, … (s), with a last frame at ``duration`` when it falls between."""
    times = np.arange(int(np.floor(duration * fps + 1e-9)) + 1) / fps
    if duration - times[-1] > 1e-9:
        times = np.append(times, duration)
    return times


def continuous_quaternions(quaternions: ArrayLike) -> Array:
    """Unit quaternions (T, N, 4), one sequence over T per node, with signs flipped where needed so
    that consecutive ones have a non-negative dot product (q and −q are the same rotation)."""
    q = np.array(quaternions, float)
    for t in range(1, len(q)):
        q[t] *= np.where(np.einsum("nk,nk->n", q[t], q[t - 1]) < 0.0, -1.0, 1.0)[:, None]
    return q


def slerp(q0: Array, q1: Array, s: Array) -> Array:
    """Spherical interpolation between unit quaternions q0, q1 (N, 4) at fractions s (T,): (T, N, 4),
    along the shorter arc (as three.js's ``Quaternion.slerpFlat``)."""
    dot = np.einsum("nk,nk->n", q0, q1)
    q1 = np.where(dot[:, None] < 0.0, -q1, q1)
    angle = np.arccos(np.clip(np.abs(dot), -1.0, 1.0))
    sin = np.sin(angle)
    near = sin < 1e-9  # (almost) the same rotation: linear interpolation is exact to first order
    safe = np.where(near, 1.0, sin)
    w0 = np.where(near, 1.0 - s[:, None], np.sin((1.0 - s[:, None]) * angle) / safe)
    w1 = np.where(near, s[:, None], np.sin(s[:, None] * angle) / safe)
    out = w0[..., None] * q0 + w1[..., None] * q1
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def select_keyframes(
    times: ArrayLike, positions: ArrayLike, quaternions: ArrayLike, tolerance_m: float, tolerance_rad: float
) -> NDArray[np.int64]:
    """Indices of the frames to keep as keyframes, first and last included: greedily, each keyframe
    is followed by the furthest frame such that interpolating every node between the two (positions
    linearly, quaternions by :func:`slerp`, as the viewer does) stays within ``tolerance_m`` (m) and
    ``tolerance_rad`` (rad) of each frame between them.

    ``times`` (T,) increasing, ``positions`` (T, N, 3), ``quaternions`` (T, N, 4) unit."""
    t = np.asarray(times, float)
    p = np.asarray(positions, float)
    q = np.asarray(quaternions, float)
    keys = [0]
    start = 0
    while start < len(t) - 1:
        end = start + 1
        while end + 1 < len(t) and _interpolates(t, p, q, start, end + 1, tolerance_m, tolerance_rad):
            end += 1
        keys.append(end)
        start = end
    return np.asarray(keys, np.int64)


def _interpolates(t: Array, p: Array, q: Array, i: int, j: int, tolerance_m: float, tolerance_rad: float) -> bool:
    """Whether keyframes at frames i and j alone reproduce every frame between them within tolerance."""
    s = (t[i + 1 : j] - t[i]) / (t[j] - t[i])
    position_error = np.linalg.norm(p[i] + s[:, None, None] * (p[j] - p[i]) - p[i + 1 : j], axis=-1)
    dot = np.abs(np.einsum("tnk,tnk->tn", slerp(q[i], q[j], s), q[i + 1 : j]))
    angle_error = 2.0 * np.arccos(np.clip(dot, -1.0, 1.0))
    return bool(position_error.max() <= tolerance_m and angle_error.max() <= tolerance_rad)
