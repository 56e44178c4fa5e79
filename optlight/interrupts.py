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
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any

#: A Python signal handler.
Handler = Callable[[int, FrameType | None], object]

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
def latched(then: Handler | None = None) -> Iterator[None]:
    """Within the block SIGINT records itself, then raises KeyboardInterrupt as usual; the record
    stays until the block ends, so :func:`check` raises it again after a library swallowed it. When
    the block ends the handler in force before is restored, or ``then`` is installed."""
    global _pending
    if not in_main_thread():
        yield
        return

    def handler(signum: int, frame: FrameType | None) -> None:
        global _pending
        _pending = True
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGINT, handler)
    _pending = False
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, then if then is not None else previous)
        _pending = False


@contextmanager
def deferred() -> Iterator[None]:
    """Within the block SIGINT is only recorded; when the block has finished, it is handed to the
    handler in force before (which raises KeyboardInterrupt, unless SIGINT was ignored). A pending
    interrupt is raised before the block starts."""
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
    if not arrived or previous is signal.SIG_IGN:
        return
    if callable(previous):
        previous(signal.SIGINT, None)  # Python's default handler or latched()'s: raises KeyboardInterrupt
    raise KeyboardInterrupt
