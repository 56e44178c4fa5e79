"""Grids of given light directions (docs/design.md §10): the :class:`Grid` type, the camera-axis
(azimuth, elevation) convention of the face databases, grid files and the Extended Yale B list.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from optlight.errors import ProblemError
from optlight.planning.lightsets.directions import Array


@dataclass(frozen=True)
class Grid:
    """A given list of light directions: ``names`` and ``directions`` (K, 3), sphere frame."""

    names: tuple[str, ...]
    directions: Array


def camera_axis_direction(azimuth: ArrayLike, elevation: ArrayLike) -> Array:
    """Unit directions (..., 3), sphere frame, of lights given by azimuth A and elevation E (rad)
    relative to the camera axis, the Yale B convention: E > 0 above the horizon, A > 0 to the
    subject's right, which faces the camera and so is the image's left (−x_S):
    ``(−sin A cos E, sin E, cos A cos E)`` with x_S right and y_S up in the image, z_S towards the
    camera. (The Yale B list is mirror-symmetric in A, so the set is the same with either sign.)"""
    a, e = np.broadcast_arrays(np.asarray(azimuth, float), np.asarray(elevation, float))
    return np.stack([-np.sin(a) * np.cos(e), np.sin(e), np.cos(a) * np.cos(e)], axis=-1)


def grid_from_degrees(pairs: Sequence[Sequence[float]], names: Sequence[str] | None = None) -> Grid:
    """A grid from (azimuth_deg, elevation_deg) pairs relative to the camera axis."""
    a = np.asarray(pairs, float).reshape(-1, 2)
    labels = tuple(names) if names is not None else tuple(f"A{x:+04.0f}E{y:+03.0f}" for x, y in a)
    return Grid(labels, camera_axis_direction(np.deg2rad(a[:, 0]), np.deg2rad(a[:, 1])))


def read_grid_file(path: str | Path, file: str = "<api>", key: str = "lightset.grid_file") -> Grid:
    """A grid from a CSV file: ``#`` comment lines, a header with the columns ``azimuth_deg`` and
    ``elevation_deg`` (relative to the camera axis, :func:`camera_axis_direction`) and optionally
    ``name``, then one light per row. Errors name ``file`` and ``key`` and the offending line."""
    path = Path(path)
    expected = "a CSV grid with columns azimuth_deg, elevation_deg [, name]"
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise ProblemError(file, key, expected, f"{path} ({e})") from None
    lines = [
        (i + 1, s) for i, s in enumerate(text.splitlines()) if s.strip() and not s.lstrip().startswith("#")
    ]
    if not lines:
        raise ProblemError(file, key, expected, f"{path} (no rows)")
    header = [h.strip() for h in next(csv.reader([lines[0][1]]))]
    if "azimuth_deg" not in header or "elevation_deg" not in header:
        raise ProblemError(file, key, expected, f"{path} line {lines[0][0]} header {lines[0][1]!r}")
    ia, ie = header.index("azimuth_deg"), header.index("elevation_deg")
    iname = header.index("name") if "name" in header else None
    pairs, names = [], []
    for number, line in lines[1:]:
        row = [c.strip() for c in next(csv.reader([line]))]
        try:
            if len(row) != len(header):
                raise ValueError
            azimuth, elevation = float(row[ia]), float(row[ie])
            if not (math.isfinite(azimuth) and math.isfinite(elevation) and -90.0 <= elevation <= 90.0):
                raise ValueError
        except ValueError:
            raise ProblemError(
                file,
                key,
                f"{len(header)} fields per row, finite angles, elevation in [−90, 90]",
                f"{path.name} line {number}: {line.strip()!r}",
            ) from None
        pairs.append((azimuth, elevation))
        names.append(row[iname] if iname is not None else f"A{azimuth:+04.0f}E{elevation:+03.0f}")
    if not pairs:
        raise ProblemError(file, key, expected, f"{path} (a header but no rows)")
    return grid_from_degrees(pairs, names)


def yale_b_grid() -> Grid:
    """The 64 flash directions of the (Extended) Yale Face Database B (``optlight/data/yale_b_64.csv``;
    its header cites the source), as :func:`read_grid_file` reads them."""
    with resources.as_file(resources.files("optlight") / "data" / "yale_b_64.csv") as path:
        return read_grid_file(path, file=str(path), key="")
