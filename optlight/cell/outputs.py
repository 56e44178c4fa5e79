"""The result of a cell search (its candidates and the best placement) and its files: the table of
candidates, the summary and the heat map."""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from optlight.cell.problem_toml import problem_toml
from optlight.cell.spec import Array, CellSpec
from optlight.export import write_folder
from optlight.jsondata import json_safe
from optlight.spec import Problem

if TYPE_CHECKING:
    from matplotlib.figure import Figure


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
