"""Exploration policies: the interface, three baselines, adapters and a registry by name.

* :class:`Policy` / :class:`EnvContext`: the interface (bind to an env, reset with the first
  observation and info, act on each observation).
* :class:`PassivePolicy`: the "human scan" (replay a trajectory, or a scripted scan loop).
* :class:`RandomPolicy`: seeded random walk that turns when blocked.
* :class:`FrontierPolicy`: nearest-frontier exploration on a depth-built occupancy map.
* :class:`CallablePolicy`, :class:`SB3Policy`, :func:`as_policy`: wrap a function or a
  Stable-Baselines3 model.
* :func:`make_policy`: build one by registry name (``"passive"``, ``"random"``,
  ``"frontier"``) or by import path ``"package.module:ClassName"``.
"""

from __future__ import annotations

import importlib
from typing import Any

from naruto_agent.mapping.occupancy import OccupancyGrid
from naruto_agent.policies.adapters import (
    CallablePolicy,
    SB3Policy,
    action_mode_of_space,
    as_policy,
)
from naruto_agent.policies.base import EnvContext, OwnReconstruction, Policy, pose_action
from naruto_agent.policies.frontier import FrontierPolicy
from naruto_agent.policies.passive import PassivePolicy, load_trajectory, subsample_poses
from naruto_agent.policies.random_policy import RandomPolicy

POLICIES: dict[str, type[Policy]] = {
    "passive": PassivePolicy,
    "random": RandomPolicy,
    "frontier": FrontierPolicy,
}
"""Registry names of the baselines and their classes (see :func:`make_policy`)."""

#: Registry names resolved by import path on first use (their modules import torch).
LAZY_POLICIES: dict[str, str] = {"naruto": "naruto_agent.naruto:NarutoPolicy"}


def policy_class(name: str) -> type[Policy]:
    """The policy class of a registry name or a ``"package.module:ClassName"`` import path."""
    if name in POLICIES:
        return POLICIES[name]
    name = LAZY_POLICIES.get(name, name)
    if ":" in name:
        module_name, _, attribute = name.partition(":")
        try:
            cls = getattr(importlib.import_module(module_name), attribute)
        except (ImportError, AttributeError) as error:
            raise ValueError(f"cannot import policy {name!r}: {error}") from error
        if not (isinstance(cls, type) and issubclass(cls, Policy)):
            raise ValueError(f"{name!r} is not a naruto_agent.policies.Policy subclass")
        return cls
    raise ValueError(
        f"unknown policy {name!r}; use one of {sorted(POLICIES)} or 'package.module:ClassName'"
    )


def make_policy(name: str, **kwargs: Any) -> Policy:
    """Build a policy by registry name or import path, with constructor keyword arguments."""
    return policy_class(name)(**kwargs)


__all__ = [
    "POLICIES",
    "CallablePolicy",
    "EnvContext",
    "FrontierPolicy",
    "OccupancyGrid",
    "OwnReconstruction",
    "PassivePolicy",
    "Policy",
    "RandomPolicy",
    "SB3Policy",
    "action_mode_of_space",
    "as_policy",
    "load_trajectory",
    "make_policy",
    "policy_class",
    "pose_action",
    "subsample_poses",
]
