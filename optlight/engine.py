"""The Dask engine of :mod:`optlight.batch` and :mod:`optlight.cell`: a client of a local cluster or
of a remote scheduler, the scheduler's check, tasks run on it (or here, in order) and their progress.

**The engine: Dask, not Ray.** Both run Python functions on a cluster. Dask's ``distributed`` is
pure Python, a plain PyPI dependency; a :class:`distributed.LocalCluster` starts here in 0.7 s and
listens on 127.0.0.1 only (``dashboard_address=None``: no dashboard; the scheduler's plain health and
metrics endpoint on a free loopback port); a remote cluster is just ``Client("tcp://host:8786")``,
its scheduler and workers started with ``dask scheduler`` / ``dask worker`` or by any cluster
manager (SLURM, Kubernetes). Ray brings its own runtime (a GCS server, raylets, an object store in
shared memory, a dashboard) with its own processes and ports, heavier than a batch of independent
solves needs; its strengths (actors, GPUs, shared objects) are of no use here. One task per plan
costs Dask about 1 ms of overhead (its documentation), against seconds per plan.

Processes: a local cluster (one single-threaded worker process per core unless ``workers`` says) is
started for the run and closed, with its client, in ``finally`` blocks, also when a signal stops the
run (:mod:`optlight.interrupts`; a plan a worker was saving then leaves no staging folder); nothing
outlives the call but the standard library's one ``multiprocessing`` resource tracker, which lives as
long as the caller.
Worker processes are spawned, so a script that calls :func:`optlight.run_batch` or
:func:`optlight.cell.design_cell` needs the usual ``if __name__
== "__main__":`` guard.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

from optlight import interrupts
from optlight.errors import OptlightError
from optlight.threads import WORKERS_PER_CORE, max_local_workers, usable_cores

if TYPE_CHECKING:
    from distributed import Client

#: Seconds to wait for a remote scheduler before giving up.
CONNECT_TIMEOUT_S = 10.0
#: The part of :data:`CONNECT_TIMEOUT_S` spent trying to connect, before the scheduler must answer.
CONNECT_SHARE = 0.8


class SchedulerError(OptlightError):
    """The Dask scheduler given by address cannot be reached."""


def error_text(e: BaseException) -> str:
    text = " ".join(str(e).split())
    return text if isinstance(e, OptlightError) else f"{type(e).__name__}: {text}"


def default_workers() -> int:
    """One worker per core this process may use."""
    return usable_cores()


def check_scheduler(address: str, timeout_s: float = CONNECT_TIMEOUT_S) -> None:
    """Ask the server at ``address`` who it is (Dask's handshake, then its ``identity``) within
    ``timeout_s`` seconds in all; :class:`SchedulerError` unless a Dask scheduler answers.

    Dask's client waits for the handshake's answer without a time limit (a server that accepts and
    says nothing holds it for ever) and reads the first 8 bytes any other server sends as a message
    length (an allocation of exabytes). The question is asked from a thread of its own, in an event
    loop of its own, so that it also works where the caller runs one (a notebook)."""
    import asyncio
    from concurrent.futures import ThreadPoolExecutor

    from distributed.comm import connect

    async def identity() -> object:
        # connection attempts give up (OSError) before the whole question does: a server that takes
        # the connection and then says nothing is told apart from one that refuses it
        comm = await connect(address, timeout=CONNECT_SHARE * timeout_s)
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    def ask() -> object:
        return asyncio.run(asyncio.wait_for(identity(), timeout_s))

    unreachable = (
        f"cannot reach the Dask scheduler at {address!r} within {timeout_s:g} s ({{}}); start one with "
        "`dask scheduler` and its workers with `dask worker ADDRESS`, or leave --scheduler out for a local cluster"
    )
    with ThreadPoolExecutor(1) as pool:
        try:
            reply = pool.submit(ask).result()
        except TimeoutError:
            raise SchedulerError(f"no answer from {address} within {timeout_s:g} s: not a Dask scheduler") from None
        except (OSError, ValueError, TypeError) as e:
            raise SchedulerError(unreachable.format(" ".join(str(e).split()) or type(e).__name__)) from None
        except Exception:  # what it sent is not Dask's protocol (a MemoryError: garbage read as a length)
            raise SchedulerError(f"{address} is not a Dask scheduler (what it sent is not Dask's protocol)") from None
    if not isinstance(reply, dict) or reply.get("type") != "Scheduler":
        kind = reply.get("type") if isinstance(reply, dict) else type(reply).__name__
        raise SchedulerError(f"{address} is not a Dask scheduler (it says it is a {kind})")


@contextmanager
def dask_client(
    scheduler: str | None = None, workers: int | None = None, *, timeout_s: float | None = None
) -> Iterator[Client]:
    """A Dask client: of the remote scheduler at ``scheduler`` (e.g. ``tcp://10.0.0.5:8786``), or of a
    :class:`~distributed.LocalCluster` of ``workers`` single-threaded processes (default: one per
    core) on 127.0.0.1 with no dashboard. The client and the local cluster are closed on exit, whatever
    happens. An unreachable scheduler, a server that is not a Dask scheduler and one that does not
    answer are a :class:`SchedulerError` within ``timeout_s`` seconds (default
    :data:`CONNECT_TIMEOUT_S`; :func:`check_scheduler`)."""
    import dask
    from distributed import Client, LocalCluster

    timeout_s = CONNECT_TIMEOUT_S if timeout_s is None else timeout_s
    # The local cluster's nannies set these in this process's environment for their workers (e.g.
    # OMP_NUM_THREADS=1) and leave them: restored on exit, or every later solve here would run
    # single-threaded (optlight.threads follows OMP_NUM_THREADS).
    spawn_environ = {name: os.environ.get(name) for name in dask.config.get("distributed.nanny.pre-spawn-environ", {})}

    cluster = None
    client = None
    try:
        if scheduler is None:
            n = workers if workers is not None else default_workers()
            if not 1 <= n <= max_local_workers():
                raise OptlightError(
                    f"a local cluster has 1 to {max_local_workers()} workers ({WORKERS_PER_CORE} per "
                    f"usable core of this machine), got {n}"
                )
            cluster = LocalCluster(
                n_workers=n,
                threads_per_worker=1,  # IPOPT and the renderer hold the GIL: parallel means processes
                processes=True,
                host="127.0.0.1",
                dashboard_address=None,
                # the scheduler's plain HTTP endpoint (health, metrics; no dashboard) on a free loopback
                # port, not on 8787, which another cluster or a dashboard may hold
                scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                # Dask's own errors stay off the terminal the workers share with this process: a
                # heartbeat that meets the scheduler already closing logs an ERROR with a traceback
                # after a batch that succeeded (seen once in a benchmark run); a row's failure is
                # the row's record, not Dask's log
                silence_logs=logging.CRITICAL,
            )
            interrupts.reached("cluster-started")
            client = Client(cluster)
        else:
            check_scheduler(scheduler, timeout_s)
            try:
                client = Client(scheduler, timeout=timeout_s)
            except (OSError, TimeoutError, ValueError, TypeError) as e:
                raise SchedulerError(
                    f"cannot reach the Dask scheduler at {scheduler!r} within {timeout_s:g} s "
                    f"({' '.join(str(e).split()) or type(e).__name__}); start one with `dask scheduler` "
                    "and its workers with `dask worker ADDRESS`, or leave --scheduler out for a local cluster"
                ) from None
            try:
                client.wait_for_workers(1, timeout=timeout_s)
            except TimeoutError:
                raise SchedulerError(
                    f"the Dask scheduler at {scheduler!r} has no worker after {timeout_s:g} s; "
                    "start some with `dask worker ADDRESS`"
                ) from None
        interrupts.reached("client-connected")
        yield client
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
        for name, value in spawn_environ.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def run_tasks(
    client: Client | None,
    tasks: Sequence[tuple[Callable[..., Any], tuple[Any, ...]]],
    on_done: Callable[[int, Any], None],
    lost: Mapping[str, Any] | None = None,
) -> None:
    """Run ``fn(*args)`` for each task, on ``client``'s workers or here in order when None, calling
    ``on_done(index, result)`` as each finishes. On a cluster, a task that raised or whose worker
    died gives ``{**lost, "error": ...}`` when ``lost`` is given, else its exception is raised."""
    if client is None:
        for i, (fn, args) in enumerate(tasks):
            on_done(i, fn(*args))
        return
    from distributed import as_completed

    futures = [client.submit(fn, *args, pure=False) for fn, args in tasks]
    interrupts.reached("tasks-submitted")
    index = {f.key: i for i, f in enumerate(futures)}
    for future in as_completed(futures):
        i = index[future.key]
        try:
            result = future.result()
        except Exception as e:  # the task raised, its worker died, or it could not be sent
            if lost is None:
                raise
            result = {**lost, "error": f"task lost: {error_text(e)}"}
        on_done(i, result)
        future.release()


@contextmanager
def engine(
    *, serial: bool, scheduler: str | None, workers: int | None, client: Client | None = None
) -> Iterator[Client | None]:
    """None (tasks run here, in order) when ``serial``; else ``client`` when given (the caller's,
    left open), else the client of :func:`dask_client`, closed on exit."""
    if serial:
        yield None
        return
    if client is not None:
        yield client
        return
    with dask_client(scheduler, workers) as client:
        yield client


@contextmanager
def progress_bar(
    show: bool, total: int, description: str, *, done: int = 0
) -> Iterator[Callable[[str | None], None]]:
    """``advance(failed)`` after each finished task (``failed`` names a failed one, else None): a rich
    progress bar on stdout when ``show``, starting at ``done`` of ``total`` (stderr is for errors)."""
    if not show:
        yield lambda failed: None
        return
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=Console(),
    ) as bar:
        label = f"{description} ({done} done before)" if done else description
        task = bar.add_task(label, total=total, completed=done)

        def advance(failed: str | None) -> None:
            if failed is not None:
                bar.console.print(f"[red]failed:[/red] {failed}")
            bar.advance(task)

        yield advance
