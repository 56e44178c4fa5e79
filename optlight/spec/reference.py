"""The problem-file reference (``docs/problems.md``, written by ``make docs``), generated from the
key declarations so the code and the documentation cannot drift apart."""

from __future__ import annotations

import dataclasses
import typing
from typing import Any

from optlight.spec.keys import bound, describe
from optlight.spec.problem import Problem


def _default_text(f: dataclasses.Field) -> str:
    """A key's default as the reference writes it."""
    if f.default is not dataclasses.MISSING:
        d = f.default
    elif f.default_factory is not dataclasses.MISSING:
        d = f.default_factory()
    else:
        return ""
    if d is None:
        return "unset"
    if isinstance(d, bool):
        return str(d).lower()
    if isinstance(d, str):
        return f'"{d}"'
    if isinstance(d, tuple) and d and dataclasses.is_dataclass(d[0]):
        return "one term with the defaults below"
    if isinstance(d, tuple):
        return "[" + ", ".join(f"{x:g}" for x in d) + "]"
    if isinstance(d, float):
        return f"{d:g}"
    return str(d)


def reference_markdown() -> str:
    """The problem-file reference, generated from the declarations in this module."""
    lines = [
        "# Problem files",
        "",
        "<!-- generated from optlight/spec/ by `make docs`; do not edit by hand -->",
        "",
        "A problem file is TOML. Every key is optional; a missing key takes its default. Unknown keys,",
        "wrong types and out-of-range values are errors that name the file and the key. Lengths are in",
        "metres (`_m`), angles in degrees (`_deg`), paths relative to the problem file.",
        "The built-in problems are in `problems/`; `optlight problems` lists them.",
        "",
        "`optlight check` (and every command, before its work) also checks what this machine can do: the",
        "solve's memory (`camera.width` × `camera.height`) and the sampled trajectory's (its duration, from",
        "`trajectory.dwell_s` and the robot's limits, × `trajectory.rate_hz`); a refusal names the key and",
        "the largest (or smallest) value that fits here.",
        "",
    ]

    def walk(cls: type, prefix: str) -> None:
        hints = typing.get_type_hints(cls)
        fields = [f for f in dataclasses.fields(cls) if not f.metadata.get("internal")]
        scalars = [
            f
            for f in fields
            if not (dataclasses.is_dataclass(hints[f.name]) or _is_table_list(hints[f.name]))
        ]
        title = f"`[{prefix}]`" if prefix else "Top level"
        lines.extend([f"## {title}", "", " ".join((cls.__doc__ or "").split()), ""])
        if scalars:
            lines.extend(["| key | type | unit | default | range | meaning |", "|---|---|---|---|---|---|"])
            for f in scalars:
                m = f.metadata
                rng = ""
                if m.get("lo") is not None or m.get("hi") is not None:
                    lo = "" if m.get("lo") is None else f"{'>' if m.get('lo_open') else '≥'} {bound(m['lo'])}"
                    hi = "" if m.get("hi") is None else f"≤ {bound(m['hi'])}"
                    rng = ", ".join(x for x in (lo, hi) if x)
                lines.append(
                    f"| `{f.name}` | {describe(hints[f.name])} | {m.get('unit', '')} | {_default_text(f)} | {rng} | {m.get('doc', '')} |"
                )
            lines.append("")
        for f in fields:
            tp = hints[f.name]
            sub = f"{prefix}.{f.name}" if prefix else f.name
            if isinstance(tp, type) and dataclasses.is_dataclass(tp):
                walk(tp, sub)
            elif _is_table_list(tp):
                lines.extend([f"`[[{sub}]]`: {f.metadata.get('doc', '')}", ""])
                walk(typing.get_args(tp)[0], f"[{sub}]")

    walk(Problem, "")
    return "\n".join(lines).rstrip() + "\n"


def _is_table_list(tp: Any) -> bool:
    """Whether ``tp`` is a list of tables (``[[a.b]]`` in TOML)."""
    args = typing.get_args(tp)
    return typing.get_origin(tp) is tuple and len(args) == 2 and dataclasses.is_dataclass(args[0])
