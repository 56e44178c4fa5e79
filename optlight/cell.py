"""Robot-cell design: where to bolt the robot (and put the camera) so that it reaches the most lights.

A *cell spec* (TOML) names a base problem, the lights to reach and the ranges to search::

    description = "where to put the panda"
    problem = "default"          # a built-in name, or a path relative to this file
    lights = "landmarks"         # the base problem's landmarks, or [[zenith_deg, azimuth_deg], ...]
    method = "coarse_to_fine"    # or "grid"
    steps = 5                    # values per searched axis (per level)
    levels = 3                   # coarse_to_fine: each level halves the window, around the best so far
    top = 3                      # best placements solved in full for their acquisition time
    preview = false              # preview.html in best_plan/

    [search]                     # [low, high] in the world frame; an axis left out keeps the problem's
    base_x_m = [-0.15, 0.15]     # robot.base_position_m[0]
    base_y_m = [-0.15, 0.15]     # robot.base_position_m[1]
    # base_z_m, base_yaw_deg (robot.base_rpy_deg[2]), camera_x_m, camera_y_m, camera_z_m

**Score of a placement.** The lights are zenith/azimuth pairs on the light sphere (the landmarks are
found once, :func:`~optlight.planning.landmarks.find_landmarks` on the base problem; the sphere's
frame follows the camera, so moving the camera moves them with it). For each placement, its problem
is built (:meth:`Setup.from_problem`) and each light is tried in azimuth order with the placement
policy (:meth:`~optlight.planning.policy.Reacher.attempt`: the IK, then with ``[environment]`` a
clear posture), warm-started from the previous light's joint angles, then from the robot's reference
posture. At the joint angles found, the exact view and beam check
(:func:`~optlight.environment.view.view_check_for`: rays from the camera to the object and from the
light to the object against the robot's collision meshes and the light housing) says whether the
capture would be clear. The score is the fraction of the lights reached with the view and the beam
clear. It is what the IK's posture gives, so a lower bound: another posture of a redundant arm may be
clear where this one is not. Ties are broken by the lights where no robot link blocks a ray (the
light's own housing may: a light near the camera axis is in the view whatever the placement), then by
the lights reached. A placement whose problem is invalid (the camera inside the light sphere,
not seeing the object) scores 0 with its error.

**Search.** ``grid``: every combination of ``steps`` values per searched axis. ``coarse_to_fine``:
that grid, then at each level L = 1 … ``levels − 1`` a grid of ``steps`` values per axis over a
window half as wide as the previous level's (2^−L of the range), centred on the best placement so far
and shifted to stay inside the range (new points only). Each placement is one task on the batch
engine (:mod:`optlight.batch`: a local Dask cluster, or a remote scheduler).

**Then the acquisition time.** The placements with the best score (at most ``top``, the most lights
reached first) are solved in full (``optlight.solve``, on the engine); the best is the one whose plan
verifies with the shortest ``plan.trajectory.duration``. Its problem is written as a problem file
(``best_problem.toml``; paths in it made absolute) and its plan as ``best_plan/``.

Written into ``OUT``: ``cell_heatmap.png`` (the score over the first two searched axes, the best over
any others; finer levels as dots), ``candidates.csv`` (every placement), ``cell.json`` (the summary)
and ``best_problem.toml``, ``best_plan/``.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import re
import time
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from optlight.batch.row import solve_row
from optlight.batch.spec import apply_overrides, base_problem, check_keys
from optlight.engine import engine, error_text, progress_bar, run_tasks
from optlight.environment.view import HOUSING, view_check_for
from optlight.errors import ProblemError
from optlight.export import check_output_folder, write_folder
from optlight.jsondata import json_safe
from optlight.planning.landmarks import find_landmarks
from optlight.planning.policy import Reacher
from optlight.setup import Setup
from optlight.spec import Problem, read_toml

if TYPE_CHECKING:
    from distributed import Client
    from matplotlib.figure import Figure

Array = NDArray[np.float64]

#: Searchable axes: spec key -> (problem key of a 3-vector, component).
AXES: dict[str, tuple[str, int]] = {
    "base_x_m": ("robot.base_position_m", 0),
    "base_y_m": ("robot.base_position_m", 1),
    "base_z_m": ("robot.base_position_m", 2),
    "base_yaw_deg": ("robot.base_rpy_deg", 2),
    "camera_x_m": ("camera.position_m", 0),
    "camera_y_m": ("camera.position_m", 1),
    "camera_z_m": ("camera.position_m", 2),
}
SPEC_KEYS = ("description", "problem", "lights", "method", "steps", "levels", "top", "preview", "search")
#: Problem keys that hold a file path (relative to the problem file, so made absolute when written elsewhere).
PATH_KEYS = (
    "object.path",
    "robot.urdf",
    "objective.reference.image",
    "objective.reference.mask",
    "lightset.grid_file",
)


# --------------------------------------------------------------------------------------------
# The cell spec
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CellSpec:
    """A validated cell spec. ``lights`` (N, 2) zenith, azimuth in rad, or None for the base
    problem's landmarks; ``ranges`` axis -> (low, high) for every axis of :data:`AXES` written."""

    source: Path | None
    description: str
    base: Problem
    lights: Array | None
    method: str
    steps: int
    levels: int
    top: int
    preview: bool
    ranges: Mapping[str, tuple[float, float]]

    @property
    def file(self) -> str:
        return str(self.source) if self.source else "<inline>"

    @property
    def searched(self) -> tuple[str, ...]:
        """The axes whose range is not a single value, in the order of :data:`AXES`."""
        return tuple(a for a in AXES if a in self.ranges and self.ranges[a][0] < self.ranges[a][1])

    def base_value(self, axis: str) -> float:
        """The base problem's value along ``axis``."""
        key, component = AXES[axis]
        section, name = key.split(".")
        return float(getattr(getattr(self.base, section), name)[component])


