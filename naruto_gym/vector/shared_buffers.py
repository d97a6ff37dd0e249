"""Observation buffers in shared memory, written by the worker processes of a sharded batched
env and read by the process that steps it.

The memory is ``multiprocessing``'s shared heap: an anonymous file that is unlinked as soon
as it is made, so nothing is left in ``/dev/shm`` whatever way the processes end (a crash,
``SIGKILL``), and the kernel frees it when the last process that maps it exits. It reaches a
worker only by inheritance (as an argument of the ``Process``), which is when the buffers are
made: before the workers start.
"""

from __future__ import annotations

import ctypes
from typing import Any

import numpy as np
from gymnasium import spaces

from naruto_gym.utils.threads import run_parallel

# Below this many bytes per part, splitting a copy between threads does not pay.
_MIN_COPY_BYTES_PER_THREAD = 1 << 20
_KEY_ORDER = ("rgb", "depth", "pose", "panorama")


class SharedObservations:
    """One shared (num_envs, ...) array per observation key.

    Args:
        observation_space: one agent's observation space (a ``Dict`` of ``Box`` es).
        num_envs: the agents.
        context: the ``multiprocessing`` context the workers start in.
    """

    def __init__(self, observation_space: spaces.Dict, num_envs: int, context: Any) -> None:
        # In the order the in-process env hands them out.
        order = [key for key in _KEY_ORDER if key in observation_space.spaces]
        order += [key for key in observation_space.spaces if key not in order]
        self.layout = {
            key: ((num_envs, *observation_space[key].shape), np.dtype(observation_space[key].dtype))
            for key in order
        }
        self.num_envs = int(num_envs)
        self._raw = {
            key: context.RawArray(ctypes.c_uint8, max(1, int(np.prod(shape)) * dtype.itemsize))
            for key, (shape, dtype) in self.layout.items()
        }
        self._arrays: dict[str, np.ndarray] | None = None

    def __getstate__(self) -> dict[str, Any]:
        return {"layout": self.layout, "num_envs": self.num_envs, "_raw": self._raw}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._arrays = None

    @property
    def arrays(self) -> dict[str, np.ndarray]:
        """The shared arrays, key -> (num_envs, ...) (views of the shared memory)."""
        if self._arrays is None:
            self._arrays = {
                key: np.frombuffer(self._raw[key], dtype, int(np.prod(shape))).reshape(shape)
                for key, (shape, dtype) in self.layout.items()
            }
        return self._arrays

    def write(self, observations: dict[str, np.ndarray], start: int, stop: int) -> None:
        """Copy the observations of agents ``start:stop`` (a worker's share) in."""
        for key, array in self.arrays.items():
            array[start:stop] = observations[key]

    def empty(self) -> dict[str, np.ndarray]:
        """New (uninitialised) arrays of the buffers' shapes, for :meth:`copy_rows`."""
        return {key: np.empty(shape, dtype) for key, (shape, dtype) in self.layout.items()}

    def copy_rows(self, target: dict[str, np.ndarray], start: int, stop: int) -> None:
        """Copy agents ``start:stop`` (a worker's share, once it has written them) into
        ``target``, so that the caller copies each share while the others still step."""
        for key, array in self.arrays.items():
            target[key][start:stop] = array[start:stop]

    def copy(self, threads: int = 1) -> dict[str, np.ndarray]:
        """New arrays holding every agent's observation (what the env hands out: the shared
        memory is written again next step), copied in up to ``threads`` threads."""
        fresh = self.empty()
        total = sum(array.nbytes for array in fresh.values())
        parts = max(1, min(threads, self.num_envs, total // _MIN_COPY_BYTES_PER_THREAD))
        bounds = np.linspace(0, self.num_envs, parts + 1).astype(np.int64)

        def copy_part(k: int) -> None:
            self.copy_rows(fresh, int(bounds[k]), int(bounds[k + 1]))

        run_parallel(copy_part, parts)
        return fresh
