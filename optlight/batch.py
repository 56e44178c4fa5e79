"""Many plans at once: a batch of problems solved on a Dask cluster.

A *batch spec* (TOML) names a base problem and the problems to solve as overrides of its keys, written
as dotted problem-file keys (``robot.base_position_m``, ``object.kind``, ``landmarks.count`` …)::

    description = "two robots, three base placements"
    problem = "default"          # the base problem: a built-in name, or a path relative to this file
    preview = false              # write preview.html in every plan folder (~15 MB each for the panda)

    [grid]                       # every combination of these values (a cartesian product)
    "robot.name" = ["panda", "xarm7"]
    "robot.base_position_m" = [[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.0, 0.05, 0.0]]

    [[rows]]                     # and/or listed rows, each a set of overrides (× the grid when both)
    label = "close"              # optional: names the row's folder
    "robot.base_position_m" = [0.1, 0.0, 0.0]

The spec is checked whole before any work starts: the rows are counted (at most :data:`MAX_ROWS`),
then every row's problem is built and validated like a problem file, and a mistake is a
:class:`~optlight.errors.ProblemError` naming the batch file and the key (``grid.robot.name[1]``,
``rows[2].landmarks.count``).

Each row is one task, ``optlight.solve(problem)`` then ``plan.save(folder)`` on a worker
(:func:`solve_row`), into ``OUT/plans/<row>/``: the workers of a local cluster write there
themselves; those of a remote cluster return the folder's files and the client writes them, so they
need no shared file system (``shared_out`` when they do share ``OUT``; they do need the problem's
own files — a mesh, a URDF, a reference image — at the same paths). A row that raises (an unreachable landmark, a
plan that fails verification, anything) is recorded as failed with its error and the batch goes on.
Warnings of the solve (UserWarning: dropped or moved landmarks) are kept per row. After each row,
``OUT/records/<row>.json`` records it; a run in the same ``OUT`` skips the rows already done (their
record says so and their folder holds ``plan.json``) and solves the rest, failed ones included. The
results table of every row, ``OUT/results.csv`` and ``OUT/results.md``, is written at the end.
``OUT`` must be new or empty, or hold an earlier batch (its :data:`BATCH_MARKER`, written first):
optlight never writes among files it did not write (the output policy of :mod:`optlight.export`;
each plan folder is written whole, and one a stopped run left is replaced only as its manifest says).

The engine (a local or remote Dask cluster, the scheduler's check) is :mod:`optlight.engine`'s.
Worker processes are spawned, so a script that calls :func:`run_batch` needs the usual ``if __name__
== "__main__":`` guard.
"""

from __future__ import annotations

import csv
import hashlib
import itertools
import json
import math
import re
import shutil
import tempfile
import time
import warnings
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from optlight import interrupts, locks
from optlight.engine import engine, error_text, progress_bar, run_tasks
from optlight.errors import ProblemError, UsageError
from optlight.export import MANIFEST, STAGING_PREFIX, check_output_folder, write_folder, writes_into
from optlight.jsondata import json_safe
from optlight.pipeline import solve
from optlight.spec import Problem, load_problem, problem_from_dict, read_toml, resolve_problem_path

if TYPE_CHECKING:
    from distributed import Client

#: Top-level keys of a batch spec.
SPEC_KEYS = ("description", "problem", "preview", "grid", "rows")
#: Most rows of one batch: each row's problem is built and checked before the batch starts (~ms each),
#: and each row is a folder of results; split a larger study into several batches.
MAX_ROWS = 10_000
METRICS = {
    "landmarks": "landmarks",
    "duration_s": "duration_s",
    "motion_time_s": "motion_time_s",
    "joint_path_rad": "joint_path_length_rad",
    "max_h_m": "max_h_residual_m",
    "mean_cost": "mean_landmark_cost",
    "verified": "verification_passed",
}
PLANS = "plans"
RECORDS = "records"
#: Written first into a batch's output folder: marks it as a batch's, which a later run resumes.
BATCH_MARKER = ".optlight-batch.json"
#: What a batch keeps when the system refuses one of its writes.
RESUME = "the rows finished so far are kept: run the batch again to resume"


