"""A wrapper chain over the batched env, sharded over worker processes: the explorer's chain
gives one process's observations, rewards and infos across an episode end; bad input is
refused with what to do, and a chain a worker cannot build is raised in the caller."""

from __future__ import annotations

from functools import partial
from typing import Any

import numpy as np
import pytest

from naruto_gym.rl.explorer_env import (
    EXPLORER_ENV,
    EXPLORER_PANORAMA_HORIZON_DEG,
    shared_train_mix,
    wrap_explorer,
)
from naruto_gym.vector import make_vector_env
from naruto_gym.vector.sharded_wrapped import ShardedWrappedEnv
from tests.process_checks import alive

SETTINGS = {
    **EXPLORER_ENV,
    "max_episode_steps": 40,
    "autoreset_mode": "SameStep",
    "panorama_horizon_deg": EXPLORER_PANORAMA_HORIZON_DEG,
}
WRAP = partial(wrap_explorer, steps_per_goal=20)


def assert_same(one: Any, other: Any, where: str) -> None:
    """Nested dicts and (object) arrays equal to the bit."""
    if isinstance(one, dict):
        assert set(one) == set(other), where
        for key in one:
            assert_same(one[key], other[key], f"{where}/{key}")
        return
    if isinstance(one, tuple):
        assert len(one) == len(other), where
        for k, (a, b) in enumerate(zip(one, other, strict=True)):
            assert_same(a, b, f"{where}[{k}]")
        return
    one, other = np.asarray(one), np.asarray(other)
    if one.dtype == object:
        assert one.shape == other.shape, where
        for k, (a, b) in enumerate(zip(one.ravel(), other.ravel(), strict=True)):
            assert_same(a, b, f"{where}[{k}]")
        return
    np.testing.assert_array_equal(one, other, err_msg=where)


def test_the_explorer_chain_in_two_workers_is_the_chain_in_one_process():
    one = WRAP(make_vector_env(8, workers=1, scene=shared_train_mix(2, 2), **SETTINGS))
    sharded = ShardedWrappedEnv(WRAP, 8, 2, shared_train_mix(2, 2), **SETTINGS)
    try:
        assert sharded.num_workers == 2
        assert sharded.single_observation_space == one.single_observation_space
        assert sharded.single_action_space == one.single_action_space
        assert_same(one.reset(seed=3), sharded.reset(seed=3), "reset")
        rng = np.random.default_rng(0)
        ended = False
        for step in range(4):  # 80 env steps per agent: one episode end
            actions = rng.integers(0, one.single_action_space.n, 8)
            expected, got = one.step(actions), sharded.step(actions)
            assert_same(expected, got, f"step {step}")
            ended |= bool(np.any(expected[3]))
        assert ended
    finally:
        one.close()
        sharded.close()


def test_bad_input_is_refused_and_the_env_stays_usable():
    env = ShardedWrappedEnv(WRAP, 2, 2, "procedural:small:7", **SETTINGS)
    pids = env.worker_pids
    try:
        env.reset(seed=0)
        with pytest.raises(ValueError, match="one per agent"):
            env.step(np.zeros(3, np.int64))
        with pytest.raises(ValueError, match="reset_mask"):
            env.reset(options={"reset_mask": np.array([True, False])})
        with pytest.raises(ValueError, match="seed list"):
            env.reset(seed=[1, 2, 3])
        with pytest.raises(ValueError, match="goal actions"):
            env.step(np.array([0, 99]))
        observations, rewards, *_ = env.step(np.zeros(2, np.int64))
        assert rewards.shape == (2,) and len(observations["candidates"]) == 2
    finally:
        env.close()
    assert not [pid for pid in pids if alive(pid)]


def test_a_share_that_splits_a_scene_group_is_refused_with_what_to_do():
    with pytest.raises(ValueError, match="agents_per_scene"):
        ShardedWrappedEnv(WRAP, 8, 2, shared_train_mix(8, 2), **SETTINGS)


def test_a_chain_that_cannot_be_built_is_raised_in_the_caller():
    with pytest.raises(ValueError, match="steps_per_goal"):
        ShardedWrappedEnv(partial(wrap_explorer, steps_per_goal=30), 2, 2, "procedural:small:7",
                          **SETTINGS)
