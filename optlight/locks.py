"""Locks on outputs: a run is refused, in one line, at the start when another is writing its output.

A lock is a Unix socket bound to a name in Linux's abstract namespace made of a hash of the output's
resolved path: binding fails while another process holds the name, and the kernel frees it when its
process ends, whatever ends it (a normal exit, ``os._exit``, a signal). It leaves no file anywhere: a
lock file beside the output would stay in the user's folder after every run that ended before
removing it. Other systems have no abstract namespace: there nothing is locked.

:func:`acquire` and :func:`release` nest within a process (the output checks and writes of
:mod:`optlight.export` take them); the lock is held while any acquire is not released. Under
:func:`holding` (the command line, around a whole command) the locks taken are kept until it ends,
so that a second command into the same ``--out`` is refused before it starts working, and the first
keeps the folder from its check until its output is in place.
"""

from __future__ import annotations

import errno
import hashlib
import socket
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from optlight.errors import OutputError

#: Prefix of the lock names in the abstract socket namespace.
LOCK_PREFIX = "optlight-output-"

_sockets: dict[str, socket.socket] = {}
_counts: dict[str, int] = {}
_holding = 0


def _key(path: str | Path) -> str:
    return str(Path(path).resolve())


def acquire(path: str | Path) -> None:
    """Take the lock of writing the output ``path``; :class:`OutputError` when another process
    holds it."""
    if not sys.platform.startswith("linux"):
        return
    key = _key(path)
    if key not in _sockets:
        lock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            lock.bind("\0" + LOCK_PREFIX + hashlib.sha256(key.encode()).hexdigest()[:32])
        except OSError as e:
            lock.close()
            if e.errno != errno.EADDRINUSE:
                raise
            raise OutputError(
                f"another optlight run is writing {path}; wait for it to end or give another folder"
            ) from None
        _sockets[key] = lock
    _counts[key] = _counts.get(key, 0) + 1


def release(path: str | Path) -> None:
    """Release one :func:`acquire` of ``path``; the lock is freed after the last, unless
    :func:`holding` keeps it."""
    key = _key(path)
    if key not in _counts:
        return
    _counts[key] -= 1
    if _counts[key] <= 0 and not _holding:
        _free(key)


def _free(key: str) -> None:
    _counts.pop(key, None)
    lock = _sockets.pop(key, None)
    if lock is not None:
        lock.close()


def claim(path: str | Path) -> None:
    """Refuse (:class:`OutputError`) an output another process is writing; under :func:`holding`,
    keep its lock until the block ends."""
    acquire(path)
    release(path)


@contextmanager
def holding() -> Iterator[None]:
    """Keep every lock taken inside until the block ends, then free those no :func:`acquire`
    still holds."""
    global _holding
    _holding += 1
    try:
        yield
    finally:
        _holding -= 1
        if not _holding:
            for key in [k for k, n in _counts.items() if n <= 0]:
                _free(key)
