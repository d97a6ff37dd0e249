"""Wrappers around NarutoReconEnv: final reconstruction metrics, and observations shaped for
learning (see :mod:`naruto_gym.rl.wrappers` for the latter)."""

from __future__ import annotations

import sys
from typing import Any

import gymnasium as gym

# How far up the call stack a TimeLimit around the env is looked for (the wrappers that
# gymnasium.make puts between them: PassiveEnvChecker, OrderEnforcing, plus user wrappers).
_TIME_LIMIT_SEARCH_FRAMES = 12


def time_limit_ends_this_step(env: gym.Env) -> bool:
    """Whether a ``TimeLimit`` wrapping ``env`` will truncate the step ``env`` is taking now.

    Called from inside ``env.step``: the ``TimeLimit`` that called into it (through any
    wrappers in between) is found on the call stack, and its step count tells whether this
    step is its last. This lets the env put the final reconstruction metrics into the last
    step's info itself, whatever budget ``gymnasium.make(..., max_episode_steps=N)`` set,
    without an extra registered wrapper (Gymnasium refuses ``additional_wrappers`` together
    with a vector entry point). False when no ``TimeLimit`` wraps the env.
    """
    frame = sys._getframe(1)
    for _ in range(_TIME_LIMIT_SEARCH_FRAMES):
        frame = frame.f_back
        if frame is None:
            return False
        caller = frame.f_locals.get("self")
        if isinstance(caller, gym.wrappers.TimeLimit) and caller.unwrapped is env:
            return caller._elapsed_steps + 1 >= caller._max_episode_steps
    return False


class FinalReconstructionMetrics(gym.Wrapper):
    """Puts the reference reconstruction's metrics into the info of an episode's last step.

    The env already does this on the step its ``TimeLimit`` truncates; this wrapper covers
    episodes ended otherwise (a ``terminated`` from a task wrapper, a custom time limit that
    is not a ``TimeLimit``). It computes the metrics once per episode end, and not at all
    when the env already added them or was made without ``reconstruct=True``.
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
