"""An env creator for RLlib whose env runners each step one batched env.

RLlib's new API stack gives every env runner (``SingleAgentEnvRunner``) a Gymnasium vector
env. It registers the creator passed to ``ray.tune.registry.register_env`` twice: as the
entry point (called with the ``env_config``) and as the vector entry point (called with the
``env_config`` plus ``num_envs``). With ``gym_env_vectorize_mode="vector_entry_point"`` it
calls the latter, and :func:`make_rllib_env` answers with the batched env
(``gymnasium.make_vec(..., vectorization_mode="vector_entry_point")``): one process steps all
of a runner's agents together. Called without ``num_envs`` (RLlib's ``"sync"`` or ``"async"``
modes) it gives one env with the same observations.

The creator lives in the package, not in a script, so that Ray can pickle it by reference:
every node of a cluster imports it from its installed naruto-gym. Ray is not imported here.

    from ray.tune.registry import register_env
    from naruto_gym.rl.rllib_env import make_rllib_env

    register_env("NarutoRecon-rllib", make_rllib_env)
    config = PPOConfig().environment("NarutoRecon-rllib", env_config={"size": 16}).env_runners(
        num_envs_per_env_runner=16, gym_env_vectorize_mode="vector_entry_point")
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from naruto_gym.wrappers.learning import for_learning

__all__ = ["LEARNING_KEYS", "make_rllib_env"]

#: ``env_config`` keys that shape the learning observations; every other key (but
#: ``num_envs``) is a keyword of the env id (``NarutoReconEnv``'s or ``make_vec``'s).
LEARNING_KEYS = ("env_id", "size", "depth", "top_down_map", "flatten")


def make_rllib_env(config: Mapping[str, Any]) -> gym.Env | gym.vector.VectorEnv:
    """One env, or the batched env of ``config["num_envs"]`` agents, for an RLlib env runner.

    Observations are those of :func:`naruto_gym.wrappers.for_learning`; with ``flatten`` they
    are also scaled to floats (colours in [0, 1]) and flattened to one vector, which RLlib's
    default model (an MLP) takes; without it they stay a ``Dict`` for a custom RLModule.

    Args:
        config: RLlib's ``env_config`` (an ``EnvContext`` or a plain mapping). Keys:
            ``env_id`` (default ``"NarutoRecon-v0"``), ``size`` (frame side, default 64),
            ``depth`` (``"float"``, the default, or ``"uint8"``), ``top_down_map`` (default
            False), ``flatten`` (default True), ``num_envs`` (set by RLlib's vector entry
            point); any other key is passed to ``gymnasium.make`` / ``make_vec`` (for example
            ``scene``, ``action_mode``, ``camera``, ``max_episode_steps``);
            ``pinhole_backend`` defaults to ``"auto"`` (the rasterizer where cheaper), the
            setting for throughput.

    Returns:
        A ``gym.Env`` without ``num_envs``, else a ``gym.vector.VectorEnv`` of the batched env.
    """
    if not isinstance(config, Mapping):
        raise TypeError(f"config must be a mapping (RLlib's env_config), got {type(config)}")
    options = dict(config)
    env_id = options.pop("env_id", "NarutoRecon-v0")
    learning = {
        "size": options.pop("size", 64),
        "depth": options.pop("depth", "float"),
        "top_down_map": options.pop("top_down_map", False),
    }
    flatten = bool(options.pop("flatten", True))
    num_envs = options.pop("num_envs", None)
    options.setdefault("pinhole_backend", "auto")
    if num_envs is None:
        env = for_learning(gym.make(env_id, **options), **learning)
        if not flatten:
            return env
        space = _float_space(env.observation_space)
        return gym.wrappers.FlattenObservation(
            gym.wrappers.TransformObservation(env, _as_float, space)
        )
    envs = gym.make_vec(
        env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **options
    )
    envs = for_learning(envs, **learning)
    if not flatten:
        return envs
    envs = gym.wrappers.vector.TransformObservation(
        envs, _as_float, single_observation_space=_float_space(envs.single_observation_space)
    )
    return gym.wrappers.vector.FlattenObservation(envs)


def _as_float(observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {
        key: value.astype(np.float32) / (255.0 if value.dtype == np.uint8 else 1.0)
        for key, value in observation.items()
    }


def _float_space(space: gym.spaces.Dict) -> gym.spaces.Dict:
    return gym.spaces.Dict(
        {
            key: gym.spaces.Box(-np.inf, np.inf, box.shape, np.float32)
            for key, box in space.spaces.items()
        }
    )
