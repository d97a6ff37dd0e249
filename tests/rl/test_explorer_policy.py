"""The registered explorer policy: it acts as the training wrappers do, and loads a model with
the settings saved beside it."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3 import PPO  # noqa: E402

from naruto_agent.policies.base import EnvContext  # noqa: E402
from naruto_agent.policies.registry import policy_class  # noqa: E402
from naruto_agent.policies.watchdog import StallWatchdogConfig  # noqa: E402
from naruto_agent.rl.explorer_policy import (  # noqa: E402
    PACKAGED_MODEL,
    MapGoalExplorer,
    export_checkpoint,
    save_settings,
)
from naruto_gym.rl.egocentric_map import EgocentricMapObservation  # noqa: E402
from naruto_gym.rl.explorer_sb3 import (  # noqa: E402
    ExplorerFeaturesExtractor,
    make_explorer_vec_env,
)
from naruto_gym.rl.goal_actions import GoalActions  # noqa: E402
from naruto_gym.rl.goal_planner import TURN_LEFT  # noqa: E402
from naruto_gym.sensors.pinhole import PinholeCamera  # noqa: E402

CAMERA = PinholeCamera(16, 16, 8, 8, 7.5, 7.5)
ENV = {
    "action_mode": "discrete",
    "camera": CAMERA,
    "panorama_shape": (32, 64),
    "coverage_samples": 1000,
    "scene": "procedural:room:7",
}
SETTINGS = {
    "steps_per_goal": 5,
    "num_candidates": 4,
    "primitive_actions": True,
    "panorama_shape": [32, 64],
}


@pytest.fixture(scope="module")
def model_path(tmp_path_factory):
    """An untrained PPO model of the explorer's spaces (4 candidates, K = 5), saved."""
    venv = make_explorer_vec_env(
        1,
        steps_per_goal=5,
        num_candidates=4,
        max_episode_steps=20,
        scene="procedural:room",
        camera=CAMERA,
        image_scale=1.0,
        coverage_samples=1000,
    )
    model = PPO(
        "MultiInputPolicy",
        venv,
        n_steps=8,
        batch_size=8,
        device="cpu",
        seed=0,
        policy_kwargs={
            "features_extractor_class": ExplorerFeaturesExtractor,
            "features_extractor_kwargs": {"features_dim": 32},
        },
    )
    path = tmp_path_factory.mktemp("explorer") / "model.zip"
    model.save(path)
    save_settings(path, SETTINGS)
    venv.close()
    return path


def test_the_name_explorer_is_registered():
    assert policy_class("explorer") is MapGoalExplorer


def test_the_policy_walks_as_the_training_wrappers_do(model_path):
    model = PPO.load(model_path, device="cpu")
    wrapped = GoalActions(
        EgocentricMapObservation(gym.make("NarutoRecon-v0", **ENV)),
        steps_per_goal=5,
        num_candidates=4,
    )
    observation, _ = wrapped.reset(seed=2)
    actions = []
    for _ in range(6):
        action, _ = model.predict(observation, deterministic=True)
        actions.append(int(action))
        observation, *_ = wrapped.step(int(action))
    wrapped_pose = wrapped.unwrapped.pose.copy()
    wrapped.close()

    env = gym.make("NarutoRecon-v0", **ENV)
    policy = MapGoalExplorer(str(model_path), deterministic=True)
    policy.bind(EnvContext.from_env(env))
    observation, info = env.reset(seed=2)
    policy.reset(observation, info)
    refusals = 0
    for _ in range(30):
        observation, _, _, _, info = env.step(policy.act(observation, info))
        refusals += int(info["collided"])
    assert len(set(actions)) > 1  # the model chose among the candidates, not one action
    np.testing.assert_allclose(env.unwrapped.pose, wrapped_pose, atol=1e-6)
    assert refusals <= 1
    env.close()


def test_a_full_size_panorama_is_subsampled_to_the_trained_one(model_path):
    env = gym.make("NarutoRecon-v0", **{**ENV, "panorama_shape": (64, 128)})
    policy = MapGoalExplorer(str(model_path))
    policy.bind(EnvContext.from_env(env))
    observation, info = env.reset(seed=0)
    policy.reset(observation, info, seed=0)
    assert env.action_space.contains(policy.act(observation, info))
    odd = gym.make("NarutoRecon-v0", **{**ENV, "panorama_shape": (48, 64)})
    policy.bind(EnvContext.from_env(odd))
    observation, info = odd.reset(seed=0)
    with pytest.raises(ValueError, match="panorama_shape"):
        policy.reset(observation, info)
    env.close()
    odd.close()


def test_a_model_trained_on_the_panorama_band_acts_the_same_on_a_full_panorama(
    model_path, tmp_path
):
    """Settings with ``panorama_horizon_deg`` (the training env cast only that band): the
    policy shows the model and its map the band, so an env that casts every row and one that
    casts only the band give the same walk."""
    banded = tmp_path / "model.zip"
    banded.write_bytes(model_path.read_bytes())
    save_settings(banded, {**SETTINGS, "panorama_horizon_deg": 30})
    poses = []
    for horizon in (None, 30):
        env = gym.make("NarutoRecon-v0", **ENV, panorama_horizon_deg=horizon)
        policy = MapGoalExplorer(str(banded), deterministic=True)
        policy.bind(EnvContext.from_env(env))
        observation, info = env.reset(seed=1)
        policy.reset(observation, info, seed=1)
        for _ in range(15):
            observation, _, _, _, info = env.step(policy.act(observation, info))
        poses.append(env.unwrapped.pose.copy())
        env.close()
    np.testing.assert_array_equal(poses[0], poses[1])


