"""The output policy: a folder is written whole through a staging folder and its manifest, or
not at all; a single file through a temporary name; what exists is replaced only as asked (the
package docstring, :mod:`optlight.export`)."""

from __future__ import annotations

import errno
import importlib.metadata
import json
import os
import shutil
import uuid
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

from optlight import interrupts, locks
from optlight.errors import OutputError, UsageError

#: The file optlight writes last into every folder it fills: the files it wrote there (JSON).
MANIFEST = ".optlight-manifest.json"
#: Prefix of the hidden staging folders and temporary files (removed unless the process is killed).
STAGING_PREFIX = ".optlight-staging-"
#: What a failed write's errno means, said before the system's own words.
WRITE_FAILURES = {
    errno.ENOSPC: "the disk is full",
    errno.EDQUOT: "the disk quota is exceeded",
    errno.EFBIG: "a file is larger than this system lets a process write",
}


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
    folder: str | Path,
    *,
    overwrite: bool = False,
    option: str = "folder",
    force: str = "overwrite=True",
    resume: str | None = None,
) -> OutputTarget:
    """Whether ``folder`` may receive an output folder (module docstring), and where to stage it.

    ``option`` names the folder in errors (``--out`` on the command line), ``force`` what the
    caller passes to allow replacing an earlier output; ``resume`` the kind of output in rounds the
    caller continues (an earlier output whose manifest names that kind is updated as with
    ``overwrite``). Raises :class:`UsageError` for an existing
    file or broken link, a non-empty folder without a valid manifest, an earlier output without
    ``overwrite``, and a location where nothing can be written (tried by creating and removing a
    staging folder there); :class:`OutputError` when another run is writing the folder (its lock,
    :mod:`optlight.locks`, kept from here to the end of a command). Writes nothing that stays.
    """
    path = Path(folder)
    locks.acquire(path)
    try:
        return _check_output_folder(path, overwrite, option, force, resume)
    finally:
        locks.release(path)


def _check_output_folder(
    path: Path, overwrite: bool, option: str, force: str, resume: str | None
) -> OutputTarget:
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
        if not overwrite and (resume is None or _manifest_resume(path) != resume):
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
    resume: str | None = None,
    resumable: str | None = None,
) -> list[Path]:
    """Fill ``folder`` with the files ``write(staging)`` writes into the staging folder it is given
    (it returns their paths), following the output policy; returns the paths in ``folder``.
    ``resume``: as for :func:`check_output_folder`; ``resumable``: the kind of output in rounds this
    one is, recorded in the manifest so that the next round may continue it (None: a finished output).

    The staging folder is removed when ``write`` raises or Ctrl-C arrives before the final renames;
    those run with Ctrl-C deferred. Raises what :func:`check_output_folder` raises,
    :class:`UsageError` (nothing changed) when a file to write exists in the folder without being
    listed in its manifest (it appeared after the check), and :class:`OutputError` naming the
    folder and the cause when the system refuses a write (a full disk, a file size limit).
    """
    locks.acquire(folder)  # held until the output is in place
    try:
        target = check_output_folder(folder, overwrite=overwrite, option=option, force=force, resume=resume)
    except BaseException:
        locks.release(folder)
        raise
    staging = target.anchor / f"{STAGING_PREFIX}{uuid.uuid4().hex[:12]}"
    moving = False
    try:
        with interrupts.deferred():  # created, then removed by the finally below: never left behind
            staging.mkdir()
        interrupts.reached("staging-created")
        files = [PurePosixPath(Path(p).relative_to(staging).as_posix()) for p in write(staging)]
        names = sorted({str(f) for f in files})
        manifest: dict[str, Any] = {"written_by": f"optlight {_version()}", "files": names}
        if resumable is not None:
            manifest["resume"] = resumable
        (staging / MANIFEST).write_text(json.dumps(manifest, indent=1) + "\n")
        interrupts.check()  # an interrupt a library swallowed while writing
        interrupts.reached("staging-written")
        with interrupts.deferred():
            interrupts.reached("renames")  # held back until the output is in place
            moving = True
            _move_into_place(staging, target, names, option)
    except OSError as e:
        partial = "some of its files may be the new output's" if moving and target.exists else "nothing was written"
        raise _write_error(target.path, e, staging, partial) from None
    finally:
        shutil.rmtree(staging, ignore_errors=True)  # gone already when renamed into place
        locks.release(folder)
    return [target.path / f for f in files]


