"""The SB3 route of the first-hour page: frames rendered at the size handed out, and SB3's
frame stacking with the package's features extractor."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.vec_env import VecFrameStack, VecMonitor  # noqa: E402

from naruto_gym.rl.sb3 import NarutoFeaturesExtractor, make_sb3_vec_env  # noqa: E402


def test_learning_env_renders_at_the_size_it_hands_out() -> None:
    venv = make_sb3_vec_env(2, scene="two_rooms", size=32, max_episode_steps=5)
    try:
        assert venv.env.unwrapped.camera.height == 32  # not 680 resized down to 32
        assert venv.reset()["rgb"].shape[0] == 2
    finally:
        venv.close()


def test_explicit_camera_settings_are_kept() -> None:
    venv = make_sb3_vec_env(1, scene="two_rooms", size=16, image_scale=0.25,
                            max_episode_steps=3)
    try:
        assert venv.env.unwrapped.camera.height == 170
        assert venv.reset()["rgb"].shape[0] == 1
    finally:
        venv.close()


def test_frame_stacking_works_with_the_features_extractor() -> None:
    venv = VecFrameStack(VecMonitor(make_sb3_vec_env(2, scene="two_rooms", size=32,
                                                     max_episode_steps=5)), 2)
    try:
        model = PPO("MultiInputPolicy", venv, n_steps=4, batch_size=4, n_epochs=1,
                    policy_kwargs={"features_extractor_class": NarutoFeaturesExtractor,
                                   "features_extractor_kwargs": {"features_dim": 32}},
                    device="cpu")
        model.learn(8)
        observations = venv.reset()
        action, _ = model.predict(observations)
        assert np.asarray(action).shape == (2,)
    finally:
        venv.close()
