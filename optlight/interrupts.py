"""Stop signals (Ctrl-C, SIGTERM, SIGHUP) that no library can swallow, and sections they cannot cut in half.

A command stops the same way whichever of :data:`SIGNALS` arrives: SIGINT (Ctrl-C), SIGTERM (what
``kill``, ``timeout``, systemd and batch systems send) or SIGHUP (the terminal closed), unless it is
ignored (``nohup``'s SIGHUP stays ignored). Under :func:`latched` each raises :class:`Interrupt`, a
KeyboardInterrupt that names its signal, so every ``finally`` and ``with`` block on the way out runs
(staging folders removed, worker processes and clusters closed); the command line then prints one
line (``optlight: interrupted``, ``terminated``, ``hung up``) and exits with status 128 + the
signal's number (130, 143, 129).

Python turns SIGINT into KeyboardInterrupt, but some libraries catch it: CasADi's IPOPT interface
stops the solve, prints a warning and returns the solution it had ("User_Requested_Stop"), and an
exception raised in a ``__del__`` or a callback is printed ("Exception ignored …") and dropped. The
run would then carry on and finish as if nothing had happened. :func:`latched` makes a signal stick:
the handler records it before raising, and :func:`check` (called between stages and before any
output is moved into place) raises it again. :func:`deferred` holds the signals back while a few
renames put an output in place, so the output appears whole or not at all; :func:`held`, while a
cleanup runs that a signal must not cut in half.

:func:`reached` is a test hook: the environment variable :data:`TEST_SIGNAL_AT` makes the command
send itself a signal when it reaches a named stage, so that tests stop it at chosen moments rather
than at random times.

Signal handlers can only be set from the main thread; elsewhere both context managers do nothing.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any

#: The signals that stop a command, and the word the command line prints for each.
SIGNALS: dict[int, str] = {
    signal.SIGINT: "interrupted",
    signal.SIGTERM: "terminated",
    **({signal.SIGHUP: "hung up"} if hasattr(signal, "SIGHUP") else {}),
}
#: Test hook: ``OPTLIGHT_TEST_SIGNAL_AT=<stage>:<SIGNAME>`` (e.g. ``nlp:SIGTERM``) makes the command
#: send itself that signal the first time it reaches that stage (:func:`reached`).
TEST_SIGNAL_AT = "OPTLIGHT_TEST_SIGNAL_AT"

_pending: int | None = None  # the first signal that arrived under latched(), not yet handled
_latched = False  # latched() is in force: the test hook is armed (in the command, never in a worker)
_hook_fired = False


class Interrupt(KeyboardInterrupt):
    """The KeyboardInterrupt one of :data:`SIGNALS` raises under :func:`latched`; ``signum`` says which."""

    def __init__(self, signum: int = signal.SIGINT) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def in_main_thread() -> bool:
    """Whether the caller runs in the main thread, the only one that may set signal handlers."""
    return threading.current_thread() is threading.main_thread()


def pending() -> bool:
    """Whether a signal arrived under :func:`latched` (or :func:`deferred`) and was not yet handled."""
    return _pending is not None


def received() -> int:
    """The signal that stopped the command: the pending one, else SIGINT (a KeyboardInterrupt that
    Python's own handler raised)."""
    return signal.SIGINT if _pending is None else _pending


def exit_status(signum: int) -> int:
    """The shell's exit status of a command stopped by ``signum``: 128 + its number (SIGINT 130,
    SIGTERM 143, SIGHUP 129)."""
    return 128 + signum


def check() -> None:
    """Raise :class:`Interrupt` when a signal is pending (one a library may have swallowed)."""
    if _pending is not None:
        raise Interrupt(_pending)


def reached(stage: str) -> None:
    """Test hook: the command reached ``stage``. When :data:`TEST_SIGNAL_AT` names this stage, the
    process sends itself the signal it names, once; only under :func:`latched` (the command line),
    so worker processes that inherit the environment are never signalled. Does nothing otherwise."""
    global _hook_fired
    at = os.environ.get(TEST_SIGNAL_AT)
    if at is None or not _latched or _hook_fired:
        return
    name, _, signame = at.rpartition(":")
    if name == stage:
        _hook_fired = True
        os.kill(os.getpid(), signal.Signals[signame])


def _install(handler: Any) -> dict[int, Any]:
    """Set ``handler`` for every one of :data:`SIGNALS` that is not ignored (``nohup``'s SIGHUP stays
    ignored); the handlers it replaced."""
    return {
        signum: signal.signal(signum, handler)
        for signum in SIGNALS
        if signal.getsignal(signum) is not signal.SIG_IGN
    }


def _restore(previous: dict[int, Any]) -> None:
    for signum, handler in previous.items():
        # None: a handler not set from Python (an embedding program's), which cannot be put back
        signal.signal(signum, signal.SIG_DFL if handler is None else handler)


@contextmanager
def latched() -> Iterator[None]:
    """Within the block each of :data:`SIGNALS` records itself (the first one is kept), then raises
    :class:`Interrupt`; the record stays until the block ends, so :func:`check` raises it again after
    a library swallowed it.

    Where Python cannot propagate it (a ``__del__``, a weakref callback during garbage collection)
    it would print "Exception ignored in … KeyboardInterrupt"; that report is dropped, since
    :func:`check` raises the interrupt again."""
    global _pending, _latched, _hook_fired
    if not in_main_thread():
        yield
        return

    def handler(signum: int, frame: FrameType | None) -> None:
        global _pending
        if _pending is None:
            _pending = signum
        raise Interrupt(signum)

    report = sys.unraisablehook

    def unraisable(info: Any) -> None:
        if not (_pending is not None and isinstance(info.exc_value, KeyboardInterrupt)):
            report(info)

    previous = _install(handler)
    sys.unraisablehook = unraisable
    _pending, _latched, _hook_fired = None, True, False
    try:
        yield
    finally:
        _restore(previous)
        sys.unraisablehook = report
        _pending, _latched = None, False


@contextmanager
def deferred() -> Iterator[None]:
    """Within the block :data:`SIGNALS` are held back (:func:`held`); a pending signal is raised
    before the block starts."""
    check()
    with held():
        yield


@contextmanager
def held() -> Iterator[None]:
    """Within the block :data:`SIGNALS` are only recorded; when the block has finished (or raised),
    the first one is handed to its handler in force before (under :func:`latched`, or Python's for
    SIGINT: raises KeyboardInterrupt; the default action: ends the process; ignored: nothing). Unlike
    :func:`deferred`, the block runs even when a signal is pending: it is for cleaning up."""
    if not in_main_thread():
        yield
        return
    arrived: list[int] = []

    def handler(signum: int, frame: FrameType | None) -> None:
        arrived.append(signum)

    previous = _install(handler)
    try:
        yield
    finally:
        _restore(previous)
        # also when the block raised: the user's signal wins over the block's error
        if arrived:
            signum = arrived[0]
            before = previous[signum]
            if callable(before):
                before(signum, None)  # Python's default handler or latched()'s: raises
            if before is not signal.SIG_IGN:
                if before in (signal.SIG_DFL, None):
                    signal.raise_signal(signum)  # the default action: the process ends here
                raise Interrupt(signum)
