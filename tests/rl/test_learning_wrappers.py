"""Learning wrappers: spaces, values, composition, and single env == vector env."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode

import naruto_gym  # noqa: F401
from naruto_gym.sensors.pinhole import PinholeCamera
from naruto_gym.vector import NarutoReconVectorEnv
from naruto_gym.wrappers import (
    EgocentricMap,
    FlatPose,
    NormalizeDepth,
    ResizeFrames,
    for_learning,
)
from naruto_gym.wrappers.observation import MAP_OCCUPIED, MAP_SEEN, pose_to_vector

SMALL = {
    "action_mode": "discrete",
    "camera": PinholeCamera(40, 30, 20, 20, 19.5, 14.5),
    "coverage_samples": 3000,
    "panorama_shape": None,
}


def make(max_episode_steps: int = 9, **kwargs):
    return gym.make("NarutoRecon-v0", max_episode_steps=max_episode_steps, **{**SMALL, **kwargs})


def test_resize_normalize_and_flat_pose_values():
    raw_env = make()
    raw, _ = raw_env.reset(seed=1)
    env = FlatPose(NormalizeDepth(ResizeFrames(make(), 16), dtype="float"))
    observation, _ = env.reset(seed=1)
    assert env.observation_space.contains(observation)
    assert observation["rgb"].shape == (16, 16, 3) and observation["depth"].shape == (16, 16, 1)
    rows = ((np.arange(16) + 0.5) * 30 / 16).astype(int)
    columns = ((np.arange(16) + 0.5) * 40 / 16).astype(int)
    np.testing.assert_array_equal(observation["rgb"], raw["rgb"][np.ix_(rows, columns)])
    expected = np.clip(raw["depth"][np.ix_(rows, columns)] / 10.0, 0, 1)
    np.testing.assert_allclose(observation["depth"][..., 0], expected, rtol=1e-6)
    # The 6D rotation gives the rotation back (third column = cross product).
    pose = observation["pose"]
    first, second = pose[3:6], pose[6:9]
    rotation = np.stack([first, second, np.cross(first, second)], axis=1)
    np.testing.assert_allclose(rotation, raw["pose"][:3, :3], atol=1e-6)
    np.testing.assert_allclose(pose[:3], raw["pose"][:3, 3], atol=1e-6)
    uint8 = NormalizeDepth(make())
    depth = uint8.reset(seed=1)[0]["depth"]
    assert depth.dtype == np.uint8 and depth.shape == (30, 40, 1)
    assert np.array_equal(depth[..., 0] == 0, raw["depth"] == 0)


def test_composes_with_gymnasium_frame_stack_and_checker():
    env = gym.wrappers.FrameStackObservation(for_learning(make(), size=16), 3)
    observation, _ = env.reset(seed=0)
    assert observation["rgb"].shape == (3, 16, 16, 3)
    assert observation["pose"].shape == (3, 9)
    observation, *_ = env.step(6)
    assert env.observation_space.contains(observation)
    check_env(for_learning(make(), size=16), skip_render_check=True)


def test_egocentric_map_accumulates_rotates_and_restarts():
    env = EgocentricMap(make(), cells=24, cell_m=0.2)
    first, _ = env.reset(seed=2)
    assert first["map"].shape == (24, 24, 2) and first["map"][..., MAP_SEEN].any()
    assert first["map"][..., MAP_OCCUPIED].any()
    seen = [int((first["map"][..., MAP_SEEN] > 0).sum())]
    for _ in range(8):  # turn in place: more of the room is seen, nothing forgotten
        observation, *_ = env.step(6)
        seen.append(int((observation["map"][..., MAP_SEEN] > 0).sum()))
    assert seen[-1] > seen[0]
    # Half a turn of the agent turns its egocentric map by half a turn.
    env.reset(seed=2)
    for _ in range(8):
        env.step(6)
    before = env.step(6)[0]["map"]
    turned = [env.step(6)[0]["map"] for _ in range(9)][-1]
    overlap = lambda a, b: ((a > 0) & (b > 0)).sum() / max((a > 0).sum(), 1)  # noqa: E731
    assert overlap(np.rot90(before[..., 0], 2), turned[..., 0]) > overlap(
        before[..., 0], turned[..., 0]
    )
    again, _ = env.reset(seed=2)
    np.testing.assert_array_equal(again["map"], first["map"])


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_vector_wrappers_match_wrapped_single_envs(mode):
    vector = for_learning(
        NarutoReconVectorEnv(2, max_episode_steps=4, autoreset_mode=mode, **SMALL),
        size=16,
        top_down_map=True,
    )
    sync = gym.vector.SyncVectorEnv(
        [lambda: for_learning(make(max_episode_steps=4), size=16, top_down_map=True)] * 2,
        autoreset_mode=mode,
    )
    assert vector.single_observation_space == sync.single_observation_space
    got, expected = vector.reset(seed=4)[0], sync.reset(seed=4)[0]
    for key in expected:
        np.testing.assert_allclose(got[key], expected[key], atol=1e-6, err_msg=key)
    rng = np.random.default_rng(0)
    for step in range(10):
        action = rng.integers(0, 10, 2)
        got, expected = vector.step(action), sync.step(action)
        for key in expected[0]:
            np.testing.assert_allclose(
                got[0][key], expected[0][key], atol=1e-6, err_msg=f"step {step} {key}"
            )
        if mode == AutoresetMode.SAME_STEP and "_final_obs" in expected[4]:
            for i in np.flatnonzero(expected[4]["_final_obs"]):
                for key, value in expected[4]["final_obs"][i].items():
                    np.testing.assert_allclose(got[4]["final_obs"][i][key], value, atol=1e-6)


def test_pose_vector_and_bad_settings():
    pose = np.eye(4)
    pose[:3, 3] = [1, 2, 3]
    np.testing.assert_array_equal(pose_to_vector(pose), [1, 2, 3, 1, 0, 0, 0, 1, 0])
    with pytest.raises(ValueError, match="dtype"):
        NormalizeDepth(make(), dtype="int16")
    with pytest.raises(ValueError, match="size"):
        ResizeFrames(make(), 0)
    with pytest.raises(ValueError, match="depth"):
        NormalizeDepth(gym.wrappers.FilterObservation(make(), ["rgb", "pose"]))
