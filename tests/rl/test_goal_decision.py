"""The decision at every goal (``decision="goal"``): the chosen goal alone decides where the
steps go, a decision lasts until its goal is done, the harness policy decides step for step
as the wrapper does (``out_of_sight``, the column it adds, is tested with the candidates in
test_goal_actions.py)."""

from __future__ import annotations

import copy

import gymnasium as gym
import numpy as np
import pytest

from naruto_agent.policies.base import EnvContext
from naruto_agent.rl.scripted_explorer import GoalWalkerPolicy, choose_candidate
from naruto_gym.rl.egocentric_map import EgocentricMapObservation
from naruto_gym.rl.goal_actions import GOAL_STEPS, GoalActions, VectorGoalActions
from naruto_gym.rl.goal_candidates import CANDIDATE_FEATURES, INTERVAL_FEATURES
from naruto_gym.rl.goal_walker import AWAIT_DECISION
from tests.agent.rl.small_env import ENV

_VALID = CANDIDATE_FEATURES.index("valid")


def _stack(decision: str = "goal", steps: int = 200, scene: str = ENV["scene"]) -> GoalActions:
    env = gym.make("NarutoRecon-v0", **{**ENV, "scene": scene}, max_episode_steps=steps)
    return GoalActions(
        EgocentricMapObservation(env), GOAL_STEPS, primitive_actions=False, decision=decision
    )


def _position(stack: GoalActions) -> np.ndarray:
    return stack.unwrapped.pose[:2, 3].copy()


def test_the_walker_walks_the_chosen_goal_alone_and_asks_for_the_next():
    stack = _stack(scene="procedural:small:3")
    stack.reset(seed=0)
    observation, *_ = stack.step(0)
    valid = np.flatnonzero(observation["candidates"][:, _VALID] > 0)
    assert len(valid) >= 3 and observation["candidates"].shape[1] == len(CANDIDATE_FEATURES)
    for slot in (int(valid[0]), int(valid[-1])):
        done = {}
        for decision in ("goal", "interval"):
            trial = copy.deepcopy(stack)
            trial.walker.decision = decision
            before = trial.walker.done[0].copy()
            _, _, _, _, info = trial.step(slot)
            done[decision] = {tuple(c) for c in np.argwhere(trial.walker.done[0] & ~before)}
            if decision == "goal":
                # Ended once the goal was done (viewed, given up or lost), well before the
                # cap; the walker waits for the agent's next goal.
                assert info["primitive_steps"] < GOAL_STEPS
                assert int(trial.walker.next_moves()[0]) == AWAIT_DECISION
            trial.close()
        chosen = tuple(stack.walker.clusters[0, slot])
        assert done["goal"] <= {chosen}  # no cluster but the chosen one was walked to
        # The interval decision walks on to the nearest candidates by itself.
        assert len(done["interval"] - {chosen}) >= 2
    stack.close()


def test_decisions_come_at_each_goal_not_every_k_steps():
    stack = _stack(steps=240)
    observation, _ = stack.reset(seed=1)
    rng = np.random.default_rng(1)
    lengths, refusals = [], 0
    while True:
        action = choose_candidate(observation["candidates"], "random", rng)
        observation, _, terminated, truncated, info = stack.step(action)
        lengths.append(info["primitive_steps"])
        refusals += info["refusals"]
        if terminated or truncated:
            break
        if info["primitive_steps"] < GOAL_STEPS:
            # Ended early: the walker had done the goal and was waiting for the next one.
            assert int(stack.walker.next_moves()[0]) == AWAIT_DECISION
    assert sum(lengths) == 240 and len(set(lengths)) > 3 and len(lengths) >= 4
    assert refusals == 0  # the walker's refusal memory and safe moves as ever
    stack.close()


def test_the_interval_decision_keeps_its_table_and_the_batched_env_refuses_the_goal_one():
    stack = _stack(decision="interval")
    observation, _ = stack.reset(seed=0)
    assert observation["candidates"].shape == (8, len(INTERVAL_FEATURES))
    stack.close()
    with pytest.raises(ValueError, match="decision"):
        VectorGoalActions(None, 20, decision="goal")  # type: ignore[arg-type]


def test_the_goal_walker_decides_at_each_goal_step_for_step_as_the_wrapper():
    rule, decisions = "largest", 4
    stack = _stack()
    observation, _ = stack.reset(seed=2)
    rng = np.random.default_rng(2)
    steps = 0
    for _ in range(decisions):
        action = choose_candidate(observation["candidates"], rule, rng)
        observation, _, _, _, info = stack.step(action)
        steps += info["primitive_steps"]
    wrapped_pose = stack.unwrapped.pose.copy()
    stack.close()

    env = gym.make("NarutoRecon-v0", **ENV, max_episode_steps=200)
    policy = GoalWalkerPolicy(rule=rule, stall_watchdog=False, decision="goal")
    assert policy.settings["decision"] == "goal" and policy.steps_per_goal == GOAL_STEPS
    policy.bind(EnvContext.from_env(env))
    observation, info = env.reset(seed=2)
    policy.reset(observation, info, seed=2)
    for _ in range(steps):
        observation, _, _, _, info = env.step(policy.act(observation, info))
    np.testing.assert_allclose(env.unwrapped.pose, wrapped_pose, atol=1e-6)
    env.close()
    with pytest.raises(ValueError, match="decision"):
        GoalWalkerPolicy(decision="sometimes")