def load_cell_spec(path: str | Path) -> CellSpec:
    """Read and validate a cell spec file (see the module docstring)."""
    path = Path(path).expanduser()
    return cell_spec_from_dict(read_toml(path), source=path.resolve())


def cell_spec_from_dict(data: Mapping[str, Any], source: Path | None = None) -> CellSpec:
    """Validate a parsed cell spec; each mistake a :class:`ProblemError` naming the file and the key."""
    file = str(source) if source else "<inline>"
    check_keys(data, SPEC_KEYS, file, "")
    base = base_problem(data, source, file)

    def integer(key: str, default: int, lo: int, hi: int) -> int:
        value = data.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
            raise ProblemError(file, key, f"an integer in [{lo}, {hi}]", value)
        return value

    method = data.get("method", "grid")
    if method not in ("grid", "coarse_to_fine"):
        raise ProblemError(file, "method", "one of 'grid', 'coarse_to_fine'", method)
    preview = data.get("preview", False)
    if not isinstance(preview, bool):
        raise ProblemError(file, "preview", "true or false", preview)
    description = data.get("description", "")
    if not isinstance(description, str):
        raise ProblemError(file, "description", "a string", description)

    search = data.get("search")
    if not isinstance(search, dict) or not search:
        raise ProblemError(file, "search", f"a table of ranges, some of {', '.join(AXES)}", search)
    check_keys(search, tuple(AXES), file, "search")
    ranges: dict[str, tuple[float, float]] = {}
    for axis, value in search.items():
        if (
            not isinstance(value, list)
            or len(value) != 2
            or not all(_finite(v) for v in value)
            or value[0] > value[1]
        ):
            raise ProblemError(file, f"search.{axis}", "[low, high], two numbers with low ≤ high", value)
        ranges[axis] = (float(value[0]), float(value[1]))
    if not any(lo < hi for lo, hi in ranges.values()):
        raise ProblemError(file, "search", "at least one range with low < high", search)

    return CellSpec(
        source=source,
        description=description,
        base=base,
        lights=_lights(data.get("lights", "landmarks"), base, file),
        method=method,
        steps=integer("steps", 5, 2, 101),
        levels=integer("levels", 3 if method == "coarse_to_fine" else 1, 1, 20),
        top=integer("top", 3, 1, 100),
        preview=preview,
        ranges=ranges,
    )


def _finite(value: Any) -> bool:
    return not isinstance(value, bool) and isinstance(value, int | float) and math.isfinite(value)


