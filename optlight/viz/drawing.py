"""Figures as jobs, drawn here or in a worker process while this one goes on writing.

A :class:`FigureJob` is a module-level function that builds a :class:`matplotlib.figure.Figure`,
its (picklable) arguments and the PNG's resolution. :meth:`FigureJob.png` draws it in this process;
a :class:`FigureWorker` draws it in a process of its own. Drawing is most of the time it takes to
write a plan's results (the six figures of the default problem ~1.5 s, the rest ~1 s), and it needs
only the plan's numbers, so the command line starts a worker before its own heavy imports (the
worker's imports take the core those and the problem's build leave idle) and hands it the figures
as soon as their numbers exist (:class:`optlight.report.FigureDrafts`, listening to the solve's
stages): the landmark figures once the captures are placed, the trajectory and path figures once the
motion is timed, drawn while it is verified and the exports and the preview are written
(``Plan.save``).

The worker is spawned, not forked: a fresh interpreter inherits none of this process's threads
(Embree's, the ray caster's pool) or locks. It ignores Ctrl-C and SIGHUP (which a terminal sends to
every process of the command) from its first instant: this process handles them
(:mod:`optlight.interrupts`) and answers by closing the worker, at once when the worker's ``with``
block ends with an exception. And it never outlives this process, whatever ended it (SIGKILL
included): it ends as soon as the pipe multiprocessing keeps from this process reaches its end.
"""

from __future__ import annotations

import atexit
import importlib
import io
import multiprocessing
import os
import signal
import sys
import threading
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any

from optlight import interrupts

if TYPE_CHECKING:  # imported where a figure is made: see optlight.viz.layout
    from matplotlib.figure import Figure


#: zlib level of the figures' PNGs (Pillow's default is 6). PNG is lossless: the pixels are the same
#: at every level. At 3 the default plan's six figures are saved ~15 % faster than at 6 (the figure
#: worker's drawing is what the command waits for at its end), at about the same total size.
PNG_COMPRESS_LEVEL = 3


@dataclass(frozen=True)
class FigureJob:
    """A figure to draw: ``build(*args)`` returns it, saved as a PNG at ``dpi``. ``build`` is a
    module-level function and ``args`` pickle, so a :class:`FigureWorker` can draw it."""

    build: Callable[..., Figure]
    args: tuple[Any, ...]
    dpi: int

    @classmethod
    def of(cls, figure: Figure, dpi: int) -> FigureJob:
        """A figure built already (matplotlib figures pickle): only its drawing is left."""
        return cls(_as_built, (figure,), dpi)

    def png(self) -> bytes:
        """The figure drawn (Agg) as PNG bytes, laid out as built (no tight bounding box)."""
        buffer = io.BytesIO()
        self.build(*self.args).savefig(
            buffer, format="png", dpi=self.dpi, pil_kwargs={"compress_level": PNG_COMPRESS_LEVEL}
        )
        return buffer.getvalue()

    def save(self, path: str | Path) -> Path:
        """The PNG written to ``path``."""
        path = Path(path)
        path.write_bytes(self.png())
        return path


def _as_built(figure: Figure) -> Figure:
    return figure


def _draw(job: FigureJob) -> bytes:
    return job.png()


#: The signals a worker ignores: those a terminal sends to every process of the command (Ctrl-C's
#: SIGINT, the hang-up's SIGHUP), which the parent handles by closing the worker.
IGNORED = tuple(s for s in interrupts.SIGNALS if s != signal.SIGTERM)


def _block_ignored() -> set[int | signal.Signals] | None:
    """Block :data:`IGNORED` in this thread; the previous mask (None where the OS has no signal masks)."""
    if not hasattr(signal, "pthread_sigmask"):
        return None
    return signal.pthread_sigmask(signal.SIG_BLOCK, set(IGNORED))


def _restore_signals(mask: set[int | signal.Signals] | None) -> None:
    if mask is not None:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)


def _start_worker() -> None:
    """In the worker: leave :data:`IGNORED` to the parent, which closes the worker; end with the
    parent (:func:`_exit_with_parent`); and end the process without tearing the interpreter down
    (:func:`_exit_now`)."""
    for signum in IGNORED:
        signal.signal(signum, signal.SIG_IGN)
    threading.Thread(target=_exit_with_parent, name="optlight-parent-watch", daemon=True).start()
    atexit.register(_exit_now)  # registered last, so run first, once the worker's loop has returned


