"""The cell spec: the base problem, the lights to reach, and the ranges of the placement axes searched."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from optlight.batch.spec import base_problem, check_keys
from optlight.errors import ProblemError
from optlight.spec import Problem, read_toml

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
