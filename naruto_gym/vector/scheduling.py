"""How the batched env spreads a step's work over threads.

Two ways, both exact (agents never share state, so any split gives the one-piece result):

* :func:`in_threads` runs one compiled loop over contiguous slices of agents in parallel (the
  loops release the GIL);
* :class:`StepShares` runs a whole step (move, then draw and count) in contiguous shares of
  agents, one per thread. Moving is mostly Python and distance queries that hold the GIL,
  drawing frames releases it: the shares move one after another, each as soon as the one
  before it starts drawing, so one share's frames are drawn while the next one moves. The
  first shares, which wait less, get more agents; the sizes follow the shares' finishing
  times step by step so that all finish together.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

from naruto_gym.utils.threads import run_parallel

Moved = TypeVar("Moved")
Observed = TypeVar("Observed")


def in_threads(work: Callable[[slice], Any], count: int, threads: int) -> None:
    """``work(part)`` over ``count`` agents split in up to ``threads`` contiguous slices of at
    least 8 agents, run in parallel (the compiled kernels release the GIL)."""
    parts = max(1, min(threads, count // 8))
    if parts == 1:  # one agent's scene at a time with scene streams: no per-call set-up
        work(slice(0, count))
        return
    bounds = np.linspace(0, count, parts + 1).astype(int)
    run_parallel(lambda k: work(slice(int(bounds[k]), int(bounds[k + 1]))), parts)


def share_bounds(shares: np.ndarray, count: int) -> np.ndarray:
    """Contiguous parts of ``count`` agents in proportion to ``shares`` (summing to 1): the
    (P + 1,) bounds, every part at least one agent."""
    parts = len(shares)
    bounds = [0] * (parts + 1)
    cumulative = 0.0
    for part in range(1, parts):  # at least one agent per part, from both ends
        cumulative += float(shares[part - 1])
        bounds[part] = min(
            max(round(cumulative * count), bounds[part - 1] + 1), count - (parts - part)
        )
    bounds[parts] = count
    return np.array(bounds, np.int64)


def balanced_shares(shares: np.ndarray, finished: np.ndarray, minimum: float) -> np.ndarray:
    """Shares for the next step: each part's grows or shrinks with how much earlier or later
    than the average it finished (damped by half, so timing noise does not make them swing),
    none below ``minimum``."""
    # Plain Python over the few parts: this runs at every split step, after the frames have
    # pushed NumPy's dispatch out of the caches.
    times = [float(value) for value in finished]
    if min(times) <= 0.0:
        return shares
    mean = sum(times) / len(times)
    updated = [
        float(share) * math.sqrt(mean / time) for share, time in zip(shares, times, strict=True)
    ]
    total = sum(updated)
    updated = [share / total for share in updated]
    low = [False] * len(updated)
    # Pin the smallest at the minimum.
    while any(share < minimum - 1e-12 for share in updated) and not all(low):
        low = [pinned or share < minimum for pinned, share in zip(low, updated, strict=True)]
        free = sum(share for pinned, share in zip(low, updated, strict=True) if not pinned)
        scale = (1.0 - minimum * sum(low)) / free if free > 0.0 else 0.0
        updated = [
            minimum if pinned else share * scale for pinned, share in zip(low, updated, strict=True)
        ]
    return np.array(updated)


class StepShares:
    """Runs a step in contiguous shares of the agents, one per thread, sized so that the
    shares finish together (see the module's description)."""

    def __init__(self) -> None:
        self._shares: np.ndarray | None = None

    def run(
        self,
        count: int,
        parts: int,
        min_agents_per_part: int,
        move: Callable[[int, int], Moved],
        observe: Callable[[int, int, int, Moved, Callable[[], None]], Observed],
    ) -> list[tuple[Moved, Observed]]:
        """Move and observe ``count`` agents in ``parts`` shares.

        Args:
            count: the agents, ``0 .. count - 1``.
            parts: the shares (threads).
            min_agents_per_part: the smallest share, in agents.
            move: ``move(start, stop)`` moves the agents ``start .. stop - 1``.
            observe: ``observe(part, start, stop, moved, frames_start)`` draws and counts
                them; it calls ``frames_start()`` as it starts drawing frames, which lets
                the next share move.

        Returns:
            Each share's ``(moved, observed)``, in order.
        """
        if self._shares is None or len(self._shares) != parts:
            self._shares = np.full(parts, 1.0 / parts)
        bounds = share_bounds(self._shares, count)
        moved = [threading.Event() for _ in range(parts)]
        started = time.perf_counter()
        finished = np.zeros(parts)

        def run(part: int) -> tuple[Moved, Observed]:
            start, stop = int(bounds[part]), int(bounds[part + 1])
            if part:
                moved[part - 1].wait()
            try:
                moves = move(start, stop)
                # The next part moves once this one's frames start (they release the GIL):
                # its Python until then would only wait for this part's.
                observed = observe(part, start, stop, moves, moved[part].set)
            finally:
                moved[part].set()
            finished[part] = time.perf_counter() - started
            return moves, observed

        results = run_parallel(run, parts)
        self._shares = balanced_shares(self._shares, finished, min_agents_per_part / count)
        return results
