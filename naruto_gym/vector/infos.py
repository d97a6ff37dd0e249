"""Infos of the batched env, laid out as ``gymnasium.vector.SyncVectorEnv`` gathers them.

Each key of the single env's info becomes an array over the agents with a ``_key`` mask of
the agents that have it (nested dicts alike), so code written for ``SyncVectorEnv`` reads the
batched env's infos unchanged.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def agents_mask(n: int, agents: np.ndarray) -> np.ndarray:
    """(n,) bool, True for ``agents``."""
    mask = np.zeros(n, bool)
    mask[np.asarray(agents, np.int64)] = True
    return mask


def batch_infos(
    n: int,
    agents: np.ndarray,
    columns: dict[str, tuple[np.ndarray, Any]],
    intrinsics: dict[str, np.ndarray],
    panorama_no_hit_share: np.ndarray | None = None,
) -> dict[str, Any]:
    """Infos of ``agents`` (arrays plus ``_key`` masks), in the single env's key order.

    Args:
        n: the agents in the batch.
        agents: the agents whose infos these are.
        columns: ``coverage``, ``coverage_gain``, ``collided``, ``collision_reason``,
            ``path_length_m`` and ``step``, each as ``(values over all n agents, dtype)``.
        intrinsics: the camera's intrinsics, key -> (n,) values (the nested ``intrinsics``).
        panorama_no_hit_share: (n,) values, None when the panorama is off.
    """
    every = len(agents) == n  # a step's infos: every agent's, no masking to do
    mask = np.ones(n, bool) if every else agents_mask(n, agents)

    def column(values: np.ndarray, dtype: Any) -> np.ndarray:
        if every:
            return np.array(values, dtype)
        array = np.full(n, None, object) if dtype is object else np.zeros(n, dtype)
        array[mask] = np.asarray(values)[mask]
        return array

    infos: dict[str, Any] = {}
    for key in ("coverage", "coverage_gain", "collided", "collision_reason", "path_length_m"):
        infos[key] = column(*columns[key])
    infos["intrinsics"] = {}
    infos["step"] = column(*columns["step"])
    for key, value in intrinsics.items():
        infos["intrinsics"][key] = column(value, value.dtype)
        infos["intrinsics"][f"_{key}"] = mask.copy()
    if panorama_no_hit_share is not None:
        infos["panorama_no_hit_share"] = column(panorama_no_hit_share, float)
    for key in list(infos):
        if not key.startswith("_"):
            infos[f"_{key}"] = mask.copy()
    return infos


def agent_info(infos: dict[str, Any], i: int) -> dict[str, Any]:
    """One agent's info dict back out of vector infos."""
    single: dict[str, Any] = {}
    for key, value in infos.items():
        if key.startswith("_") or not infos.get(f"_{key}", np.zeros(i + 1, bool))[i]:
            continue
        if isinstance(value, dict):
            single[key] = agent_info(value, i)
        else:
            item = value[i]
            single[key] = item.item() if isinstance(item, np.generic) else item
    return single


def overwrite_agents(
    infos: dict[str, Any], update: dict[str, Any], agents: np.ndarray
) -> dict[str, Any]:
    """``infos`` with the entries of ``agents`` taken from ``update`` (same layout)."""
    for key, value in update.items():
        if key.startswith("_"):
            continue
        if isinstance(value, dict):
            infos[key] = overwrite_agents(infos.get(key, {}), value, agents)
        else:
            infos[key][agents] = value[agents]
    return infos


def merge_shard_infos(parts: list[tuple[dict[str, Any], int, int]], n: int) -> dict[str, Any]:
    """The infos of ``n`` agents from those of contiguous shares of them.

    Args:
        parts: each share's infos (laid out over its own agents) with the share's first and
            past-the-last agent; shares not listed contribute no keys (all masks False).
        n: the agents in the batch.

    Returns:
        The infos over all ``n`` agents, as one env would give them: a key any share has
        becomes an (n, ...) array (zeros, or None for objects, where a share lacks it) with
        its ``_key`` mask, nested dicts alike.
    """
    merged: dict[str, Any] = {}
    for infos, _, _ in parts:
        for key, value in infos.items():
            if key in merged:
                continue
            if isinstance(value, dict):
                merged[key] = merge_shard_infos(
                    [(share.get(key, {}), start, stop) for share, start, stop in parts], n
                )
                continue
            value = np.asarray(value)
            shape = (n, *value.shape[1:])
            array = (
                np.full(shape, None, object)
                if value.dtype == object
                else np.zeros(shape, value.dtype)
            )
            for share, start, stop in parts:
                if key in share:
                    array[start:stop] = share[key]
            merged[key] = array
    return merged
