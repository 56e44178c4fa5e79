"""A problem file's ``[lightset]`` as the set cost to design or the grid to map
(docs/design.md §10).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from optlight.errors import OptlightError, ProblemError
from optlight.planning.lightsets.cost import ImageSetTerm, SetCost, SetTerm
from optlight.planning.lightsets.grid import Grid, grid_from_degrees, read_grid_file, yale_b_grid
from optlight.planning.lightsets.photometric_stereo import PhotometricStereoTerm
from optlight.planning.lightsets.rti import RieszEnergy

if TYPE_CHECKING:
    from optlight.objectives import Objective
    from optlight.scene import Scene
    from optlight.spec import Problem


def set_cost_from_problem(problem: Problem, scene: Scene, objective: Objective | None = None) -> SetCost:
    """The set cost of a problem's ``[lightset]``: ``photometric_stereo`` (the per-pixel term on
    ``scene``) or ``rti`` (Riesz energy), plus ``image_weight`` × the image objective averaged over
    the lights when that weight is positive (``objective``, the problem's ``[objective]``)."""
    spec = problem.lightset
    file = str(problem.source) if problem.source else "<inline>"
    terms: list[tuple[float, SetTerm]] = []
    if spec.kind == "photometric_stereo":
        terms.append(
            (
                1.0,
                PhotometricStereoTerm.from_scene(
                    scene,
                    regularization=spec.regularization,
                    saturation_level=spec.saturation_level,
                    softness=spec.softness,
                ),
            )
        )
    elif spec.kind == "rti":
        terms.append((1.0, RieszEnergy(spec.riesz_exponent)))
    else:
        raise ProblemError(
            file, "lightset.kind", "a designed set ('photometric_stereo' or 'rti') for a set cost", spec.kind
        )
    if spec.image_weight > 0:
        if objective is None:
            raise OptlightError("lightset.image_weight > 0 needs the problem's image objective")
        terms.append((spec.image_weight, ImageSetTerm(objective, scene)))
    return SetCost(terms)


def grid_from_problem(problem: Problem) -> Grid:
    """The grid of a problem's ``[lightset]`` (kind = grid): ``grid_deg`` pairs, ``grid_file``, or the
    Yale B 64 directions when neither is set."""
    spec = problem.lightset
    file = str(problem.source) if problem.source else "<inline>"
    if spec.grid_deg is not None:
        return _distinct_grid(grid_from_degrees(spec.grid_deg), file, "lightset.grid_deg", "grid_deg[{}]", 0)
    if spec.grid_file is not None:
        key = "lightset.grid_file"
        grid = read_grid_file(problem.resolve(spec.grid_file), file, key)
        return _distinct_grid(grid, file, key, f"{Path(spec.grid_file).name} data row {{}}", 1)
    return yale_b_grid()


#: Grid directions closer than this (rad) are the same light: one capture cannot stand for two.
SAME_DIRECTION_RAD = 1e-9


def _distinct_grid(grid: Grid, file: str, key: str, entry: str, first: int) -> Grid:
    """``grid`` when no two of its directions are the same light (within :data:`SAME_DIRECTION_RAD`);
    else a :class:`ProblemError` naming ``file``, ``key`` and the first two such entries (``entry``
    formatted with their index counted from ``first``)."""
    d = grid.directions
    cross = np.linalg.norm(np.cross(d[:, None, :], d[None, :, :]), axis=2)
    angle = np.arctan2(cross, d @ d.T)
    same = np.argwhere(np.triu(angle <= SAME_DIRECTION_RAD, k=1))
    if same.size:
        i, j = same[0]
        raise ProblemError(
            file,
            key,
            "distinct light directions (a grid light is one capture)",
            f"{entry.format(i + first)} ({grid.names[i]}) and {entry.format(j + first)} ({grid.names[j]}) "
            "are the same direction",
        )
    return grid
