"""The tools' one episode loop: the order of its calls, its hooks and its phases."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import naruto_gym  # noqa: F401  (registers the env ids)
from naruto_agent.episode_loop import (
    EpisodeHook,
    EvalPoints,
    StepRecords,
    eval_point_steps,
    run_episode_loop,
)
from naruto_agent.policies import EnvContext, make_policy

STEPS = 6


def _env(policy, steps=STEPS):
    return gym.make(
        "NarutoRecon-v0",
        scene="two_rooms",
        image_scale=0.1,
        action_mode=policy.preferred_action_mode,
        max_episode_steps=steps,
        panorama_shape=(16, 32),
        coverage_samples=2000,
    )


class Calls(EpisodeHook):
    phase = "calls"

    def __init__(self):
        self.calls = []

    def before_reset(self, env, policy):
        self.calls.append(("before_reset", policy.context.max_episode_steps))

    def on_reset(self, observation, info):
        self.calls.append(("reset", 0))

    def on_step(self, step, observation, info, last):
        self.calls.append(("step", step, last))


def test_the_loop_runs_as_a_hand_written_one():
    """Same seed, same policy: the loop's path is the one of bind, reset, act and step."""
    policy = make_policy("random")
    env = _env(policy)
    policy.bind(EnvContext.from_env(env, max_episode_steps=STEPS))
    observation, info = env.reset(seed=3, options=policy.reset_options())
    policy.reset(observation, info, seed=3)
    by_hand = [observation["pose"][:3, 3].copy()]
    for _ in range(STEPS):
        observation, _, terminated, truncated, info = env.step(policy.act(observation, info))
        by_hand.append(observation["pose"][:3, 3].copy())
        if terminated or truncated:
            break
    env.close()

    policy = make_policy("random")
    env = _env(policy)
    records, calls = StepRecords(), Calls()
    result = run_episode_loop(env, policy, STEPS, seed=3, hooks=[records, calls])
    env.close()
    assert result.steps_run == STEPS and result.truncated
    assert np.allclose(np.array(records.positions), np.array(by_hand))
    assert len(records.coverage) == STEPS + 1
    assert calls.calls[:2] == [("before_reset", STEPS), ("reset", 0)]
    assert calls.calls[2:] == [("step", step, step == STEPS) for step in range(1, STEPS + 1)]
    assert {"reset_env", "reset_policy", "policy", "env", "calls"} <= set(result.seconds)
    assert all(seconds >= 0 for seconds in result.seconds.values())


def test_eval_points_are_called_at_their_steps_and_the_last():
    policy = make_policy("random")
    env = _env(policy, steps=10)
    called = []
    points = EvalPoints(10, 3, lambda step, last: called.append((step, last)), at_last=True)
    result = run_episode_loop(env, policy, 10, seed=0, hooks=[points])
    env.close()
    assert called == [(step, False) for step in eval_point_steps(10, 3)] + [(10, True)]
    assert eval_point_steps(10, 3) == [2, 5, 8]
    assert "eval_points" in result.seconds


def test_the_loop_stops_at_max_episode_steps_and_refuses_none():
    policy = make_policy("random")
    env = _env(policy, steps=50)
    result = run_episode_loop(env, policy, 4, seed=0)
    assert result.steps_run == 4 and not result.truncated
    with pytest.raises(ValueError, match="max_episode_steps must be an integer of at least 1"):
        run_episode_loop(env, policy, 0, seed=0)
    env.close()


def test_the_context_reads_the_episode_length_from_the_time_limit_or_the_env():
    """``EnvContext.from_env`` takes the length given, else the TimeLimit's, else the env's
    own ``max_episode_steps``; the old keyword ``step_budget`` is refused with the new one."""
    from naruto_gym import NarutoReconEnv

    made = _env(make_policy("random"), steps=9)
    assert EnvContext.from_env(made).max_episode_steps == 9
    assert EnvContext.from_env(made, max_episode_steps=4).max_episode_steps == 4
    made.close()
    small = {"scene": "two_rooms", "image_scale": 0.05, "panorama_shape": None}
    assert EnvContext.from_env(NarutoReconEnv(max_episode_steps=7, **small)).max_episode_steps == 7
    assert EnvContext.from_env(NarutoReconEnv(**small)).max_episode_steps is None
    with pytest.raises(ValueError, match="'step_budget' was renamed: pass max_episode_steps=5"):
        EnvContext.from_env(made, step_budget=5)
