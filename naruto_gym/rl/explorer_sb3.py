"""Stable-Baselines3 pieces of the map-and-goal explorer: the batched env with the egocentric
map and goal actions as an SB3 ``VecEnv``, the suite's training mix, and a features extractor.

    from stable_baselines3 import PPO
    from naruto_gym.rl.explorer_sb3 import ExplorerFeaturesExtractor, make_explorer_vec_env

    venv = make_explorer_vec_env(16, max_episode_steps=400)
    model = PPO("MultiInputPolicy", venv, policy_kwargs={
        "features_extractor_class": ExplorerFeaturesExtractor})

Needs ``pip install naruto-gym[sb3]``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

from naruto_gym.rl.egocentric_map import VectorEgocentricMapObservation
from naruto_gym.rl.explorer_env import EXPLORER_ENV, train_mix
from naruto_gym.rl.goal_actions import VectorGoalActions
from naruto_gym.rl.sb3 import Sb3VecEnv
from naruto_gym.vector.vector_env import NarutoReconVectorEnv

__all__ = [
    "ExplorerFeaturesExtractor",
    "channels_first",
    "channels_last",
    "make_explorer_vec_env",
    "map_encoder",
    "panorama_encoder",
]


def make_explorer_vec_env(
    num_envs: int,
    steps_per_goal: int = 20,
    num_candidates: int = 8,
    primitive_actions: bool = True,
    map_options: dict[str, Any] | None = None,
    **env_kwargs: Any,
) -> Sb3VecEnv:
    """The batched env (``SAME_STEP`` autoreset) with the egocentric map observation and goal
    actions, as an SB3 ``VecEnv``: one SB3 step is ``steps_per_goal`` env steps.

    Args:
        num_envs: agents.
        steps_per_goal: env steps per action.
        num_candidates: candidate goals offered per decision.
        primitive_actions: the discrete moves are actions too.
        map_options: :class:`~naruto_gym.rl.egocentric_map.EgocentricMapBuilder` keywords.
        **env_kwargs: ``NarutoReconVectorEnv`` keywords over :data:`EXPLORER_ENV` (``scene``
            defaults to :func:`train_mix`; ``max_episode_steps`` to 400, a multiple of
            ``steps_per_goal`` as it must be).
    """
    options = {**EXPLORER_ENV, **env_kwargs}
    options.setdefault("scene", train_mix(num_envs))
    options.setdefault("max_episode_steps", 400)
    env = NarutoReconVectorEnv(num_envs, autoreset_mode=AutoresetMode.SAME_STEP, **options)
    env = VectorEgocentricMapObservation(env, **(map_options or {}))
    env = VectorGoalActions(
        env, steps_per_goal, num_candidates=num_candidates, primitive_actions=primitive_actions
    )
    return Sb3VecEnv(env)


def channels_first(space: spaces.Box) -> tuple[int, int, int]:
    """(channels, height, width) of an image box stored either way (the channels the
    smallest axis)."""
    shape = space.shape
    return (
        (shape[0], shape[1], shape[2])
        if int(np.argmin(shape)) == 0
        else (shape[2], shape[0], shape[1])
    )


def channels_last(images: torch.Tensor) -> torch.Tensor:
    """The images laid out channels-last in memory (the shape unchanged): oneDNN's CPU
    convolutions run about twice as fast on that layout."""
    return images.contiguous(memory_format=torch.channels_last)


# Small on purpose: a trained model ships inside the package (at most 5 MB).
def map_encoder(channels: int) -> torch.nn.Sequential:
    """The CNN over the egocentric ``map`` channels (flattened output)."""
    return torch.nn.Sequential(
        torch.nn.Conv2d(channels, 32, 3, 1, 1),
        torch.nn.ReLU(),
        torch.nn.Conv2d(32, 32, 4, 2, 1),
        torch.nn.ReLU(),
        torch.nn.Conv2d(32, 32, 4, 2, 1),
        torch.nn.ReLU(),
        torch.nn.Flatten(),
    )


def panorama_encoder(channels: int) -> torch.nn.Sequential:
    """The CNN over the depth ``panorama`` (flattened output)."""
    return torch.nn.Sequential(
        torch.nn.Conv2d(channels, 16, 4, 2, 1),
        torch.nn.ReLU(),
        torch.nn.Conv2d(16, 16, 4, 2, 1),
        torch.nn.ReLU(),
        torch.nn.Flatten(),
    )


class ExplorerFeaturesExtractor(BaseFeaturesExtractor):
    """Features of the explorer's observation: a CNN over the ``map`` channels, a CNN over the
    ``panorama``, an MLP over the relative ``pose`` and one over the ``candidates`` feature
    table (all its rows at once, so that it can compare them); concatenated and projected to
    ``features_dim``. uint8 images arrive in [0, 1] (SB3's preprocessing), channel-first.

    The CNNs take their inputs channels-last in memory (NHWC; the shapes are unchanged): on
    CPU, oneDNN's convolutions then run in that layout, forward and backward, about twice as
    fast, with the same arithmetic up to the order of their sums.

    Args:
        observation_space: ``Dict`` with ``map``, ``panorama``, ``pose`` and ``candidates``.
        features_dim: output size.

    Attributes:
        compute_dtype: None (float32), or a lower precision (``torch.bfloat16``) the layers
            compute in under autocast, e.g. during a learner's update on a CPU with bfloat16
            instructions (about twice as fast); the features come out float32 either way, so
            the policy's and value's heads after it keep their precision.
    """

    def __init__(self, observation_space: spaces.Dict, features_dim: int = 128) -> None:
        super().__init__(observation_space, features_dim)
        self.compute_dtype: torch.dtype | None = None
        missing = {"map", "panorama", "pose", "candidates"} - set(observation_space.spaces)
        if missing:
            raise ValueError(
                f"ExplorerFeaturesExtractor needs the egocentric map observation with the "
                f"goal actions' candidates (map, panorama, pose, candidates); {sorted(missing)} "
                f"missing from {observation_space}"
            )
        channels, height, width = channels_first(observation_space["map"])
        self.map = map_encoder(channels)
        pano_channels, pano_height, pano_width = channels_first(observation_space["panorama"])
        self.panorama = panorama_encoder(pano_channels)
        pose_size = int(np.prod(observation_space["pose"].shape))
        self.pose = torch.nn.Sequential(torch.nn.Linear(pose_size, 32), torch.nn.ReLU())
        table_size = int(np.prod(observation_space["candidates"].shape))
        self.candidates = torch.nn.Sequential(
            torch.nn.Linear(table_size, 64),
            torch.nn.ReLU(),
            torch.nn.Linear(64, 64),
            torch.nn.ReLU(),
        )
        with torch.no_grad():
            width_out = (
                self.map(torch.zeros(1, channels, height, width)).shape[1]
                + self.panorama(torch.zeros(1, pano_channels, pano_height, pano_width)).shape[1]
                + 32
                + 64
            )
        self.head = torch.nn.Sequential(torch.nn.Linear(width_out, features_dim), torch.nn.ReLU())

    def forward(self, observations: dict[str, torch.Tensor]) -> torch.Tensor:
        lower = self.compute_dtype
        with torch.autocast(
            observations["map"].device.type, dtype=lower or torch.bfloat16, enabled=bool(lower)
        ):
            features = self.head(
                torch.cat(
                    [
                        self.map(channels_last(observations["map"])),
                        self.panorama(channels_last(observations["panorama"])),
                        self.pose(observations["pose"].flatten(1)),
                        self.candidates(observations["candidates"].flatten(1)),
                    ],
                    1,
                )
            )
        return features.float()
