"""The explorer's goal walker with a scripted choice: the classic baseline of its action space.

    naruto-benchmark --policies goal-walker explorer explorer-untrained
    naruto-demo --policy goal-walker
    naruto-benchmark --policies goal-walker --policy-kwargs '{"rule": "nearest"}'
    naruto-benchmark --policies goal-walker --policy-kwargs '{"decision": "goal"}'

:class:`GoalWalkerPolicy` is the explorer
(:class:`~naruto_agent.rl.explorer_policy.MapGoalExplorer`) with its network replaced by a
fixed rule over the same candidate goals: the same map, candidates, walker, watchdog and
settings (read from the explorer checkpoint's JSON file), one candidate chosen every
``steps_per_goal`` steps by :func:`choose_candidate` (``decision="goal"``: the rule chooses
each goal the walker walks, at every goal, as the decision at every goal of
:mod:`naruto_gym.rl.goal_actions`).
Paired with the explorer on the same scenes and seeds, it says what the learned choice adds
over the best simple rule of its own action space.

The rules read the candidate feature table
(:data:`~naruto_gym.rl.goal_candidates.CANDIDATE_FEATURES`: slot 0 the nearest by path, empty
slots all zeros) and pick among the valid slots, ties going to the nearer candidate
(:data:`CHOICE_RULES`):

* ``nearest``: candidate 0, the nearest by path (the walker's own choice once a goal is done);
* ``largest``: the largest share of target cells in its cluster;
* ``size-per-metre``: the largest share of target cells per metre of path, plus
  :data:`PATH_OFFSET_M` (the classic frontier utility: what is to see over what it costs to
  get there);
* ``ahead``: the cluster nearest the agent's heading (the least turning);
* ``random``: a valid slot drawn uniformly, seeded by the episode's seed.

The default, :data:`DEFAULT_RULE`, is the rule with the highest mean coverage area on the train
split (``benchmarks/explorer_scripted_check.py``; the run is in docs/rl.md).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from naruto_agent.policies.registry import register_policy
from naruto_agent.rl.explorer_policy import (
    DEFAULT_SETTINGS,
    PACKAGED_MODEL,
    CandidateGoalPolicy,
    read_settings,
    settings_path,
)
from naruto_gym.rl.goal_actions import GOAL_STEPS
from naruto_gym.rl.goal_candidates import CANDIDATE_FEATURES
from naruto_gym.rl.goal_walker import DECISIONS

__all__ = ["CHOICE_RULES", "DEFAULT_RULE", "GoalWalkerPolicy", "choose_candidate"]

#: The scripted choices (module docstring).
CHOICE_RULES = ("nearest", "largest", "size-per-metre", "ahead", "random")
#: The rule of ``goal-walker`` without a ``rule`` keyword: the best on the train split.
DEFAULT_RULE = "largest"
#: Metres added to a candidate's path in ``size-per-metre`` (a candidate at the agent's feet
#: is not worth infinitely more than one a step away).
PATH_OFFSET_M = 1.0

_VALID = CANDIDATE_FEATURES.index("valid")
_PATH = CANDIDATE_FEATURES.index("path_m")
_BEARING_COS = CANDIDATE_FEATURES.index("bearing_cos")
_SIZE = CANDIDATE_FEATURES.index("size")
#: The table's path and distance columns are in tens of metres.
_TABLE_M = 10.0


def check_rule(rule: str) -> str:
    """``rule`` when it is one of :data:`CHOICE_RULES`.

    Raises:
        ValueError: any other rule (the message lists them).
    """
    if rule not in CHOICE_RULES:
        raise ValueError(f"unknown choice rule {rule!r}; use one of {', '.join(CHOICE_RULES)}")
    return rule


def choose_candidate(candidates: np.ndarray, rule: str, rng: np.random.Generator) -> int:
    """The slot a scripted rule picks from one agent's candidate feature table.

    Args:
        candidates: ``(N, F)`` table of :data:`~naruto_gym.rl.goal_candidates.CANDIDATE_FEATURES`
            rows (valid slots first, nearest first).
        rule: one of :data:`CHOICE_RULES`.
        rng: the generator of ``random`` (the other rules do not draw).

    Returns:
        The slot; 0 with no valid candidate (the walker then wanders to the place farthest
        from its trail).

    Raises:
        ValueError: an unknown rule.
    """
    check_rule(rule)
    table = np.asarray(candidates, np.float64)
    valid = np.flatnonzero(table[:, _VALID] > 0)
    if len(valid) == 0 or rule == "nearest":
        return 0
    if rule == "random":
        return int(valid[rng.integers(len(valid))])
    rows = table[valid]
    if rule == "largest":
        score = rows[:, _SIZE]
    elif rule == "size-per-metre":
        score = rows[:, _SIZE] / (rows[:, _PATH] * _TABLE_M + PATH_OFFSET_M)
    else:  # ahead
        score = rows[:, _BEARING_COS]
    return int(valid[np.argmax(score)])  # argmax keeps the first (nearest) of ties


@register_policy("goal-walker")
class GoalWalkerPolicy(CandidateGoalPolicy):
    """The explorer's map, candidates and walker with a scripted choice (module docstring).

    Args:
        rule: the choice, one of :data:`CHOICE_RULES` (default :data:`DEFAULT_RULE`).
        settings_from: the explorer checkpoint whose settings (``steps_per_goal``, the number
            of candidates, the map's options, the panorama size) the walker takes; None: the
            packaged checkpoint's (the training script's defaults where none is shipped).
        stall_watchdog: watch the walk for stalls and walk out of one, as the explorer does.
        decision: None, the settings' decision; ``"interval"``, every ``steps_per_goal``
            steps; ``"goal"``, at every goal (at most :data:`GOAL_STEPS
            <naruto_gym.rl.goal_actions.GOAL_STEPS>` steps apart, candidates only).

    Raises:
        ValueError: an unknown rule or decision.
        FileNotFoundError: a ``settings_from`` checkpoint without its JSON settings file.
    """

    def __init__(
        self,
        rule: str = DEFAULT_RULE,
        settings_from: str | None = None,
        stall_watchdog: bool = True,
        decision: str | None = None,
    ) -> None:
        settings = _walker_settings(settings_from)
        if decision is not None and decision not in DECISIONS:
            raise ValueError(f"decision must be one of {DECISIONS} or None, got {decision!r}")
        if decision == "goal" and settings.get("decision") != "goal":
            settings = {**settings, "steps_per_goal": GOAL_STEPS, "primitive_actions": False}
        if decision == "interval" and settings.get("decision") == "goal":
            settings = {**settings, "steps_per_goal": DEFAULT_SETTINGS["steps_per_goal"]}
        if decision is not None:
            settings["decision"] = decision
        super().__init__(settings, stall_watchdog)
        self.rule = check_rule(rule)
        self.rng = np.random.default_rng()

    def reset(self, observation: dict[str, Any], info: dict[str, Any], seed: int | None = None):
        super().reset(observation, info, seed)
        if seed is not None:
            self.rng = np.random.default_rng(seed)

    def choose(self, observation: dict[str, np.ndarray]) -> int:
        return choose_candidate(observation["candidates"], self.rule, self.rng)


def _walker_settings(settings_from: str | None) -> dict[str, Any]:
    """The explorer checkpoint's settings the walker runs with (module docstring)."""
    if settings_from is None:
        return read_settings(PACKAGED_MODEL) if PACKAGED_MODEL.exists() else dict(DEFAULT_SETTINGS)
    stored = settings_path(Path(settings_from))
    if not stored.exists():
        raise FileNotFoundError(
            f"no settings file {stored} beside {settings_from}: pass the .zip that "
            f"benchmarks/train_explorer.py wrote (its .json beside it)"
        )
    return read_settings(settings_from)
