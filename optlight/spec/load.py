"""Loading a problem file: the built-in problems, reading TOML, and checking every key against its
declaration (type, range, known name) into a :class:`~optlight.spec.problem.Problem`."""

from __future__ import annotations

import dataclasses
import math
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, Literal

from optlight.errors import ProblemError
from optlight.spec.consistency import check_consistency
from optlight.spec.keys import bound, describe
from optlight.spec.problem import Problem

#: Folder of the built-in problem files and their data, shipped inside the package (the
#: repository's top-level ``problems/`` points here).
PROBLEMS_DIR = Path(__file__).resolve().parent.parent / "problems"


def available_problems() -> dict[str, str]:
    """Built-in problem names mapped to their one-line descriptions."""
    out = {}
    for path in sorted(PROBLEMS_DIR.glob("*.toml")):
        try:
            with path.open("rb") as f:
                out[path.stem] = str(tomllib.load(f).get("description", ""))
        except (OSError, tomllib.TOMLDecodeError):
            out[path.stem] = "(unreadable)"
    return out


def resolve_problem_path(name_or_path: str | Path) -> Path:
    """A problem file from a path, or from the name of a file in ``problems/``."""
    path = Path(name_or_path).expanduser()
    if path.is_file():
        return path.resolve()
    named = PROBLEMS_DIR / f"{name_or_path}.toml"
    if named.is_file():
        return named
    names = ", ".join(available_problems()) or "none"
    raise ProblemError(str(name_or_path), "", f"an existing file or a built-in problem ({names})")


def read_toml(path: Path) -> dict[str, Any]:
    """The parsed TOML file at ``path``; a :class:`ProblemError` naming the file when it cannot be
    read or parsed (problem files, batch and cell specs)."""
    try:
        with path.open("rb") as f:
            return tomllib.load(f)
    except tomllib.TOMLDecodeError as e:
        raise ProblemError(str(path), "", f"valid TOML ({e})") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ProblemError(str(path), "", f"a readable TOML file ({e})") from None


def load_problem(name_or_path: str | Path) -> Problem:
    """Read and validate a problem file (a path or a built-in name) into a :class:`Problem`."""
    path = resolve_problem_path(name_or_path)
    return problem_from_dict(read_toml(path), source=path)


def problem_from_dict(data: dict[str, Any], source: Path | None = None) -> Problem:
    """Validate a parsed problem (as from TOML) into a :class:`Problem`."""
    file = str(source) if source else "<inline>"
    problem = _build(Problem, data, "", file)
    problem = dataclasses.replace(problem, source=source)
    robot = data.get("robot", {})
    if problem.robot.urdf is not None and "name" not in robot:  # a user arm is named by its file
        problem = dataclasses.replace(
            problem, robot=dataclasses.replace(problem.robot, name=Path(problem.robot.urdf).stem)
        )
    check_consistency(problem, file)
    return problem


def _build(cls: type, data: Any, path: str, file: str) -> Any:
    """Build dataclass ``cls`` from ``data``, checking keys, types and ranges."""
    if not isinstance(data, dict):
        raise ProblemError(file, path or "(top level)", "a table", data)
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if not f.metadata.get("internal")}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        where = f"{path}.{unknown[0]}" if path else unknown[0]
        raise ProblemError(file, where, f"one of the keys {', '.join(fields)} (unknown key)")
    values = {}
    for name, value in data.items():
        where = f"{path}.{name}" if path else name
        values[name] = _convert(hints[name], value, fields[name].metadata, where, file)
    return cls(**values)


def _convert(tp: Any, value: Any, meta: Any, where: str, file: str) -> Any:
    """Convert one TOML value to the declared type ``tp``, or raise :class:`ProblemError`."""
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        inner = [a for a in args if a is not type(None)]
        # ``float | tuple[float, ...]``: a TOML list is the per-item form, anything else the scalar
        lists = [a for a in inner if typing.get_origin(a) is tuple]
        scalars = [a for a in inner if typing.get_origin(a) is not tuple]
        if lists and scalars:
            if isinstance(value, list):
                return _convert(lists[0], value, meta, where, file)
            return _convert(scalars[0], value, meta, where, file)
        return _convert(inner[0], value, meta, where, file)
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        return _build(tp, value, where, file)
    if origin is Literal:
        if value not in args:
            raise ProblemError(file, where, "one of " + ", ".join(repr(a) for a in args), value)
        return value
    if origin is tuple:
        if not isinstance(value, list):
            raise ProblemError(file, where, describe(tp), value)
        if len(args) == 2 and args[1] is Ellipsis:
            items = [_convert(args[0], v, meta, f"{where}[{i}]", file) for i, v in enumerate(value)]
            if not items:
                raise ProblemError(file, where, "a non-empty list", value)
            return tuple(items)
        if len(value) != len(args):
            raise ProblemError(file, where, describe(tp), value)
        return tuple(
            _convert(a, v, meta, f"{where}[{i}]", file)
            for i, (a, v) in enumerate(zip(args, value, strict=True))
        )
    if tp is bool:
        if not isinstance(value, bool):
            raise ProblemError(file, where, "true or false", value)
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ProblemError(file, where, "an integer", value)
        _check_range(value, meta, where, file)
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise ProblemError(file, where, "a finite number", value)
        _check_range(value, meta, where, file)
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ProblemError(file, where, "a string", value)
        return value
    raise TypeError(f"spec type {tp!r} at {where} is not supported")  # a bug in this module


def _check_range(x: float, meta: Any, where: str, file: str) -> None:
    """``x`` (as the file wrote it, int or float) within the key's declared range."""
    lo, hi, lo_open = meta.get("lo"), meta.get("hi"), meta.get("lo_open", False)
    unit = f" {meta.get('unit')}" if meta.get("unit") else ""
    if lo is not None and (x < lo or (lo_open and x == lo)):
        raise ProblemError(file, where, f"a value {'>' if lo_open else '≥'} {bound(lo)}{unit}", x)
    if hi is not None and x > hi:
        raise ProblemError(file, where, f"a value ≤ {bound(hi)}{unit}", x)
