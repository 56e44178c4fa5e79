"""Export of a verified plan: trajectory.csv, plan.json, lights.lp and figures (DESIGN §6–§7).

Nothing is written for a plan that failed verification, and no output is ever left half written or
written over files optlight did not write. The output policy (:func:`check_output_folder`,
:func:`write_folder`, :func:`check_output_file`, :func:`write_file`):

- a folder that does not exist, or an empty one, receives the whole output: the files are written
  into a hidden staging folder that is renamed into place (or, for an existing empty folder, whose
  files are renamed into it) at the end;
- a folder optlight filled before is recognised by its manifest (:data:`MANIFEST`, the list of the
  files optlight wrote there, written last); it is updated only with ``overwrite`` (the command
  line's ``--force``), and then only the files it lists are replaced or removed: files the user
  added there are kept;
- anything else that exists (a file, a folder holding files optlight did not write, a broken link)
  is refused with a one-line :class:`UsageError`, before any work when the caller checks first;
- a single output file (a PNG) is written to a temporary name beside it and renamed over it; an
  existing file is replaced only with ``overwrite``, a folder never.

The final renames run with Ctrl-C deferred (:func:`optlight.interrupts.deferred`), so an output
appears whole or not at all; until then an interrupt removes the staging folder or temporary file.

lights.lp follows the PTM / relight convention: the first line is the number of images, then one line
``filename x y z`` per image, (x, y, z) the unit vector from the object towards the light with x to
the right of the image, y towards its top and z towards the camera. From a direction d in the OpenCV
camera frame (x right, y down, z forward) that is (d_x, −d_y, −d_z): see :func:`lp_direction`.
"""

from __future__ import annotations

import dataclasses
import datetime
import enum
import importlib.metadata
import json
import math
import os
import shutil
import uuid
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight import interrupts
from optlight.errors import UsageError, VerificationError
from optlight.planning.timing import Trajectory
from optlight.spec import image_names
from optlight.verify import VerificationReport

if TYPE_CHECKING:
    from matplotlib.figure import Figure

Array = NDArray[np.float64]

#: Distributions whose versions plan.json records.
LIBRARIES = ("numpy", "scipy", "casadi", "pin", "toppra", "meshcat", "optlight")
#: Keys of plan.json written by :func:`write_results` itself; the caller's plan dict may not use them.
RESERVED_KEYS = ("verification", "timing", "versions", "files", "created_utc")
#: The file optlight writes last into every folder it fills: the files it wrote there (JSON).
MANIFEST = ".optlight-manifest.json"
#: Prefix of the hidden staging folders and temporary files (removed unless the process is killed).
STAGING_PREFIX = ".optlight-staging-"


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


def write_json(path: str | Path, data: Any) -> Path:
    """Write ``data`` (made JSON-safe by :func:`json_safe`) to ``path`` as indented JSON, creating
    the parent folders; returns the path."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(json_safe(data), indent=2, allow_nan=False) + "\n")
    return out


def json_safe(value: Any, where: str = "") -> Any:
    """``value`` as plain JSON data: NumPy arrays and scalars to lists and numbers, tuples to lists,
    dataclasses and mappings to dicts (keys as strings), paths to strings, enums to their values,
    non-finite floats to None. Anything else raises TypeError naming where it was found."""
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, int | np.integer) and not isinstance(value, np.bool_):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist(), where)
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, enum.Enum):
        return json_safe(value.value, where)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return json_safe({f.name: getattr(value, f.name) for f in dataclasses.fields(value)}, where)
    if isinstance(value, Mapping):
        return {str(k): json_safe(v, f"{where}.{k}" if where else str(k)) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v, f"{where}[{i}]") for i, v in enumerate(value)]
    raise TypeError(f"{where or 'value'}: cannot write {type(value).__name__} to JSON")


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
    """Write a verified plan into ``folder`` (the output policy of the module docstring) and return
    the paths written.

    Files: ``trajectory.csv`` (:meth:`Trajectory.to_csv` at ``csv_rate_hz`` plus the boundaries),
    ``plan.json`` (``plan_dict`` plus the verification report, the trajectory's timing, library
    versions and the creation time), ``lights.lp`` (one line per capture, in capture order, names
    from ``image_pattern.format(index=i)``) and ``<name>.png`` for each of ``figures``; then the
    manifest.

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

    def plan_text(files: list[str]) -> str:
        return json.dumps({**plan, "files": files}, indent=2, allow_nan=False) + "\n"

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
    plan_text([])  # fails here, before anything is written, when plan_dict holds non-JSON data

    def write(staging: Path) -> list[Path]:
        files = ["trajectory.csv", "plan.json", "lights.lp", *(f"{n}.png" for n in figures or {})]
        trajectory.to_csv(staging / "trajectory.csv", joint_names, rate_hz=csv_rate_hz)
        (staging / "lights.lp").write_text(lp_text(names, lp_direction(directions)))
        for name, figure in (figures or {}).items():
            figure.savefig(staging / f"{name}.png", dpi=120)
        for writer in writers:
            files += [str(Path(p).relative_to(staging)) for p in writer(staging)]
        (staging / "plan.json").write_text(plan_text(files))
        return [staging / f for f in files]

    return write_folder(folder, write, overwrite=overwrite)


