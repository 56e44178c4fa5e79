"""The batch spec: a base problem, a grid of overrides and listed rows, each row's problem built
and checked before the batch starts."""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from optlight.errors import ProblemError
from optlight.spec import Problem, load_problem, problem_from_dict, read_toml, resolve_problem_path

#: Top-level keys of a batch spec.
SPEC_KEYS = ("description", "problem", "preview", "grid", "rows")
#: Most rows of one batch: each row's problem is built and checked before the batch starts (~ms each),
#: and each row is a folder of results; split a larger study into several batches.
MAX_ROWS = 10_000


@dataclass(frozen=True)
class BatchRow:
    """One problem of a batch: ``id`` (its folder and record name: a label and a digest of the whole
    problem, so an edited row is solved again), ``where`` (where the spec writes it, for messages),
    its ``overrides`` (dotted key -> value, as written) and the validated ``problem``."""

    id: str
    where: str
    overrides: Mapping[str, Any]
    problem: Problem


@dataclass(frozen=True)
class BatchSpec:
    """A validated batch spec: the ``base`` problem, the ``rows`` in spec order, the override ``keys``
    in order of first appearance, and whether plan folders get ``preview.html``."""

    source: Path | None
    description: str
    base: Problem
    rows: tuple[BatchRow, ...]
    keys: tuple[str, ...]
    preview: bool

    @property
    def file(self) -> str:
        return str(self.source) if self.source else "<inline>"


def load_batch_spec(path: str | Path) -> BatchSpec:
    """Read and validate a batch spec file (see the module docstring)."""
    path = Path(path).expanduser()
    return batch_spec_from_dict(read_toml(path), source=path.resolve())


def batch_spec_from_dict(data: Mapping[str, Any], source: Path | None = None) -> BatchSpec:
    """Validate a parsed batch spec: the base problem, the grid and the rows, and every row's problem
    (each a :class:`ProblemError` naming the spec file and the key)."""
    file = str(source) if source else "<inline>"
    check_keys(data, SPEC_KEYS, file, "")
    base = base_problem(data, source, file)
    preview = data.get("preview", False)
    if not isinstance(preview, bool):
        raise ProblemError(file, "preview", "true or false", preview)
    description = data.get("description", "")
    if not isinstance(description, str):
        raise ProblemError(file, "description", "a string", description)

    grid = data.get("grid", {})
    if not isinstance(grid, dict):
        raise ProblemError(file, "grid", "a table of dotted problem keys, each with a list of values", grid)
    axes = flatten(grid)
    for key, values in axes.items():
        if not isinstance(values, list) or not values:
            raise ProblemError(file, f"grid.{key}", "a non-empty list of values", values)
    listed = data.get("rows", [{}])
    if not isinstance(listed, list) or not listed or not all(isinstance(r, dict) for r in listed):
        raise ProblemError(file, "rows", "a non-empty array of tables ([[rows]])", listed)
    count = len(listed) * math.prod(len(v) for v in axes.values())
    if count > MAX_ROWS:  # counted before any row's problem is built
        lengths = " × ".join(f"{len(v)} ({k})" for k, v in axes.items())
        raise ProblemError(
            file,
            "grid" if axes else "rows",
            f"at most {MAX_ROWS} rows, the grid's list lengths multiplied and times the [[rows]] "
            f"({lengths or 'no grid'} × {len(listed)} rows)",
            count,
        )

    rows: list[BatchRow] = []
    seen: dict[str, str] = {}
    for i, table in enumerate(listed):
        label = table.get("label")
        if label is not None and (not isinstance(label, str) or not label.strip()):
            raise ProblemError(file, f"rows[{i}].label", "a non-empty string", label)
        fixed = flatten({k: v for k, v in table.items() if k != "label"})
        for key in fixed:
            if key in axes:
                raise ProblemError(file, f"rows[{i}].{key}", "a key that [grid] does not also vary", key)
        for combo in itertools.product(*(enumerate(v) for v in axes.values())):
            sources = {k: f"rows[{i}].{k}" for k in fixed}
            overrides = dict(fixed)
            for key, (j, value) in zip(axes, combo, strict=True):
                overrides[key] = value
                sources[key] = f"grid.{key}[{j}]"
            where = ", ".join(sources.values()) or "problem"
            problem = apply_overrides(base, overrides, sources, file)
            row = BatchRow(row_id(problem, overrides, label), where, overrides, problem)
            if row.id in seen:
                raise ProblemError(file, where, f"a problem different from {seen[row.id]}'s", "the same one")
            seen[row.id] = where
            rows.append(row)
    keys = tuple(dict.fromkeys(k for row in rows for k in row.overrides))
    return BatchSpec(source, description, base, tuple(rows), keys, preview)


