"""goal-walker: the explorer's map, candidates and walker with a scripted choice rule; it
walks as the training wrappers do with the same rule, with the explorer's settings."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from naruto_agent.policies.base import EnvContext
from naruto_agent.policies.registry import policy_class
from naruto_agent.rl.explorer_policy import PACKAGED_MODEL, read_settings
from naruto_agent.rl.scripted_explorer import (
    CHOICE_RULES,
    DEFAULT_RULE,
    GoalWalkerPolicy,
    choose_candidate,
)
from naruto_gym.rl.egocentric_map import EgocentricMapObservation
from naruto_gym.rl.goal_actions import GoalActions
from naruto_gym.rl.goal_candidates import CANDIDATE_FEATURES
from tests.agent.rl.small_env import ENV


def _table(rows: list[dict[str, float]], slots: int = 6) -> np.ndarray:
    table = np.zeros((slots, len(CANDIDATE_FEATURES)), np.float32)
    for i, row in enumerate(rows):
        table[i, 0] = 1.0
        for name, value in row.items():
            table[i, CANDIDATE_FEATURES.index(name)] = value
    return table


def test_each_rule_picks_its_candidate_among_the_valid_slots():
    table = _table([
        {"path_m": 0.05, "size": 0.2, "bearing_cos": -1.0},  # nearest, behind
        {"path_m": 0.30, "size": 0.9, "bearing_cos": 0.0},  # largest, far
        {"path_m": 0.10, "size": 0.6, "bearing_cos": 1.0},  # ahead, best per metre
    ])  # fmt: skip
    rng = np.random.default_rng(0)
    picks = {rule: choose_candidate(table, rule, rng) for rule in CHOICE_RULES if rule != "random"}
    assert picks == {"nearest": 0, "largest": 1, "size-per-metre": 2, "ahead": 2}
    drawn = {choose_candidate(table, "random", rng) for _ in range(60)}
    assert drawn == {0, 1, 2}
    assert choose_candidate(_table([]), "largest", rng) == 0  # none valid: the walker wanders
    ties = _table([{"size": 0.5}, {"size": 0.5}])
    assert choose_candidate(ties, "largest", rng) == 0  # a tie goes to the nearer candidate
    with pytest.raises(ValueError, match="nearest"):
        choose_candidate(table, "farthest", rng)


def test_the_policy_walks_as_the_wrappers_do_with_the_same_rule():
    rule = "largest"
    settings = GoalWalkerPolicy().settings
    period, count = int(settings["steps_per_goal"]), int(settings["num_candidates"])
    wrapped = GoalActions(
        EgocentricMapObservation(gym.make("NarutoRecon-v0", **ENV)), period, num_candidates=count
    )
    observation, _ = wrapped.reset(seed=2)
    rng = np.random.default_rng(2)
    for _ in range(2):
        observation, *_ = wrapped.step(choose_candidate(observation["candidates"], rule, rng))
    wrapped_pose = wrapped.unwrapped.pose.copy()
    wrapped.close()

    env = gym.make("NarutoRecon-v0", **ENV)
    policy = GoalWalkerPolicy(rule=rule, stall_watchdog=False)
    policy.bind(EnvContext.from_env(env))
    observation, info = env.reset(seed=2)
    policy.reset(observation, info, seed=2)
    for _ in range(2 * period):
        observation, _, _, _, info = env.step(policy.act(observation, info))
    np.testing.assert_allclose(env.unwrapped.pose, wrapped_pose, atol=1e-6)
    env.close()


def test_it_is_registered_with_the_explorers_settings_and_checks_its_arguments(tmp_path):
    assert policy_class("goal-walker") is GoalWalkerPolicy
    policy = GoalWalkerPolicy()
    assert policy.rule == DEFAULT_RULE and policy.stall_watchdog is not None
    if PACKAGED_MODEL.exists():
        assert policy.settings == read_settings(PACKAGED_MODEL)
    with pytest.raises(ValueError, match="size-per-metre"):
        GoalWalkerPolicy(rule="best")
    with pytest.raises(FileNotFoundError, match="train_explorer.py"):
        GoalWalkerPolicy(settings_from=str(tmp_path / "model.zip"))