def _exit_with_parent() -> None:
    """In a thread of the worker: wait until the parent process is gone, then end the worker at once.

    Spawned, the worker holds the read end of a pipe whose write end only the parent holds
    (:func:`multiprocessing.parent_process`'s sentinel); it reaches its end when the parent ends,
    whatever ended it. The worker's own queue would never tell (it holds both ends of it), and an
    orphaned worker would keep the caller's stdout and stderr open."""
    parent = multiprocessing.parent_process()
    if parent is not None:
        parent.join()
        os._exit(1)


def _exit_now() -> None:
    """End the worker with status 0 without the rest of the interpreter's shutdown: freeing
    matplotlib's and CasADi's modules takes 0.2–0.3 s, which closing the worker would wait for at the
    end of every command. Nothing is lost: each PNG went back through a pipe written synchronously
    before the worker took its next job, and its standard streams are flushed here."""
    for stream in (sys.stdout, sys.stderr):
        if stream is not None:
            stream.flush()
    os._exit(0)


#: Modules a worker imports before its first figure: those of a plan's figures (and, through them,
#: the classes their arguments unpickle into), and the matplotlib they import as they build one.
#: Named, not imported here: the figure modules import this one.
PRELOAD = (
    "optlight.viz.figures",
    "optlight.viz.trajectory_figures",
    "matplotlib.collections",
    "matplotlib.projections.polar",
    "mpl_toolkits.mplot3d",
)


def _warm_up() -> None:
    """In the worker: import :data:`PRELOAD` and draw a small figure with text, so that the first
    real figure does not pay for the imports and the font cache."""
    from matplotlib.figure import Figure

    for name in PRELOAD:
        importlib.import_module(name)
    figure = Figure(figsize=(1.0, 1.0))
    figure.add_subplot().set_title("warm-up")
    figure.savefig(io.BytesIO(), format="png", dpi=50)


class FigureWorker:
    """One process that draws :class:`FigureJob` s: :meth:`draw` returns at once with a future of
    the PNG bytes. The process starts (and warms up, :func:`_warm_up`) when the worker is made and
    stops on :meth:`close` or at the end of a ``with`` block, which drops the figures not drawn yet.

    Like any spawned process, it imports the main module of a script that makes one: such a script
    needs the ``if __name__ == "__main__":`` guard (the ``optlight`` command has it).
    """

    def __init__(self) -> None:
        self._pool = ProcessPoolExecutor(
            max_workers=1, mp_context=multiprocessing.get_context("spawn"), initializer=_start_worker
        )
        # The process starts with the first job: now, not at the first figure. IGNORED are blocked
        # while it starts, so that it is born ignoring them (the mask carries over to the new
        # interpreter) rather than printing a KeyboardInterrupt from its imports; here a signal
        # meanwhile waits, and is delivered on unblocking: then the worker is closed at once, as no
        # ``with`` block will.
        blocked = _block_ignored()
        try:
            try:
                self._pool.submit(_warm_up)
            finally:
                _restore_signals(blocked)
        except BaseException:
            self.close(terminate=True)
            raise

    def draw(self, job: FigureJob) -> Future[bytes]:
        """The PNG bytes of ``job``, drawn in the worker (errors come back through the future)."""
        return self._pool.submit(_draw, job)

    def close(self, terminate: bool = False) -> None:
        """Stop the process once the figure it is drawing is done, or at once with ``terminate``;
        figures still queued are dropped. Signals are held back meanwhile (:func:`interrupts.held`):
        one that cut the shutdown in half would leave the process running and its queues' semaphores
        unreleased (the resource tracker then reports them "leaked")."""
        with interrupts.held():
            interrupts.reached("figure-worker-closing")
            if terminate:
                # ProcessPoolExecutor has no public way to stop a busy worker (before Python 3.14)
                for process in list((self._pool._processes or {}).values()):
                    process.terminate()
            self._pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> FigureWorker:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, value: BaseException | None, traceback: TracebackType | None
    ) -> None:
        self.close(terminate=kind is not None)  # an error or a signal: the figures are not wanted
