"""Batched vector env: many agents stepped together in one process (see ``vector_env``)."""

from naruto_gym.vector.vector_env import NarutoReconVectorEnv, make_vector_env

__all__ = ["NarutoReconVectorEnv", "make_vector_env"]
