"""The landmark sweep (docs/design.md §5): the objective of the NumPy render with shadow rays at a
light position (:func:`exact_cost`), over a grid of zeniths per azimuth (:func:`sweep_costs`), and
the sweep's local minima that seed the refinements.
"""

from __future__ import annotations

import math
from functools import partial

import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.geometry import LightSphere
from optlight.objectives import Objective
from optlight.planning.landmarks.types import Array, Progress
from optlight.scene import Scene
from optlight.threads import in_background

# --------------------------------------------------------------------------------------------
# Evaluation with the NumPy renderer
# --------------------------------------------------------------------------------------------


def exact_cost(scene: Scene, objective: Objective, position: ArrayLike) -> float:
    """The objective of the NumPy render (shadow rays) with the light at ``position`` (world, m)."""
    return objective.numpy(scene.pixels(position))


def sweep_costs(
    scene: Scene,
    objective: Objective,
    zenith: ArrayLike,
    azimuth: ArrayLike,
    progress: Progress | None = None,
) -> Array:
    """The objective at every (azimuth[j], zenith[i]) (rad), shape (M, N): NumPy renderer with shadow
    rays at every sample, the histograms of one azimuth batched. ``progress(j + 1, M)`` after each
    azimuth."""
    zenith, azimuth = np.atleast_1d(np.asarray(zenith, float)), np.atleast_1d(np.asarray(azimuth, float))
    out = np.empty((azimuth.size, zenith.size))
    pole = includes_pole(zenith) and azimuth.size > 1
    # an azimuth's objective is computed in the background while the next one's shadow rays are
    # cast (on both threads): the objective alone would leave a core idle; the same numbers either way
    pending = None
    for j, phi in enumerate(azimuth):
        rest = zenith[1:] if pole and j else zenith  # the pole is the first azimuth's
        positions = scene.sphere.position(rest, float(phi))
        masks = scene.visibility(positions)
        if pending is not None:
            out[j - 1, -pending[1] :] = pending[0].result()
            if progress is not None:
                progress(j, azimuth.size)
        pending = in_background(partial(sweep_objective, scene, objective, positions, masks)), rest.size
    if pending is not None:
        out[-1, -pending[1] :] = pending[0].result()
        if progress is not None:
            progress(azimuth.size, azimuth.size)
    if pole:
        out[1:, 0] = out[0, 0]
    return out


def includes_pole(zenith: Array) -> bool:
    """Whether the first of the (sorted) sweep zeniths is the pole, θ = 0: the one light all azimuths
    share (a(0, φ) does not depend on φ, to the bit), which a sweep renders once."""
    return bool(zenith.size) and zenith[0] == 0.0


def sweep_objective(scene: Scene, objective: Objective, positions: Array, masks: Array) -> Array:
    """The objective (N,) of the renders with the lights at ``positions`` (N, 3) and the visibility
    ``masks`` (N, P)."""
    return objective.numpy_batch(np.stack([scene.pixels(a, v) for a, v in zip(positions, masks, strict=True)]))


def zenith_grid(sphere: LightSphere, step: float) -> Array:
    """Zeniths from ``zenith_min`` to ``zenith_max`` (both included), at most ``step`` (rad) apart."""
    n = max(1, math.ceil((sphere.zenith_max - sphere.zenith_min) / step - 1e-9))
    return np.linspace(sphere.zenith_min, sphere.zenith_max, n + 1)


def local_minima(values: ArrayLike) -> NDArray[np.intp]:
    """Indices of the local minima of a 1-D sequence (ends included, plateaus give their first
    index), lowest first."""
    c = np.asarray(values, float)
    left = np.r_[np.inf, c[:-1]]
    right = np.r_[c[1:], np.inf]
    idx = np.flatnonzero((c < left) & (c <= right))
    return idx[np.argsort(c[idx], kind="stable")]