def _lights(value: Any, base: Problem, file: str) -> Array | None:
    """``lights``: "landmarks" (None), or (N, 2) zenith, azimuth in rad within the base's zenith range."""
    if value == "landmarks":
        return None
    expected = '"landmarks" or a non-empty list of [zenith_deg, azimuth_deg] pairs'
    if not isinstance(value, list) or not value:
        raise ProblemError(file, "lights", expected, value)
    zmin, zmax = base.light_sphere.zenith_min_deg, base.light_sphere.zenith_max_deg
    for i, pair in enumerate(value):
        if not isinstance(pair, list) or len(pair) != 2 or not all(_finite(v) for v in pair):
            raise ProblemError(file, f"lights[{i}]", "[zenith_deg, azimuth_deg]", pair)
        if not zmin <= pair[0] <= zmax:
            raise ProblemError(
                file, f"lights[{i}][0]", f"a zenith in the problem's [{zmin:g}, {zmax:g}] deg", pair[0]
            )
    return np.deg2rad(np.array(value, float))


# --------------------------------------------------------------------------------------------
# Tasks (run on the workers)
# --------------------------------------------------------------------------------------------


def landmark_lights(problem: Problem) -> Array:
    """(N, 2) zenith, azimuth (rad) of the problem's landmarks."""
    landmarks = find_landmarks(Setup.from_problem(problem))
    return np.column_stack([landmarks.zeniths, landmarks.azimuths])


def evaluate_placement(problem: Problem, lights: Array) -> dict[str, Any]:
    """The score of one placement (module docstring): how many of ``lights`` (N, 2: zenith, azimuth
    in rad) the robot ``reached``, how many of those with the view and the beam ``clear``, how many
    where no robot link blocks a ray (``robot_clear``: only the light's own housing may, which no
    placement changes) and where the housing blocks the view (``housing_blocked``), for each body
    that is the first obstacle of some view or beam ray the number of lights where it is
    (``blocked_by``, most first), ``error`` when the problem cannot be built or the evaluation
    failed (then all counts are 0), and the evaluation's ``time_s``."""
    start = time.perf_counter()
    out: dict[str, Any] = {**unscored(len(lights)), "error": None}
    try:
        setup = Setup.from_problem(problem)
        reacher, robot = Reacher(setup), setup.robot
        thetas = []
        previous = robot.theta_ref
        for zenith, azimuth in lights[np.argsort(lights[:, 1], kind="stable")]:
            position = setup.sphere.position(zenith, azimuth)
            attempt = reacher.attempt(position, previous)
            if attempt.theta is None and previous is not robot.theta_ref:
                attempt = reacher.attempt(position, robot.theta_ref)
            if attempt.theta is not None:
                thetas.append(attempt.theta)
                previous = attempt.theta
        out["reached"] = len(thetas)
        if thetas:
            view = view_check_for(robot, setup.scene, problem.light).check(
                np.array(thetas), np.zeros(len(thetas))
            )
            out["clear"] = sum(c.view_blocked == 0.0 and c.beam_blocked == 0.0 for c in view.captures)
            out["robot_clear"] = sum(
                not ({*c.view_bodies, *c.beam_bodies} - {HOUSING}) for c in view.captures
            )
            out["housing_blocked"] = sum(HOUSING in c.view_bodies for c in view.captures)
            blockers = Counter(b for c in view.captures for b in {*c.view_bodies, *c.beam_bodies})
            out["blocked_by"] = dict(blockers.most_common())
    except Exception as e:  # a placement's failure is its score (0), not the search's end
        out.update(unscored(len(lights)), error=error_text(e))
    out["time_s"] = time.perf_counter() - start
    return out


def unscored(lights: int) -> dict[str, Any]:
    """The counts of a placement that could not be scored."""
    return {
        "lights": lights,
        "reached": 0,
        "clear": 0,
        "robot_clear": 0,
        "housing_blocked": 0,
        "blocked_by": {},
    }


