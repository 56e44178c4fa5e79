"""The record of each row (what makes a batch resumable) and the results table of every row."""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from optlight.batch.row import METRICS, write_plan_files
from optlight.batch.spec import BatchRow
from optlight.export import writes_into
from optlight.jsondata import json_safe

PLANS = "plans"
RECORDS = "records"
#: What a batch keeps when the system refuses one of its writes.
RESUME = "the rows finished so far are kept: run the batch again to resume"


@dataclass(frozen=True)
class RowRecord:
    """What a batch knows of a row: ``status`` "ok" or "failed", its ``folder`` (relative to the
    batch's output folder, None when nothing was saved), ``error``, ``warnings``, the plan's
    ``metrics`` (see :data:`METRICS`), ``solve_s`` and ``skipped`` (done by an earlier run)."""

    id: str
    overrides: Mapping[str, Any]
    status: str
    folder: str | None
    error: str | None
    warnings: tuple[str, ...]
    metrics: Mapping[str, Any]
    solve_s: float
    skipped: bool = False

    def to_dict(self) -> dict[str, Any]:
        data = json_safe(self)
        data.pop("skipped")
        return data

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, skipped: bool = False) -> RowRecord:
        return cls(
            id=data["id"],
            overrides=data["overrides"],
            status=data["status"],
            folder=data["folder"],
            error=data["error"],
            warnings=tuple(data["warnings"]),
            metrics=data["metrics"],
            solve_s=math.nan if data["solve_s"] is None else float(data["solve_s"]),
            skipped=skipped,
        )


@dataclass(frozen=True)
class BatchResult:
    """A finished batch: a record per row in spec order, the results table's files, the number of
    ``workers`` used (0 for a serial run) and the run's wall time ``elapsed_s``."""

    out: Path
    records: tuple[RowRecord, ...]
    table_csv: Path
    table_md: Path
    workers: int
    elapsed_s: float
    keys: tuple[str, ...] = field(default=())

    @property
    def ok(self) -> int:
        return sum(r.status == "ok" for r in self.records)

    @property
    def failed(self) -> int:
        return sum(r.status != "ok" for r in self.records)

    @property
    def skipped(self) -> int:
        return sum(r.skipped for r in self.records)


def _record_path(out: Path, row_id: str) -> Path:
    return out / RECORDS / f"{row_id}.json"


def done_record(out: Path, row: BatchRow) -> RowRecord | None:
    """The record of a row an earlier run finished (record "ok" and ``plan.json`` in its folder)."""
    path = _record_path(out, row.id)
    try:
        record = RowRecord.from_dict(json.loads(path.read_text()), skipped=True)
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if record.status != "ok" or record.folder is None or not (out / record.folder / "plan.json").is_file():
        return None
    return record


def store_row(out: Path, row: BatchRow, outcome: Mapping[str, Any]) -> RowRecord:
    """Record a finished row: its files into ``plans/<id>/`` (:func:`write_plan_files`) unless the
    worker saved them there itself, then its record ``records/<id>.json`` (written whole, then
    renamed)."""
    folder: str | None = None
    target = out / PLANS / row.id
    files: Mapping[str, bytes] = outcome.get("files") or {}
    if files:
        write_plan_files(target, files)
    if files or outcome.get("saved"):
        folder = target.relative_to(out).as_posix()
    record = RowRecord(
        id=row.id,
        overrides=row.overrides,
        status=outcome["status"],
        folder=folder,
        error=outcome.get("error"),
        warnings=tuple(outcome.get("warnings", ())),
        metrics=outcome.get("metrics", {}),
        solve_s=float(outcome.get("solve_s", math.nan)),
    )
    path = _record_path(out, row.id)
    with writes_into(out, RESUME):
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.tmp")
        tmp.write_text(json.dumps(record.to_dict(), indent=1) + "\n")
        tmp.replace(path)
    return record


TABLE_COLUMNS = ("row", "status", *METRICS, "solve_s", "warnings", "folder", "error")


def table_rows(records: Sequence[RowRecord], keys: Sequence[str]) -> list[list[str]]:
    """The results table as text cells: the row's id, its override values, status, metrics, solve
    time, number of warnings, folder and error."""
    header = ["row", *keys, *TABLE_COLUMNS[1:]]
    rows = [header]
    for r in records:
        cells = [r.id, *(_cell(r.overrides.get(k, "")) for k in keys), r.status]
        cells += [_cell(r.metrics.get(k, "")) for k in METRICS]
        cells += [_cell(r.solve_s), str(len(r.warnings)), r.folder or "", r.error or ""]
        rows.append(cells)
    return rows


def _cell(value: Any) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return "" if not math.isfinite(value) else f"{value:.6g}"
    if isinstance(value, list):
        return "[" + ", ".join(_cell(v) for v in value) + "]"
    return str(value)


def write_table(out: Path, records: Sequence[RowRecord], keys: Sequence[str]) -> tuple[Path, Path]:
    """``results.csv`` and ``results.md`` in ``out``: one line per row (:func:`table_rows`)."""
    rows = table_rows(records, keys)
    csv_path, md_path = out / "results.csv", out / "results.md"
    with writes_into(out, RESUME), csv_path.open("w", newline="") as f:
        csv.writer(f).writerows(rows)

    def line(cells: Sequence[str]) -> str:
        return "| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |"

    ok = sum(r.status == "ok" for r in records)
    md = [f"# Batch results: {ok} of {len(records)} rows solved", "", line(rows[0])]
    md.append("|" + "---|" * len(rows[0]))
    md += [line(cells) for cells in rows[1:]]
    with writes_into(out, RESUME):
        md_path.write_text("\n".join(md) + "\n")
    return csv_path, md_path
