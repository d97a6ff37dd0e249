"""Adapters that turn a plain callable or a Stable-Baselines3 model into a :class:`Policy`."""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from naruto_agent.policies.base import EnvContext, Info, Observation, Policy

ACTION_MODES = ("pose", "delta", "discrete")


def action_mode_of_space(space: gym.Space) -> str:
    """The env action mode whose action space has this shape.

    ``Discrete`` is ``"discrete"``, ``Box(6,)`` is ``"delta"`` and ``Box(7,)`` is ``"pose"``.
    """
    if isinstance(space, gym.spaces.Discrete):
        return "discrete"
    if isinstance(space, gym.spaces.Box) and space.shape == (6,):
        return "delta"
    if isinstance(space, gym.spaces.Box) and space.shape == (7,):
        return "pose"
    raise ValueError(
        f"cannot tell the action mode of action space {space}: expected Discrete (discrete), "
        "Box(6,) (delta) or Box(7,) (pose)"
    )


def _check_modes(action_modes: tuple[str, ...] | list[str] | str) -> tuple[str, ...]:
    modes = (action_modes,) if isinstance(action_modes, str) else tuple(action_modes)
    unknown = [mode for mode in modes if mode not in ACTION_MODES]
    if not modes or unknown:
        raise ValueError(f"action_modes must be a non-empty subset of {ACTION_MODES}, got {modes}")
    return modes


def _accepts_info(function: Callable[..., Any]) -> bool:
    """True when ``function`` takes a second positional argument (the info)."""
    try:
        parameters = list(inspect.signature(function).parameters.values())
    except (TypeError, ValueError):
        return False
    positional = [p for p in parameters if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    has_varargs = any(p.kind == p.VAR_POSITIONAL for p in parameters)
    return has_varargs or len(positional) >= 2


class CallablePolicy(Policy):
    """A policy from a plain function ``f(observation) -> action`` or
    ``f(observation, info) -> action``.

    Args:
        function: the callable; it receives the observation dict (and the last info when it
            takes two arguments).
        action_modes: the action mode(s) its actions are in (default ``"pose"``).
        on_reset: optional ``g(observation, info)`` called at every episode start.
    """

    def __init__(
        self,
        function: Callable[..., Any],
        action_modes: tuple[str, ...] | str = ("pose",),
        on_reset: Callable[[Observation, Info], None] | None = None,
    ) -> None:
        super().__init__()
        if not callable(function):
            raise ValueError(f"CallablePolicy needs a callable, got {type(function).__name__}")
        self.function = function
        self.action_modes = _check_modes(action_modes)
        self.on_reset = on_reset
        self._with_info = _accepts_info(function)

    def reset(self, observation: Observation, info: Info, seed: int | None = None) -> None:
        super().reset(observation, info, seed)
        if self.on_reset is not None:
            self.on_reset(observation, info)

    def act(self, observation: Observation, info: Info | None = None) -> Any:
        if self._with_info:
            return self.function(observation, info if info is not None else {})
        return self.function(observation)


class SB3Policy(Policy):
    """A policy from a Stable-Baselines3 model (anything with ``predict(obs, state,
    episode_start, deterministic)``), recurrent models included.

    Args:
        model: the SB3 model (``PPO``, ``SAC``, ``RecurrentPPO``...).
        deterministic: use the mode of the action distribution (default True).
        observation_transform: maps the env observation to what the model was trained on
            (e.g. a dict filtered to ``rgb`` and ``depth``); identity by default. Dict
            observations are filtered to the model's observation-space keys automatically.
        action_mode: the action mode of the model's actions; inferred from
            ``model.action_space`` by default.
    """

    def __init__(
        self,
        model: Any,
        deterministic: bool = True,
        observation_transform: Callable[[Observation], Any] | None = None,
        action_mode: str | None = None,
    ) -> None:
        super().__init__()
        if not hasattr(model, "predict"):
            raise ValueError(
                f"SB3Policy needs a model with a predict() method, got {type(model).__name__}"
            )
        self.model = model
        self.deterministic = bool(deterministic)
        self.observation_transform = observation_transform
        mode = action_mode or action_mode_of_space(model.action_space)
        self.action_modes = _check_modes(mode)
        self._state: Any = None
        self._episode_start = np.ones((1,), dtype=bool)

    def bind(self, context: EnvContext) -> None:
        super().bind(context)
        if (
            isinstance(context.action_space, gym.spaces.Box)
            and isinstance(self.model.action_space, gym.spaces.Box)
            and context.action_space.shape != self.model.action_space.shape
        ):
            raise ValueError(
                f"the model's actions have shape {self.model.action_space.shape}, the env's "
                f"{context.action_space.shape}"
            )

    def reset(self, observation: Observation, info: Info, seed: int | None = None) -> None:
        super().reset(observation, info, seed)
        self._state = None
        self._episode_start = np.ones((1,), dtype=bool)

    def _model_input(self, observation: Observation) -> Any:
        if self.observation_transform is not None:
            return self.observation_transform(observation)
        space = getattr(self.model, "observation_space", None)
        if isinstance(space, gym.spaces.Dict) and isinstance(observation, dict):
            return {key: observation[key] for key in space.spaces}
        return observation

    def act(self, observation: Observation, info: Info | None = None) -> Any:
        action, self._state = self.model.predict(
            self._model_input(observation),
            state=self._state,
            episode_start=self._episode_start,
            deterministic=self.deterministic,
        )
        self._episode_start = np.zeros((1,), dtype=bool)
        if self.action_modes[0] == "discrete":
            return int(np.asarray(action).reshape(-1)[0])
        return np.asarray(action, dtype=np.float32)


def as_policy(obj: Any, action_modes: tuple[str, ...] | str = ("pose",)) -> Policy:
    """Wrap anything policy-like: a :class:`Policy` (returned as is), an SB3-style model
    (has ``predict`` and ``action_space``) or a callable.

    Args:
        obj: the thing to wrap.
        action_modes: action modes of a callable's actions (ignored otherwise).
    """
    if isinstance(obj, Policy):
        return obj
    if hasattr(obj, "predict") and hasattr(obj, "action_space"):
        return SB3Policy(obj)
    if callable(obj):
        return CallablePolicy(obj, action_modes)
    raise ValueError(
        f"cannot make a policy from {type(obj).__name__}: pass a Policy, an SB3 model or a "
        "callable f(observation[, info]) -> action"
    )