# --------------------------------------------------------------------------------------------
# The batch spec
# --------------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------------
# One row, on a worker
# --------------------------------------------------------------------------------------------


def solve_row(problem: Problem, preview: bool = False, folder: str | None = None) -> dict[str, Any]:
    """The worker's task: ``optlight.solve(problem)``, then ``plan.save``.

    With ``folder`` (a path the worker can write: the batch's own folder on this machine or on a
    shared file system) the plan is saved there (through a hidden sibling renamed into place) and
    ``saved`` is True; without it, into a temporary folder whose ``files`` (relative path -> bytes)
    are returned for the client to write. Also returned, as plain data: ``status`` ("ok", or
    "failed" with ``error``), the plan's numbers under ``metrics`` (also for a plan that failed
    verification), the UserWarnings raised (``warnings``) and the row's time ``solve_s``. Never
    raises for a row's own failure: the batch records it and goes on."""
    start = time.perf_counter()
    out: dict[str, Any] = {"status": "failed", "error": None, "metrics": {}, "files": {}, "saved": False}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            plan = solve(problem)
            summary = plan.summary()
            out["metrics"] = {key: summary[name] for key, name in METRICS.items()}
            if folder is not None:
                # overwrite: a folder a stopped run of this batch filled (its manifest) is replaced
                plan.save(folder, preview=preview, overwrite=True)
                out["saved"] = True
            else:
                with tempfile.TemporaryDirectory(prefix="optlight-row-") as tmp:
                    saved = Path(tmp) / "plan"
                    plan.save(saved, preview=preview)
                    out["files"] = {
                        p.relative_to(saved).as_posix(): p.read_bytes()
                        for p in sorted(saved.rglob("*"))
                        if p.is_file()
                    }
            out["status"] = "ok"
        except Exception as e:  # a row's failure of any kind is its record, not the batch's end
            out["error"] = error_text(e)
    out["warnings"] = list(
        dict.fromkeys(str(w.message) for w in caught if issubclass(w.category, UserWarning))
    )
    out["solve_s"] = time.perf_counter() - start
    return out


def write_plan_files(target: Path, files: Mapping[str, bytes]) -> Path:
    """Write a plan folder's ``files`` (relative path -> bytes, as a worker sent them) into ``target``
    through the output policy of :mod:`optlight.export`: whole or not at all, a folder a stopped run
    of this batch filled replaced (``overwrite``), any other refused; the manifest is written anew."""

    def write(staging: Path) -> list[Path]:
        written = []
        for name, content in files.items():
            if name == MANIFEST:
                continue
            path = staging / name
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(content)
            written.append(path)
        return written

    write_folder(target, write, overwrite=True)
    return target


# --------------------------------------------------------------------------------------------
# Records and the results table
# --------------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------------
# The whole batch
# --------------------------------------------------------------------------------------------


