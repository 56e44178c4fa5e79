"""Plain JSON data from optlight's values: the one sanitiser every JSON file and ``to_dict`` uses."""

from __future__ import annotations

import dataclasses
import enum
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np


def json_safe(value: Any, where: str = "") -> Any:
    """``value`` as plain JSON data: NumPy arrays and scalars to lists and numbers, tuples to lists,
    dataclasses and mappings to dicts (keys as strings), paths to strings, enums to their values,
    non-finite floats to None. Anything else raises TypeError naming where it was found."""
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, int | np.integer) and not isinstance(value, np.bool_):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist(), where)
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, enum.Enum):
        return json_safe(value.value, where)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return json_safe({f.name: getattr(value, f.name) for f in dataclasses.fields(value)}, where)
    if isinstance(value, Mapping):
        return {str(k): json_safe(v, f"{where}.{k}" if where else str(k)) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v, f"{where}[{i}]") for i, v in enumerate(value)]
    raise TypeError(f"{where or 'value'}: cannot write {type(value).__name__} to JSON")