# --------------------------------------------------------------------------------------------
# Candidates and the search
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Candidate:
    """One placement: ``values`` axis -> value (every axis of the spec), the search ``level`` it was
    made at, its score's counts (:func:`evaluate_placement`), and once solved in full
    (``solve``: the batch's row outcome without files) its acquisition time."""

    index: int
    values: Mapping[str, float]
    level: int
    lights: int
    reached: int
    clear: int
    robot_clear: int
    housing_blocked: int
    blocked_by: Mapping[str, int]
    error: str | None
    time_s: float
    solve: Mapping[str, Any] | None = None

    @property
    def fraction(self) -> float:
        """Fraction of the lights reached with the view and the beam clear."""
        return self.clear / self.lights if self.lights else 0.0

    @property
    def duration_s(self) -> float:
        """The full plan's trajectory duration (s); inf when not solved or when the solve failed."""
        value = (self.solve or {}).get("metrics", {}).get("duration_s")
        return float(value) if value is not None else math.inf

    @property
    def verified(self) -> bool:
        """The full plan was solved, verified and saved."""
        return self.solve is not None and self.solve.get("status") == "ok"

    def rank(self) -> tuple[float, int, int, int]:
        """Sort key of the score: the fraction clear, then the lights where no robot link blocks the
        view or the beam, then the lights reached (most first)."""
        return (-self.fraction, -self.robot_clear, -self.reached, self.index)


@dataclass(frozen=True)
class CellResult:
    """A finished cell search: the spec, the ``lights`` (N, 2 rad) scored, every ``candidates``
    placement in evaluation order, the ``best`` one and its ``best_problem``, the files written, the
    wall time ``elapsed_s`` of the whole design and ``search_s`` of the scoring alone."""

    spec: CellSpec
    lights: Array
    candidates: tuple[Candidate, ...]
    best: Candidate
    best_problem: Problem
    files: Mapping[str, Path]
    elapsed_s: float
    search_s: float

    @property
    def throughput_per_min(self) -> float:
        """Placements scored per minute of wall time of the scoring (the landmark search and the full
        solves excluded)."""
        return 60.0 * len(self.candidates) / self.search_s if self.search_s > 0 else math.inf

    def summary_lines(self) -> list[str]:
        """What the command prints."""
        best = self.best
        where = ", ".join(f"{a} = {best.values[a]:g}" for a in self.spec.searched)
        lines = [
            f"{len(self.candidates)} placements scored against {len(self.lights)} lights in {self.elapsed_s:.1f} s",
            f"best: {where}: {best.clear} of {best.lights} lights reached with the view clear "
            f"({best.reached} reached)",
        ]
        if best.solve is not None:
            if math.isfinite(best.duration_s):
                verdict = "verified" if best.verified else f"not saved: {best.solve.get('error')}"
                lines.append(f"acquisition time {best.duration_s:.2f} s ({verdict})")
            else:
                lines.append(f"full solve failed: {best.solve.get('error')}")
        if best.housing_blocked:
            lines.append(
                f"the light's own housing blocks the camera's view at {best.housing_blocked} of the "
                f"{best.lights} lights, whatever the placement: they are too near the camera axis"
            )
        if best.clear == 0:
            lines.append(
                "no placement in the ranges reaches a light with the view clear; the best is ranked by "
                f"the lights where no robot link is in the way ({best.robot_clear})"
            )
        lines += [f"wrote {path}" for path in self.files.values()]
        return lines


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


# --------------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------------


def write_cell(out: Path, result: CellResult, *, overwrite: bool = False) -> dict[str, Path]:
    """Write the heat map, the candidates table, the summary, the best problem file and plan into
    ``out``, whole or not at all (:func:`optlight.export.write_folder`)."""
    names = {
        "heatmap": "cell_heatmap.png",
        "candidates": "candidates.csv",
        "problem": "best_problem.toml",
        "summary": "cell.json",
    }
    plan_files: Mapping[str, bytes] = (result.best.solve or {}).get("files") or {}

    def write(staging: Path) -> list[Path]:
        heatmap_figure(result).savefig(staging / names["heatmap"], dpi=120)
        _write_candidates(staging / names["candidates"], result)
        (staging / names["problem"]).write_text(problem_toml(result.best_problem))
        written = [staging / names[k] for k in ("heatmap", "candidates", "problem")]
        for name, content in plan_files.items():  # the best plan's folder, its own manifest included
            path = staging / "best_plan" / name
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(content)
            written.append(path)
        (staging / names["summary"]).write_text(json.dumps(json_safe(_summary(result)), indent=1) + "\n")
        return [*written, staging / names["summary"]]

    write_folder(out, write, overwrite=overwrite)
    files = {key: out / name for key, name in names.items()}
    if plan_files:
        files["plan"] = out / "best_plan"
    return files


