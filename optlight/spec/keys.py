"""Declaring a problem-file key: its default, one-line doc, unit and range (:func:`key`), a nested
table (:func:`section`), the bounds several sections share, and how a key's type and bounds read in
the reference and in refusals (:func:`describe`, :func:`bound`)."""

from __future__ import annotations

import dataclasses
import types
import typing
from dataclasses import field
from typing import Any, Literal

Vec3 = tuple[float, float, float]

#: Largest seed of a random generator: NumPy's and Mitsuba's (a 32-bit sample seed, offset per capture).
SEED_MAX = 2**31 - 1
#: Largest IPOPT or generalized-IK iteration cap: one unreachable pose at 10⁴ IK iterations already
#: costs a second, and a plan solves hundreds of them.
MAX_ITERATIONS = 10_000
#: Camera responses ``[world] gamma`` may have: real ones are 1–2.4; at 1/10 or 10 every capture is all
#: but black or white.
GAMMA_RANGE = (0.1, 10.0)



def key(
    default: Any,
    doc: str,
    *,
    unit: str = "",
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
) -> Any:
    """Declare a problem-file key: default, one-line doc, unit and closed (or left-open) range."""
    meta = {"doc": doc, "unit": unit, "lo": lo, "hi": hi, "lo_open": lo_open}
    if isinstance(default, list | dict) or dataclasses.is_dataclass(default):
        value = default
        return field(default_factory=lambda: value, metadata=meta)
    return field(default=default, metadata=meta)


def section(cls: type, doc: str) -> Any:
    """Declare a nested table whose keys all have defaults."""
    return field(default_factory=cls, metadata={"doc": doc})


def describe(tp: Any) -> str:
    """How the reference and the refusals name a key's type: number, list of 3 numbers, the allowed
    literals, table, …"""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(describe(a) if a is not type(None) else "unset" for a in args)
    if origin is Literal:
        return " or ".join(f'"{a}"' for a in args)
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"list of {describe(args[0])}"
        return f"list of {len(args)} {describe(args[0])}s"
    if dataclasses.is_dataclass(tp):
        return "table"
    return {float: "number", int: "integer", bool: "boolean", str: "string"}.get(tp, str(tp))


def bound(x: float) -> str:
    """A declared bound as text: an integer in full (2147483647), a float as ``:g``."""
    return str(x) if isinstance(x, int) else f"{x:g}"
