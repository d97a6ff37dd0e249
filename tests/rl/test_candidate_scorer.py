"""The per-candidate scorer of the decision at every goal: shared weights score each candidate
(a permutation of the candidates permutes the choice; empty slots are never chosen), PPO
learns with it on the agents stepped one decision at a time, and the explorer policy plays
the model, deciding at each goal."""

from __future__ import annotations

import numpy as np
import pytest
import torch

pytest.importorskip("stable_baselines3")

import gymnasium as gym  # noqa: E402
from gymnasium import spaces  # noqa: E402
from stable_baselines3 import PPO  # noqa: E402

from naruto_agent.policies.base import EnvContext  # noqa: E402
from naruto_agent.rl.explorer_policy import MapGoalExplorer, save_settings  # noqa: E402
from naruto_gym.rl.goal_actions import GOAL_STEPS  # noqa: E402
from naruto_gym.rl.goal_candidates import CANDIDATE_FEATURES  # noqa: E402
from naruto_gym.rl.goal_choice_sb3 import (  # noqa: E402
    CandidateScorerPolicy,
    GoalDecisionVecEnv,
)
from tests.agent.rl.small_env import ENV  # noqa: E402

SLOTS, FEATURES = 8, len(CANDIDATE_FEATURES)
SPACE = spaces.Dict(
    {
        "map": spaces.Box(0, 255, (10, 32, 32), np.uint8),
        "panorama": spaces.Box(0, 255, (1, 16, 32), np.uint8),
        "pose": spaces.Box(-np.inf, np.inf, (9,), np.float32),
        "candidates": spaces.Box(-1.0, np.inf, (SLOTS, FEATURES), np.float32),
    }
)


def _policy(seed: int = 0) -> CandidateScorerPolicy:
    torch.manual_seed(seed)
    return CandidateScorerPolicy(SPACE, spaces.Discrete(SLOTS), lambda _: 3e-4)


def _observations(rng: np.random.Generator, batch: int = 4) -> dict[str, np.ndarray]:
    observations = {
        key: np.stack([box.sample() for _ in range(batch)]) for key, box in SPACE.items()
    }
    table = rng.uniform(-1.0, 1.0, (batch, SLOTS, FEATURES)).astype(np.float32)
    table[..., 0] = 1.0
    table[:, 5:] = 0.0  # three empty slots
    observations["candidates"] = table
    return observations


def _probabilities_and_values(policy, observations):
    tensors, _ = policy.obs_to_tensor(observations)
    with torch.no_grad():
        probabilities = policy.get_distribution(tensors).distribution.probs.numpy()
        values = policy.predict_values(tensors).numpy()
    return probabilities, values


def test_permuting_the_candidates_permutes_the_choice_and_keeps_the_value():
    policy = _policy()
    # Scores far from uniform, so that the check sees the scorer's weights at work.
    torch.nn.init.normal_(policy.mlp_extractor.score[-1].weight, std=1.0)
    observations = _observations(np.random.default_rng(0))
    probabilities, values = _probabilities_and_values(policy, observations)
    order = np.random.default_rng(1).permutation(SLOTS)
    shuffled = {**observations, "candidates": observations["candidates"][:, order]}
    again, same = _probabilities_and_values(policy, shuffled)
    np.testing.assert_allclose(again, probabilities[:, order], atol=1e-6)
    np.testing.assert_allclose(same, values, atol=1e-5)
    assert probabilities[:, 5:].max() < 1e-12  # empty slots are never chosen
    assert probabilities[:, :5].std(axis=1).max() > 0.01


def test_an_untrained_scorer_chooses_about_uniformly_among_the_valid_candidates():
    probabilities, _ = _probabilities_and_values(_policy(), _observations(np.random.default_rng(2)))
    np.testing.assert_allclose(probabilities[:, :5], 0.2, atol=0.01)


def test_the_scorer_needs_one_action_per_slot():
    with pytest.raises(ValueError, match="Discrete\\(8\\)"):
        CandidateScorerPolicy(SPACE, spaces.Discrete(SLOTS + 10), lambda _: 3e-4)


def _two_agents() -> GoalDecisionVecEnv:
    """Two agents deciding at every goal in generated train rooms, 60-step episodes."""
    return GoalDecisionVecEnv(
        2,
        max_episode_steps=60,
        scenes=("procedural:room:train",),
        episodes_per_scene=1,
        camera=ENV["camera"],
        image_scale=1.0,
        coverage_samples=1000,
    )


@pytest.fixture(scope="module")
def model_path(tmp_path_factory):
    """A PPO model of the scorer after one update on two agents deciding at every goal."""
    venv = _two_agents()
    model = PPO(CandidateScorerPolicy, venv, n_steps=4, batch_size=8, n_epochs=1, seed=0)
    model.learn(8)
    path = tmp_path_factory.mktemp("goal_explorer") / "model.zip"
    model.save(path)
    save_settings(
        path,
        {
            "decision": "goal",
            "steps_per_goal": GOAL_STEPS,
            "num_candidates": 8,
            "primitive_actions": False,
        },
    )
    venv.close()
    return path


def test_the_agents_take_as_many_env_steps_as_their_goals_take(model_path):
    venv = _two_agents()
    venv.reset()
    steps, ended = [[], []], [0, 0]
    for _ in range(12):
        _, _, dones, infos = venv.step(np.zeros(2, np.int64))
        for i, info in enumerate(infos):
            steps[i].append(info["primitive_steps"])
            if dones[i]:
                assert "terminal_observation" in info and info["final_info"]["coverage"] > 0
                assert sum(steps[i]) == 60 * (ended[i] + 1)
                ended[i] += 1
    assert min(ended) >= 1 and len({s for agent in steps for s in agent}) > 2
    venv.close()


@pytest.mark.parametrize("weights", ["trained", "untrained"])
def test_the_explorer_plays_the_model_deciding_at_each_goal(model_path, weights):
    chosen: list[int] = []

    class Recording(MapGoalExplorer):
        def choose(self, observation):
            chosen.append(self.step_count)
            return super().choose(observation)

    env = gym.make("NarutoRecon-v0", **ENV, max_episode_steps=120)
    policy = Recording(str(model_path), weights=weights, stall_watchdog=False)
    assert policy.walker is None and policy.settings["decision"] == "goal"
    policy.bind(EnvContext.from_env(env))
    observation, info = env.reset(seed=0)
    policy.reset(observation, info, seed=0)
    for step in range(120):
        policy.step_count = step
        observation, _, _, _, info = env.step(policy.act(observation, info))
    gaps = np.diff(chosen)
    assert len(chosen) >= 3 and len(set(gaps.tolist())) > 1 and gaps.max() <= GOAL_STEPS
    env.close()
