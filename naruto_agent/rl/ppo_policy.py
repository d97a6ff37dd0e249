"""A PPO model trained by ``benchmarks/train_ppo.py`` as a harness policy.

    naruto-benchmark --policies random frontier naruto_agent.rl.ppo_policy:PPOExplorer \\
        --image-scale 0.1 --policy-kwargs '{"naruto_agent.rl.ppo_policy:PPOExplorer":
        {"model_path": "runs/ppo/final_model.zip"}}'

The env gives raw observations; they are turned into the learning observations the model was
trained on (frames resized to ``size``, depth as an image, pose as position + 6D rotation, and
the egocentric top-down map when the model was trained with it). The frame size, the depth
format and the map are read from the saved model's observation space, so a model and its
settings cannot disagree at run time; settings given explicitly are checked against it when
the model is loaded. Evaluate with the camera it was trained with (``--image-scale`` of the
training).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

from naruto_agent.policies.adapters import SB3Policy
from naruto_agent.policies.base import Info, Observation
from naruto_gym.wrappers.observation import DepthFormat, LearningObservation


@dataclass(frozen=True)
class LearningSettings:
    """The learning-observation settings a model's observation space was made with.

    Attributes:
        size: square frame side.
        top_down_map: the observations hold the egocentric top-down ``map``.
        depth: ``"uint8"`` or ``"float"``.
    """

    size: int
    top_down_map: bool
    depth: DepthFormat


def learning_settings(space: Any) -> LearningSettings:
    """Read :class:`LearningSettings` from a model's observation space (the ``Dict`` of
    ``rgb``, ``depth``, ``pose`` and maybe ``map`` that ``make_sb3_vec_env`` gives, with images
    channel-last or channel-first as SB3 stores them).

    Raises:
        ValueError: the space is not such a ``Dict`` (the message says what to pass).
    """
    frames = space.spaces if isinstance(space, spaces.Dict) else {}
    rgb = frames.get("rgb")
    if not (isinstance(rgb, spaces.Box) and len(rgb.shape) == 3):
        raise ValueError(
            f"the model's observation space is not the learning observations of "
            f"make_sb3_vec_env / for_learning (a Dict with an (H, W, 3) 'rgb'), got {space}; "
            "load it with SB3Policy and an observation_transform of its own"
        )
    height, width = rgb.shape[:2] if rgb.shape[-1] == 3 else rgb.shape[1:]
    if height != width:
        raise ValueError(
            f"the model's frames are {height} x {width}; PPOExplorer needs square "
            "frames (the size of make_sb3_vec_env)"
        )
    depth = frames.get("depth")
    depth_format = "float" if depth is not None and depth.dtype != np.uint8 else "uint8"
    return LearningSettings(int(height), "map" in frames, depth_format)


class PPOExplorer(SB3Policy):
    """Loads a Stable-Baselines3 PPO zip (discrete actions) and acts with it.

    Args:
        model_path: the ``.zip`` saved by training.
        size: the frame side the model saw; None reads it from the model. A value the model
            disagrees with is an error.
        deterministic: act with the mode of the action distribution (False samples, which
            keeps a policy from looping where its mode would).
        top_down_map: the model was trained with the egocentric top-down map
            (``train_ppo.py --top-down-map``; the policy builds it from the observations);
            None reads it from the model. A value the model disagrees with is an error.

    Raises:
        ValueError: ``size`` or ``top_down_map`` disagrees with the saved model, or the
            model's observations are not the learning observations (the message says which
            setting to pass).
    """

    def __init__(
        self,
        model_path: str,
        size: int | None = None,
        deterministic: bool = False,
        top_down_map: bool | None = None,
    ) -> None:
        from stable_baselines3 import PPO

        model = PPO.load(model_path, device="cpu")
        found = learning_settings(model.observation_space)
        if size is not None and size != found.size:
            raise ValueError(
                f"{model_path} was trained on {found.size} x {found.size} frames, not {size}: "
                f"pass size={found.size} (or leave size out to read it from the model)"
            )
        if top_down_map is not None and top_down_map != found.top_down_map:
            with_map = "with" if found.top_down_map else "without"
            raise ValueError(
                f"{model_path} was trained {with_map} the top-down map: pass "
                f"top_down_map={found.top_down_map} (or leave it out to read it from the model)"
            )
        self.settings = found
        self.learning_observation = LearningObservation(
            found.size, depth=found.depth, top_down_map=found.top_down_map
        )
        super().__init__(
            model, deterministic=deterministic, observation_transform=self.learning_observation
        )

    def reset(self, observation: Observation, info: Info, seed: int | None = None) -> None:
        super().reset(observation, info, seed)
        self.learning_observation.start_episode(self.context.camera, self.context.bounds)
