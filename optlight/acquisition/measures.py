"""What the loop judges a round by: the measured and modelled costs of its captures and, with a
light set, the set's own measure (:func:`round_measure`); and the rule that a round improves on
another (:func:`improves`)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.capture import Capture
from optlight.capture.calibration import Calibration, calibrated_setup
from optlight.photometric_stereo import gbuffer_normal_map, recover_from_scene
from optlight.plan import Plan
from optlight.planning.lightsets import Cap, coverage
from optlight.setup import Setup

Array = NDArray[np.float64]

def measured_costs(setup: Setup, captures: Sequence[Capture]) -> Array:
    """The problem's objective (``setup.objective``, camera resolution) on each recorded image."""
    index = setup.scene.gbuffer.pixel_index
    return np.array([setup.objective.numpy(c.image.ravel()[index]) for c in captures])


def modelled_costs(model: Setup, positions: ArrayLike) -> Array:
    """The objective on ``model``'s own images (NumPy renderer, shadow rays) at light ``positions``."""
    return np.array([model.objective.numpy(model.scene.pixels(a)) for a in np.asarray(positions, float)])


#: What the loop judges a round by, per ``[lightset] kind`` (:func:`round_measure`); lower is better.
MEASURES = {
    "none": "measured cost",
    "photometric_stereo": "photometric-stereo normal error (deg)",
    "rti": "RTI covering radius (deg)",
    "grid": "grid angular error (deg)",
}


def round_measure(setup: Setup, plan: Plan, captures: Sequence[Capture], calibration: Calibration | None) -> float:
    """The measure of a round (:data:`MEASURES`, by ``[lightset] kind``; lower is better):

    - no light set: the mean over the captures of the problem's objective on the recorded images;
    - photometric_stereo: the mean over the object's pixels of the angle (deg) between the normal
      photometric stereo recovers from the recorded images and the model's (G-buffer) normal, 90°
      where it recovers none (fewer than three usable lights): the images linearised by the
      ``calibration``'s response γ, its ambient image subtracted, its light power as the lights'
      strength, the lights where the robot put them (directions from the object's centre, the
      directional model; :func:`~optlight.photometric_stereo.recover_from_scene`);
    - rti: the covering radius (deg) of the captured lights on the allowed cap (every point of the
      cap within it of a light; :func:`~optlight.planning.lightsets.coverage`);
    - grid: the largest angle (deg) between a grid direction and the light captured for it (the
      plan's grid report: the captures are at the plan's lights)."""
    spec = setup.problem.lightset
    if spec.kind == "none":
        return float(np.mean(measured_costs(setup, captures)))
    if spec.kind == "grid":
        return float((plan.lightset or {}).get("grid", {}).get("max_moved_deg", 0.0))
    sphere = setup.sphere
    d = np.array([c.light_position for c in captures]) - sphere.center
    directions = (d / np.linalg.norm(d, axis=1, keepdims=True)) @ sphere.rotation  # sphere frame
    if spec.kind == "rti":
        return coverage(directions, Cap(sphere.zenith_min, sphere.zenith_max))["covering_radius_deg"]
    scene = (setup if calibration is None else calibrated_setup(setup, calibration)).scene
    images = np.stack([c.image for c in captures])  # linearised by the calibrated response
    recovery = recover_from_scene(scene, directions, images, spec.dark_level, spec.saturation_level)
    error = recovery.angular_error(gbuffer_normal_map(setup.scene))[scene.gbuffer.mask]
    return float(np.mean(np.where(np.isnan(error), 90.0, error)))


def improves(cost: float, kept: float, tolerance: float) -> bool:
    """A measured ``cost`` is an improvement on the ``kept`` one when it is at least ``tolerance``
    (relative) below it: the loop's stop rule and its choice of plan. A smaller decrease is within
    what the camera's noise makes."""
    return cost < kept * (1.0 - tolerance)
