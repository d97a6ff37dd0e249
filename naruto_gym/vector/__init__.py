"""Batched vector envs: many agents stepped together, in this process
(:class:`NarutoReconVectorEnv`) or sharded over worker processes (:class:`ShardedVectorEnv`);
:func:`make_vector_env` picks one from ``workers``. :class:`SharedSceneStreams` puts agents in
groups on shared generated scenes, for training on many scenes; :class:`ShardedWrappedEnv`
runs a wrapper chain over the batched env in worker processes, each on a share of the
agents."""

from naruto_gym.vector.base import BatchedEnvBase
from naruto_gym.vector.factory import make_vector_env
from naruto_gym.vector.sharded_env import ShardedVectorEnv
from naruto_gym.vector.sharded_wrapped import ShardedWrappedEnv
from naruto_gym.vector.shared_scenes import SharedSceneStreams
from naruto_gym.vector.vector_env import NarutoReconVectorEnv

__all__ = [
    "BatchedEnvBase",
    "NarutoReconVectorEnv",
    "ShardedVectorEnv",
    "ShardedWrappedEnv",
    "SharedSceneStreams",
    "make_vector_env",
]
