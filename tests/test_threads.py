"""The work split of :mod:`optlight.threads`: order, the threads it runs on, nesting and fork; the
background thread."""

from __future__ import annotations

import multiprocessing
import threading

import pytest

from optlight.threads import in_background, map_slices


def _slices_and_threads(size: int) -> list[tuple[slice, int]]:
    return map_slices(lambda s: (s, threading.get_ident()), size, 1)


def test_slices_come_back_in_order_and_the_caller_works_the_first(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    for _ in range(3):  # the kept pool serves later calls too
        parts = _slices_and_threads(10)
        assert [s for s, _ in parts] == [slice(0, 3), slice(3, 6), slice(6, 10)]
        assert parts[0][1] == threading.get_ident()
        assert all(ident != threading.get_ident() for _, ident in parts[1:])
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    assert _slices_and_threads(10) == [(slice(0, 10), threading.get_ident())]


def test_a_split_inside_a_pool_thread_does_not_wait_on_its_own_pool(monkeypatch: pytest.MonkeyPatch) -> None:
    # Two threads: one pool thread. Its slice splits again; were that split queued on the same busy
    # pool thread, the call would never return.
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    results: list[list[list[slice]]] = []

    def nested(s: slice) -> list[slice]:
        return [inner for inner, _ in _slices_and_threads(s.stop - s.start)]

    caller = threading.Thread(target=lambda: results.append(map_slices(nested, 8, 2)), daemon=True)
    caller.start()
    caller.join(timeout=20.0)
    assert not caller.is_alive(), "a nested split waited on its own pool"
    assert results == [[[slice(0, 2), slice(2, 4)], [slice(0, 4)]]]  # split in the caller, not in the pool


def _split_in_child(queue: multiprocessing.Queue) -> None:  # type: ignore[type-arg]
    queue.put([s for s, _ in _slices_and_threads(4)])


def test_a_forked_child_splits_work_on_threads_of_its_own(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    _slices_and_threads(4)  # the parent's pool thread exists; the child has none of it
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    child = context.Process(target=_split_in_child, args=(queue,))
    child.start()
    try:
        assert queue.get(timeout=20.0) == [slice(0, 2), slice(2, 4)]
    finally:
        child.join(timeout=20.0)
        if child.is_alive():
            child.kill()
    assert child.exitcode == 0


def test_background_work_runs_beside_the_caller_and_splits_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    release = threading.Event()

    def work() -> tuple[int, list[slice]]:
        assert release.wait(timeout=20.0)  # the caller goes on meanwhile, or this never ends
        return threading.get_ident(), [s for s, _ in _slices_and_threads(4)]

    future = in_background(work)
    assert not future.done()
    release.set()
    ident, slices = future.result(timeout=20.0)
    assert ident != threading.get_ident()
    assert slices == [slice(0, 4)]  # alone in its thread: the caller's splits keep the pool
    assert [s for s, _ in _slices_and_threads(4)] == [slice(0, 2), slice(2, 4)]  # and the caller's do split


def test_background_work_with_one_thread_runs_now_and_keeps_its_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    future = in_background(threading.get_ident)
    assert future.done() and future.result() == threading.get_ident()

    def fail() -> None:
        raise ValueError("in the background")

    with pytest.raises(ValueError, match="in the background"):
        in_background(fail).result()
