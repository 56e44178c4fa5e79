"""Ctrl-C (SIGINT) that no library can swallow, and sections it cannot cut in half.

Python turns SIGINT into KeyboardInterrupt, but some libraries catch it: CasADi's IPOPT interface
stops the solve, prints a warning and returns the solution it had ("User_Requested_Stop"), and an
exception raised in a ``__del__`` or a callback is printed ("Exception ignored …") and dropped. The
run would then carry on and finish as if nothing had happened. :func:`latched` makes an interrupt
stick: the handler records it before raising, and :func:`check` (called between stages and before
any output is moved into place) raises it again. :func:`deferred` holds an interrupt back while a
few renames put an output in place, so the output appears whole or not at all.

Signal handlers can only be set from the main thread; elsewhere both context managers do nothing.
"""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any

_pending = False


def in_main_thread() -> bool:
    """Whether the caller runs in the main thread, the only one that may set signal handlers."""
    return threading.current_thread() is threading.main_thread()


def pending() -> bool:
    """Whether a SIGINT arrived under :func:`latched` (or :func:`deferred`) and was not yet raised."""
    return _pending


def check() -> None:
    """Raise KeyboardInterrupt when an interrupt is pending (one a library may have swallowed)."""
    if _pending:
        raise KeyboardInterrupt


@contextmanager
def latched() -> Iterator[None]:
    """Within the block SIGINT records itself, then raises KeyboardInterrupt as usual; the record
    stays until the block ends, so :func:`check` raises it again after a library swallowed it.

    Where Python cannot propagate it (a ``__del__``, a weakref callback during garbage collection)
    it would print "Exception ignored in … KeyboardInterrupt"; that report is dropped, since
    :func:`check` raises the interrupt again."""
    global _pending
    if not in_main_thread():
        yield
        return

    def handler(signum: int, frame: FrameType | None) -> None:
        global _pending
        _pending = True
        raise KeyboardInterrupt

    report = sys.unraisablehook

    def unraisable(info: Any) -> None:
        if not (_pending and isinstance(info.exc_value, KeyboardInterrupt)):
            report(info)

    previous = signal.signal(signal.SIGINT, handler)
    sys.unraisablehook = unraisable
    _pending = False
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        sys.unraisablehook = report
        _pending = False


@contextmanager
def deferred() -> Iterator[None]:
    """Within the block SIGINT is only recorded; when the block has finished (or raised), it is
    handed to the handler in force before (which raises KeyboardInterrupt, unless SIGINT was
    ignored). A pending interrupt is raised before the block starts."""
    check()
    if not in_main_thread():
        yield
        return
    arrived = False

    def handler(signum: int, frame: FrameType | None) -> None:
        nonlocal arrived
        arrived = True

    previous: Any = signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        # also when the block raised: the user's interrupt wins over the block's error
        if arrived and previous is not signal.SIG_IGN:
            if callable(previous):
                previous(signal.SIGINT, None)  # Python's default handler or latched()'s: raises
            raise KeyboardInterrupt
