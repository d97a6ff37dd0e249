"""Behaviour of NarutoReconEnv: reset options, actions, bad input, coverage, info."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import naruto_gym  # noqa: F401
from naruto_gym import NarutoReconEnv
from naruto_gym.geometry.transforms import look_at_rotation, make_pose, quaternion_from_pose

SMALL = {"image_scale": 0.1, "coverage_samples": 2000}


def make_env(**kwargs) -> gym.Env:
    return gym.make("NarutoRecon-v0", **{**SMALL, **kwargs}).unwrapped


@pytest.fixture
def env():
    environment = make_env()
    environment.reset(seed=0)
    yield environment
    environment.close()


def test_observation_dtypes_and_info(env):
    observation, info = env.reset(seed=1)
    assert observation["rgb"].dtype == np.uint8
    assert observation["depth"].dtype == np.float32
    assert observation["pose"].shape == (4, 4)
    assert "panorama" in observation
    assert set(info) >= {"coverage", "collided", "path_length_m", "intrinsics"}
    assert 0.0 < info["coverage"] < 1.0
    assert info["intrinsics"]["width"] == observation["rgb"].shape[1]


def test_random_start_is_collision_free(env):
    for seed in range(5):
        observation, _ = env.reset(seed=seed)
        position = observation["pose"][:3, 3].astype(np.float64)
        assert env.collision.clearance(position) >= env.settings.start_clearance_m - 1e-4


def test_reset_with_exact_pose(env):
    position = env.pose[:3, 3]
    pose = make_pose(look_at_rotation(position, position + [1.0, 0.5, 0.0]), position)
    observation, info = env.reset(options={"pose": pose})
    np.testing.assert_allclose(observation["pose"], pose, atol=1e-6)
    assert info["path_length_m"] == 0.0


@pytest.mark.parametrize(
    "bad_pose, message",
    [
        (np.eye(3), "4x4"),
        (np.full((4, 4), np.nan), "NaN"),
        (np.diag([2.0, 1.0, 1.0, 1.0]), "rotation"),
        (make_pose(np.eye(3), [1e3, 0.0, 0.0]), "outside the scene bounds"),
    ],
)
def test_reset_rejects_bad_pose(env, bad_pose, message):
    with pytest.raises(ValueError, match=message):
        env.reset(options={"pose": bad_pose})


def test_pose_action_moves_at_most_the_limits(env):
    start = env.pose
    far_target = start[:3, 3] + np.array([5.0, 0.0, 0.0])
    rotation = Rotation.from_matrix(start[:3, :3]) * Rotation.from_euler("y", 90, degrees=True)
    action = np.concatenate([far_target, rotation.as_quat()]).astype(np.float32)
    action[:3] = np.clip(action[:3], env.action_space.low[:3], env.action_space.high[:3])
    observation, _, _, _, info = env.step(action)
    pose = observation["pose"].astype(np.float64)
    assert np.linalg.norm(pose[:3, 3] - start[:3, 3]) <= env.settings.max_translation_m + 1e-6
    angle = Rotation.from_matrix(start[:3, :3]).inv() * Rotation.from_matrix(pose[:3, :3])
    assert angle.magnitude() == pytest.approx(np.deg2rad(20.0), abs=1e-4)


def test_pose_action_reaches_a_near_target_exactly(env):
    start = env.pose
    target = start[:3, 3] + np.array([0.0, 0.0, 0.03])
    action = np.concatenate([target, quaternion_from_pose(start)]).astype(np.float32)
    observation, _, _, _, info = env.step(action)
    if not info["collided"]:
        np.testing.assert_allclose(observation["pose"][:3, 3], target, atol=1e-5)


def test_discrete_actions_follow_their_names():
    env = make_env(action_mode="discrete")
    env.reset(seed=2)
    start = env.pose
    _, _, _, _, info = env.step(4)  # move up
    if not info["collided"]:
        np.testing.assert_allclose(env.pose[:3, 3] - start[:3, 3], [0, 0, 0.1], atol=1e-6)
    before = env.pose
    env.step(6)  # turn left: yaw +20 degrees about world z, position unchanged
    np.testing.assert_allclose(env.pose[:3, 3], before[:3, 3])
    yaw_before = np.arctan2(before[1, 2], before[0, 2])
    yaw_after = np.arctan2(env.pose[1, 2], env.pose[0, 2])
    assert np.angle(np.exp(1j * (yaw_after - yaw_before))) == pytest.approx(np.deg2rad(20), 1e-6)
    for _ in range(10):
        env.step(8)  # look up, clamped
    assert np.rad2deg(np.arcsin(env.pose[2, 2])) == pytest.approx(80.0, abs=1e-4)


def test_delta_action_is_camera_frame_and_bounded():
    env = make_env(action_mode="delta")
    env.reset(seed=4)
    start = env.pose
    _, _, _, _, info = env.step(np.array([0, 0, 1, 0, 0, 0], np.float32))  # forward
    if not info["collided"]:
        np.testing.assert_allclose(env.pose[:3, 3], start[:3, 3] + 0.1 * start[:3, 2], atol=1e-6)
    start = env.pose
    env.step(np.array([1, 1, 1, 1, 1, 1], np.float32))
    assert np.linalg.norm(env.pose[:3, 3] - start[:3, 3]) <= 0.1 + 1e-6


@pytest.mark.parametrize(
    "mode, bad_action",
    [
        ("pose", np.full(7, np.nan, np.float32)),
        ("pose", np.zeros(6, np.float32)),
        ("pose", np.array([0, 0, 0, 0, 0, 0, 0], np.float32)),  # zero quaternion
        ("pose", np.array([1e4, 0, 0, 0, 0, 0, 1], np.float32)),
        ("delta", np.array([2, 0, 0, 0, 0, 0], np.float32)),
        ("delta", np.array([np.inf, 0, 0, 0, 0, 0], np.float32)),
        ("delta", "forward"),
        ("discrete", 10),
        ("discrete", -1),
        ("discrete", 1.5),
    ],
)
def test_bad_actions_raise_and_leave_env_usable(mode, bad_action):
    env = make_env(action_mode=mode)
    env.reset(seed=0)
    pose_before = env.pose
    coverage_before = env.coverage.coverage
    with pytest.raises(ValueError):
        env.step(bad_action)
    np.testing.assert_array_equal(env.pose, pose_before)
    assert env.coverage.coverage == coverage_before
    env.step(env.action_space.sample())  # still usable


def test_step_before_reset_raises():
    env = make_env()
    with pytest.raises(RuntimeError, match="reset"):
        env.step(env.action_space.sample())


def test_coverage_grows_and_reward_is_gain(env):
    env.reset(seed=5)
    total_reward, coverage = 0.0, env.coverage.coverage
    for _ in range(6):
        _, reward, _, _, info = env.step(
            np.array([0, 0, 0, 0, 1.0, 0], np.float32)
            if env.settings.action_mode == "delta"
            else _turn_in_place(env)
        )
        assert isinstance(reward, float)
        expected = 100.0 * info["coverage_gain"] - (0.1 if info["collided"] else 0.0)
        assert reward == pytest.approx(expected)
        total_reward += reward
    assert env.coverage.coverage > coverage
    assert env.coverage.coverage >= coverage + total_reward / 100.0 - 1e-9


def _turn_in_place(env) -> np.ndarray:
    turned = Rotation.from_rotvec([0, 0, np.deg2rad(20)]) * Rotation.from_matrix(env.pose[:3, :3])
    return np.concatenate([env.pose[:3, 3], turned.as_quat()]).astype(np.float32)


def test_truncates_at_registered_budget():
    env = gym.make("NarutoRecon-v0", max_episode_steps=3, **SMALL)
    env.reset(seed=0)
    results = [env.step(env.action_space.sample()) for _ in range(3)]
    assert [r[3] for r in results] == [False, False, True]
    assert not any(r[2] for r in results)


def test_invalid_configuration_errors():
    with pytest.raises(ValueError, match="action_mode"):
        make_env(action_mode="teleport")
    with pytest.raises(ValueError, match="render_mode"):
        NarutoReconEnv(render_mode="human", **SMALL)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        make_env(scene="/nonexistent/room.ply")
