"""Infos (and rewards) of a sharded batched env's workers, packed for their pipe.

A step's infos are a nested dict of a few dozen small arrays per worker; pickled as they are,
unpickling them one worker after another costs the stepping process more than the step's
other work. Packed, a worker sends one bytes object with every numeric array's data, the
object arrays (collision reasons, final observations) as they are, and the layout (key path,
dtype, shape of each array) only when it changed since its last message: a step's layout is
the same step after step. The stepping process then fills each merged (num_envs, ...) array
with one copy per worker.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from naruto_gym.vector.infos import merge_shard_infos

Path = tuple[str, ...]
Layout = tuple[tuple[Path, str, tuple[int, ...]], ...]
Packed = tuple[Layout | None, bytes, list[np.ndarray]]


def _leaves(tree: dict[str, Any], prefix: Path = ()) -> Iterator[tuple[Path, np.ndarray]]:
    for key, value in tree.items():
        if isinstance(value, dict):
            yield from _leaves(value, (*prefix, key))
        else:
            yield (*prefix, key), np.asarray(value)


def _insert(tree: dict[str, Any], path: Path, value: Any) -> None:
    for key in path[:-1]:
        tree = tree.setdefault(key, {})
    tree[path[-1]] = value


class InfoPacker:
    """A worker's side: packs each message, sending the layout only when it changed."""

    def __init__(self) -> None:
        self._last: Layout | None = None

    def pack(self, tree: dict[str, Any]) -> Packed:
        """``tree`` (nested dicts of arrays) as (layout or None, data, object arrays)."""
        leaves = list(_leaves(tree))
        layout = tuple((path, array.dtype.str, array.shape) for path, array in leaves)
        data = b"".join(array.tobytes() for _, array in leaves if array.dtype != object)
        objects = [array for _, array in leaves if array.dtype == object]
        sent = None if layout == self._last else layout
        self._last = layout
        return sent, data, objects


class InfoUnpacker:
    """The stepping process's side: the workers' last layouts, and the merge."""

    def __init__(self, workers: int) -> None:
        self._layouts: list[Layout | None] = [None] * workers
        self._shapes: list[tuple | None] = [None] * workers

    def _layout(self, worker: int, packed: Packed) -> Layout:
        if packed[0] is not None:
            self._layouts[worker] = packed[0]
            # The layout but the agent count: the same for every worker in a regular step.
            self._shapes[worker] = tuple(
                (path, dtype, shape[1:]) for path, dtype, shape in packed[0]
            )
        return self._layouts[worker]

    def unpack(self, worker: int, packed: Packed) -> dict[str, Any]:
        """One worker's message as its nested dict."""
        layout = self._layout(worker, packed)
        tree: dict[str, Any] = {}
        offset, objects = 0, iter(packed[2])
        for path, dtype, shape in layout:
            if dtype == "|O":
                _insert(tree, path, next(objects))
                continue
            count = math.prod(shape)
            array = np.frombuffer(packed[1], dtype, count, offset).reshape(shape)
            offset += array.nbytes
            _insert(tree, path, array)
        return tree

    def merge(
        self, packed: Sequence[Packed], bounds: Sequence[tuple[int, int]], n: int
    ) -> dict[str, Any]:
        """Every worker's message merged over the ``n`` agents (worker ``k`` holds agents
        ``bounds[k]``), as :func:`merge_shard_infos` merges them."""
        layouts = [self._layout(k, message) for k, message in enumerate(packed)]
        if any(shape != self._shapes[0] for shape in self._shapes[1:]):
            return merge_shard_infos(
                [
                    (self.unpack(k, (None, *message[1:])), *bounds[k])
                    for k, message in enumerate(packed)
                ],
                n,
            )
        tree: dict[str, Any] = {}
        offsets = [0] * len(packed)
        objects = [iter(message[2]) for message in packed]
        for j, (path, dtype, shape) in enumerate(layouts[0]):
            if dtype == "|O":
                merged = np.full((n, *shape[1:]), None, object)
                for k, (start, stop) in enumerate(bounds):
                    merged[start:stop] = next(objects[k])
            else:
                merged = np.empty((n, *shape[1:]), dtype)
                for k, (start, stop) in enumerate(bounds):
                    share = layouts[k][j][2]
                    part = np.frombuffer(packed[k][1], dtype, math.prod(share), offsets[k])
                    merged[start:stop] = part.reshape(share)
                    offsets[k] += part.nbytes
            _insert(tree, path, merged)
        return tree
