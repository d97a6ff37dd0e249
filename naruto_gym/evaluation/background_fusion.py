"""Fusion of an episode's frames on a background thread, in the order they came.

The reference reconstruction is scoring only: nothing an agent does waits for it until the
scores are asked for. Open3D releases the GIL while it fuses, so one background thread takes
the fusion off the path of the episode's steps (a policy's mapping and planning, the next
frame's rendering) on any machine with a second CPU. The frames are fused in submission
order, so the map is the same as with fusion in the caller's thread.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

#: Frames that may wait for fusion before :meth:`BackgroundFusion.submit` waits for the
#: oldest: bounds the memory the copies hold (a 680 x 1200 frame is about 13 MB).
DEFAULT_MAX_PENDING = 8


class BackgroundFusion:
    """Runs ``fuse(item)`` for each submitted item on one background thread, in order.

    A failure is raised in the caller's thread at the next :meth:`submit` or :meth:`wait`;
    the items submitted after the failed one are dropped with it, and the queue stays usable.

    Args:
        fuse: what to do with each item (called on the background thread).
        max_pending: items that may wait; :meth:`submit` waits for the oldest beyond it.
    """

    def __init__(self, fuse: Callable[[Any], None], max_pending: int = DEFAULT_MAX_PENDING) -> None:
        if max_pending < 1:
            raise ValueError(f"max_pending must be at least 1, got {max_pending}")
        self._fuse = fuse
        self.max_pending = int(max_pending)
        self._executor: ThreadPoolExecutor | None = None
        self._pending: deque[Future] = deque()
        self.busy_seconds = 0.0
        """Seconds the background thread has spent fusing."""

    def _timed(self, item: Any) -> None:
        start = time.perf_counter()
        try:
            self._fuse(item)
        finally:
            self.busy_seconds += time.perf_counter() - start

    def submit(self, item: Any) -> None:
        """Queue one item (first raising an earlier item's failure, if any)."""
        self._collect(block_beyond=self.max_pending - 1)
        if self._executor is None:
            self._executor = ThreadPoolExecutor(1, thread_name_prefix="naruto-reference-fusion")
        self._pending.append(self._executor.submit(self._timed, item))

    def wait(self) -> None:
        """Return once every submitted item is fused; raise the first failure."""
        self._collect(block_beyond=0)

    @property
    def pending(self) -> int:
        """Items submitted and not yet known to be fused."""
        return len(self._pending)

    def _collect(self, block_beyond: int) -> None:
        """Take finished items off the queue, waiting for the oldest while more than
        ``block_beyond`` are pending; on a failure, drop the rest and raise it."""
        while self._pending and (self._pending[0].done() or len(self._pending) > block_beyond):
            future = self._pending.popleft()
            error = future.exception()  # waits for it
            if error is not None:
                for later in self._pending:
                    later.cancel()
                for later in self._pending:
                    if not later.cancelled():
                        later.exception()  # already running: let it end first
                self._pending.clear()
                raise error

    def close(self) -> None:
        """Wait for the queue, then stop the thread (a later :meth:`submit` starts another)."""
        try:
            self.wait()
        finally:
            if self._executor is not None:
                self._executor.shutdown(wait=True)
                self._executor = None
