"""The map-and-goal explorer's env settings, its training mix (with the agents grouped on
shared scenes, :func:`shared_train_mix`), and its env creator for RLlib (no learning library
is imported here).

    from ray.tune.registry import register_env
    from naruto_gym.rl.explorer_env import make_rllib_explorer_env

    register_env("NarutoExplorer", make_rllib_explorer_env)
    config = PPOConfig().environment("NarutoExplorer", env_config={
        "scene": "procedural:small:17", "max_episode_steps": 400}).env_runners(
        num_envs_per_env_runner=4, gym_env_vectorize_mode="sync")
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from naruto_gym.rl.egocentric_map import EgocentricMapObservation, VectorEgocentricMapObservation
from naruto_gym.rl.goal_actions import GoalActions, VectorGoalActions
from naruto_gym.scenes.suite import scene_name
from naruto_gym.vector.shared_scenes import SharedSceneStreams

__all__ = [
    "EXPLORER_ENV",
    "EXPLORER_PANORAMA_HORIZON_DEG",
    "TRAIN_MIX",
    "make_rllib_explorer_env",
    "shared_train_mix",
    "train_mix",
    "wrap_explorer",
]

#: The suite's train split the explorer learns on: closed and open variants of the small
#: and flat classes (scene streams: a new generated scene every episode).
TRAIN_MIX = tuple(
    scene_name(size_class, variant=variant, split="train")
    for size_class in ("small", "flat")
    for variant in ("closed", "open")
)

#: The explorer's env settings: discrete moves, a small pinhole frame (it only feeds the
#: seen-surface channel and the reward), drawn by the rasterizer where cheaper (``"auto"``,
#: the setting for throughput), and a (32, 64) depth panorama for the map.
EXPLORER_ENV: dict[str, Any] = {
    "action_mode": "discrete",
    "pinhole_backend": "auto",
    "image_scale": 0.05,
    "panorama_shape": (32, 64),
    "coverage_samples": 5000,
}


#: The elevation band of the panorama rows the explorer's map reads (its ``horizon_deg``):
#: ``panorama_horizon_deg`` at this value casts only those rows (the others read 0), a
#: third of the panorama's rays. The policy must then see the same band at evaluation.
EXPLORER_PANORAMA_HORIZON_DEG = 30.0


def train_mix(num_envs: int, scenes: tuple[str, ...] = TRAIN_MIX) -> list[str]:
    """One scene stream per agent, ``scenes`` in turn (``num_envs`` a multiple of their
    number mixes them evenly): every agent draws and builds a scene of its own every
    episode."""
    return [scenes[i % len(scenes)] for i in range(num_envs)]


def shared_train_mix(
    agents_per_scene: int = 4, episodes_per_scene: int = 4, scenes: tuple[str, ...] = TRAIN_MIX
) -> SharedSceneStreams:
    """The training mix with the agents in groups of ``agents_per_scene`` on shared scenes,
    each group's scene kept for ``episodes_per_scene`` episodes of each of its agents (the
    batched env's ``scene``; see :class:`~naruto_gym.vector.shared_scenes.SharedSceneStreams`).
    A scene is built once for many episodes and a group's rays are cast in one call; with
    ``num_envs = agents_per_scene * len(scenes)`` (16 by default) each stream has one group.

    Raises:
        ValueError: a count that is not a positive integer.
    """
    return SharedSceneStreams(scenes, agents_per_scene, episodes_per_scene)


def wrap_explorer(
    env: gym.vector.VectorEnv,
    steps_per_goal: int = 20,
    num_candidates: int = 8,
    primitive_actions: bool = True,
) -> gym.vector.VectorEnv:
    """The explorer's chain over a batched env: the egocentric map observation, then goal
    actions walked every ``steps_per_goal`` env steps (the ``wrap`` of
    :class:`~naruto_gym.vector.sharded_wrapped.ShardedWrappedEnv`, through
    ``functools.partial`` for other settings)."""
    return VectorGoalActions(
        VectorEgocentricMapObservation(env),
        steps_per_goal,
        num_candidates=num_candidates,
        primitive_actions=primitive_actions,
    )


def make_rllib_explorer_env(config: Mapping[str, Any]) -> gym.Env:
    """One ``NarutoReconEnv`` with the egocentric map observation and goal actions, its
    observation flattened to one float vector (colours and depths in [0, 1]) for RLlib's
    default model. RLlib vectorises it with ``gym_env_vectorize_mode="sync"``.

    Args:
        config: RLlib's ``env_config``: ``steps_per_goal`` (default 20), ``num_candidates``
            (8), ``primitive_actions`` (True), ``map_options`` (``EgocentricMapBuilder``
            keywords), ``flatten`` (True); every other key is a ``NarutoReconEnv`` keyword
            over :data:`EXPLORER_ENV` (``scene`` is required: one scene, e.g.
            ``"procedural:small:17"``).

    Raises:
        TypeError: ``config`` is not a mapping.
        ValueError: no ``scene``.
    """
    if not isinstance(config, Mapping):
        raise TypeError(f"config must be a mapping (RLlib's env_config), got {type(config)}")
    options = dict(config)
    options.pop("num_envs", None)
    if "goal_grid" in options:
        raise ValueError(
            "env_config['goal_grid'] is gone: the goal actions offer candidate goals now; "
            "set 'num_candidates' (default 8) instead"
        )
    walker = {
        key: options.pop(key) for key in ("num_candidates", "primitive_actions") if key in options
    }
    steps_per_goal = options.pop("steps_per_goal", 20)
    map_options = options.pop("map_options", {})
    flatten = bool(options.pop("flatten", True))
    if "scene" not in options:
        raise ValueError(
            "make_rllib_explorer_env needs a 'scene' in env_config, e.g. "
            "'procedural:small:17' (one suite training scene)"
        )
    env = gym.make("NarutoRecon-v0", **{**EXPLORER_ENV, **options})
    env = GoalActions(EgocentricMapObservation(env, **map_options), steps_per_goal, **walker)
    if not flatten:
        return env
    space = gym.spaces.Dict(
        {
            key: gym.spaces.Box(-np.inf, np.inf, box.shape, np.float32)
            for key, box in env.observation_space.spaces.items()
        }
    )
    scaled = gym.wrappers.TransformObservation(env, _as_float, space)
    return gym.wrappers.FlattenObservation(scaled)


def _as_float(observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {
        key: value.astype(np.float32) / (255.0 if value.dtype == np.uint8 else 1.0)
        for key, value in observation.items()
    }
