"""The disk cache of results that cost seconds and depend only on their inputs: the preview's
decimated robot meshes (:mod:`optlight.viz.meshes`) and the collision spheres fitted to a robot's
bodies (:mod:`optlight.environment.spheres`).

One npz file of named arrays per entry, named by a hash of a key that holds everything the result
depends on (a version number included, changed when the computation changes), in
:func:`cache_folder`. Writes go through a temporary file and a rename, so that a concurrent reader
never sees half a file; a file that cannot be read is computed again and replaced; where the cache
cannot be written, nothing is, and each run computes again.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

Arrays = dict[str, NDArray[Any]]


def cache_folder(kind: str) -> Path | None:
    """Where entries of ``kind`` ("meshes", "spheres") are cached: ``$OPTLIGHT_CACHE/<kind>``
    (``OPTLIGHT_CACHE`` set but empty: no disk cache), else ``$XDG_CACHE_HOME/optlight/<kind>``, else
    ``~/.cache/optlight/<kind>``; None when it cannot be created."""
    configured = os.environ.get("OPTLIGHT_CACHE")
    if configured == "":
        return None
    if configured is not None:
        folder = Path(configured) / kind
    else:
        folder = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "optlight" / kind
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    return folder


def cached_arrays(kind: str, key: str, compute: Callable[[], Mapping[str, NDArray[Any]]]) -> Arrays:
    """The arrays of the entry ``key`` of ``kind`` from the disk cache, else ``compute()``'s, written
    there."""
    folder = cache_folder(kind)
    path = folder / f"{hashlib.sha256(key.encode()).hexdigest()[:32]}.npz" if folder else None
    if path is not None and path.exists():
        try:
            with np.load(path) as data:
                return {name: data[name] for name in data.files}
        except (OSError, ValueError, KeyError):
            pass  # a damaged file: computed again below and replaced
    arrays = dict(compute())
    if path is not None:
        _write_atomically(path, arrays)
    return arrays


def _write_atomically(path: Path, arrays: Mapping[str, NDArray[Any]]) -> None:
    """Write ``arrays`` to ``path`` (npz) through a temporary file and a rename."""
    try:
        handle, name = tempfile.mkstemp(dir=path.parent, suffix=".npz.tmp")
    except OSError:
        return
    try:
        with os.fdopen(handle, "wb") as out:
            np.savez(out, **arrays)  # type: ignore[arg-type]  # numpy's stub types **kwds as allow_pickle's bool
        os.replace(name, path)
    except OSError:
        Path(name).unlink(missing_ok=True)