def _write_candidates(path: Path, result: CellResult) -> None:
    axes = list(result.spec.ranges)
    header = ["index", "level", *axes, "lights", "reached", "clear", "robot_clear", "housing_blocked"]
    header += ["fraction", "duration_s", "verified"]
    header += ["time_s", "blocked_by", "error"]
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        for c in result.candidates:
            solved = c.solve is not None
            writer.writerow(
                [c.index, c.level, *(f"{c.values[a]:.9g}" for a in axes), c.lights, c.reached, c.clear]
                + [c.robot_clear, c.housing_blocked]
                + [f"{c.fraction:.6g}", f"{c.duration_s:.6g}" if math.isfinite(c.duration_s) else ""]
                + [str(c.verified).lower() if solved else "", f"{c.time_s:.4g}"]
                + [
                    " ".join(f"{k}:{n}" for k, n in c.blocked_by.items()),
                    c.error or (c.solve or {}).get("error") or "",
                ]
            )


def _summary(result: CellResult) -> dict[str, Any]:
    spec, best = result.spec, result.best
    return {
        "spec": str(spec.source) if spec.source else None,
        "problem": str(spec.base.source) if spec.base.source else None,
        "method": spec.method,
        "ranges": {a: list(r) for a, r in spec.ranges.items()},
        "lights_deg": np.rad2deg(result.lights),
        "candidates": len(result.candidates),
        "elapsed_s": result.elapsed_s,
        "search_s": result.search_s,
        "placements_per_min": result.throughput_per_min,
        "best": {
            "values": best.values,
            "fraction": best.fraction,
            "reached": best.reached,
            "clear": best.clear,
            "robot_clear": best.robot_clear,
            "housing_blocked": best.housing_blocked,
            "duration_s": best.duration_s if math.isfinite(best.duration_s) else None,
            "verified": best.verified,
            "error": (best.solve or {}).get("error"),
        },
        "solved": [
            {"index": c.index, "values": c.values, "duration_s": c.duration_s, "status": c.solve["status"]}
            for c in result.candidates
            if c.solve is not None
        ],
    }


def heatmap_figure(result: CellResult) -> Figure:
    """The score over the first two searched axes (the best over any other axis): the first level as
    a colour map, finer levels as dots, the best placement as a star, the base problem's as a cross;
    with one searched axis, the score along it. Where no placement has a clear light, the secondary
    score (lights with no robot link in the way) is shown instead."""
    from matplotlib.figure import Figure

    spec = result.spec
    searched = spec.searched
    fig = Figure(figsize=(6.4, 5.2), layout="constrained")
    ax = fig.add_subplot()
    best = result.best
    cands = result.candidates
    n = len(result.lights)

    def score(c: Candidate) -> float:
        return c.fraction

    label = f"fraction of the {n} lights reached with the view clear"
    if not any(c.clear for c in cands):  # all zero: show the secondary score that ranked them

        def score(c: Candidate) -> float:
            return c.robot_clear / c.lights if c.lights else 0.0

        label = f"fraction of the {n} lights with no robot link in the view\n(none is fully clear)"
    if len(searched) == 1:
        (axis,) = searched
        order = sorted(cands, key=lambda c: c.values[axis])
        ax.plot([c.values[axis] for c in order], [score(c) for c in order], "o-", ms=4)
        ax.plot(best.values[axis], score(best), "*", color="tab:red", ms=14, label="best")
        ax.axvline(spec.base_value(axis), color="grey", ls="--", label="base problem")
        ax.set_xlabel(axis)
        ax.set_ylabel(label)
        ax.set_ylim(-0.02, 1.02)
        ax.legend()
    else:
        xa, ya = searched[:2]
        xs = np.unique([c.values[xa] for c in cands if c.level == 0])
        ys = np.unique([c.values[ya] for c in cands if c.level == 0])
        grid = np.full((len(ys), len(xs)), np.nan)
        for c in cands:
            if c.level == 0:
                i, j = np.searchsorted(ys, c.values[ya]), np.searchsorted(xs, c.values[xa])
                grid[i, j] = np.nanmax([grid[i, j], score(c)])
        mesh = ax.pcolormesh(_edges(xs), _edges(ys), grid, cmap="viridis", vmin=0.0, vmax=1.0, shading="flat")
        fig.colorbar(mesh, ax=ax, label=label)
        finer = [c for c in cands if c.level > 0]
        if finer:
            ax.scatter(
                [c.values[xa] for c in finer],
                [c.values[ya] for c in finer],
                c=[score(c) for c in finer],
                cmap="viridis",
                vmin=0.0,
                vmax=1.0,
                s=18,
                edgecolors="black",
                linewidths=0.5,
                label="finer levels",
            )
        ax.plot(best.values[xa], best.values[ya], "*", color="tab:red", ms=16, mec="white", label="best")
        ax.plot(
            spec.base_value(xa), spec.base_value(ya), "x", color="white", ms=10, mew=2, label="base problem"
        )
        ax.set_xlabel(xa)
        ax.set_ylabel(ya)
        ax.legend(loc="upper right", fontsize=8, framealpha=0.8)
    title = f"{spec.base.name}: {spec.base.robot.name} placement, {len(cands)} candidates"
    if math.isfinite(best.duration_s):
        title += f"\nbest: {best.clear}/{best.lights} lights clear, acquisition {best.duration_s:.1f} s"
    else:
        title += f"\nbest: {best.clear}/{best.lights} lights clear"
    ax.set_title(title, fontsize=10)
    return fig


