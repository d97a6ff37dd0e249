"""Policy interface, adapters and the three baselines, on small cheap envs."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import naruto_gym  # noqa: F401  (registers the env ids)
from naruto_agent.policies import (
    CallablePolicy,
    EnvContext,
    FrontierPolicy,
    PassivePolicy,
    RandomPolicy,
    SB3Policy,
    as_policy,
    load_trajectory,
    make_policy,
    pose_action,
    subsample_poses,
)
from naruto_gym.geometry.transforms import pose_from_position_quaternion
from tests.agent.synthetic_panoramas import floor_panorama

CHEAP = {"image_scale": 0.1, "panorama_shape": (16, 32), "coverage_samples": 3000}


def make_env(policy_mode: str = "pose", scene: str = "two_rooms", steps: int = 50, **kwargs):
    return gym.make(
        "NarutoRecon-v0",
        scene=scene,
        action_mode=policy_mode,
        max_episode_steps=steps,
        **{**CHEAP, **kwargs},
    )


def rollout(env, policy, steps: int, seed: int = 0):
    """Run a policy; returns the poses (start included), infos and the policy."""
    policy.bind(EnvContext.from_env(env, max_episode_steps=steps))
    observation, info = env.reset(seed=seed, options=policy.reset_options())
    policy.reset(observation, info, seed=seed)
    poses, infos = [observation["pose"].astype(np.float64)], [info]
    for _ in range(steps):
        observation, _, terminated, truncated, info = env.step(policy.act(observation, info))
        poses.append(observation["pose"].astype(np.float64))
        infos.append(info)
        if terminated or truncated:
            break
    return np.array(poses), infos


# -- interface and adapters -------------------------------------------------------------
def test_callable_policy_with_and_without_info():
    env = make_env()
    seen_infos = []

    def stay(observation, info):
        seen_infos.append(info)
        return pose_action(observation["pose"])

    poses, _ = rollout(env, CallablePolicy(stay), 3)
    np.testing.assert_allclose(poses[-1], poses[0], atol=1e-5)
    assert len(seen_infos) == 3 and "coverage" in seen_infos[0]

    def forward_only(observation):  # one argument: no info passed
        pose = observation["pose"].astype(np.float64)
        pose[:3, 3] += pose[:3, 2] * 0.05
        return pose_action(pose)

    policy = as_policy(forward_only)
    assert isinstance(policy, CallablePolicy)
    poses, infos = rollout(env, policy, 2)
    moved = np.linalg.norm(poses[-1][:3, 3] - poses[0][:3, 3])
    assert moved > 0.0 or infos[-1]["collided"]
    env.close()


def test_policy_refuses_an_unsupported_action_mode():
    env = make_env("discrete")
    with pytest.raises(ValueError, match="action_mode='pose'"):
        RandomPolicy(seed=0).bind(EnvContext.from_env(env))
    env.close()


def test_sb3_model_is_wrapped_and_acts_in_discrete_mode():
    sb3 = pytest.importorskip("stable_baselines3")
    env = make_env("discrete", image_scale=0.06, panorama_shape=None)
    model = sb3.PPO("MultiInputPolicy", env, n_steps=8, batch_size=8, device="cpu", seed=0)
    policy = as_policy(model)
    assert isinstance(policy, SB3Policy) and policy.action_modes == ("discrete",)
    poses, infos = rollout(env, policy, 4)
    assert len(poses) == 5 and all("coverage" in info for info in infos)
    # Deterministic actions of a fixed model: the same rollout twice.
    again, _ = rollout(env, policy, 4)
    np.testing.assert_allclose(again, poses, atol=1e-6)
    env.close()


def test_make_policy_by_name_and_import_path():
    assert isinstance(make_policy("random", seed=3), RandomPolicy)
    assert isinstance(make_policy("naruto_agent.policies:FrontierPolicy"), FrontierPolicy)
    with pytest.raises(ValueError, match="unknown policy"):
        make_policy("nope")


# -- random ------------------------------------------------------------------------------
def _context(bounds=((0.0, 0.0, 0.0), (5.0, 5.0, 3.0))):
    bounds = np.array(bounds)
    space = gym.spaces.Box(
        np.concatenate([bounds[0], -np.ones(4)]).astype(np.float32),
        np.concatenate([bounds[1], np.ones(4)]).astype(np.float32),
    )
    from naruto_gym.sensors.pinhole import PinholeCamera

    return EnvContext("pose", space, bounds, PinholeCamera().scaled(0.1))


def test_random_picks_a_new_direction_away_from_a_block():
    policy = RandomPolicy(seed=5, min_run_steps=50, max_run_steps=50)
    policy.bind(_context())
    pose = np.eye(4)
    pose[:3, 3] = (2.5, 2.5, 1.5)
    observation = {"pose": pose.astype(np.float32)}
    policy.reset(observation, {}, seed=5)
    first = policy.direction.copy()
    policy.act(observation, {"collided": False})
    np.testing.assert_allclose(policy.direction, first)  # no block: the run goes on
    policy.act(observation, {"collided": True})
    assert policy.turns_after_block == 1
    assert float(policy.direction @ first) < np.cos(np.deg2rad(60.0)) + 1e-9


def test_random_walk_sweeps_its_camera_from_side_to_side_within_the_turn_limit():
    """The camera swings up to ``sweep_yaw_deg`` either side of the run's heading (a look
    only ahead sees nothing new crossing a seen room); 0 looks straight ahead."""

    def yaw_offsets(**settings):
        policy = RandomPolicy(seed=5, min_run_steps=60, max_run_steps=60, stall_watchdog=False,
                              **settings)  # the pose is held: no stall recovery
        policy.bind(_context())
        pose = np.eye(4)
        pose[:3, 3] = (2.5, 2.5, 1.5)
        observation = {"pose": pose.astype(np.float32)}
        policy.reset(observation, {}, seed=5)
        heading = np.arctan2(policy.direction[1], policy.direction[0])
        offsets = []
        for _ in range(32):
            action = policy.act(observation, {"collided": False})
            looks = pose_from_position_quaternion(action[:3], action[3:])[:3, 2]  # viewing axis
            yaw = np.arctan2(looks[1], looks[0]) - heading
            offsets.append(np.degrees(np.arctan2(np.sin(yaw), np.cos(yaw))))
        return np.array(offsets)

    swept = yaw_offsets()
    assert swept.max() > 40.0 and swept.min() < -40.0
    assert np.abs(swept).max() <= 45.0 + 1e-3
    assert np.abs(np.diff(swept)).max() <= 20.0  # inside the env's turn limit
    assert np.abs(yaw_offsets(sweep_yaw_deg=0.0)).max() < 1e-3
    with pytest.raises(ValueError, match="sweep_period_steps"):
        RandomPolicy(sweep_period_steps=1)


def test_random_walk_does_not_push_against_walls_and_is_seeded():
    env = make_env(steps=120)
    poses, infos = rollout(env, RandomPolicy(), 120, seed=4)
    collided = np.array([info["collided"] for info in infos[1:]])
    # Never more than two blocked steps in a row: it turns away instead of pushing on.
    longest = max(
        (len(run) for run in "".join("x" if c else "." for c in collided).split(".")), default=0
    )
    assert longest <= 2
    assert infos[-1]["path_length_m"] > 0.5 * 0.1 * 120
    again, _ = rollout(env, RandomPolicy(), 120, seed=4)
    np.testing.assert_allclose(again, poses, atol=1e-6)
    other, _ = rollout(env, RandomPolicy(), 120, seed=5)
    assert not np.allclose(other[-1], poses[-1])
    env.close()


def test_random_walk_reads_its_way_from_the_panorama_and_bumps_far_less():
    """With the depth panorama the walk draws a new run instead of a move it shows blocked
    (a surface in the way, or leaving the scan): far fewer refused moves than the same walk
    without the check, on the closed scene and with its ceiling and part of its floor gone."""
    for scene in ("two_rooms", "two_rooms:no_ceiling+holes"):
        env = make_env(scene=scene, steps=150, panorama_shape=(32, 64))
        refused = {}
        for check in (True, False):
            policy = RandomPolicy(panorama_check=check)
            _, infos = rollout(env, policy, 150, seed=4)
            refused[check] = sum(bool(info["collided"]) for info in infos[1:])
            assert (policy.turns_before_block > 0) == check
        env.close()
        assert refused[False] >= 5, refused
        assert refused[True] <= refused[False] / 3, (scene, refused)


def test_random_walk_turns_in_place_where_every_way_looks_blocked_then_lets_the_env_decide():
    """Surfaces all around, closer than a step: no redrawn run is clear. The walk turns in
    place for ``max_held_moves`` steps (drawing new runs at each), then sends a move."""
    policy = RandomPolicy(seed=3, max_held_moves=2)
    context = _context()
    policy.bind(context)
    pose = np.eye(4)
    pose[:3, 3] = (2.5, 2.5, 1.5)
    panorama = np.full((16, 32), context.agent_radius_m + 0.005, np.float32)
    observation = {"pose": pose.astype(np.float32), "panorama": panorama}
    policy.reset(observation, {}, seed=3)
    targets = [policy.act(observation, {"collided": False})[:3] for _ in range(3)]
    np.testing.assert_allclose(targets[0], pose[:3, 3], atol=1e-6)
    np.testing.assert_allclose(targets[1], pose[:3, 3], atol=1e-6)
    assert np.linalg.norm(targets[2] - pose[:3, 3]) > 0.5 * context.max_translation_m
    assert policy.turns_before_block == 3 * policy.config.max_redraws
    assert policy.held_steps == 0  # the count starts again after the move is sent
    # Without the panorama the walk never holds.
    policy.reset({"pose": pose.astype(np.float32)}, {}, seed=3)
    assert np.linalg.norm(policy.act({"pose": pose.astype(np.float32)})[:3] - pose[:3, 3]) > 0


def _panorama_with_one_opening(opening_half_deg: float = 60.0) -> np.ndarray:
    """A 16 x 32 panorama: floor 0.3 m below, surfaces 9 cm away on every side but one
    opening towards +x (``opening_half_deg`` either side, from the floor's edge up)."""
    from naruto_gym.sensors.panorama import EquirectangularCamera

    rays = EquirectangularCamera(16, 32).ray_directions.astype(np.float64).reshape(-1, 3)
    azimuth = np.degrees(np.arctan2(rays[:, 1], rays[:, 0]))
    distance = np.full(len(rays), 0.09)
    down = rays[:, 2] <= -0.3
    distance[down] = 0.3 / -rays[down, 2]
    distance[~down & (np.abs(azimuth) < opening_half_deg)] = 3.0
    return distance.reshape(16, 32).astype(np.float32)


def test_random_walk_sweeps_all_around_for_the_one_clear_way_before_it_holds():
    """One narrow way out: where the random draws all miss it, the sweep of headings finds
    it and the walk moves through it at once (without the sweep it would turn in place)."""
    context = _context()
    pose = np.eye(4)
    pose[:3, 3] = (2.5, 2.5, 1.5)
    observation = {"pose": pose.astype(np.float32), "panorama": _panorama_with_one_opening()}
    swept = 0
    for seed in range(8):
        policy = RandomPolicy(seed=seed)
        policy.bind(context)
        policy.reset(observation, {}, seed=seed)
        move = policy.act(observation, {"collided": False})[:3] - pose[:3, 3]
        assert np.linalg.norm(move) > 0.5 * context.max_translation_m, seed
        assert abs(np.degrees(np.arctan2(move[1], move[0]))) < 20.0, (seed, move)
        assert policy.held_steps == 0
        if policy.turns_before_block == policy.config.max_redraws:
            swept += 1
            unswept = RandomPolicy(seed=seed, sweep_headings=0)
            unswept.bind(context)
            unswept.reset(observation, {}, seed=seed)
            held = unswept.act(observation, {"collided": False})[:3]
            np.testing.assert_allclose(held, pose[:3, 3], atol=1e-6)
    assert swept >= 1  # some seeds' random draws all missed the opening


def test_surface_top_is_the_height_under_most_of_the_surface_area_shown():
    """A floor 1 m below: its height. A small patch 3 m up (a stray fragment) barely raises
    the quantile; the highest point it shows would."""
    from naruto_agent.guards.panorama_clearance import surface_top

    panorama = floor_panorama()
    assert surface_top(panorama) == pytest.approx(-1.0, abs=1e-3)
    panorama[0, :4] = 3.0  # straight up, a few pixels
    assert surface_top(panorama) == pytest.approx(-1.0, abs=1e-3)
    assert surface_top(panorama, quantile=1.0) > 2.9
    assert surface_top(np.zeros((8, 16), np.float32)) == -np.inf


def test_random_walk_turns_back_under_an_open_top_before_the_env_refuses():
    """The single room without a ceiling, seed 9: the walk's climbs reached the wall tops and
    the env refused 12 of them as escapes; read from the panorama, none."""
    env = make_env(scene="replica_like_room:no_ceiling", steps=300, image_scale=0.25,
                   panorama_shape=(64, 128))
    refused = {}
    for check in (True, False):
        _, infos = rollout(env, RandomPolicy(panorama_check=check), 300, seed=9)
        refused[check] = sum(info.get("collision_reason") == "escape" for info in infos[1:])
    env.close()
    assert refused[False] >= 3 and refused[True] == 0, refused


# -- passive -----------------------------------------------------------------------------
def test_subsample_poses_keeps_ends_and_fits_the_budget():
    poses = np.repeat(np.eye(4)[None], 101, axis=0)
    poses[:, 0, 3] = np.arange(101)
    picked = subsample_poses(poses, 10)
    assert len(picked) == 11
    assert picked[0, 0, 3] == 0 and picked[-1, 0, 3] == 100
    assert subsample_poses(poses[:5], 10).shape == (5, 4, 4)
    with pytest.raises(ValueError):
        subsample_poses(poses, 0)


def test_load_trajectory_rejects_bad_files(tmp_path):
    bad = tmp_path / "traj.txt"
    bad.write_text("1 2 3\n")
    with pytest.raises(ValueError, match="16 numbers"):
        load_trajectory(bad)
    with pytest.raises(ValueError, match="does not exist"):
        load_trajectory(tmp_path / "missing.txt")


def test_passive_replays_the_replica_trajectory_exactly(replica_dir):
    trajectory = load_trajectory(replica_dir / "traj.txt")[:25]
    env = make_env(scene=str(replica_dir / "mesh.ply"), steps=24)
    poses, infos = rollout(env, PassivePolicy(trajectory), 24)
    np.testing.assert_allclose(poses, trajectory, atol=2e-4)
    assert not any(info["collided"] for info in infos)
    # Fitted to a smaller budget: every 3rd pose, still reached exactly.
    env = make_env(scene=str(replica_dir / "mesh.ply"), steps=8)
    policy = PassivePolicy(trajectory)
    poses, _ = rollout(env, policy, 8)
    np.testing.assert_allclose(poses, trajectory[::3], atol=2e-4)
    env.close()


def test_passive_scripted_scan_walks_along_the_walls():
    env = make_env(scene="replica_like_room", steps=150)
    policy = PassivePolicy()
    poses, infos = rollout(env, policy, 150, seed=1)
    assert sum(info["collided"] for info in infos) <= 3
    assert infos[-1]["path_length_m"] > 8.0  # it walks, not just turns
    # It went around: the path spans most of the room in both directions.
    extent = np.ptp(poses[:, :2, 3], axis=0)
    assert np.all(extent > 2.0)
    env.close()
