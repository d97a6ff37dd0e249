"""``make_vector_env``: the batched env for a number of worker processes.

The vector entry point of the registered ids (``gymnasium.make_vec(id, num_envs,
vectorization_mode="vector_entry_point", workers=...)``): one process gives a
:class:`~naruto_gym.vector.vector_env.NarutoReconVectorEnv`, more give a
:class:`~naruto_gym.vector.sharded_env.ShardedVectorEnv`, whose workers each step a share of
the agents as a ``NarutoReconVectorEnv``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from naruto_gym.utils.threads import resolve_threads
from naruto_gym.vector.base import BatchedEnvBase
from naruto_gym.vector.sharded import resolve_workers
from naruto_gym.vector.sharded_env import ShardedVectorEnv
from naruto_gym.vector.vector_env import NarutoReconVectorEnv


def make_vector_env(num_envs: int = 1, workers: int | None = None, **kwargs: Any) -> BatchedEnvBase:
    """A batched env of ``num_envs`` agents stepped in ``workers`` processes.

    Args:
        num_envs: the agents.
        workers: the processes that step them: 1 for this process (a
            ``NarutoReconVectorEnv``), more for worker processes (a ``ShardedVectorEnv``);
            None chooses from the CPUs (the ``threads`` keyword, else the
            ``NARUTO_GYM_THREADS`` environment variable or every CPU) and ``num_envs``, see
            :func:`~naruto_gym.vector.sharded.default_workers`: one process on fewer than 4
            CPUs.
        **kwargs: the keywords of ``NarutoReconVectorEnv``.

    Raises:
        ValueError: a bad ``workers`` (not a positive integer, or more than ``num_envs``) or
            any keyword the env refuses.
    """
    if isinstance(num_envs, (int, np.integer)) and not isinstance(num_envs, bool) and num_envs > 0:
        count = resolve_workers(workers, num_envs, resolve_threads(kwargs.get("threads")))
    else:
        count = 1  # the env refuses num_envs by name
    if count == 1:
        return NarutoReconVectorEnv(num_envs=num_envs, **kwargs)
    return ShardedVectorEnv(num_envs=num_envs, workers=count, **kwargs)
