"""A light set as the pipeline's landmarks (issue 12): design, map, order and report.

When ``[lightset] kind`` is not "none", the landmark stage designs the set instead of the
per-azimuth search (:mod:`optlight.planning.lightsets`):

- ``photometric_stereo`` / ``rti``: :func:`~optlight.planning.lightsets.design_light_set` of the
  problem's set cost (:func:`~optlight.planning.lightsets.set_cost_from_problem`, on the search
  scene) over the allowed cap ``Cap.from_sphere(setup.sphere)`` (the camera's view taken out);
- ``grid``: the problem's grid mapped to the nearest lights on that cap
  (:func:`~optlight.planning.lightsets.map_grid`), every replacement reported.

Each light becomes a :class:`~optlight.planning.landmarks.Landmark` (status "set" or "grid"; its
``cost`` is the image objective there, NumPy renderer with shadow rays at the search resolution), so
it goes through the same placement (an unreachable light is moved along its azimuth by the placement
NLP, or dropped with a warning under ``[landmarks] allow_partial``), path, NLP, timing and
verification as any landmark. A set is captured in a short open tour in joint space.
:func:`set_summary` compares what was requested with what the robot achieves: the light counts, how
far each light moved, and the set cost at the requested and at the achieved directions.

Angles are radians in code, degrees in the summary.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.planning.landmarks import CostGrid, Landmark, LandmarkSet, exact_cost
from optlight.planning.lightsets import (
    Cap,
    GridMapping,
    SetCost,
    angles_of,
    design_light_set,
    grid_from_problem,
    map_grid,
    set_cost_from_problem,
)
from optlight.planning.path import azimuth_order, shortest_open_tour
from optlight.setup import Setup

Array = NDArray[np.float64]

#: Margin (rad) between the set's lights and the zenith where the lamp enters the camera's view.
VIEW_MARGIN = math.radians(3.0)


@dataclass(frozen=True)
class SetDesign:
    """What the set stage asked for: ``kind``, the ``requested`` directions (N, 3, sphere frame),
    the set ``cost`` function (None for a grid) and its value at the requested directions, the grid
    mapping (grid kind), the design's wall time (s)."""

    kind: str
    requested: Array
    cost: SetCost | None
    requested_cost: float | None
    grid: GridMapping | None
    time_s: float


def landmarks_of_set(setup: Setup) -> tuple[LandmarkSet, SetDesign]:
    """The problem's light set as landmarks (module docstring), and what was requested."""
    t0 = time.perf_counter()
    spec, cap = setup.problem.lightset, allowed_cap(setup)
    cost: SetCost | None = None
    requested_cost: float | None = None
    grid: GridMapping | None = None
    if spec.kind == "grid":
        wanted = grid_from_problem(setup.problem)
        grid = map_grid(
            wanted,
            cap,
            spacing=math.radians(spec.candidate_spacing_deg),
            outside_cap=spec.grid_outside_cap,
            file=str(setup.problem.source) if setup.problem.source else "<inline>",
        )
        directions, requested = grid.achieved, grid.requested
        status: Literal["set", "grid"] = "grid"
    else:
        cost = set_cost_from_problem(setup.problem, setup.search_scene, setup.search_objective)
        result = design_light_set(cost, spec.count, cap, starts=spec.starts, seed=spec.seed)
        directions = requested = result.directions
        requested_cost, status = result.cost, "set"
    # indexed in azimuth order: the placement chains each light's posture from the previous one's,
    # which keeps neighbours on one IK branch as in the per-azimuth search
    by_azimuth = np.argsort(angles_of(directions)[1], kind="stable")
    directions, requested = directions[by_azimuth], requested[by_azimuth]
    landmarks = tuple(_landmark(setup, i, d, status) for i, d in enumerate(directions))
    elapsed = time.perf_counter() - t0
    empty = np.zeros(0)
    found = LandmarkSet(
        landmarks=landmarks,
        mode="set",
        reference_histogram=empty,
        reference_label=f"light set ({spec.kind})",
        histograms=np.zeros((len(landmarks), 0)),
        sweep=CostGrid(empty, empty, np.zeros((0, 0))),
        resolution=(setup.search_scene.camera.width, setup.search_scene.camera.height),
        time_s=elapsed,
        view_zenith=setup.view_zenith,
        notes=tuple(_grid_notes(grid)),
    )
    return found, SetDesign(spec.kind, requested, cost, requested_cost, grid, elapsed)