# --------------------------------------------------------------------------------------------
# The output policy
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class OutputTarget:
    """Where an output goes, as :func:`check_output_folder` / :func:`check_output_file` found it.

    ``path`` the folder or file; ``anchor`` the existing folder the staging folder or temporary file
    goes in (the folder itself when it exists, else its nearest existing ancestor, so nothing is
    created outside it before the final rename); ``exists`` whether ``path`` exists; ``previous``
    the files a folder's manifest lists (those ``overwrite`` may replace or remove).
    """

    path: Path
    anchor: Path
    exists: bool
    previous: tuple[str, ...] = ()


def check_output_folder(
    folder: str | Path, *, overwrite: bool = False, option: str = "folder", force: str = "overwrite=True"
) -> OutputTarget:
    """Whether ``folder`` may receive an output folder (module docstring), and where to stage it.

    ``option`` names the folder in errors (``--out`` on the command line), ``force`` what the
    caller passes to allow replacing an earlier output. Raises :class:`UsageError` for an existing
    file or broken link, a non-empty folder without a valid manifest, an earlier output without
    ``overwrite``, and a location where nothing can be written (tried by creating and removing a
    staging folder there). Writes nothing that stays.
    """
    path = Path(folder)
    if path.is_symlink() and not path.exists():
        raise UsageError(option, f"{path} is a broken symbolic link; give a new or empty folder")
    if not path.exists():
        anchor = _existing_ancestor(path, option)
        _probe(anchor, option)
        return OutputTarget(path, anchor, exists=False)
    if not path.is_dir():
        raise UsageError(
            option, f"{path} is an existing file; optlight writes a folder there: give a new or empty folder"
        )
    try:
        entries = list(path.iterdir())
    except OSError as e:
        raise UsageError(option, f"cannot read the folder {path} ({e.strerror})") from None
    previous: tuple[str, ...] = ()
    if entries:
        listed = _read_manifest(path)
        if listed is None:
            raise UsageError(
                option,
                f"{path} is not empty and holds files optlight did not write; give a new or empty folder "
                "(optlight never replaces files it did not write)",
            )
        if not overwrite:
            raise UsageError(
                option,
                f"{path} holds the output of an earlier optlight run; pass {force} to replace it "
                "(files you added there are kept)",
            )
        previous = listed
    _probe(path, option)
    return OutputTarget(path, path, exists=True, previous=previous)


def write_folder(
    folder: str | Path,
    write: Callable[[Path], Sequence[Path]],
    *,
    overwrite: bool = False,
    option: str = "folder",
    force: str = "overwrite=True",
) -> list[Path]:
    """Fill ``folder`` with the files ``write(staging)`` writes into the staging folder it is given
    (it returns their paths), following the output policy; returns the paths in ``folder``.

    The staging folder is removed when ``write`` raises or Ctrl-C arrives before the final renames;
    those run with Ctrl-C deferred. Raises what :func:`check_output_folder` raises, and
    :class:`UsageError` (nothing changed) when a file to write exists in the folder without being
    listed in its manifest (it appeared after the check).
    """
    target = check_output_folder(folder, overwrite=overwrite, option=option, force=force)
    staging = target.anchor / f"{STAGING_PREFIX}{uuid.uuid4().hex[:12]}"
    try:
        with interrupts.deferred():  # created, then removed by the finally below: never left behind
            staging.mkdir()
        files = [PurePosixPath(Path(p).relative_to(staging).as_posix()) for p in write(staging)]
        names = sorted({str(f) for f in files})
        (staging / MANIFEST).write_text(
            json.dumps({"written_by": f"optlight {_version()}", "files": names}, indent=1) + "\n"
        )
        interrupts.check()  # an interrupt a library swallowed while writing
        with interrupts.deferred():
            _move_into_place(staging, target, names, option)
    finally:
        shutil.rmtree(staging, ignore_errors=True)  # gone already when renamed into place
    return [target.path / f for f in files]


