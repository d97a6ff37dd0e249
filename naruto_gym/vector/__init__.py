"""Batched vector envs: many agents stepped together, in this process
(:class:`NarutoReconVectorEnv`) or sharded over worker processes (:class:`ShardedVectorEnv`);
:func:`make_vector_env` picks one from ``workers``."""

from naruto_gym.vector.base import BatchedEnvBase
from naruto_gym.vector.factory import make_vector_env
from naruto_gym.vector.sharded_env import ShardedVectorEnv
from naruto_gym.vector.vector_env import NarutoReconVectorEnv

__all__ = ["BatchedEnvBase", "NarutoReconVectorEnv", "ShardedVectorEnv", "make_vector_env"]
