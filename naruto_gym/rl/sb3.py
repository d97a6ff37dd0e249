"""Stable-Baselines3 on the batched vector env: a ``VecEnv`` adapter and a features extractor.

    from stable_baselines3 import PPO
    from naruto_gym.rl.sb3 import NarutoFeaturesExtractor, make_sb3_vec_env

    venv = make_sb3_vec_env(64, scene="procedural:room", size=64)
    model = PPO("MultiInputPolicy", venv, policy_kwargs={
        "features_extractor_class": NarutoFeaturesExtractor})

Needs ``pip install naruto-gym[sb3]``.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

from naruto_gym.sensors.pinhole import PinholeCamera
from naruto_gym.vector import make_vector_env
from naruto_gym.vector.infos import agent_info
from naruto_gym.wrappers.learning import for_learning


class Sb3VecEnv(VecEnv):
    """A Gymnasium vector env (``SAME_STEP`` autoreset) as a Stable-Baselines3 ``VecEnv``.

    Observations pass through unchanged (a dict of batched arrays); infos become one dict per
    env, with ``terminal_observation`` and ``TimeLimit.truncated`` on finished episodes, as
    SB3 expects.

    Args:
        env: a vector env whose ``metadata["autoreset_mode"]`` is ``AutoresetMode.SAME_STEP``
            (``NarutoReconVectorEnv(..., autoreset_mode="SameStep")``, possibly wrapped).
    """

    def __init__(self, env: gym.vector.VectorEnv) -> None:
        if env.metadata.get("autoreset_mode") != AutoresetMode.SAME_STEP:
            raise ValueError(
                "Sb3VecEnv needs a vector env with autoreset_mode=AutoresetMode.SAME_STEP "
                "(SB3 expects the next episode's first observation on the step that ends one); "
                "make it with autoreset_mode='SameStep'"
            )
        self.env = env
        super().__init__(env.num_envs, env.single_observation_space, env.single_action_space)
        self._actions: np.ndarray | None = None
        self._seed: int | None = None
        self._options: dict[str, Any] | None = None

    def reset(self) -> dict[str, np.ndarray]:
        observations, _ = self.env.reset(seed=self._seed, options=self._options)
        self._seed = None
        return observations

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> tuple[Any, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        observations, rewards, terminated, truncated, infos = self.env.step(self._actions)
        dones = terminated | truncated
        single_infos = [agent_info(infos, i) for i in range(self.num_envs)]
        for i in np.flatnonzero(dones):
            single_infos[i]["terminal_observation"] = infos["final_obs"][i]
            single_infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            if "final_info" in infos:
                single_infos[i]["final_info"] = agent_info(infos["final_info"], int(i))
        return observations, rewards.astype(np.float32), dones, single_infos

    def close(self) -> None:
        self.env.close()

    def seed(self, seed: int | None = None) -> list[int | None]:
        self._seed = seed
        return [None if seed is None else seed + i for i in range(self.num_envs)]

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        value = getattr(self.env.unwrapped, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        setattr(self.env.unwrapped, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any
    ) -> list[Any]:
        result = getattr(self.env.unwrapped, method_name)(*method_args, **method_kwargs)
        return [result for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def get_images(self) -> list[np.ndarray]:
        raise NotImplementedError("the batched vector env does not render")


def make_sb3_vec_env(
    num_envs: int,
    size: int = 64,
    top_down_map: bool = False,
    depth: str = "uint8",
    **env_kwargs: Any,
) -> Sb3VecEnv:
    """A batched env of :func:`~naruto_gym.vector.make_vector_env` (discrete actions unless
    ``action_mode`` says otherwise, ``SAME_STEP`` autoreset) with the learning observations of
    :func:`naruto_gym.wrappers.for_learning`, as an SB3 ``VecEnv``.

    Args:
        num_envs: agents.
        size: square frame side.
        top_down_map: add the egocentric top-down map.
        depth: ``"uint8"`` or ``"float"``.
        **env_kwargs: ``make_vector_env`` keywords (``scene``, ``max_episode_steps``,
            ``camera``, ``workers``, ...). Without ``camera`` or ``image_scale`` the env
            renders frames ``size`` pixels high (the default camera scaled), so nothing is
            drawn only to be thrown away by the resize. ``pinhole_backend`` defaults to
            ``"auto"`` (the rasterizer where cheaper), the setting for throughput.
    """
    env_kwargs.setdefault("action_mode", "discrete")
    env_kwargs.setdefault("panorama_shape", None)
    env_kwargs.setdefault("pinhole_backend", "auto")
    if "camera" not in env_kwargs and "image_scale" not in env_kwargs:
        # Render about the size handed out (the frame's height), not the full camera.
        env_kwargs["image_scale"] = min(1.0, size / PinholeCamera().height)
    env = make_vector_env(num_envs, autoreset_mode=AutoresetMode.SAME_STEP, **env_kwargs)
    return Sb3VecEnv(for_learning(env, size=size, depth=depth, top_down_map=top_down_map))


def _channels_first(space: spaces.Box) -> tuple[int, int, int]:
    """(channels, height, width) of an image-like box, channel-first or channel-last."""
    shape = space.shape
    if len(shape) == 2:
        return 1, shape[0], shape[1]
    # The channel axis is the smallest one (SB3's rule, also after VecFrameStack has stacked
    # frames along it: 4 stacked RGB frames are 12 channels, still fewer than the pixels).
    if int(np.argmin(shape)) == 0:
        return shape[0], shape[1], shape[2]
    return shape[2], shape[0], shape[1]


class NarutoFeaturesExtractor(BaseFeaturesExtractor):
    """Features of the learning observations: one small CNN over ``rgb`` and ``depth``
    stacked as channels, one over the top-down ``map`` when present, an MLP over the flat
    ``pose``; concatenated and projected to ``features_dim``.

    Accepts images channel-first (SB3 transposes uint8 images) or channel-last; uint8 inputs
    arrive scaled to [0, 1] by SB3's preprocessing.

    Args:
        observation_space: the ``Dict`` observation space.
        features_dim: output size.
    """

    def __init__(self, observation_space: spaces.Dict, features_dim: int = 256) -> None:
        super().__init__(observation_space, features_dim)
        self.frame_keys = [k for k in ("rgb", "depth") if k in observation_space.spaces]
        if not self.frame_keys:
            raise ValueError("NarutoFeaturesExtractor needs 'rgb' or 'depth' observations")
        shapes = [_channels_first(observation_space.spaces[k]) for k in self.frame_keys]
        if len({shape[1:] for shape in shapes}) != 1:
            raise ValueError(f"rgb and depth must have the same size, got {shapes}; resize them")
        channels = sum(shape[0] for shape in shapes)
        height, width = shapes[0][1:]
        self.frames = _cnn(channels, small=min(height, width) < 64)
        width_out = _flat_size(self.frames, channels, height, width)
        self.has_map = "map" in observation_space.spaces
        if self.has_map:
            map_channels, map_h, map_w = _channels_first(observation_space.spaces["map"])
            self.map = _cnn(map_channels, small=True)
            width_out += _flat_size(self.map, map_channels, map_h, map_w)
        self.has_pose = "pose" in observation_space.spaces
        if self.has_pose:
            pose_size = int(np.prod(observation_space.spaces["pose"].shape))
            self.pose = torch.nn.Sequential(torch.nn.Linear(pose_size, 64), torch.nn.ReLU())
            width_out += 64
        self.head = torch.nn.Sequential(torch.nn.Linear(width_out, features_dim), torch.nn.ReLU())
        self._spaces = observation_space.spaces

    def forward(self, observations: dict[str, torch.Tensor]) -> torch.Tensor:
        frames = torch.cat(
            [_as_channels_first(observations[k], self._spaces[k]) for k in self.frame_keys], 1
        )
        parts = [self.frames(frames)]
        if self.has_map:
            parts.append(self.map(_as_channels_first(observations["map"], self._spaces["map"])))
        if self.has_pose:
            parts.append(self.pose(observations["pose"].flatten(1)))
        return self.head(torch.cat(parts, 1))


def _cnn(channels: int, small: bool = False) -> torch.nn.Sequential:
    """Nature-DQN-sized CNN for frames of 64 pixels and more, a two-layer one below."""
    if small:
        return torch.nn.Sequential(
            torch.nn.Conv2d(channels, 16, 4, 2),
            torch.nn.ReLU(),
            torch.nn.Conv2d(16, 32, 3, 2),
            torch.nn.ReLU(),
            torch.nn.Flatten(),
        )
    return torch.nn.Sequential(
        torch.nn.Conv2d(channels, 32, 8, 4),
        torch.nn.ReLU(),
        torch.nn.Conv2d(32, 64, 4, 2),
        torch.nn.ReLU(),
        torch.nn.Conv2d(64, 64, 3, 1),
        torch.nn.ReLU(),
        torch.nn.Flatten(),
    )


def _flat_size(network: torch.nn.Module, channels: int, height: int, width: int) -> int:
    with torch.no_grad():
        return int(network(torch.zeros(1, channels, height, width)).shape[1])


def _as_channels_first(tensor: torch.Tensor, space: spaces.Box) -> torch.Tensor:
    if tensor.dim() == 3:
        return tensor.unsqueeze(1)
    channels, height, width = _channels_first(space)
    if tensor.shape[1] == channels and tensor.shape[2] == height:
        return tensor
    return tensor.permute(0, 3, 1, 2)
