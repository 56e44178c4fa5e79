"""Work split over the cores this process may use, for the few loops whose library code releases
the GIL: Embree's ray queries and NumPy's element-wise kernels on large arrays.

The thread count follows ``OMP_NUM_THREADS`` when it is set, the convention of numerical libraries:
Dask's workers set it to 1 (one single-threaded process per core, :mod:`optlight.batch`), so a
batch is never oversubscribed. Otherwise it is the number of cores the process may run on.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import TypeVar

T = TypeVar("T")


def usable_cores() -> int:
    """The number of cores this process may run on (its CPU affinity where the OS has one)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


#: Most worker processes of a local cluster per usable core (``optlight batch`` and ``cell``): each
#: worker is a single-threaded solver process, so more than a few per core only share the cores,
#: multiply the memory and make the cluster slow to start.
WORKERS_PER_CORE = 4


def max_local_workers() -> int:
    """The most worker processes a local cluster may start here: :data:`WORKERS_PER_CORE` per usable core."""
    return WORKERS_PER_CORE * usable_cores()


def thread_count() -> int:
    """Threads to split work over: ``OMP_NUM_THREADS`` when it is a positive integer, else
    :func:`usable_cores`."""
    value = os.environ.get("OMP_NUM_THREADS", "")
    if value.isdigit() and int(value) > 0:
        return int(value)
    return usable_cores()


_in_pool = threading.local()
_pools: dict[int | str, ThreadPoolExecutor] = {}
_pools_lock = threading.Lock()


def _mark_pool_thread() -> None:
    _in_pool.flag = True


def _pool(workers: int | str) -> ThreadPoolExecutor:
    """The process's pool of ``workers`` threads (or, for "background", its one background thread),
    started on first use and kept. Starting the threads on every call cost ~1 ms per call, as much
    as the rays of a 64-px search render."""
    with _pools_lock:
        if workers not in _pools:
            count = 1 if workers == "background" else int(workers)
            _pools[workers] = ThreadPoolExecutor(
                count, thread_name_prefix=f"optlight_{workers}", initializer=_mark_pool_thread
            )
        return _pools[workers]


def _forget_pools() -> None:
    """A forked child has none of its parent's threads: its pools start again on first use."""
    global _pools_lock
    _pools.clear()
    _pools_lock = threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pools)


def map_slices(work: Callable[[slice], T], size: int, min_size: int) -> list[T]:
    """``work`` on consecutive slices of ``range(size)``, each at least ``min_size`` long (one slice,
    in the calling thread, when ``size < 2 min_size`` or :func:`thread_count` is 1), in order.

    The calling thread works the first slice and a pool of threads kept for the process (:func:`_pool`)
    the others. ``work`` must release the GIL for the split to pay, and must not depend on another
    slice's result. Results come back in slice order: concatenated, they are the same array whatever
    the thread count. Called from a pool thread, it works in that thread alone: a pool thread
    waiting on its own pool could wait for ever."""
    parts = max(1, min(thread_count(), size // max(1, min_size)))
    if parts == 1 or getattr(_in_pool, "flag", False):
        return [work(slice(0, size))]
    bounds = [size * k // parts for k in range(parts + 1)]
    slices = [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
    rest = [_pool(parts - 1).submit(work, s) for s in slices[1:]]
    first = work(slices[0])
    return [first, *(f.result() for f in rest)]


def in_background(work: Callable[[], T]) -> Future[T]:
    """``work()`` started in the process's background thread, while the caller goes on with other
    work: the next step of a loop computed during this one. The background thread works alone
    (:func:`map_slices` does not split there), so the caller's own splits keep the pool. With
    :func:`thread_count` 1, or called from a pool thread, ``work`` runs now, in the calling thread,
    and the future comes back done. ``work`` must release the GIL for most of its time to pay."""
    if thread_count() == 1 or getattr(_in_pool, "flag", False):
        done: Future[T] = Future()
        try:
            done.set_result(work())
        except BaseException as e:  # as a pool thread would: the caller meets it at .result()
            done.set_exception(e)
        return done
    return _pool("background").submit(work)
