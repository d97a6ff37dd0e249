"""The thread pool every compiled loop shares: :func:`run_parallel` and the default count.

The rasterizer, the batched env and the CPU hash grid split their work into parts that run
compiled code with the GIL released; they hand the parts to one pool per process.
"""

from __future__ import annotations

import itertools
import os
import queue
import threading
from collections.abc import Callable


class _WorkerPool:
    """Daemon threads that run the callables put in their queue, nothing more: a split step
    hands work over several times per step, and what a thread does after its last signal
    (``concurrent.futures``' bookkeeping took 20-40 microseconds) holds up the thread it woke.
    The callables handle their own errors (:func:`run_parallel`'s ``work``)."""

    def __init__(self, workers: int) -> None:
        self._tasks: queue.SimpleQueue = queue.SimpleQueue()
        for index in range(workers):
            threading.Thread(target=self._serve, name=f"naruto-raster-{index}", daemon=True).start()

    def _serve(self) -> None:
        while True:
            self._tasks.get()()

    def submit(self, task: Callable[[], None]) -> None:
        self._tasks.put(task)


_POOL_LOCK = threading.Lock()
_POOLS: dict[tuple[int, int], _WorkerPool] = {}


def _pool(workers: int) -> _WorkerPool:
    """A thread pool of the current process (a forked child must not reuse its parent's)."""
    key = (os.getpid(), workers)
    with _POOL_LOCK:
        pool = _POOLS.get(key)
        if pool is None:
            pool = _POOLS[key] = _WorkerPool(workers)
        return pool


def run_parallel(function, count: int) -> list:
    """``[function(0), ..., function(count - 1)]``, shared between this thread and the pool.

    Indices are claimed one at a time by whichever thread is free, and this thread only waits
    for indices another thread has started: when the pool's threads are slow to get a core
    (a busy machine), this thread does the work itself instead of waiting for them.
    """
    if count == 1:
        return [function(0)]
    claims = itertools.count()
    results: list = [None] * count
    errors: list[BaseException] = []
    done = [threading.Event() for _ in range(count)]

    def work() -> None:
        while (index := next(claims)) < count:
            try:
                results[index] = function(index)
            except BaseException as error:  # re-raised in the calling thread
                errors.append(error)
            finally:
                done[index].set()

    pool = _pool(count - 1)
    for _ in range(count - 1):
        pool.submit(work)
    work()
    for event in done:
        event.wait()
    if errors:
        raise errors[0]
    return results


def default_thread_count() -> int:
    """Threads a rasterizer uses by default: the CPUs this process may run on, at most 2
    (the development machine's count; env workers of a vector env each run their own
    renderer, so more would oversubscribe them). Pass ``threads`` to use more."""
    try:
        available = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        available = os.cpu_count() or 1
    return max(1, min(available, 2))