def check_output_file(
    path: str | Path, *, overwrite: bool = False, option: str = "file", force: str = "overwrite=True"
) -> OutputTarget:
    """Whether an output file may be written at ``path``: an existing file only with ``overwrite``,
    never a folder; the nearest existing folder above it must be writable. Raises :class:`UsageError`."""
    out = Path(path)
    if out.is_dir():
        raise UsageError(option, f"{out} is a folder; give the path of the file to write")
    exists = out.exists() or out.is_symlink()
    if exists and not overwrite:
        raise UsageError(option, f"{out} exists; pass {force} to replace it")
    anchor = _existing_ancestor(out, option)
    _probe(anchor, option)
    return OutputTarget(out, anchor, exists=exists)


def write_file(
    path: str | Path,
    write: Callable[[Path], object],
    *,
    overwrite: bool = False,
    option: str = "file",
    force: str = "overwrite=True",
) -> Path:
    """Write one file through ``write(temporary)`` (the temporary path keeps ``path``'s suffix) and
    rename it to ``path`` (missing folders above it created then), following the output policy."""
    target = check_output_file(path, overwrite=overwrite, option=option, force=force)
    out = target.path
    temporary = target.anchor / f"{STAGING_PREFIX}{uuid.uuid4().hex[:12]}{out.suffix}"
    try:
        write(temporary)
        interrupts.check()
        with interrupts.deferred():
            out.parent.mkdir(parents=True, exist_ok=True)
            os.replace(temporary, out)
    finally:
        temporary.unlink(missing_ok=True)
    return out


def _existing_ancestor(path: Path, option: str) -> Path:
    """The nearest existing folder at or above ``path``'s parent; a file there is refused."""
    anchor = path.absolute().parent
    while not anchor.exists():
        anchor = anchor.parent
    if not anchor.is_dir():
        raise UsageError(option, f"{anchor} is a file, so {path} cannot be created")
    return anchor


def _probe(folder: Path, option: str) -> None:
    """Refuse a folder where optlight cannot create (and remove) a staging folder."""
    probe = folder / f"{STAGING_PREFIX}probe-{uuid.uuid4().hex[:12]}"
    try:
        with interrupts.deferred():  # never left behind
            probe.mkdir()
            probe.rmdir()
    except OSError as e:
        raise UsageError(option, f"cannot write in {folder} ({e.strerror or e})") from None


def _read_manifest(folder: Path) -> tuple[str, ...] | None:
    """The files the folder's manifest lists, or None when it has no valid manifest (a listed path
    must be relative and stay inside the folder)."""
    try:
        data = json.loads((folder / MANIFEST).read_text())
    except (OSError, ValueError):
        return None
    files = data.get("files") if isinstance(data, dict) else None
    if not isinstance(files, list) or not all(isinstance(f, str) and f for f in files):
        return None
    for f in files:
        p = PurePosixPath(f)
        if p.is_absolute() or ".." in p.parts or str(p) == MANIFEST or "\\" in f:
            return None
    return tuple(files)


def _move_into_place(staging: Path, target: OutputTarget, names: Sequence[str], option: str) -> None:
    """Rename the staged output into place: the staging folder itself when the folder is new, else
    each file into the folder (then remove the files of the earlier output that the new one does not
    have), the manifest last."""
    folder = target.path
    if not target.exists:
        folder.parent.mkdir(parents=True, exist_ok=True)
        os.rename(staging, folder)
        return
    previous = set(target.previous)
    for name in names:
        dest = folder / name
        if (dest.exists() or dest.is_symlink()) and name not in previous:
            raise UsageError(
                option, f"{dest} appeared and was not written by optlight; move it away (nothing was changed)"
            )
    for name in names:
        dest = folder / name
        dest.parent.mkdir(parents=True, exist_ok=True)
        os.replace(staging / name, dest)
    for name in sorted(previous - set(names)):
        old = folder / name
        if old.is_file() or old.is_symlink():
            old.unlink()
    os.replace(staging / MANIFEST, folder / MANIFEST)


def _version() -> str:
    try:
        return importlib.metadata.version("optlight")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"
