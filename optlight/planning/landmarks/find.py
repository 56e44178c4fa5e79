"""Finding the landmarks (docs/design.md §5): :func:`find_landmarks` runs the azimuth mode or the
free mode over a work cell's allowed lights, and :func:`distinct_landmarks` drops landmarks closer
than a tolerance.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from functools import partial

import numpy as np

from optlight.errors import ProblemError
from optlight.geometry import LightSphere, direction_in_sphere_frame
from optlight.planning.landmarks.refinement import CapRefiner, ZenithSearch
from optlight.planning.landmarks.search import Candidate, LandmarkSearch
from optlight.planning.landmarks.sweep import (
    includes_pole,
    local_minima,
    sweep_costs,
    sweep_objective,
    zenith_grid,
)
from optlight.planning.landmarks.types import Array, CostGrid, Landmark, LandmarkSet, Progress
from optlight.planning.nlp import Solve
from optlight.spec import LandmarksSpec, SolverSpec
from optlight.threads import in_background
from optlight.workcell import ImageCosts, Workcell


def find_landmarks(
    cell: Workcell,
    costs: ImageCosts,
    spec: LandmarksSpec,
    solver: SolverSpec,
    file: str = "<inline>",
    *,
    progress: Progress | None = None,
    found: Callable[[Landmark], None] | None = None,
) -> LandmarkSet:
    """The landmarks on the lights ``cell``'s sphere allows, for the image objective ``costs``
    (``[objective]``), searched as ``spec`` (``[landmarks]``) says with IPOPT's ``solver`` settings
    (``[solver]``); ``file`` the problem file its errors name. See the module docstring; from a
    built setup: ``find_landmarks(setup.workcell, setup.image_costs, setup.landmark_spec,
    setup.solver, setup.file)``. ``progress(done, total)`` is called after each azimuth (azimuth
    mode) or each sweep row and landmark (free mode); ``found(landmark)`` with each landmark as it is
    found, in the order of the result (e.g. to place it meanwhile,
    :class:`~optlight.pipeline.PlacementAhead`)."""
    t0 = time.perf_counter()
    search = LandmarkSearch(cell, costs, spec, solver, file)
    found = found or (lambda landmark: None)
    if search.spec.mode == "azimuth":
        landmarks, histograms, visibilities, grid = _azimuth_mode(search, progress, found)
    else:
        landmarks, histograms, visibilities, grid = _free_mode(search, progress, found)
    return LandmarkSet(
        landmarks=tuple(landmarks),
        mode=search.spec.mode,
        reference_histogram=search.objective.reference.histogram,
        reference_label=search.objective.reference.label,
        histograms=np.array(histograms).reshape(len(landmarks), -1),
        sweep=grid,
        resolution=(search.search.camera.width, search.search.camera.height),
        time_s=time.perf_counter() - t0,
        view_zenith=cell.view_zenith,
        notes=tuple(_view_notes(search, landmarks, grid)),
        shadows=np.packbits(np.array(visibilities, bool).reshape(len(landmarks), -1), axis=1),
    )


def _view_notes(search: LandmarkSearch, landmarks: list[Landmark], grid: CostGrid) -> list[str]:
    """One line on the landmarks whose azimuth's best sweep sample lies in the camera's view (zenith
    below the smallest allowed one): which they are, where those samples were and how far the
    landmarks, the best clear lights, are from them (azimuth mode; in free mode, whether the cap's
    best sample lies there)."""
    limit = search.sphere.zenith_min
    inside = grid.zenith < limit - 1e-12
    if not inside.any():
        return []
    view = f"in the camera's view (zenith < {math.degrees(limit):.1f}°)"
    if search.spec.mode == "free":
        best = int(np.unravel_index(int(np.argmin(grid.cost)), grid.cost.shape)[1])
        if not inside[best]:
            return []
        return [f"the cap's best light (zenith {math.degrees(grid.zenith[best]):.1f}°) is left out: it is {view}"]
    moved: dict[int, tuple[float, float]] = {}
    for lm, row in zip(landmarks, grid.cost, strict=True):
        i = int(np.argmin(row))
        if inside[i] and row[i] < row[~inside].min():
            moved[lm.index] = (math.degrees(grid.zenith[i]), math.degrees(lm.zenith - grid.zenith[i]))
    if not moved:
        return []
    inside_best = [z for z, _ in moved.values()]
    away = [d for _, d in moved.values()]
    return [
        f"landmarks {_index_ranges(sorted(moved))} ({len(moved)} of {len(landmarks)}): the best light of "
        f"their azimuth (zenith {min(inside_best):.1f}–{max(inside_best):.1f}°) is {view}; each is the best clear "
        f"light instead, {min(away):.1f}–{max(away):.1f}° from it"
    ]


def _index_ranges(indices: Sequence[int]) -> str:
    """Sorted indices as runs: [0, 1, 2, 5, 7, 8] → "0–2, 5, 7–8"."""
    runs: list[list[int]] = []
    for i in indices:
        if runs and i == runs[-1][-1] + 1:
            runs[-1].append(i)
        else:
            runs.append([i])
    return ", ".join(f"{r[0]}–{r[-1]}" if len(r) > 1 else f"{r[0]}" for r in runs)


def distinct_landmarks(landmarks: Sequence[Landmark], tolerance: float) -> tuple[list[Landmark], list[str]]:
    """The landmarks that are distinct captures: of landmarks whose directions from O are within
    ``tolerance`` (rad) of each other, only the lowest-cost one is kept (they would give the same
    image); the notes name the ones merged. The order of ``landmarks`` is kept."""
    kept: list[int] = []
    merged: dict[int, list[int]] = {}
    directions = direction_in_sphere_frame([lm.zenith for lm in landmarks], [lm.azimuth for lm in landmarks])
    limit = math.cos(tolerance) - 1e-12
    for i in sorted(range(len(landmarks)), key=lambda i: landmarks[i].cost):
        twin = next((k for k in kept if directions[k] @ directions[i] >= limit), None)
        if twin is None:
            kept.append(i)
        else:
            merged.setdefault(twin, []).append(i)
    notes = [
        f"landmarks {', '.join(str(landmarks[i].index) for i in sorted([k, *others]))} are one capture "
        f"(within {math.degrees(tolerance):g}° of each other): landmark {landmarks[k].index} is kept"
        for k, others in sorted(merged.items())
    ]
    return [landmarks[i] for i in sorted(kept)], notes


#: What a mode finds: the landmarks, their histograms and visibility masks at the camera's
#: resolution, and the sweep.
_Found = tuple[list[Landmark], list[Array], list[Array], CostGrid]


def _azimuth_mode(search: LandmarkSearch, progress: Progress | None, found: Callable[[Landmark], None]) -> _Found:
    spec = search.spec
    refiner = ZenithSearch(search.search, search.search_objective, search.sphere)
    zenith = _sweep_zeniths(search, math.radians(spec.sweep_step_deg))
    allowed = np.flatnonzero(zenith >= search.sphere.zenith_min)
    azimuth = 2 * np.pi * np.arange(spec.count) / spec.count
    costs = np.empty((spec.count, zenith.size))
    landmarks: list[Landmark] = []
    histograms: list[Array] = []
    visibilities: list[Array] = []

    has_pole = includes_pole(zenith)

    def shadows(j: int, skip_pole: bool) -> tuple[Array, Array]:
        """The lights of azimuth j's sweep (the pole left out when ``skip_pole``) and their masks."""
        positions = search.search.sphere.position(zenith[1:] if skip_pole else zenith, float(azimuth[j]))
        return positions, search.search.visibility(positions)

    # The next azimuth's shadow rays are cast in the background while this one's sweep objective,
    # refinement and camera-resolution scores are computed here: ~12 ms of rays there against
    # ~16 ms here on the default face (with the objective there too, the background would take ~15 ms
    # against ~10 ms here, and this thread would wait). The same numbers either way.
    pending = in_background(partial(shadows, 0, False))
    pole: tuple[float, Array] | None = None
    t0 = time.perf_counter()
    for j, phi in enumerate(azimuth):
        positions, masks = pending.result()
        if j + 1 < spec.count:
            pending = in_background(partial(shadows, j + 1, has_pole))
        costs[j, -len(positions) :] = sweep_objective(search.search, search.search_objective, positions, masks)
        if pole is not None:  # the pole, the one light every azimuth shares, is the first azimuth's
            costs[j, 0], masks = pole[0], np.vstack([pole[1], masks])
        elif has_pole:
            pole = (float(costs[0, 0]), masks[0])
        seeds = [
            Candidate(float(zenith[i]), float(phi), float(costs[j, i]), "sweep")
            for i in allowed[local_minima(costs[j, allowed])]
        ]
        best, iterations, first_status = seeds[0], 0, ""
        for seed in seeds[: spec.seeds]:
            mask = masks[int(np.searchsorted(zenith, seed.zenith))]
            # a seed on the view's boundary (or the cap's edge) the objective rises from needs no search
            if refiner.rises_from_end(float(phi), seed.zenith, seed.cost, mask):
                iterations += 1
                continue
            bracket = _bracket(zenith, seed.zenith, search.sphere)

            def solve(_zenith: float, azimuth: float, mask: Array, bracket: tuple[float, float] = bracket) -> Solve:
                return refiner.solve(azimuth, mask, bracket)

            refined, its, status = search.refine(seed, solve, mask)
            iterations += its
            first_status = first_status or status
            if refined is not None and refined.cost < best.cost:
                best = refined
        sample = dataclasses.replace(seeds[0], solver_status=first_status)
        best = sample if best is seeds[0] else best
        lm, hist, mask = search.finish(j, sample, best, iterations, t0, polish=True)
        t0 = time.perf_counter()
        landmarks.append(lm)
        histograms.append(hist)
        visibilities.append(mask)
        found(lm)
        if progress is not None:
            progress(j + 1, spec.count)
    return landmarks, histograms, visibilities, CostGrid(zenith, azimuth, costs)