def _edges(centers: Array) -> Array:
    """Cell edges around sorted ``centers`` (midpoints, half a step beyond the ends)."""
    if len(centers) == 1:
        return np.array([centers[0] - 0.5, centers[0] + 0.5])
    mid = (centers[1:] + centers[:-1]) / 2
    return np.concatenate([[2 * centers[0] - mid[0]], mid, [2 * centers[-1] - mid[-1]]])


# --------------------------------------------------------------------------------------------
# A problem as a TOML file
# --------------------------------------------------------------------------------------------


_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def problem_toml(problem: Problem) -> str:
    """The problem as a problem file: :meth:`Problem.to_dict` (every set key) written as TOML, its
    file paths made absolute (the file is read from elsewhere). ``load_problem`` of the text gives the
    same problem."""
    data = problem.to_dict()
    for dotted in PATH_KEYS:
        *parents, name = dotted.split(".")
        node = data
        for part in parents:
            node = node.get(part, {})
        if isinstance(node.get(name), str):
            node[name] = str(problem.resolve(node[name]))
    lines: list[str] = []
    _toml_table(lines, data, ())
    return "\n".join(lines).strip() + "\n"


def _toml_table(lines: list[str], table: Mapping[str, Any], path: tuple[str, ...]) -> None:
    """Scalars and arrays of ``table`` first, then its tables ``[a.b]``, then its arrays of tables."""
    tables = {k: v for k, v in table.items() if isinstance(v, dict)}
    arrays = {
        k: v for k, v in table.items() if isinstance(v, list) and v and all(isinstance(x, dict) for x in v)
    }
    for key, value in table.items():
        if key not in tables and key not in arrays:
            lines.append(f"{_toml_key(key)} = {_toml_value(value)}")
    for key, value in tables.items():
        lines += ["", "[" + ".".join(_toml_key(p) for p in (*path, key)) + "]"]
        _toml_table(lines, value, (*path, key))
    for key, items in arrays.items():
        for item in items:
            lines += ["", "[[" + ".".join(_toml_key(p) for p in (*path, key)) + "]]"]
            _toml_table(lines, item, (*path, key))


def _toml_key(key: str) -> str:
    return key if _BARE_KEY.match(key) else json.dumps(key, ensure_ascii=False)


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return (
            repr(value)
            if math.isfinite(value)
            else ("nan" if math.isnan(value) else f"{'-' if value < 0 else ''}inf")
        )
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)  # JSON's escapes are TOML basic-string escapes
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")
