"""The NARUTO agent (Feng et al., CVPR 2024) as a policy of this project's env.

* :class:`NarutoPolicy` / :class:`NarutoConfig`: the agent (mapper + goal search + E-RRT +
  rotation planning), acting in the env's ``"pose"`` action mode; ``policy.mesh()`` is its
  reconstruction.
* Its parts, one job each: :class:`AgentMap` (the mapper and the planner view),
  :class:`NarutoScanChecks` (the shared :class:`~naruto_agent.guards.ScanGuard` read with the
  agent's map), :class:`MoveChecker` (the check of a move before it is sent),
  :class:`GoalPlanner` (the planning step) and :class:`RecoveryPlanner` (the recovery steps
  as plans).
* :func:`uncertainty_aware_goal_search` and its parts (:func:`candidate_goals`,
  :func:`safe_goal_mask`, :func:`select_targets`, :func:`visibility`, :func:`search_goals`):
  the goal search as pure functions.
* :class:`NarutoStateMachine`, :class:`State`, :data:`TRANSITIONS`, :class:`Plan`: the
  planner's state machine.

Run it like any policy::

    policy = NarutoPolicy(mapper_kind="tsdf")
    policy.bind(EnvContext.from_env(env))
    obs, info = env.reset(seed=0)
    policy.reset(obs, info, seed=0)
    for _ in range(500):
        obs, reward, terminated, truncated, info = env.step(policy.act(obs, info))
    env.unwrapped.evaluate(policy.mesh())
"""

from naruto_agent.naruto.agent_map import AgentMap
from naruto_agent.naruto.config import MAPPERS, NarutoConfig, build_config
from naruto_agent.naruto.goal_planning import GoalPlanner
from naruto_agent.naruto.goal_search import (
    GoalSearchConfig,
    GoalSearchResult,
    candidate_goals,
    safe_goal_mask,
    search_goals,
    select_targets,
    uncertainty_aware_goal_search,
    visibility,
)
from naruto_agent.naruto.move_checks import MoveChecker
from naruto_agent.naruto.policy import NarutoPolicy
from naruto_agent.naruto.recovery_plans import RecoveryPlanner
from naruto_agent.naruto.scan_checks import NarutoScanChecks
from naruto_agent.naruto.state_machine import TRANSITIONS, NarutoStateMachine, Plan, State

__all__ = [
    "MAPPERS",
    "TRANSITIONS",
    "AgentMap",
    "GoalPlanner",
    "GoalSearchConfig",
    "GoalSearchResult",
    "MoveChecker",
    "NarutoConfig",
    "NarutoPolicy",
    "NarutoScanChecks",
    "NarutoStateMachine",
    "Plan",
    "RecoveryPlanner",
    "State",
    "build_config",
    "candidate_goals",
    "safe_goal_mask",
    "search_goals",
    "select_targets",
    "uncertainty_aware_goal_search",
    "visibility",
]
