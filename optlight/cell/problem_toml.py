"""A problem as a TOML file (the best placement's problem, ``best_problem.toml``)."""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from typing import Any

from optlight.spec import Problem

#: Problem keys that hold a file path (relative to the problem file, so made absolute when written elsewhere).
PATH_KEYS = (
    "object.path",
    "robot.urdf",
    "objective.reference.image",
    "objective.reference.mask",
    "lightset.grid_file",
)


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
