"""``PPOExplorer`` reads its learning-observation settings from the saved model and refuses
settings the model disagrees with at load time, not mid-episode."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

pytest.importorskip("stable_baselines3")

from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.vec_env import DummyVecEnv  # noqa: E402

from naruto_agent.benchmark import build_specs, run_episode  # noqa: E402
from naruto_agent.rl.ppo_policy import LearningSettings, PPOExplorer  # noqa: E402
from naruto_gym.rl.sb3 import NarutoFeaturesExtractor  # noqa: E402

SIZE = 16
EXPLORER = "naruto_agent.rl.ppo_policy:PPOExplorer"


class _LearningSpaces(gym.Env):
    """Only the spaces of the learning observations (what a saved model keeps of its env)."""

    def __init__(self, top_down_map: bool) -> None:
        frames = {
            "rgb": spaces.Box(0, 255, (SIZE, SIZE, 3), np.uint8),
            "depth": spaces.Box(0, 255, (SIZE, SIZE, 1), np.uint8),
            "pose": spaces.Box(-np.inf, np.inf, (9,), np.float32),
        }
        if top_down_map:
            frames["map"] = spaces.Box(0, 255, (32, 32, 2), np.uint8)
        self.observation_space = spaces.Dict(frames)
        self.action_space = spaces.Discrete(10)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return self.observation_space.sample(), {}

    def step(self, action):
        return self.observation_space.sample(), 0.0, False, False, {}


@pytest.fixture(scope="module", params=[True, False], ids=["map", "no_map"])
def saved_model(request, tmp_path_factory):
    """(path, top_down_map) of a small untrained PPO saved as training saves it."""
    venv = DummyVecEnv([lambda: _LearningSpaces(request.param)])
    model = PPO("MultiInputPolicy", venv, n_steps=8, batch_size=8, device="cpu",
                policy_kwargs={"features_extractor_class": NarutoFeaturesExtractor,
                               "features_extractor_kwargs": {"features_dim": 16},
                               "net_arch": [8]})
    path = tmp_path_factory.mktemp("ppo") / "model.zip"
    model.save(path)
    return path, request.param


def test_settings_come_from_the_saved_model(saved_model):
    path, top_down_map = saved_model
    explorer = PPOExplorer(str(path))
    assert explorer.settings == LearningSettings(SIZE, top_down_map, "uint8")
    assert (explorer.learning_observation.map is not None) == top_down_map
    # Settings that agree are fine.
    PPOExplorer(str(path), size=SIZE, top_down_map=top_down_map)


def test_settings_the_model_disagrees_with_fail_at_load_time(saved_model):
    path, top_down_map = saved_model
    with pytest.raises(ValueError, match=f"pass top_down_map={top_down_map}"):
        PPOExplorer(str(path), top_down_map=not top_down_map)
    with pytest.raises(ValueError, match=f"trained on {SIZE} x {SIZE} frames, not 64: pass "
                                         f"size={SIZE}"):
        PPOExplorer(str(path), size=64)


def test_a_map_model_runs_in_the_harness_without_settings(saved_model):
    path, top_down_map = saved_model
    if not top_down_map:
        pytest.skip("the map model is the case that failed mid-episode")
    spec = build_specs(["two_rooms"], [EXPLORER], [0], 3, image_scale=0.05, reconstruct=False,
                       policy_kwargs={EXPLORER: {"model_path": str(path)}},
                       env_kwargs={"panorama_shape": [8, 16], "coverage_samples": 500})[0]
    record = run_episode(spec)
    assert record["status"] == "ok" and record["steps_run"] == 3
