"""One row of a batch, on a worker: solve its problem and save the plan (or return its files)."""

from __future__ import annotations

import tempfile
import time
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from optlight.engine import error_text
from optlight.export import MANIFEST, write_folder
from optlight.pipeline import solve
from optlight.spec import Problem

METRICS = {
    "landmarks": "landmarks",
    "duration_s": "duration_s",
    "motion_time_s": "motion_time_s",
    "joint_path_rad": "joint_path_length_rad",
    "max_h_m": "max_h_residual_m",
    "mean_cost": "mean_landmark_cost",
    "verified": "verification_passed",
}


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
