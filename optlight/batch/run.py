"""The whole batch: its output folder, its rows run on the engine, and the results table."""

from __future__ import annotations

import json
import shutil
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from optlight import interrupts, locks
from optlight.batch.records import PLANS, RESUME, BatchResult, RowRecord, done_record, store_row, write_table
from optlight.batch.row import solve_row
from optlight.batch.spec import BatchSpec, load_batch_spec
from optlight.engine import engine, progress_bar, run_tasks
from optlight.errors import UsageError
from optlight.export import STAGING_PREFIX, check_output_folder, writes_into
from optlight.jsondata import json_safe

if TYPE_CHECKING:
    from distributed import Client


#: Written first into a batch's output folder: marks it as a batch's, which a later run resumes.
BATCH_MARKER = ".optlight-batch.json"


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
