"""A light set as the pipeline's landmarks: design, map, order and report.

When ``[lightset] kind`` is not "none", the landmark stage designs the set instead of the
per-azimuth search (:mod:`optlight.planning.lightsets`):

- ``photometric_stereo`` / ``rti``: :func:`~optlight.planning.lightsets.design_light_set` of the
  problem's set cost (:func:`~optlight.planning.lightsets.set_cost_from_problem`, on the search
  scene) over the allowed cap ``Cap.from_sphere(cell.sphere)`` (the camera's view taken out) and,
  with ``[lightset] design_over = "reachable"`` (the default), over the lights the robot reaches
  there clear of the environment and the camera's view: a reachability map of the cap first
  (:func:`~optlight.planning.reach.reachability_map`), whose smooth clear field
  (:class:`~optlight.planning.reach.ClearField`) is a row f(d_i) ≥ :data:`CLEAR_MARGIN` of the set
  NLP for every light. Designed on the cap alone, a set loses the lights the arm reaches only
  across the view cone, and their replacements are chosen one at a time;
- ``grid``: the problem's grid (:func:`~optlight.planning.lightsets.grid_from_problem`) mapped to
  the nearest lights on that cap
  (:func:`~optlight.planning.lightsets.map_grid`), every replacement reported; with ``design_over =
  "reachable"`` the map is made too, for the placement's replacements (:class:`SetReplacement`).

Each light becomes a :class:`~optlight.planning.landmarks.Landmark` (status "set" or "grid"; its
``cost`` is the image objective there, NumPy renderer with shadow rays at the search resolution), so
it goes through the same placement, path, NLP, timing and verification as any landmark. A light the
robot cannot reach clear is replaced by :class:`SetReplacement`, the reachable clear light that best
keeps the set (or dropped with a warning under ``[landmarks] allow_partial``). A set is captured in
a short open tour in joint space.
:func:`set_summary` compares what was requested with what the robot achieves: the light counts, how
far each light moved, and the set cost at the requested and at the achieved directions.

Angles are radians in code, degrees in the summary.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any, Literal

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.errors import OutOfReachError
from optlight.geometry import LightSphere
from optlight.planning.landmarks import CostGrid, Landmark, LandmarkSet, exact_cost
from optlight.planning.lightsets import (
    Cap,
    Grid,
    GridMapping,
    SetCost,
    angles_of,
    design_light_set,
    map_grid,
)
from optlight.planning.path import azimuth_order, shortest_open_tour
from optlight.planning.policy import Attempt, Reacher, too_close_mm, why_moved
from optlight.planning.reach import ClearField, ReachabilityMap, reachability_map
from optlight.robot import Robot
from optlight.spec import LandmarksSpec, LightSetSpec
from optlight.workcell import ImageCosts, Workcell

Array = NDArray[np.float64]

#: Margin (rad) between the set's lights and the zenith where the lamp enters the camera's view.
VIEW_MARGIN = math.radians(3.0)


@dataclass(frozen=True)
class SetDesign:
    """What the set stage asked for: ``kind``, the ``requested`` directions (N, 3, sphere frame),
    the set ``cost`` function (None for a grid) and its value at the requested directions, the grid
    mapping (grid kind), the design's wall time (s); a set designed over the reachable lights, the
    reachability map ``reach`` and its clear ``field``."""

    kind: str
    requested: Array
    cost: SetCost | None
    requested_cost: float | None
    grid: GridMapping | None
    time_s: float
    reach: ReachabilityMap | None = None
    field: ClearField | None = None


#: Smallest value of the clear field (:class:`~optlight.planning.reach.ClearField`, in [−1, 1]) at a
#: designed light: well inside the map's clear cells, not on the border with a blocked one.
CLEAR_MARGIN = 0.5


def landmarks_of_set(
    reacher: Reacher,
    spec: LightSetSpec,
    landmark_spec: LandmarksSpec,
    wanted: Grid | SetCost,
    file: str = "<inline>",
    progress: Callable[[int, int], None] | None = None,
) -> tuple[LandmarkSet, SetDesign]:
    """The light set ``spec`` (``[lightset]``) as landmarks (module docstring) on the lights of the
    reacher's work cell, and what was requested: ``wanted`` is the grid to map (kind "grid") or the
    set cost to design (on the search scene of the reacher's image costs); ``landmark_spec``
    (``[landmarks]``) says whether a set may be smaller than asked; ``file`` the problem file its
    errors name; ``progress(done, total)`` over the reachability map's cells."""
    t0 = time.perf_counter()
    cell, costs, cap = reacher.cell, reacher.costs, allowed_cap(reacher.cell)
    reach: ReachabilityMap | None = None
    field: ClearField | None = None
    cost: SetCost | None = None
    requested_cost: float | None = None
    grid: GridMapping | None = None
    notes: list[str] = []
    if spec.design_over == "reachable":
        step = spec.reach_step_deg
        reach = reachability_map(reacher, step, 2.0 * step, progress=progress)
        if not reach.clear.any():  # nothing to design over or replace with: say so before the NLPs
            raise OutOfReachError(
                f"{cell.robot.name} reaches no light of the cap clear of the environment and the camera's "
                f"view (reachability map, {reach.success.size} cells, {100 * reach.reachable_fraction:.0f} % "
                "reached by the IK)"
            )
        field = ClearField.from_map(reach)
    if isinstance(wanted, Grid):
        grid = map_grid(
            wanted,
            cap,
            spacing=math.radians(spec.candidate_spacing_deg),
            outside_cap=spec.grid_outside_cap,
            file=file,
        )
        directions, requested = grid.achieved, grid.requested
        status: Literal["set", "grid"] = "grid"
    else:
        cost = wanted
        allowed = None
        if field is not None:
            clear = field  # for the closure: never None

            def allowed(d: ca.MX) -> ca.MX:
                return CLEAR_MARGIN - clear.casadi(d)

        count, pool = spec.count, None
        if reach is not None and field is not None:
            pool = clear_lights(reach, field, cap)
            count = fitting_count(cell.robot, spec, landmark_spec, pool, reach)
        result = design_light_set(cost, count, cap, starts=spec.starts, seed=spec.seed, allowed=allowed)
        if pool is not None and field is not None and not _on_clear_cells(result.directions, field):
            # IPOPT from uniform starts found no set inside a thin clear region: start on it
            result = design_light_set(
                cost, count, cap, starts=spec.starts, seed=spec.seed, allowed=allowed, start_pool=pool
            )
        directions, requested_cost = result.directions, result.cost
        if pool is not None and field is not None:
            directions, moved = _onto_clear_cells(directions, field, pool)
            if moved:
                notes += moved
                requested_cost = cost.numpy(directions, cost.parameters(directions))
        requested, status = directions, "set"
    # indexed in azimuth order: the placement chains each light's posture from the previous one's,
    # which keeps neighbours on one IK branch as in the per-azimuth search
    by_azimuth = np.argsort(angles_of(directions)[1], kind="stable")
    directions, requested = directions[by_azimuth], requested[by_azimuth]
    landmarks = tuple(_landmark(cell.sphere, costs, i, d, status) for i, d in enumerate(directions))
    elapsed = time.perf_counter() - t0
    empty = np.zeros(0)
    found = LandmarkSet(
        landmarks=landmarks,
        mode="set",
        reference_histogram=empty,
        reference_label=f"light set ({spec.kind})",
        histograms=np.zeros((len(landmarks), 0)),
        sweep=CostGrid(empty, empty, np.zeros((0, 0))),
        resolution=(costs.search_scene.camera.width, costs.search_scene.camera.height),
        time_s=elapsed,
        view_zenith=cell.view_zenith,
        notes=(*_grid_notes(grid), *notes),
    )
    return found, SetDesign(spec.kind, requested, cost, requested_cost, grid, elapsed, reach, field)


def clear_lights(reach: ReachabilityMap, field: ClearField, cap: Cap) -> Array:
    """The cells (K, 3, sphere frame) of the map the robot reaches clear, inside the design's ``cap``
    and well inside the clear region (field ≥ :data:`CLEAR_MARGIN`): the lights a set designed over
    the reachable lights may take."""
    cells = reach.directions[reach.clear.ravel()]
    cells = cells[cap.contains(cells, tol=0.0)]
    return cells[field.numpy(cells) >= CLEAR_MARGIN]


def fitting_count(
    robot: Robot, spec: LightSetSpec, landmark_spec: LandmarksSpec, pool: Array, reach: ReachabilityMap
) -> int:
    """How many lights the set gets: ``spec.count`` (``[lightset] count``), or the number of the
    map's clear lights ``pool`` when that is fewer (``landmark_spec.allow_partial``; an
    :class:`OutOfReachError` naming ``robot`` that says how many fit otherwise; solve adds a base)."""
    if len(pool) >= spec.count:
        return spec.count
    where = (
        f"{robot.name} reaches {len(pool)} distinct lights of the allowed cap clear of the environment, "
        f"the camera's view and the beam (reachability map at {spec.reach_step_deg:g}°, "
        f"{int(reach.clear.sum())} clear cells) for a set of {spec.count}"
    )
    if not landmark_spec.allow_partial or len(pool) < 1:
        raise OutOfReachError(f"{where}: set [lightset] count = {len(pool)} (or less)")
    return len(pool)


def _on_clear_cells(directions: Array, field: ClearField) -> bool:
    """Whether every light (N, 3) is where the clear field keeps the set's lights."""
    return bool((field.numpy(directions) >= CLEAR_MARGIN - 1e-6).all())


def _onto_clear_cells(directions: Array, field: ClearField, pool: Array) -> tuple[Array, list[str]]:
    """The lights (N, 3) with each one off the clear region (field below :data:`CLEAR_MARGIN`, where
    the set NLP did not converge) moved to the nearest clear light of ``pool`` (K, 3) that no other
    light of the set takes; and one note naming them."""
    out = directions.copy()
    off = np.flatnonzero(field.numpy(directions) < CLEAR_MARGIN - 1e-6)
    if off.size == 0:
        return out, []
    taken = np.zeros(len(pool), bool)
    kept = np.setdiff1d(np.arange(len(out)), off)
    if kept.size:  # the pool cells the lights that stay are on or nearest to
        taken[np.argmax(out[kept] @ pool.T, axis=1)] = True
    angles = []
    for i in off:
        closeness = np.where(taken, -np.inf, pool @ out[i])
        j = int(np.argmax(closeness))
        taken[j] = True
        angles.append(math.degrees(math.acos(float(np.clip(pool[j] @ out[i], -1.0, 1.0)))))
        out[i] = pool[j]
    return out, [
        f"the set design left {off.size} of {len(out)} lights off the lights the reachability map found clear; "
        f"each was moved to the nearest clear one (up to {max(angles):.1f}°)"
    ]


def allowed_cap(cell: Workcell) -> Cap:
    """The cap the set is designed on: the allowed sphere's (``cell.sphere``), its inner edge
    :data:`VIEW_MARGIN` further from the camera's axis when the view limits it (a light designed
    exactly on that edge leaves the trajectory NLP's view rows no slack)."""
    cap = Cap.from_sphere(cell.sphere)
    if cell.view_zenith <= 0:
        return cap
    return Cap(min(cap.zenith_min + VIEW_MARGIN, 0.5 * (cap.zenith_min + cap.zenith_max)), cap.zenith_max)


def _landmark(
    sphere: LightSphere, costs: ImageCosts, index: int, direction: Array, status: Literal["set", "grid"]
) -> Landmark:
    """Light ``index`` of the set at ``direction`` (frame of ``sphere``) as a landmark, its cost the
    image objective on the search scene of ``costs``."""
    position = sphere.center + sphere.radius * sphere.rotation @ direction
    zenith, azimuth = angles_of(direction)
    return Landmark(
        index=index,
        zenith=float(zenith),
        azimuth=float(azimuth),
        position=position,
        cost=exact_cost(costs.search_scene, costs.search_objective, position),
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


def directions_of(sphere: LightSphere, landmarks: Sequence[Landmark]) -> Array:
    """Unit directions (M, 3), frame of ``sphere``, from its centre O to the landmarks' positions."""
    d = (np.array([lm.position for lm in landmarks]).reshape(-1, 3) - sphere.center) @ sphere.rotation
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def tour_order(thetas: Array, costs: Array | None = None) -> NDArray[np.int64]:
    """A short open tour through the joint configurations ``thetas`` (M, n): the capture order of a set,
    on the (M, M) ``costs`` between them (:func:`~optlight.planning.policy.tour_costs`; default the
    joint-space distance)."""
    if costs is None:
        costs = np.linalg.norm(thetas[:, None, :] - thetas[None, :, :], axis=2)
    return shortest_open_tour(costs)


def joint_distance(thetas: Array, order: ArrayLike) -> float:
    """Σ |θ_{k+1} − θ_k|_∞ (rad) along ``order``: the largest joint's travel, a proxy of the motion time
    between captures at equal joint speed limits."""
    steps = np.diff(thetas[np.asarray(order)], axis=0)
    return float(np.abs(steps).max(axis=1, initial=0.0).sum())


#: Clear cells of the design's reachability map whose postures start the IK at a light the previous
#: light's posture does not reach clear, before a replacement is looked for.
MAP_STARTS = 3
#: Candidates a replacement scores: the nearest this many lattice lights to the light replaced.
REPLACEMENT_CANDIDATES = 120
#: Of those, how many it tries with the robot, best score first, before it gives the light up.
REPLACEMENT_TRIES = 30


class SetReplacement:
    """The light set's rule for a light the robot cannot reach clear (a
    :data:`~optlight.planning.policy.Replacement`).

    When the set stage made a reachability map (``design_over = "reachable"``), the light itself is
    first tried from the clear postures the map found at the :data:`MAP_STARTS` cells nearest it (the
    previous light's posture may be on an IK branch that blocks the camera there). Else, of the
    allowed cap's lattice at ``[lightset] candidate_spacing_deg``, the :data:`REPLACEMENT_CANDIDATES`
    lights nearest the one replaced (with a map, only those its clear field puts on the clear side;
    none within ``[landmarks] distinct_deg`` of another light of the set, which would be the same
    capture twice) are scored — designed kinds by the set cost with the other lights where they are (those replaced
    before at their replacements), a grid by the angle to its requested direction — and tried with
    the robot (:meth:`Reacher.attempt`) best score first: from the previous light's angles (its IK
    branch), then from the map's posture nearest each, then from θ_ref with restarts. The first
    reached clear replaces it (status "placed")."""

    def __init__(
        self,
        reacher: Reacher,
        design: SetDesign,
        landmarks: Sequence[Landmark],
        spec: LightSetSpec,
        landmark_spec: LandmarksSpec,
    ) -> None:
        self.design, self.reacher, self.landmark_spec = design, reacher, landmark_spec
        cell = reacher.cell
        cap = allowed_cap(cell)
        self.lattice = cap.lattice(cap.area_count(math.radians(spec.candidate_spacing_deg)))
        self.directions = dict(
            zip((lm.index for lm in landmarks), directions_of(cell.sphere, landmarks), strict=True)
        )
        reach, self.field = design.reach, design.field
        if reach is not None:
            clear = reach.clear.ravel()
            self.map_cells = reach.directions[clear]
            self.map_thetas = reach.theta.reshape(-1, reach.theta.shape[-1])[clear]

    def _map_postures(self, direction: Array, count: int = MAP_STARTS) -> list[Array]:
        """The clear joint angles the design's reachability map found at the ``count`` clear cells
        nearest ``direction`` (sphere frame), nearest first; none without a map."""
        if self.field is None:
            return []
        return list(self.map_thetas[np.argsort(-(self.map_cells @ direction))[:count]])

    def _scores(self, index: int, candidates: Array) -> Array:
        """Each candidate's score as light ``index`` (lower is better)."""
        cost = self.design.cost
        if cost is None:  # a grid: the nearest to what was requested
            return -(candidates @ self.design.requested[index])
        others = [d for i, d in self.directions.items() if i != index]
        return np.array([cost.numpy(np.vstack([*others, c])) for c in candidates])

    def __call__(
        self, lm: Landmark, attempts: Sequence[Attempt], previous: Array
    ) -> tuple[Landmark, Array, str] | str:
        cell = self.reacher.cell
        here = self.directions[lm.index]
        for theta_map in self._map_postures(here):
            theta = self.reacher.attempt(lm.position, theta_map, restarts=False).theta
            if theta is not None:
                best = attempts[0]
                reason = (
                    f"{best.row} {too_close_mm(best.clearance):.1f} mm too close"
                    if best.ik.success
                    else "no convergence"
                )
                note = (
                    "reached clear from the posture the reachability map found at a clear cell near it "
                    f"(the IK from the previous light's posture and from θ_ref: {reason})"
                )
                return replace(lm, status="placed"), theta, note
        nearest = np.argsort(-(self.lattice @ here))[:REPLACEMENT_CANDIDATES]
        if self.field is not None:
            nearest = nearest[self.field.numpy(self.lattice[nearest]) > 0.0]
        # not onto another light of the set: a grid's score (the angle to its own direction) does not
        # see the others, and two unreachable yale_grid lights took the same replacement (64 captures,
        # 61 distinct lights)
        others = np.array([d for i, d in self.directions.items() if i != lm.index]).reshape(-1, 3)
        apart = math.cos(math.radians(self.landmark_spec.distinct_deg))
        nearest = nearest[(self.lattice[nearest] @ others.T).max(axis=1, initial=-1.0) < apart]
        scores = self._scores(lm.index, self.lattice[nearest])
        tried = nearest[np.argsort(scores, kind="stable")][:REPLACEMENT_TRIES]
        # first from the previous light's angles alone (the posture chain's IK branch: a restart may
        # land on another, a reconfiguration the trajectory cannot make), then from the map's
        # posture nearest each, then from θ_ref with restarts
        found = self._first_clear(
            self.lattice[tried],
            [
                lambda _: [(previous, False)],
                lambda d: [(t, False) for t in self._map_postures(d, 1)],
                lambda _: [(cell.robot.theta_ref, True)],
            ],
        )
        if found is not None:
            direction, theta = found
            before = self._score_text(lm.index, here)
            self.directions[lm.index] = direction
            after = self._score_text(lm.index, direction)
            light = replace(
                _landmark(cell.sphere, self.reacher.costs, lm.index, direction, "set"), status="placed"
            )
            moved = math.degrees(math.acos(float(np.clip(direction @ here, -1.0, 1.0))))
            note = (
                f"replaced by the light at zenith {math.degrees(light.zenith):.1f}°, azimuth "
                f"{math.degrees(light.azimuth):.1f}°, {moved:.1f}° away, the reachable one that best keeps "
                f"the set ({before} -> {after}) {why_moved(cell.robot, attempts[0])}"
            )
            return light, theta, note
        del self.directions[lm.index]  # dropped: out of the set the others are scored with
        return (
            f"nor is any of the {len(tried)} lights that best keep the set among the {len(nearest)} "
            f"nearest it (lattice at [lightset] candidate_spacing_deg) reachable clear"
        )

    def _first_clear(
        self, candidates: Array, passes: Sequence[Callable[[Array], list[tuple[Array, bool]]]]
    ) -> tuple[Array, Array] | None:
        """The first of ``candidates`` (K, 3, sphere frame; in order, pass by pass) the robot reaches
        clear from one of the (start, restarts) pairs ``pass(direction)`` gives, and its angles."""
        sphere = self.reacher.cell.sphere
        for starts in passes:
            for direction in candidates:
                position = sphere.center + sphere.radius * sphere.rotation @ direction
                for start, restarts in starts(direction):
                    theta = self.reacher.attempt(position, start, restarts=restarts).theta
                    if theta is not None:
                        return direction, theta
        return None

    def _score_text(self, index: int, direction: Array) -> str:
        """The score of ``direction`` as light ``index``, in words: the set cost, or the angle off the
        requested grid direction."""
        if self.design.cost is None:
            off = math.degrees(math.acos(float(np.clip(direction @ self.design.requested[index], -1.0, 1.0))))
            return f"{off:.1f}° off the grid direction"
        return f"set cost {float(self._scores(index, direction[None])[0]):.4g}"


def set_summary(
    sphere: LightSphere, design: SetDesign, placed: Sequence[Landmark], thetas: Array, order: ArrayLike
) -> dict[str, Any]:
    """Requested vs achieved (directions in the frame of ``sphere``), JSON-safe: counts, per-light
    move (deg) from the requested direction
    (placed lights by index), the set cost at the requested and the achieved directions (designed
    kinds), and the capture order's joint travel against azimuth order's."""
    achieved = directions_of(sphere, placed)
    requested = design.requested[[lm.index for lm in placed]]
    # atan2 of |a×b| and a·b: arccos near 1 turns float rounding into micro-degrees of "move"
    moved = np.degrees(
        np.arctan2(np.linalg.norm(np.cross(achieved, requested), axis=1), np.sum(achieved * requested, axis=1))
    )
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
    if design.reach is not None:
        reach = design.reach
        summary["reach_map"] = {
            "map_cells": int(reach.success.size),
            "clear_pct": 100.0 * reach.clear_fraction,
            "map_time_s": reach.time_s,
        }
    if design.grid is not None:
        summary["grid"] = design.grid.report()
    if design.cost is not None:
        summary["set_cost_requested"] = design.requested_cost
        summary["set_cost_achieved"] = design.cost.numpy(achieved, design.cost.parameters(achieved))
    return summary
