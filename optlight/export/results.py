"""A plan's results folder: trajectory.csv, plan.json with the library versions, and every other
file of the plan, written at once through the output policy."""

from __future__ import annotations

import datetime
import importlib.metadata
import json
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from optlight import interrupts
from optlight.errors import VerificationError
from optlight.export.files import Array, lp_direction, lp_text
from optlight.export.policy import write_folder
from optlight.jsondata import json_safe
from optlight.motion import Trajectory
from optlight.spec.sizing import image_names
from optlight.verify import VerificationReport

#: Distributions whose versions plan.json records.
LIBRARIES = ("numpy", "scipy", "casadi", "pin", "toppra", "ruckig", "meshcat", "optlight")
#: Keys of plan.json written by :func:`write_results` itself; the caller's plan dict may not use them.
RESERVED_KEYS = ("verification", "timing", "versions", "files", "created_utc")


def library_versions() -> dict[str, str | None]:
    """Installed versions of :data:`LIBRARIES` (None where not installed)."""
    out: dict[str, str | None] = {}
    for name in LIBRARIES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = None
    return out


def write_results(
    folder: str | Path,
    *,
    trajectory: Trajectory,
    report: VerificationReport,
    plan_dict: Mapping[str, Any],
    joint_names: Sequence[str],
    light_directions_camera: ArrayLike,
    image_pattern: str,
    figures: Mapping[str, Callable[[], bytes]] | None = None,
    writers: Sequence[Callable[[Path], Sequence[Path]]] = (),
    overwrite: bool = False,
    csv_rate_hz: float = 100.0,
) -> list[Path]:
    """Write a verified plan into ``folder`` (the output policy of the module docstring) and return
    the paths written.

    Files: ``trajectory.csv`` (:meth:`Trajectory.to_csv` at ``csv_rate_hz`` plus the boundaries),
    ``plan.json`` (``plan_dict`` plus the verification report, the trajectory's timing, library
    versions and the creation time), ``lights.lp`` (one line per capture, in capture order, names
    from ``image_pattern.format(index=i)``) and ``<name>.png`` for each of ``figures``, the PNG bytes
    each callable returns; then the manifest. The figures are asked for last, so that one drawn in
    another process meanwhile (:mod:`optlight.viz.drawing`) is not waited for before the rest.

    Args:
        light_directions_camera: (M, 3) unit vectors from the object towards the light at each capture,
            in the OpenCV camera frame (e.g. ``camera.to_camera_frame((a − O) / b)``).
        writers: callables that write further files (figures, preview, report) into the folder they
            are given and return the paths they wrote; they run before plan.json is written, so the
            folder appears with all of them or not at all.
        overwrite: update a folder optlight filled before (only the files its manifest lists).

    Raises:
        VerificationError: the report failed; nothing is written.
        UsageError: ``folder`` may not receive the results (:func:`check_output_folder`).
        ValueError, TypeError: bad inputs, data JSON cannot hold; raised before anything is written.
    """
    folder = Path(folder)
    directions, names = _checked_inputs(
        folder, trajectory, report, plan_dict, light_directions_camera, image_pattern, figures
    )

    def plan_text(files: list[str]) -> str:
        return json.dumps({**plan, "files": files}, indent=2, allow_nan=False) + "\n"

    plan = _plan_record(trajectory, report, plan_dict, joint_names, csv_rate_hz)
    plan_text([])  # fails here, before anything is written, when plan_dict holds non-JSON data

    def write(staging: Path) -> list[Path]:
        files = ["trajectory.csv", "plan.json", "lights.lp", *(f"{n}.png" for n in figures or {})]
        trajectory.to_csv(staging / "trajectory.csv", joint_names, rate_hz=csv_rate_hz)
        (staging / "lights.lp").write_text(lp_text(names, lp_direction(directions)))
        for writer in writers:
            files += [str(Path(p).relative_to(staging)) for p in writer(staging)]
        interrupts.reached("figures")
        for name, png in (figures or {}).items():
            (staging / f"{name}.png").write_bytes(png())
        (staging / "plan.json").write_text(plan_text(files))
        return [staging / f for f in files]

    return write_folder(folder, write, overwrite=overwrite)


def _checked_inputs(
    folder: Path,
    trajectory: Trajectory,
    report: VerificationReport,
    plan_dict: Mapping[str, Any],
    light_directions_camera: ArrayLike,
    image_pattern: str,
    figures: Mapping[str, Callable[[], bytes]] | None,
) -> tuple[Array, list[str]]:
    """:func:`write_results`'s checks, before anything is written: the (M, 3) unit light directions
    and the M image names, M the trajectory's captures; raises as :func:`write_results` says."""
    if not report.passed:
        raise VerificationError(
            f"refusing to write {folder}: the plan failed verification\n{report.summary()}", report
        )
    directions = np.asarray(light_directions_camera, float)
    captures = trajectory.capture_times
    if directions.shape != (captures.size, 3):
        raise ValueError(
            f"expected ({captures.size}, 3) light directions, one per capture, got {directions.shape}"
        )
    norms = np.linalg.norm(directions, axis=1)
    if not np.allclose(norms, 1.0, atol=1e-6):
        raise ValueError(
            f"light directions must be unit vectors (norms {norms.min():.6g} … {norms.max():.6g})"
        )
    names = image_names(image_pattern, captures.size)
    clash = sorted(set(plan_dict) & set(RESERVED_KEYS))
    if clash:
        raise ValueError(f"plan_dict may not use the keys {clash}: write_results fills them")
    for name in figures or {}:
        if not name or Path(name).name != name or name.startswith("."):
            raise ValueError(f"figure name {name!r} must be a plain file stem")
    return directions, names


def _plan_record(
    trajectory: Trajectory,
    report: VerificationReport,
    plan_dict: Mapping[str, Any],
    joint_names: Sequence[str],
    csv_rate_hz: float,
) -> dict[str, Any]:
    """plan.json without its ``files``: ``plan_dict`` plus the verification report, the trajectory's
    timing, the library versions and the creation time."""
    return {
        **json_safe(dict(plan_dict)),
        "verification": report.to_dict(),
        "timing": json_safe(
            {
                "duration_s": trajectory.duration,
                "capture_times_s": trajectory.capture_times,
                "landmark_intervals_s": trajectory.landmark_intervals,
                "segment_times_s": trajectory.segment_times,
                "joint_names": list(joint_names),
                "csv_rate_hz": csv_rate_hz,
            }
        ),
        "versions": library_versions(),
        "created_utc": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }
