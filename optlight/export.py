"""Export of a verified plan: trajectory.csv, plan.json, lights.lp and figures (DESIGN §6–§7).

Nothing is written for a plan that failed verification, and a results folder is never left half
written: the files go into a hidden sibling folder that is renamed into place at the end.

lights.lp follows the PTM / relight convention: the first line is the number of images, then one line
``filename x y z`` per image, (x, y, z) the unit vector from the object towards the light with x to
the right of the image, y towards its top and z towards the camera. From a direction d in the OpenCV
camera frame (x right, y down, z forward) that is (d_x, −d_y, −d_z): see :func:`lp_direction`.
"""

from __future__ import annotations

import datetime
import importlib.metadata
import json
import os
import shutil
import uuid
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.errors import VerificationError
from optlight.jsondata import json_safe
from optlight.planning.timing import Trajectory
from optlight.verify import VerificationReport

if TYPE_CHECKING:
    from matplotlib.figure import Figure

Array = NDArray[np.float64]

#: Distributions whose versions plan.json records.
LIBRARIES = ("numpy", "scipy", "casadi", "pin", "toppra", "meshcat", "optlight")
#: Keys of plan.json written by :func:`write_results` itself; the caller's plan dict may not use them.
RESERVED_KEYS = ("verification", "timing", "versions", "files", "created_utc")


def lp_direction(d_camera: ArrayLike) -> Array:
    """Light direction(s) in .lp coordinates from unit vector(s) d (..., 3) in the OpenCV camera
    frame pointing from the object towards the light: (d_x, −d_y, −d_z).

    A frontal light between object and camera (d = (0, 0, −1)) gives (0, 0, 1); a light above the
    object (d_y < 0, the image's y axis points down) gives y > 0.
    """
    d = np.asarray(d_camera, float)
    if d.shape[-1:] != (3,):
        raise ValueError(f"directions must have shape (..., 3), got {d.shape}")
    return d * np.array([1.0, -1.0, -1.0])


def lp_text(filenames: Sequence[str], directions_lp: ArrayLike) -> str:
    """The content of a .lp file: the image count, then ``filename x y z`` per image."""
    d = np.asarray(directions_lp, float).reshape(-1, 3)
    if len(filenames) != len(d):
        raise ValueError(f"{len(filenames)} file names for {len(d)} light directions")
    lines = [str(len(d))]
    lines.extend(f"{name} {x:.9f} {y:.9f} {z:.9f}" for name, (x, y, z) in zip(filenames, d, strict=True))
    return "\n".join(lines) + "\n"


def image_names(pattern: str, count: int) -> list[str]:
    """``pattern.format(index=i)`` for i = 0 … count−1; names must be distinct and free of whitespace."""
    try:
        names = [pattern.format(index=i) for i in range(count)]
    except (KeyError, IndexError, ValueError) as e:
        raise ValueError(f"image pattern {pattern!r} must format with only {{index}} ({e})") from None
    if len(set(names)) != len(names):
        raise ValueError(f"image pattern {pattern!r} gives repeated names; use {{index}}")
    bad = [n for n in names if not n or any(c.isspace() for c in n)]
    if bad:
        raise ValueError(f"image names may not be empty or contain whitespace (.lp format): {bad[0]!r}")
    return names


def write_json(path: str | Path, data: Any) -> Path:
    """Write ``data`` (made JSON-safe by :func:`json_safe`) to ``path`` as indented JSON, creating
    the parent folders; returns the path."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(json_safe(data), indent=2, allow_nan=False) + "\n")
    return out


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
    figures: Mapping[str, Figure] | None = None,
    writers: Sequence[Callable[[Path], Sequence[Path]]] = (),
    overwrite: bool = False,
    csv_rate_hz: float = 100.0,
) -> list[Path]:
    """Write a verified plan into ``folder`` and return the paths written.

    Files: ``trajectory.csv`` (:meth:`Trajectory.to_csv` at ``csv_rate_hz`` plus the boundaries),
    ``plan.json`` (``plan_dict`` plus the verification report, the trajectory's timing, library
    versions and the creation time), ``lights.lp`` (one line per capture, in capture order, names
    from ``image_pattern.format(index=i)``) and ``<name>.png`` for each of ``figures``.

    Args:
        light_directions_camera: (M, 3) unit vectors from the object towards the light at each capture,
            in the OpenCV camera frame (e.g. ``camera.to_camera_frame((a − O) / b)``).
        writers: callables that write further files (figures, preview, report) into the folder they
            are given and return the paths they wrote; they run before plan.json is written, so the
            folder appears with all of them or not at all.
        overwrite: replace an existing non-empty ``folder``; otherwise that is an error.

    Raises:
        VerificationError: the report failed; nothing is written.
        ValueError, FileExistsError, TypeError: bad inputs, an existing folder, data JSON cannot hold;
            raised before anything is written.
    """
    folder = Path(folder)
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
    if folder.exists() and not (folder.is_dir() and not any(folder.iterdir())) and not overwrite:
        raise FileExistsError(f"{folder} exists and is not empty; pass overwrite=True to replace it")

    def plan_text(files: list[str]) -> str:
        return json.dumps({**plan, "files": files}, indent=2, allow_nan=False) + "\n"

    files = ["trajectory.csv", "plan.json", "lights.lp", *(f"{n}.png" for n in figures or {})]
    plan = {
        **json_safe(dict(plan_dict)),
        "verification": report.to_dict(),
        "timing": json_safe(
            {
                "duration_s": trajectory.duration,
                "capture_times_s": captures,
                "landmark_intervals_s": trajectory.landmark_intervals,
                "segment_times_s": trajectory.segment_times,
                "joint_names": list(joint_names),
                "csv_rate_hz": csv_rate_hz,
            }
        ),
        "versions": library_versions(),
        "created_utc": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }
    plan_text(files)  # fails here, before anything is written, when plan_dict holds non-JSON data

    folder.parent.mkdir(parents=True, exist_ok=True)
    staging = folder.parent / f".{folder.name}.tmp-{uuid.uuid4().hex[:8]}"
    staging.mkdir()
    try:
        trajectory.to_csv(staging / "trajectory.csv", joint_names, rate_hz=csv_rate_hz)
        (staging / "lights.lp").write_text(lp_text(names, lp_direction(directions)))
        for name, figure in (figures or {}).items():
            figure.savefig(staging / f"{name}.png", dpi=120)
        for writer in writers:
            files += [str(Path(p).relative_to(staging)) for p in writer(staging)]
        (staging / "plan.json").write_text(plan_text(files))
        _move_into_place(staging, folder)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return [folder / f for f in files]


def _move_into_place(staging: Path, folder: Path) -> None:
    """Rename ``staging`` to ``folder``, replacing what is there (the old folder is deleted last)."""
    if not folder.exists():
        os.rename(staging, folder)
        return
    old = folder.parent / f".{folder.name}.old-{uuid.uuid4().hex[:8]}"
    os.rename(folder, old)
    try:
        os.rename(staging, folder)
    except BaseException:
        os.rename(old, folder)
        raise
    if old.is_dir():
        shutil.rmtree(old)
    else:
        old.unlink()
