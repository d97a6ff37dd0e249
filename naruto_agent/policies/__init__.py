"""Exploration policies: the interface, three baselines, adapters, a registry by name, a
stall watchdog and the one recovery from a stall they share.

* :class:`Policy` / :class:`EnvContext`: the interface (bind to an env, reset with the first
  observation and info, act on each observation).
* :class:`PassivePolicy`: the "human scan" (replay a trajectory, or a scripted scan loop).
* :class:`RandomPolicy`: seeded random walk that turns when blocked.
* :class:`FrontierPolicy`: nearest-frontier exploration on a depth-built occupancy map.
* :class:`PassiveConfig`, :class:`RandomConfig`, :class:`FrontierConfig`: their settings;
  the open-scan guard they share is :class:`~naruto_agent.guards.ScanGuard`.
* :class:`CallablePolicy`, :class:`SB3Policy`, :func:`as_policy`: wrap a function or a
  Stable-Baselines3 model.
* :class:`PointsLayer`, :class:`LinesLayer`, :class:`BoxesLayer`, :class:`ScalarLayer`:
  what a policy shows of its thinking (:meth:`Policy.view_layers`) in a recording.
* :func:`register_policy`, :func:`make_policy`, :func:`policy_class`, :func:`policy_names`:
  the registry (every registered name, and any ``"package.module:ClassName"``).
* :mod:`~naruto_agent.policies.watchdog`: the stall watchdog, which notices a policy that
  stops getting anywhere.
* :mod:`~naruto_agent.policies.stall_recovery`: the way out of a stall every policy shares
  (:class:`StallRecovery`, :class:`ReachablePlaces`, :func:`panorama_places`).

See docs/policies.md for the interface and how to add a policy.
"""

from __future__ import annotations

from naruto_agent.guards.scan_guard import ScanGuard, ScanGuardConfig
from naruto_agent.mapping.occupancy import OccupancyGrid
from naruto_agent.policies.adapters import (
    CallablePolicy,
    SB3Policy,
    action_mode_of_space,
    as_policy,
)
from naruto_agent.policies.base import EnvContext, OwnReconstruction, Policy, pose_action
from naruto_agent.policies.config import FrontierConfig, PassiveConfig, RandomConfig
from naruto_agent.policies.frontier import FrontierPolicy
from naruto_agent.policies.layers import (
    BoxesLayer,
    LinesLayer,
    PointsLayer,
    ScalarLayer,
)
from naruto_agent.policies.passive import PassivePolicy, load_trajectory, subsample_poses
from naruto_agent.policies.random_policy import RandomPolicy
from naruto_agent.policies.registry import (
    LAZY_POLICIES,
    POLICIES,
    make_policy,
    policy_class,
    policy_names,
    register_lazy_policy,
    register_policy,
)
from naruto_agent.policies.stall_recovery import (
    ReachablePlaces,
    StallRecovery,
    StallRecoveryConfig,
    panorama_places,
)
from naruto_agent.policies.watchdog import StallEvent, StallWatchdog, StallWatchdogConfig

__all__ = [
    "LAZY_POLICIES",
    "POLICIES",
    "BoxesLayer",
    "CallablePolicy",
    "EnvContext",
    "FrontierConfig",
    "FrontierPolicy",
    "LinesLayer",
    "OccupancyGrid",
    "OwnReconstruction",
    "PassiveConfig",
    "PassivePolicy",
    "PointsLayer",
    "Policy",
    "RandomConfig",
    "RandomPolicy",
    "SB3Policy",
    "ScalarLayer",
    "ScanGuard",
    "ScanGuardConfig",
    "ReachablePlaces",
    "StallEvent",
    "StallRecovery",
    "StallRecoveryConfig",
    "StallWatchdog",
    "StallWatchdogConfig",
    "action_mode_of_space",
    "as_policy",
    "load_trajectory",
    "panorama_places",
    "make_policy",
    "policy_class",
    "policy_names",
    "pose_action",
    "register_lazy_policy",
    "register_policy",
    "subsample_poses",
]