def _bracket(zenith: Array, seed: float, sphere: LightSphere) -> tuple[float, float]:
    """The zeniths (rad) between the sweep neighbours of the sweep sample ``seed`` (a local minimum
    of the sweep, so the objective's minimum near it lies there), within ``sphere``'s allowed range."""
    i = int(np.searchsorted(zenith, seed))
    lo = zenith[max(i - 1, 0)]
    hi = zenith[min(i + 1, zenith.size - 1)]
    return max(float(lo), sphere.zenith_min), min(float(hi), sphere.zenith_max)


def _sweep_zeniths(search: LandmarkSearch, step: float) -> Array:
    """The sweep's zeniths: the whole ``[light_sphere]`` range (the cost map shows what the view takes
    away), at most ``step`` apart, plus the smallest allowed zenith (the view's boundary) itself."""
    full = zenith_grid(search.requested, step)
    return np.unique(np.r_[full, search.sphere.zenith_min])


def _free_mode(search: LandmarkSearch, progress: Progress | None, found: Callable[[Landmark], None]) -> _Found:
    spec = search.spec
    step = math.radians(spec.sweep_step_deg)
    separation = math.radians(spec.min_separation_deg)
    zenith = _sweep_zeniths(search, step)
    azimuth = np.linspace(0.0, 2 * np.pi, max(3, math.ceil(2 * np.pi / step - 1e-9)), endpoint=False)
    total = azimuth.size + spec.count
    costs = sweep_costs(
        search.search,
        search.search_objective,
        zenith,
        azimuth,
        None if progress is None else (lambda done, _n: progress(done, total)),
    )
    refiner = CapRefiner(search.search, search.search_objective, search.solver, spec.count, search.sphere)
    # Samples as unique directions: the pole (θ = 0) once, not once per azimuth; only allowed ones.
    jj, ii = np.meshgrid(np.arange(azimuth.size), np.arange(zenith.size), indexing="ij")
    keep = ((zenith[ii] > 0) | (jj == 0)) & (zenith[ii] >= search.sphere.zenith_min)
    jj, ii = jj[keep], ii[keep]
    order = np.argsort(costs[jj, ii], kind="stable")
    directions = direction_in_sphere_frame(zenith[ii], azimuth[jj])
    accepted: list[Array] = []
    landmarks: list[Landmark] = []
    histograms: list[Array] = []
    visibilities: list[Array] = []
    for k in order:
        if len(landmarks) == spec.count:
            break
        if not _separated(directions[k], accepted, separation):
            continue
        t0 = time.perf_counter()
        sample = Candidate(float(zenith[ii[k]]), float(azimuth[jj[k]]), float(costs[jj[k], ii[k]]), "sweep")
        refined, iterations, status = search.refine(
            sample, lambda t, p, v: refiner.solve(t, p, v, np.array(accepted).reshape(-1, 3), separation)
        )
        sample = dataclasses.replace(sample, solver_status=status)
        best = sample
        if (
            refined is not None
            and refined.cost < sample.cost
            and _separated(direction_in_sphere_frame(refined.zenith, refined.azimuth), accepted, separation)
        ):
            best = refined
        lm, hist, mask = search.finish(len(landmarks), sample, best, iterations, t0, polish=False)
        landmarks.append(lm)
        histograms.append(hist)
        visibilities.append(mask)
        accepted.append(direction_in_sphere_frame(lm.zenith, lm.azimuth))
        found(lm)
        if progress is not None:
            progress(azimuth.size + len(landmarks), total)
    if len(landmarks) < spec.count:
        raise ProblemError(
            search.file,
            "landmarks.count",
            f"at most {len(landmarks)} landmarks {spec.min_separation_deg:g}° apart on the allowed cap "
            "(or a smaller landmarks.min_separation_deg)",
            spec.count,
        )
    return landmarks, histograms, visibilities, CostGrid(zenith, azimuth, costs)


def _separated(direction: Array, accepted: list[Array], separation: float) -> bool:
    """True when ``direction`` is at least ``separation`` (rad) from every accepted direction (up to
    a 1e-9 tolerance on the cosine)."""
    return not accepted or float((np.array(accepted) @ direction).max()) <= math.cos(separation) + 1e-9
