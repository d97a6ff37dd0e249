"""The RLlib example trains on a local Ray instance, each env runner stepping one batched env.

Skipped where RLlib does not import (the main test environment has ``ray[default]`` only);
``scripts/run_tests.sh`` runs it in a second environment with ``ray[rllib]`` and the Gymnasium
RLlib pins (see ``scripts/rllib_env.sh``)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from tests.scripts import load_script

pytest.importorskip("ray.rllib.algorithms.ppo", reason="needs naruto-gym[ray] (Ray + RLlib)")

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "rllib_ppo.py"


def _example():
    return load_script(EXAMPLE, "rllib_ppo")


def _runner_env_type(runner) -> str:
    return type(runner.env.unwrapped).__name__


@pytest.mark.slow
def test_a_remote_env_runner_steps_the_batched_env_and_ppo_trains(monkeypatch):
    # Ray's workers import naruto_gym: this checkout's, as the test process does.
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]))
    example = _example()
    args = example.Args(iterations=1, size=8, max_episode_steps=10, train_batch_size=64,
                        minibatch_size=32, num_env_runners=1, num_envs_per_env_runner=4,
                        num_cpus=2, seed=0)
    ray, PPOConfig, register_env = example.import_rllib()  # noqa: N806
    register_env(example.ENV_NAME, example.make_rllib_env)
    example.init_ray(ray, args)
    try:
        algorithm = example.build_algorithm(PPOConfig, args)
        try:
            envs = algorithm.env_runner_group.foreach_env_runner(
                _runner_env_type, local_env_runner=False)
            assert envs == ["NarutoReconVectorEnv"]
            result = algorithm.train()
        finally:
            algorithm.stop()
    finally:
        ray.shutdown()
    runners = result["env_runners"]
    assert runners["num_env_steps_sampled_lifetime"] >= 64
    assert runners["num_episodes_lifetime"] >= 4  # 4 agents, episodes of 10 steps


@pytest.mark.slow
def test_main_trains_in_the_driver_with_the_batched_env(capsys):
    example = _example()
    results = example.main(example.Args(iterations=1, size=8, max_episode_steps=10,
                                        train_batch_size=40, minibatch_size=20,
                                        num_envs_per_env_runner=2, num_cpus=2))
    assert results[0]["env_runners"]["num_env_steps_sampled_lifetime"] >= 40
    assert "iteration 1: env steps" in capsys.readouterr().out


def test_a_bad_vectorization_mode_is_refused_before_ray_starts():
    example = _example()
    with pytest.raises(ValueError, match="vectorization_mode must be one of"):
        example.main(example.Args(vectorization_mode="threads"))