def test_a_model_and_settings_that_disagree_are_refused(model_path, tmp_path):
    with pytest.raises(FileNotFoundError, match="train_explorer.py"):
        MapGoalExplorer(str(tmp_path / "missing.zip"))
    other = tmp_path / "model.zip"
    other.write_bytes(model_path.read_bytes())
    (tmp_path / "model.json").write_text(json.dumps({**SETTINGS, "num_candidates": 8}))
    with pytest.raises(ValueError, match="18"):
        MapGoalExplorer(str(other))
    (tmp_path / "model.json").write_text(json.dumps({**SETTINGS, "goal_grid": 4}))
    with pytest.raises(ValueError, match="num_candidates"):
        MapGoalExplorer(str(other))


def test_without_a_path_it_loads_the_packaged_checkpoint_or_says_how_to_train():
    if PACKAGED_MODEL.exists():
        assert MapGoalExplorer().steps_per_goal > 0
        assert PACKAGED_MODEL.stat().st_size <= 5 * 2**20
    else:
        with pytest.raises(FileNotFoundError, match="train_explorer.py"):
            MapGoalExplorer()


def test_an_exported_checkpoint_has_no_optimiser_state_and_acts_the_same(model_path, tmp_path):
    exported = export_checkpoint(model_path, tmp_path / "explorer.zip")
    assert PPO.load(exported, device="cpu").policy.optimizer.state_dict()["state"] == {}
    assert json.loads((tmp_path / "explorer.json").read_text())["num_candidates"] == 4
    original, small = MapGoalExplorer(str(model_path)), MapGoalExplorer(str(exported))
    observation = {
        key: np.asarray(v)[None] for key, v in small.model.observation_space.sample().items()
    }
    np.testing.assert_array_equal(
        original.model.predict(observation, deterministic=True)[0],
        small.model.predict(observation, deterministic=True)[0],
    )


def test_the_explorer_watches_for_stalls_by_default():
    assert MapGoalExplorer().stall_watchdog.config == StallWatchdogConfig()
    assert MapGoalExplorer(stall_watchdog=False).stall_watchdog is None


def test_the_explorer_recovers_from_a_stall_and_leaves_the_spot():
    """Held on one spot (the env is sent a turn in place whatever the explorer asks) until its
    watchdog fires (within a window); its recovery then walks more than 0.5 m away within 20
    steps (turns included: the explorer moves in discrete steps)."""
    policy = MapGoalExplorer()
    env = gym.make("NarutoRecon-v0", **{**ENV, "scene": "replica_like_room"})
    policy.bind(EnvContext.from_env(env, max_episode_steps=200))
    observation, info = env.reset(seed=3)
    policy.reset(observation, info, seed=3)
    for _ in range(10):  # under way first
        observation, _, _, _, info = env.step(policy.act(observation, info))
    spot = observation["pose"][:3, 3].copy()
    for _ in range(StallWatchdogConfig().window_steps + 1):
        action = policy.act(observation, info)
        if policy.stall_events:
            break
        observation, _, _, _, info = env.step(TURN_LEFT)
    assert len(policy.stall_events) == 1 and policy.stall_events[0].recovery
    farthest = 0.0
    for _ in range(20):
        observation, _, _, _, info = env.step(action)
        farthest = max(farthest, float(np.linalg.norm(observation["pose"][:3, 3] - spot)))
        action = policy.act(observation, info)
    assert farthest > 0.5, policy.stall_events
    env.close()


def test_the_features_extractor_runs_channels_last_with_channel_first_results() -> None:
    """Its CNNs take channels-last inputs (about twice as fast on CPU); the features are those
    of the same layers run on channel-first inputs."""
    import torch

    model = PPO.load(PACKAGED_MODEL, device="cpu")
    extractor = model.policy.features_extractor
    assert isinstance(extractor, ExplorerFeaturesExtractor)
    generator = torch.Generator().manual_seed(0)
    observations = {
        key: torch.rand((5, *space.shape), generator=generator)
        for key, space in model.observation_space.spaces.items()
    }
    seen = []
    hook = extractor.map[0].register_forward_pre_hook(lambda _, inputs: seen.append(inputs[0]))
    with torch.no_grad():
        features = extractor(observations)
        expected = extractor.head(torch.cat([
            _channel_first(extractor.map, observations["map"]),
            _channel_first(extractor.panorama, observations["panorama"]),
            extractor.pose(observations["pose"].flatten(1)),
            extractor.candidates(observations["candidates"].flatten(1)),
        ], 1))
    hook.remove()
    assert seen[0].is_contiguous(memory_format=torch.channels_last)
    assert torch.allclose(features, expected, atol=1e-5)


def _channel_first(layers, images):
    """``layers`` run on channel-first (default contiguous) inputs and activations."""
    import torch

    for layer in layers:
        images = layer(images.contiguous(memory_format=torch.contiguous_format))
    return images