def check_output_file(
    path: str | Path,
    *,
    overwrite: bool = False,
    option: str = "file",
    force: str = "overwrite=True",
    ours: Callable[[Path], bool] | None = None,
) -> OutputTarget:
    """Whether an output file may be written at ``path``: an existing file only with ``overwrite``,
    and then only when ``ours(path)`` says optlight wrote it (when given), never a folder; the nearest
    existing folder above it must be writable. Raises :class:`UsageError`, and :class:`OutputError`
    when another run is writing the file (as :func:`check_output_folder`)."""
    out = Path(path)
    locks.acquire(out)
    try:
        return _check_output_file(out, overwrite, option, force, ours)
    finally:
        locks.release(out)


def _check_output_file(
    out: Path, overwrite: bool, option: str, force: str, ours: Callable[[Path], bool] | None
) -> OutputTarget:
    if out.is_dir():
        raise UsageError(option, f"{out} is a folder; give the path of the file to write")
    exists = out.exists() or out.is_symlink()
    if exists and not overwrite:
        raise UsageError(option, f"{out} exists; pass {force} to replace it")
    if exists and ours is not None and (out.is_symlink() or not ours(out)):
        raise UsageError(
            option, f"{out} exists and optlight did not write it; {force} replaces only a file optlight wrote"
        )
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
    ours: Callable[[Path], bool] | None = None,
) -> Path:
    """Write one file through ``write(temporary)`` (the temporary path keeps ``path``'s suffix) and
    rename it to ``path`` (missing folders above it created then), following the output policy
    (``ours``: see :func:`check_output_file`)."""
    locks.acquire(path)  # held until the file is in place
    try:
        target = check_output_file(path, overwrite=overwrite, option=option, force=force, ours=ours)
    except BaseException:
        locks.release(path)
        raise
    out = target.path
    temporary = target.anchor / f"{STAGING_PREFIX}{uuid.uuid4().hex[:12]}{out.suffix}"
    try:
        write(temporary)
        interrupts.check()
        with interrupts.deferred():
            out.parent.mkdir(parents=True, exist_ok=True)
            os.replace(temporary, out)
    except OSError as e:
        raise _write_error(out, e, temporary) from None
    finally:
        temporary.unlink(missing_ok=True)
        locks.release(path)
    return out


@contextmanager
def writes_into(folder: Path, kept: str) -> Iterator[None]:
    """Writes into ``folder`` outside :func:`write_folder` (a batch's records and table, which a run
    adds as it goes): a write the system refuses is an :class:`OutputError` naming the folder, the
    cause and what is ``kept``."""
    try:
        yield
    except OSError as e:
        raise _write_error(folder, e, folder, kept) from None


def _write_error(path: Path, error: OSError, within: Path, done: str = "nothing was written") -> OutputError:
    """The one-line error for ``error``, met while writing the output ``path`` through ``within``
    (the staging folder, the temporary file, the folder itself): the folder, the cause, the file it
    was writing (relative to ``within``), and what was ``done``."""
    cause = error.strerror or str(error)
    if error.errno in WRITE_FAILURES:
        cause = f"{WRITE_FAILURES[error.errno]} ({cause})"
    if error.filename:
        name = Path(os.fsdecode(error.filename))
        cause += f" at {name.relative_to(within) if name.is_relative_to(within) and name != within else name}"
    return OutputError(f"cannot write {path}: {cause}; {done}")


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


def _manifest_resume(folder: Path) -> str | None:
    """The kind of output in rounds the folder's manifest says may be continued, or None."""
    try:
        data = json.loads((folder / MANIFEST).read_text())
    except (OSError, ValueError):
        return None
    kind = data.get("resume") if isinstance(data, dict) else None
    return kind if isinstance(kind, str) else None


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
