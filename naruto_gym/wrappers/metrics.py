"""``FinalReconstructionMetrics``: the reference reconstruction's metrics at an episode's end."""

from __future__ import annotations

from typing import Any

import gymnasium as gym

__all__ = ["FinalReconstructionMetrics"]


class FinalReconstructionMetrics(gym.Wrapper):
    """Puts the reference reconstruction's metrics into the info of an episode's last step.

    Wrap it around the ``TimeLimit`` (``gymnasium.make``'s, whatever its budget) or any other
    wrapper that ends episodes: it sees every episode end, which the env itself cannot (the
    env adds the metrics itself only on the step that reaches its own ``max_episode_steps``,
    which ``gymnasium.make`` keeps for the ``TimeLimit`` and does not pass on). It
    computes the metrics once per episode end, and not at all when the env already added them
    or was made without ``reconstruct=True``.
    """

    def step(self, action: Any):
        observation, reward, terminated, truncated, info = self.env.step(action)
        env = self.env.unwrapped
        if (
            (terminated or truncated)
            and "reconstruction" not in info
            and getattr(env, "reconstruction", None) is not None
        ):
            info = {**info, "reconstruction": env.reconstruction_metrics()}
        return observation, reward, terminated, truncated, info