def allowed_cap(setup: Setup) -> Cap:
    """The cap the set is designed on: the allowed sphere's (``setup.sphere``), its inner edge
    :data:`VIEW_MARGIN` further from the camera's axis when the view limits it (a light designed
    exactly on that edge leaves the trajectory NLP's view rows no slack)."""
    cap = Cap.from_sphere(setup.sphere)
    if setup.view_zenith <= 0:
        return cap
    return Cap(min(cap.zenith_min + VIEW_MARGIN, 0.5 * (cap.zenith_min + cap.zenith_max)), cap.zenith_max)


def _landmark(setup: Setup, index: int, direction: Array, status: Literal["set", "grid"]) -> Landmark:
    """Light ``index`` of the set at ``direction`` (sphere frame) as a landmark."""
    sphere = setup.sphere
    position = sphere.center + sphere.radius * sphere.rotation @ direction
    zenith, azimuth = angles_of(direction)
    return Landmark(
        index=index,
        zenith=float(zenith),
        azimuth=float(azimuth),
        position=position,
        cost=exact_cost(setup.search_scene, setup.search_objective, position),
        status=status,
        solver_status="",
        iterations=0,
        time_s=0.0,
    )


def _grid_notes(grid: GridMapping | None) -> list[str]:
    """One line when grid directions were replaced on the cap (off the cap or in the camera's view)."""
    if grid is None or not grid.replaced_count:
        return []
    return [
        f"{grid.replaced_count} of {len(grid.names)} grid lights lie outside the allowed cap and were "
        f"replaced by the nearest allowed light (moved up to {math.degrees(float(grid.moved.max())):.1f}°)"
    ]


def directions_of(setup: Setup, landmarks: Sequence[Landmark]) -> Array:
    """Unit directions (M, 3), sphere frame, from O to the landmarks' positions."""
    sphere = setup.sphere
    d = (np.array([lm.position for lm in landmarks]).reshape(-1, 3) - sphere.center) @ sphere.rotation
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def tour_order(thetas: Array) -> NDArray[np.int64]:
    """A short open tour through the joint configurations ``thetas`` (M, n): the capture order of a set."""
    return shortest_open_tour(np.linalg.norm(thetas[:, None, :] - thetas[None, :, :], axis=2))


def joint_distance(thetas: Array, order: ArrayLike) -> float:
    """Σ |θ_{k+1} − θ_k|_∞ (rad) along ``order``: the largest joint's travel, a proxy of the motion time
    between captures at equal joint speed limits."""
    steps = np.diff(thetas[np.asarray(order)], axis=0)
    return float(np.abs(steps).max(axis=1, initial=0.0).sum())


def set_summary(
    setup: Setup, design: SetDesign, placed: Sequence[Landmark], thetas: Array, order: ArrayLike
) -> dict[str, Any]:
    """Requested vs achieved, JSON-safe: counts, per-light move (deg) from the requested direction
    (placed lights by index), the set cost at the requested and the achieved directions (designed
    kinds), and the capture order's joint travel against azimuth order's."""
    achieved = directions_of(setup, placed)
    requested = design.requested[[lm.index for lm in placed]]
    moved = np.degrees(np.arccos(np.clip(np.sum(achieved * requested, axis=1), -1.0, 1.0)))
    summary: dict[str, Any] = {
        "kind": design.kind,
        "requested": len(design.requested),
        "achieved": len(placed),
        "dropped": sorted(set(range(len(design.requested))) - {lm.index for lm in placed}),
        "moved_by_placement": [
            {"index": lm.index, "moved_deg": float(m)}
            for lm, m in zip(placed, moved, strict=True)
            if m > 1e-6
        ],
        "design_time_s": design.time_s,
        "order_joint_travel_rad": {
            "tour": joint_distance(thetas, order),
            "azimuth": joint_distance(thetas, azimuth_order([lm.azimuth for lm in placed])),
        },
    }
    if design.grid is not None:
        summary["grid"] = design.grid.report()
    if design.cost is not None:
        summary["set_cost_requested"] = design.requested_cost
        summary["set_cost_achieved"] = design.cost.numpy(achieved, design.cost.parameters(achieved))
    return summary
