"""The search over placements: a grid per level, refined around the best, scored on the engine, the
best few solved in full."""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from optlight.batch.row import solve_row
from optlight.batch.spec import apply_overrides
from optlight.cell.outputs import Candidate, CellResult, write_cell
from optlight.cell.scoring import evaluate_placement, landmark_lights, unscored
from optlight.cell.spec import AXES, Array, CellSpec, load_cell_spec
from optlight.engine import engine, error_text, progress_bar, run_tasks
from optlight.errors import ProblemError
from optlight.export import check_output_folder
from optlight.spec import Problem

if TYPE_CHECKING:
    from distributed import Client


#: Decimals the searched values are rounded to (m, and degrees for yaw): far below any placement's
#: precision, far above the residues of floating-point steps (see :func:`axis_values`).
GRID_DECIMALS = 12


def axis_values(lo: float, hi: float, steps: int) -> Array:
    """``steps`` evenly spaced values on [lo, hi], or the one value when lo = hi, rounded to
    :data:`GRID_DECIMALS` decimals: lo + i·step leaves residues of ~1e-17, and a finer level's window
    around 0.075 m of the example cell began at −1.4e-17 m instead of 0 (and had 0.11249999999999996
    for 0.1125), which the command printed and ``best_problem.toml`` kept."""
    values = np.array([lo]) if lo == hi else np.linspace(lo, hi, steps)
    return np.round(values, GRID_DECIMALS) + 0.0  # + 0.0: a rounded −0.0 becomes 0.0


def level_grid(spec: CellSpec, level: int, center: Mapping[str, float] | None) -> list[dict[str, float]]:
    """The placements of one level: the whole ranges at level 0; at level L the window of half-width
    w_L = (hi − lo)/2^(L+1) per axis around ``center``, shifted to stay inside [lo, hi]."""
    per_axis = []
    for axis, (lo, hi) in spec.ranges.items():
        if level == 0 or center is None or lo == hi:
            per_axis.append(axis_values(lo, hi, spec.steps))
            continue
        w = (hi - lo) / 2.0 ** (level + 1)
        c = min(max(center[axis], lo + w), hi - w)
        per_axis.append(axis_values(c - w, c + w, spec.steps))
    axes = list(spec.ranges)
    mesh = np.meshgrid(*per_axis, indexing="ij")
    return [
        dict(zip(axes, map(float, point), strict=True))
        for point in np.stack([m.ravel() for m in mesh], axis=1)
    ]


def placement_problem(spec: CellSpec, values: Mapping[str, float]) -> Problem:
    """The base problem with the placement ``values`` written into its vectors (validated)."""
    vectors: dict[str, list[float]] = {}
    sources: dict[str, str] = {}
    for axis, value in values.items():
        key, component = AXES[axis]
        section, name = key.split(".")
        vector = vectors.setdefault(key, list(getattr(getattr(spec.base, section), name)))
        vector[component] = value
        sources[key] = f"search.{axis}"
    return apply_overrides(spec.base, vectors, sources, spec.file)


