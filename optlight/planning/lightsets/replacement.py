"""Grid lights replaced by allowed ones (docs/design.md §10): :func:`map_grid` maps each grid
direction to the nearest allowed light and reports every replacement (:class:`GridMapping`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.errors import OptlightError, ProblemError, UnreachableError
from optlight.planning.lightsets.directions import Array, Cap, angles_of
from optlight.planning.lightsets.grid import Grid


@dataclass(frozen=True)
class GridMapping:
    """Requested and achieved lights of a grid: ``requested`` and ``achieved`` (K, 3) sphere frame,
    ``moved`` (K,) the angle between them (rad), ``replaced`` (K,) where they differ, ``names``."""

    names: tuple[str, ...]
    requested: Array
    achieved: Array
    moved: Array
    replaced: NDArray[np.bool_]

    @property
    def replaced_count(self) -> int:
        return int(self.replaced.sum())

    def report(self) -> dict[str, Any]:
        """Requested vs achieved in a JSON-friendly summary (degrees)."""
        return {
            "requested": len(self.names),
            "achieved_exactly": len(self.names) - self.replaced_count,
            "replaced": [
                {"name": n, "moved_deg": math.degrees(float(m))}
                for n, m, r in zip(self.names, self.moved, self.replaced, strict=True)
                if r
            ],
            "max_moved_deg": math.degrees(float(self.moved.max(initial=0.0))),
        }


def map_grid(
    grid: Grid,
    cap: Cap,
    allowed: Callable[[Array], NDArray[np.bool_]] | NDArray[np.bool_] | None = None,
    candidates: ArrayLike | None = None,
    *,
    spacing: float = math.radians(2.0),
    distinct: bool = True,
    outside_cap: Literal["replace", "error"] = "replace",
    file: str = "<api>",
    key: str = "lightset.grid",
) -> GridMapping:
    """Each grid direction mapped to the nearest allowed light.

    ``allowed``: a callable ``directions (M, 3) -> bool (M,)`` (the lead's reachable-and-clear
    predicate), or a boolean mask over ``candidates`` (M, 3), or None (the whole cap). Candidates:
    ``candidates`` when given, else the grid's own directions plus a lattice of the cap about
    ``spacing`` (rad) apart; only those on the cap and allowed are used. ``distinct``: no two grid
    lights share a candidate (an assignment minimising Σ moved², :func:`scipy.optimize.linear_sum_assignment`);
    otherwise each takes its nearest. ``outside_cap = "error"`` refuses grid directions off the cap
    (a :class:`ProblemError` naming ``key``) instead of replacing them.
    Raises :class:`UnreachableError` when fewer candidates are allowed than the grid needs."""
    from scipy.optimize import linear_sum_assignment

    requested = np.asarray(grid.directions, float)
    if outside_cap == "error":
        outside = np.flatnonzero(~cap.contains(requested, tol=1e-9))
        if outside.size:
            zenith = math.degrees(float(angles_of(requested[outside[0]])[0]))
            raise ProblemError(
                file,
                key,
                f"grid directions inside the cap (zenith ≤ {math.degrees(cap.zenith_max):g}°)",
                f"{grid.names[outside[0]]} at zenith {zenith:.1f}°",
            )
    if isinstance(allowed, np.ndarray):
        if candidates is None:
            raise OptlightError("an allowed mask needs the candidates it is over")
        pool = np.asarray(candidates, float)
        ok = np.asarray(allowed, bool)
        if ok.shape != (len(pool),):
            raise OptlightError(f"allowed mask of shape {ok.shape} for {len(pool)} candidates")
    else:
        pool = (
            np.asarray(candidates, float)
            if candidates is not None
            else np.vstack([requested, cap.lattice(cap.area_count(spacing))])
        )
        ok = np.ones(len(pool), bool) if allowed is None else np.asarray(allowed(pool), bool)
    ok = ok & cap.contains(pool)
    usable = pool[ok]
    need = len(requested) if distinct else 1
    if len(usable) < need:
        raise UnreachableError(
            f"{len(usable)} allowed light directions for a grid of {len(requested)}: "
            "widen the cap or the allowed region"
        )
    # atan2(|a × b|, a·b): accurate for small angles too, where arccos(a·b) is off by ~1e-8 rad
    cross = np.linalg.norm(np.cross(requested[:, None, :], usable[None, :, :]), axis=2)
    angle = np.arctan2(cross, requested @ usable.T)
    pick = angle.argmin(axis=1)
    if distinct:
        # grid lights that are allowed as they are keep their place; the rest share what is left
        exact = angle[np.arange(len(requested)), pick] <= 1e-12
        rest = np.flatnonzero(~exact)
        free = np.setdiff1d(np.arange(len(usable)), pick[exact])
        if len(free) < len(rest) or len(set(pick[exact])) < exact.sum():
            raise UnreachableError(
                f"{len(usable)} allowed light directions cannot hold a grid of {len(requested)} distinct lights"
            )
        rows, cols = linear_sum_assignment(angle[np.ix_(rest, free)] ** 2)
        pick[rest[rows]] = free[cols]
    achieved = usable[pick]
    moved = angle[np.arange(len(requested)), pick]
    return GridMapping(grid.names, requested, achieved, moved, moved > 1e-12)