def run_batch(
    spec: BatchSpec | str | Path,
    out: str | Path,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    serial: bool = False,
    progress: bool = True,
    client: Client | None = None,
    shared_out: bool = False,
) -> BatchResult:
    """Solve every row of a batch spec (a :class:`BatchSpec` or a file) into ``out``.

    On a local cluster of ``workers`` processes (default: one per core), on the remote Dask
    ``scheduler`` when an address is given, or here, one row after the other, when ``serial``. Rows
    done by an earlier run into ``out`` are skipped. ``progress`` shows a progress bar on stdout.
    ``client``: a Dask client of the caller's to run on instead (kept open; e.g. one cluster for
    several batches in a notebook). Workers of a local cluster save the plans into ``out``
    themselves; those of a remote scheduler (or a given client) send the files back to be written
    here, unless ``shared_out`` says that ``out`` is the same path on a file system they share.
    Returns the records of every row (see :class:`BatchResult`); a failed row does not raise."""
    out = Path(out)
    resume = check_batch_folder(out)
    spec = spec if isinstance(spec, BatchSpec) else load_batch_spec(spec)
    interrupts.reached("spec-checked")
    with writes_into(out, RESUME):
        out.mkdir(parents=True, exist_ok=True)
        if not resume:
            (out / BATCH_MARKER).write_text(
                json.dumps({"written_by": "optlight batch", "spec": json_safe(spec.source)}, indent=1) + "\n"
            )
    start = time.perf_counter()
    records: list[RowRecord | None] = [done_record(out, row) for row in spec.rows]
    todo = [i for i, r in enumerate(records) if r is None]
    # workers on this machine save into out themselves; remote ones send the files unless out is shared
    direct = serial or shared_out or (scheduler is None and client is None)
    plans = out.resolve() / PLANS
    tasks = [
        (solve_row, (spec.rows[i].problem, spec.preview, str(plans / spec.rows[i].id) if direct else None))
        for i in todo
    ]
    with (
        no_staging_left(out, local=not serial and scheduler is None and client is None),  # left last
        engine(serial=serial or not todo, scheduler=scheduler, workers=workers, client=client) as client,
        progress_bar(progress, len(spec.rows), "batch", done=len(spec.rows) - len(todo)) as advance,
    ):

        def on_done(k: int, outcome: Any) -> None:
            i = todo[k]
            records[i] = store_row(out, spec.rows[i], outcome)
            advance(spec.rows[i].id if outcome["status"] != "ok" else None)
            interrupts.reached("row-done")

        used = 0 if client is None else len(client.scheduler_info(n_workers=-1)["workers"])
        run_tasks(client, tasks, on_done, lost={"status": "failed", "metrics": {}, "warnings": []})
        interrupts.reached("rows-done")
    interrupts.reached("cluster-closed")
    final = tuple(r for r in records if r is not None)
    csv_path, md_path = write_table(out, final, spec.keys)
    interrupts.reached("table-written")
    return BatchResult(out, final, csv_path, md_path, used, time.perf_counter() - start, spec.keys)


@contextmanager
def no_staging_left(out: Path, *, local: bool) -> Iterator[None]:
    """On leaving, however (listed before the engine in a ``with``, after its local cluster closed):
    when ``local``, remove the staging folders (:data:`~optlight.export.STAGING_PREFIX`) its workers
    left when they were stopped as they saved a plan (a signal stopped the batch): a new plan's
    beside its folder (in ``out/plans``, or in ``out`` before ``plans`` existed), an earlier plan's
    in its folder. Remote workers are not stopped with the client: what they write is theirs to
    finish."""
    try:
        yield
    finally:
        if local:
            patterns = (f"{STAGING_PREFIX}*", f"{PLANS}/{STAGING_PREFIX}*", f"{PLANS}/*/{STAGING_PREFIX}*")
            for staging in [path for pattern in patterns for path in out.glob(pattern)]:
                if staging.is_dir() and not staging.is_symlink():
                    shutil.rmtree(staging, ignore_errors=True)
                else:
                    staging.unlink(missing_ok=True)


def check_batch_folder(out: Path, option: str = "out") -> bool:
    """Whether ``out`` holds an earlier batch (its :data:`BATCH_MARKER`), which a run resumes; else it
    must be a new or empty folder (:func:`optlight.export.check_output_folder`): optlight never writes
    among files it did not write. Raises :class:`UsageError` (``option`` names the folder) otherwise,
    and :class:`~optlight.errors.OutputError` when another run is writing it (:mod:`optlight.locks`)."""
    locks.claim(out)
    if (out / BATCH_MARKER).is_file():
        return True
    if out.is_dir() and any(out.iterdir()):
        raise UsageError(
            option,
            f"{out} is not empty and holds no earlier batch; give a new or empty folder "
            "(a batch resumes only in the folder of an earlier batch)",
        )
    check_output_folder(out, option=option)
    return False
