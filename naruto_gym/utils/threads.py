"""The thread pool every compiled loop shares: :func:`run_parallel` and the default count.

The rasterizer, the batched env and the CPU hash grid split their work into parts that run
compiled code with the GIL released; they hand the parts to one pool per process. How many
threads they use by default follows the machine (:func:`default_thread_count`): every CPU
the process may run on, one per process in the workers of a multi-process vector env or a
Ray actor, and ``NARUTO_GYM_THREADS`` overrides both.
"""

from __future__ import annotations

import itertools
import multiprocessing
import os
import queue
import threading
from collections.abc import Callable

import numpy as np


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


#: The environment variable that sets the thread count of every compiled loop of a process
#: (the rasterizer, the batched env's loops, Open3D's ray casts and distance queries, the CPU
#: hash grid) where no ``threads=`` keyword is passed.
THREADS_ENV_VAR = "NARUTO_GYM_THREADS"


def available_cpus() -> int:
    """The CPUs this process may run on (its affinity mask, as ``taskset`` or a container's
    CPU set restricts it), or every CPU where the platform has no affinity mask."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


def _positive_int(text: str, name: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise ValueError(f"{name}={text!r} must be a positive integer (a thread count); unset it "
                         "for the default")
    return value


def is_worker_process() -> bool:
    """Whether this process is one of several that share the machine: a ``multiprocessing``
    child (the workers of Gymnasium's ``AsyncVectorEnv``) or a Ray worker (an actor or
    task). Each such process defaults to one thread, or to ``OMP_NUM_THREADS`` where it is
    set, as Ray sets it to the CPUs an actor asked for."""
    return multiprocessing.parent_process() is not None or "RAY_RAYLET_PID" in os.environ


def default_thread_count() -> int:
    """Threads a compiled loop uses where its caller passes no ``threads``.

    In this order: the ``NARUTO_GYM_THREADS`` environment variable; in a worker process
    (:func:`is_worker_process`: one of many env copies, so that N copies do not start N
    thread pools of every core each) ``OMP_NUM_THREADS`` or else 1; otherwise every CPU the
    process may run on (:func:`available_cpus`).
    """
    text = os.environ.get(THREADS_ENV_VAR, "").strip()
    if text:
        return _positive_int(text, THREADS_ENV_VAR)
    if is_worker_process():
        text = os.environ.get("OMP_NUM_THREADS", "").strip()
        return min(_positive_int(text, "OMP_NUM_THREADS"), available_cpus()) if text else 1
    return available_cpus()


def resolve_threads(threads: int | None) -> int:
    """``threads`` checked (a positive integer), or :func:`default_thread_count` for None."""
    if threads is None:
        return default_thread_count()
    if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or threads < 1:
        raise ValueError(f"threads must be a positive integer (or None for the default), got "
                         f"{threads!r}")
    return int(threads)