def check_keys(data: Mapping[str, Any], allowed: Sequence[str], file: str, prefix: str) -> None:
    """:class:`ProblemError` for the first key of ``data`` not in ``allowed``."""
    unknown = sorted(set(data) - set(allowed))
    if unknown:
        where = f"{prefix}.{unknown[0]}" if prefix else unknown[0]
        raise ProblemError(file, where, f"one of the keys {', '.join(allowed)} (unknown key)")


def base_problem(data: Mapping[str, Any], source: Path | None, file: str) -> Problem:
    """The spec's ``problem``: a path relative to the spec file, else a built-in name. The base file's
    own mistakes name that file."""
    name = data.get("problem")
    if not isinstance(name, str) or not name:
        raise ProblemError(file, "problem", "the base problem: a built-in name or a problem file path", name)
    near = (source.parent / name) if source is not None else Path(name)
    try:
        path = near if near.is_file() else resolve_problem_path(name)
    except ProblemError as e:
        raise ProblemError(file, "problem", e.expected, name) from None
    return load_problem(path)


def flatten(table: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested tables as dotted keys (``{"robot": {"name": x}}`` and ``{"robot.name": x}`` alike)."""
    out: dict[str, Any] = {}
    for key, value in table.items():
        dotted = f"{prefix}.{key}" if prefix else key
        if isinstance(value, dict):
            out.update(flatten(value, dotted))
        else:
            out[dotted] = value
    return out


def apply_overrides(
    base: Problem, overrides: Mapping[str, Any], sources: Mapping[str, str], file: str
) -> Problem:
    """``base`` with each dotted key set to its value, validated; a mistake names ``file`` and the
    override's place in the spec (``sources[key]``), with the problem key's own suffix."""
    data = base.to_dict()
    for key, value in overrides.items():
        node = data
        parts = key.split(".")
        for depth, part in enumerate(parts[:-1]):
            child = node.setdefault(part, {})
            if not isinstance(child, dict):
                where = ".".join(parts[: depth + 1])
                raise ProblemError(file, sources[key], f"a key inside a table ({where} is a value)", key)
            node = child
        node[parts[-1]] = value
    try:
        return problem_from_dict(data, source=base.source)
    except ProblemError as e:
        owner = next((k for k in overrides if e.key == k or e.key.startswith((f"{k}.", f"{k}["))), None)
        if owner is not None:
            raise ProblemError(file, sources[owner] + e.key[len(owner) :], e.expected, e.got) from None
        where = ", ".join(sources.values()) or "problem"
        raise ProblemError(file, f"{where} (problem key {e.key})", e.expected, e.got) from None


def row_id(problem: Problem, overrides: Mapping[str, Any], label: str | None) -> str:
    """``<label or the override values>-<8 hex digits of the whole problem and its file>``."""
    text = label or "_".join(_value_text(v) for v in overrides.values()) or "base"
    slug = re.sub(r"[^A-Za-z0-9.+-]+", "_", text).strip("_")[:60] or "row"
    content = json.dumps([str(problem.source), problem.to_dict()], sort_keys=True, default=str)
    return f"{slug}-{hashlib.sha1(content.encode()).hexdigest()[:8]}"


def _value_text(value: Any) -> str:
    if isinstance(value, list):
        return ",".join(_value_text(v) for v in value)
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)
