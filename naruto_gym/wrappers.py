"""Wrappers around NarutoReconEnv."""

from __future__ import annotations

from typing import Any

import gymnasium as gym


class FinalReconstructionMetrics(gym.Wrapper):
    """Puts the reference reconstruction's metrics into the info of an episode's last step.

    The env fuses every frame when made with ``reconstruct=True``; only the wrapper chain knows
    when an episode is cut by the ``TimeLimit``, so scoring happens here, once per episode, on
    the step that is terminated or truncated. Without ``reconstruct=True`` it does nothing.
    """

    def step(self, action: Any):
        observation, reward, terminated, truncated, info = self.env.step(action)
        env = self.env.unwrapped
        if (terminated or truncated) and getattr(env, "reconstruction", None) is not None:
            info = {**info, "reconstruction": env.reconstruction_metrics()}
        return observation, reward, terminated, truncated, info
