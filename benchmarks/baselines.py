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

from optlight.errors import OptlightError
from optlight.geometry import LightSphere
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
    sphere: LightSphere | None = None,
) -> SweepResult:
    """The paper's fine zenith sweep along ``landmarks.count`` azimuths φ_j = 2πj/M, every sample
    rendered at ``scene``'s resolution (default: the camera's) with shadow rays. ``objective``
    defaults to the problem's, built on ``scene``; ``sphere`` is the zenith range swept (default
    ``scene``'s cap; pass ``Setup.sphere`` to sweep only the lights clear of the camera's view, the
    domain our search uses)."""
    scene = scene if scene is not None else Scene.from_problem(problem)
    objective = objective if objective is not None else Objective.from_problem(problem, scene)
    zenith = zenith_grid(sphere if sphere is not None else scene.sphere, math.radians(step_deg))
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


def per_knot_ik_plan(problem: Problem) -> dict[str, float | bool]:
    """The paper's pipeline from landmarks to a timed trajectory: great-circle knots, generalized IK
    at every knot (each started from the previous one), timed as our plans are; no trajectory NLP.

    The same stages as :func:`optlight.solve` (captures, placement, visiting order, path, timing with
    the transfers from and back to the start, verification), so the difference to it is the
    trajectory NLP alone. Returns the time (s, landmark search included), the joint path length
    Σ|Δθ| over the knots (rad), the motion time without dwells (s, transfers included), the largest
    |h| over the knots (m, pinocchio) and whether the timed trajectory passes verification.
    """
    from optlight.geometry import h_residual
    from optlight.pipeline import capture_path, choose_captures, place_captures, time_knots, verify_knots
    from optlight.plan import joint_path_length
    from optlight.planning.policy import knot_ik, visiting_order
    from optlight.planning.set_landmarks import tour_order
    from optlight.setup import Setup
    from optlight.spec.sizing import check_trajectory_samples

    start = time.perf_counter()
    setup = Setup.from_problem(problem)
    _, design, captures, _ = choose_captures(setup)
    placement = place_captures(setup, captures, design)
    order = (
        tour_order(placement.thetas)
        if design is not None
        else visiting_order(setup.trajectory_spec, setup.limits, placement)
    )
    positions = np.array([placement.landmarks[i].position for i in order])
    path = capture_path(setup.sphere, setup.trajectory_spec, positions, placement.thetas[order])
    knots, _ = knot_ik(setup.workcell, path, placement.thetas[order])
    trajectory = time_knots(setup, path, knots)
    elapsed = time.perf_counter() - start
    h = max(
        float(
            np.abs(h_residual(*setup.robot.light_pose(theta), setup.sphere.center, setup.sphere.radius)).max()
        )
        for theta in knots
    )
    dwell = float(np.sum(np.diff(trajectory.landmark_intervals, axis=1)))
    try:  # a plan the pipeline would refuse before sampling it (hours long) is not verified
        check_trajectory_samples(problem, setup.robot.n, trajectory.duration, dwell)
        passed = verify_knots(setup, trajectory, positions, knots, path.transfers).passed
    except OptlightError:
        passed = False
    intervals = trajectory.landmark_intervals
    return {
        "time_s": elapsed,
        "joint_path_length": joint_path_length(knots),
        "motion_time": float(trajectory.duration - np.sum(intervals[:, 1] - intervals[:, 0])),
        "max_h_residual": h,
        "verification_passed": passed,
    }
