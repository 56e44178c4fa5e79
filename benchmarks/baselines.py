"""Baselines the benchmarks compare against.

:func:`paper_sweep` is the paper's own landmark search (Section 4): along each of ``M`` equally spaced
azimuths, move the zenith over [θ_min, θ_max] in fine steps (0.5° by default), render every sample
with the NumPy renderer and shadow rays at the camera's resolution, and keep the zenith of the
lowest objective. Exhaustive, no derivatives, no seeds.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from optlight.objectives import Objective
from optlight.planning.landmarks import CostGrid, Progress, sweep_costs, zenith_grid
from optlight.scene import Scene
from optlight.spec import Problem

Array = NDArray[np.float64]


@dataclass(frozen=True)
class SweepResult:
    """Per azimuth (M,): the best ``zenith`` (rad) of the sweep, its ``azimuth`` (rad), its ``cost``,
    and the wall time ``time_s`` of that azimuth's sweep; ``grid`` holds every sample."""

    zenith: Array
    azimuth: Array
    cost: Array
    time_s: Array
    grid: CostGrid


def paper_sweep(
    problem: Problem,
    scene: Scene | None = None,
    step_deg: float = 0.5,
    objective: Objective | None = None,
    progress: Progress | None = None,
) -> SweepResult:
    """The paper's fine zenith sweep along ``landmarks.count`` azimuths φ_j = 2πj/M, every sample
    rendered at ``scene``'s resolution (default: the camera's) with shadow rays. ``objective``
    defaults to the problem's, built on ``scene``."""
    scene = scene if scene is not None else Scene.from_problem(problem)
    objective = objective if objective is not None else Objective.from_problem(problem, scene)
    zenith = zenith_grid(scene.sphere, math.radians(step_deg))
    count = problem.landmarks.count
    azimuth = 2 * np.pi * np.arange(count) / count
    costs = np.empty((count, zenith.size))
    times = np.empty(count)
    for j, phi in enumerate(azimuth):
        t0 = time.perf_counter()
        costs[j] = sweep_costs(scene, objective, zenith, phi)[0]
        times[j] = time.perf_counter() - t0
        if progress is not None:
            progress(j + 1, count)
    best = costs.argmin(axis=1)
    return SweepResult(
        zenith=zenith[best],
        azimuth=azimuth,
        cost=costs[np.arange(count), best],
        time_s=times,
        grid=CostGrid(zenith, azimuth, costs),
    )
