"""Stable-Baselines3 on the batched vector env: the VecEnv adapter and the features extractor."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3 import PPO  # noqa: E402

from naruto_gym.rl.sb3 import NarutoFeaturesExtractor, Sb3VecEnv, make_sb3_vec_env  # noqa: E402
from naruto_gym.sensors.pinhole import PinholeCamera  # noqa: E402
from naruto_gym.vector import NarutoReconVectorEnv  # noqa: E402

SETTINGS = {
    "camera": PinholeCamera(32, 32, 16, 16, 15.5, 15.5),
    "coverage_samples": 3000,
    "max_episode_steps": 5,
}


def save_tiny_model(venv, path) -> None:
    """An untrained PPO model over the package's features extractor, saved at ``path``."""
    PPO(
        "MultiInputPolicy",
        venv,
        n_steps=8,
        batch_size=16,
        policy_kwargs={
            "features_extractor_class": NarutoFeaturesExtractor,
            "features_extractor_kwargs": {"features_dim": 32},
        },
    ).save(path)


def test_adapter_steps_like_sb3_expects():
    venv = make_sb3_vec_env(3, size=32, top_down_map=True, **SETTINGS)
    assert venv.env.unwrapped.settings.pinhole_backend == "auto"  # learning wants throughput
    observations = venv.reset()
    assert venv.observation_space.contains({k: v[0] for k, v in observations.items()})
    for _ in range(5):
        observations, rewards, dones, infos = venv.step(np.array([0, 6, 1]))
        assert rewards.shape == (3,) and len(infos) == 3
    assert dones.all()  # the budget of 5 steps ends every episode together
    for info in infos:
        assert info["TimeLimit.truncated"]
        assert info["terminal_observation"]["rgb"].shape == (32, 32, 3)
        assert info["terminal_observation"]["pose"].shape == (9,)
        assert 0.0 <= info["final_info"]["coverage"] <= 1.0
    # The observation returned with done is the new episode's first one (its step is 0).
    assert all(info["step"] == 0 for info in infos)
    assert not np.array_equal(observations["pose"][0], infos[0]["terminal_observation"]["pose"])


def test_ppo_learns_a_few_updates_with_the_features_extractor(tmp_path):
    venv = make_sb3_vec_env(2, size=32, top_down_map=True, **SETTINGS)
    model = PPO(
        "MultiInputPolicy",
        venv,
        n_steps=8,
        batch_size=16,
        n_epochs=1,
        seed=0,
        policy_kwargs={
            "features_extractor_class": NarutoFeaturesExtractor,
            "features_extractor_kwargs": {"features_dim": 32},
        },
    )
    model.learn(32)
    model.save(tmp_path / "model.zip")
    loaded = PPO.load(tmp_path / "model.zip")
    actions, _ = loaded.predict(venv.reset(), deterministic=True)
    assert actions.shape == (2,) and np.all((actions >= 0) & (actions < 10))


def test_adapter_refuses_next_step_autoreset():
    with pytest.raises(ValueError, match="SAME_STEP"):
        Sb3VecEnv(NarutoReconVectorEnv(1, action_mode="discrete", **SETTINGS))


def test_saved_model_acts_as_a_harness_policy(tmp_path):
    import gymnasium as gym

    from naruto_agent.policies import EnvContext
    from naruto_agent.rl.ppo_policy import PPOExplorer

    camera = PinholeCamera().scaled(0.05)
    venv = make_sb3_vec_env(2, size=32, camera=camera, coverage_samples=2000, max_episode_steps=5)
    save_tiny_model(venv, tmp_path / "m")
    env = gym.make(
        "NarutoRecon-v0",
        action_mode="discrete",
        camera=camera,
        coverage_samples=2000,
        max_episode_steps=5,
    )
    policy = PPOExplorer(str(tmp_path / "m.zip"), size=32)
    policy.bind(EnvContext.from_env(env))
    observation, info = env.reset(seed=0)
    policy.reset(observation, info, seed=0)
    for _ in range(3):  # raw observations (panorama on, 34 x 60 frames) are transformed
        observation, *_, info = env.step(int(policy.act(observation, info)))


def test_a_model_trained_with_the_map_acts_with_the_map_it_builds(tmp_path):
    """``PPOExplorer(top_down_map=True)`` gives the model the egocentric map the training
    chain gave it: the same map as the single-env wrappers build from the same frames."""
    import gymnasium as gym

    from naruto_agent.policies import EnvContext
    from naruto_agent.rl.ppo_policy import PPOExplorer
    from naruto_gym.wrappers import LearningObservation, for_learning

    camera = PinholeCamera().scaled(0.05)
    venv = make_sb3_vec_env(
        2, size=32, top_down_map=True, camera=camera, coverage_samples=2000, max_episode_steps=5
    )
    save_tiny_model(venv, tmp_path / "m")
    settings = {
        "action_mode": "discrete",
        "camera": camera,
        "coverage_samples": 2000,
        "max_episode_steps": 6,
    }
    env = gym.make("NarutoRecon-v0", **settings)
    wrapped = for_learning(gym.make("NarutoRecon-v0", **settings), size=32, top_down_map=True)
    policy = PPOExplorer(str(tmp_path / "m.zip"), size=32, top_down_map=True)
    policy.bind(EnvContext.from_env(env))
    observation, info = env.reset(seed=0)
    expected, _ = wrapped.reset(seed=0)
    policy.reset(observation, info, seed=0)
    seen = []
    for _ in range(4):
        given = policy.learning_observation(observation)
        assert np.array_equal(given["map"], expected["map"])
        seen.append(int((given["map"][..., 0] > 0).sum()))
        action = int(policy.act(observation, info))
        observation, *_, info = env.step(action)
        expected, *_ = wrapped.step(action)
    assert seen[-1] > 0
    with pytest.raises(RuntimeError, match="start_episode"):
        LearningObservation(32, top_down_map=True)(observation)