def design_cell(
    spec: CellSpec | str | Path,
    out: str | Path,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    serial: bool = False,
    progress: bool = True,
    client: Client | None = None,
    overwrite: bool = False,
) -> CellResult:
    """Search the placements of a cell spec (a :class:`CellSpec` or a file) and write the results into
    ``out`` (module docstring). The engine (:mod:`optlight.engine`) as :func:`optlight.batch.run_batch`:
    a local cluster of ``workers`` processes, the remote ``scheduler``, the caller's ``client``, or here when ``serial``.
    ``out`` follows the output policy of :mod:`optlight.export`, checked before any work: a new or
    empty folder, or with ``overwrite`` an earlier optlight output (only its own files replaced)."""
    out = Path(out)
    check_output_folder(out, overwrite=overwrite)
    spec = spec if isinstance(spec, CellSpec) else load_cell_spec(spec)
    start = time.perf_counter()
    candidates: list[Candidate] = []
    with engine(serial=serial, scheduler=scheduler, workers=workers, client=client) as client:
        lights = spec.lights
        if lights is None:
            found: list[Array] = []
            run_tasks(client, [(landmark_lights, (spec.base,))], lambda i, r: found.append(r))
            lights = found[0]
        seen: set[tuple[float, ...]] = set()
        search_start = time.perf_counter()
        for level in range(spec.levels):
            center = min(candidates, key=Candidate.rank).values if candidates else None
            grid = [v for v in level_grid(spec, level, center) if _point(v) not in seen]
            if not grid:
                break
            seen.update(_point(v) for v in grid)
            _score(client, spec, grid, level, lights, candidates, progress)
        search_s = time.perf_counter() - search_start
        candidates = _solve_best(client, spec, candidates, progress)
    best = min(candidates, key=lambda c: (c.rank()[0], not c.verified, c.duration_s, *c.rank()[1:]))
    best_problem = placement_problem(spec, best.values)
    best_problem = dataclasses.replace(
        best_problem,
        description=f"{spec.base.description or spec.base.name} — cell design: "
        + ", ".join(f"{a} = {best.values[a]:g}" for a in spec.searched),
    )
    elapsed = time.perf_counter() - start
    result = CellResult(spec, lights, tuple(candidates), best, best_problem, {}, elapsed, search_s)
    return dataclasses.replace(result, files=write_cell(out, result, overwrite=overwrite))


def _point(values: Mapping[str, float]) -> tuple[float, ...]:
    return tuple(round(v, 9) for v in values.values())


def _score(
    client: Any,
    spec: CellSpec,
    grid: Sequence[Mapping[str, float]],
    level: int,
    lights: Array,
    candidates: list[Candidate],
    progress: bool,
) -> None:
    """Score the placements of ``grid`` on the engine, appending them to ``candidates``."""
    first = len(candidates)
    problems: list[Problem | str] = []
    for values in grid:
        try:
            problems.append(placement_problem(spec, values))
        except ProblemError as e:
            problems.append(error_text(e))
    tasks = [(evaluate_placement, (p, lights)) for p in problems if isinstance(p, Problem)]
    built = [i for i, p in enumerate(problems) if isinstance(p, Problem)]
    outcomes: dict[int, Mapping[str, Any]] = {
        i: {**unscored(len(lights)), "error": p, "time_s": 0.0}
        for i, p in enumerate(problems)
        if isinstance(p, str)
    }
    with progress_bar(progress, len(tasks), f"cell level {level + 1}/{spec.levels}") as advance:

        def on_done(k: int, outcome: Mapping[str, Any]) -> None:
            outcomes[built[k]] = outcome
            advance(None)

        run_tasks(client, tasks, on_done, lost={**unscored(len(lights)), "time_s": math.nan})
    for i, values in enumerate(grid):
        o = outcomes[i]
        candidates.append(
            Candidate(
                first + i,
                dict(values),
                level,
                o["lights"],
                o["reached"],
                o["clear"],
                o["robot_clear"],
                o["housing_blocked"],
                o["blocked_by"],
                o["error"],
                o["time_s"],
            )
        )


def _solve_best(client: Any, spec: CellSpec, candidates: list[Candidate], progress: bool) -> list[Candidate]:
    """Solve in full the placements with the best score and robot-clear count (at most ``spec.top``,
    the most lights reached first); returns the candidates with those outcomes attached."""
    ranked = sorted(candidates, key=Candidate.rank)
    if not ranked or ranked[0].reached == 0:
        return candidates
    chosen = [c for c in ranked if c.rank()[:2] == ranked[0].rank()[:2]][: spec.top]
    tasks = [(solve_row, (placement_problem(spec, c.values), spec.preview)) for c in chosen]
    solved = list(candidates)
    with progress_bar(progress, len(tasks), "full solves") as advance:

        def on_done(k: int, outcome: Mapping[str, Any]) -> None:
            solved[chosen[k].index] = dataclasses.replace(chosen[k], solve=outcome)
            advance(None if outcome["status"] == "ok" else f"placement {chosen[k].index}: {outcome['error']}")

        run_tasks(client, tasks, on_done, lost={"status": "failed", "metrics": {}, "warnings": []})
    return solved
