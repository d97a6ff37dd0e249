"""Refusing Open3D and Embree work in a child forked from a process that already did some.

Open3D and Embree run their queries on a thread pool. A ``fork`` copies only the calling
thread: the child inherits the pool's bookkeeping (and any lock a pool thread held at that
moment) without its threads, and its first query can wait forever. A child forked *before*
its parent cast any ray is safe, since nothing native exists yet; one forked after is not.
The first native call of a process records the process; a later call from a forked child of it
raises a :class:`RuntimeError` that says how to start workers instead (the way PyTorch refuses
CUDA in a forked child), rather than hanging.
"""

from __future__ import annotations

import os

_native_pid: int | None = None
"""The process that first ran Open3D or Embree code (None: none yet)."""

FORKED_AFTER_NATIVE_USE = (
    "this process was forked from process {parent}, which had already cast rays with "
    "Open3D/Embree; their thread pools do not survive fork and the ray casts here could hang. "
    "Start worker processes with 'spawn' or 'forkserver': gym.make_vec(..., "
    "vectorization_mode='async', vector_kwargs={{'context': 'spawn'}}), "
    "multiprocessing.get_context('spawn'), or the batched env (gym.make_vec(..., "
    "vectorization_mode='vector_entry_point'), which starts its workers with spawn)"
)


def enter_native_code() -> None:
    """Call before any Open3D or Embree work of the env.

    Raises:
        RuntimeError: this process is a forked child of one that already did such work.
    """
    global _native_pid
    pid = os.getpid()
    if _native_pid == pid:
        return
    if _native_pid is not None:
        raise RuntimeError(FORKED_AFTER_NATIVE_USE.format(parent=_native_pid))
    _native_pid = pid
