"""Never stuck: stall detection, recovery steps, refused moves, and randomised episodes."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest

import naruto_gym  # noqa: F401  (registers the env)
from naruto_agent.mapping.observed_space import ObservedSpace
from naruto_agent.mapping.sdf_volume import SdfVolume
from naruto_agent.naruto import NarutoPolicy
from naruto_agent.naruto.recovery import (
    BlockedSpace,
    ProgressMonitor,
    RecoveryConfig,
    RecoveryKind,
    densify,
    look_around_targets,
)
from naruto_agent.policies import EnvContext
from naruto_gym.scenes import make_random_scene
from tests.agent.synthetic_panoramas import floor_panorama, wall_panorama


def test_standing_still_without_new_space_is_a_stall() -> None:
    monitor = ProgressMonitor(RecoveryConfig(window=10))
    for _ in range(9):
        monitor.record(np.zeros(3), 0.1)
    assert not monitor.stalled()  # not a full window yet
    monitor.record(np.zeros(3), 0.1)
    assert monitor.stalled() and monitor.needs_recovery()


def test_moving_or_measuring_is_progress() -> None:
    moving = ProgressMonitor(RecoveryConfig(window=10))
    measuring = ProgressMonitor(RecoveryConfig(window=10))
    for step in range(20):
        moving.record(np.array([0.05 * step, 0.0, 0.0]), 0.1)
        measuring.record(np.zeros(3), 0.1 + 0.001 * step)
    assert not moving.stalled() and not measuring.stalled()


def test_failed_plans_escalate_through_every_recovery() -> None:
    monitor = ProgressMonitor(RecoveryConfig(max_failed_plans=2))
    kinds = []
    for _ in range(4):
        monitor.plan_failed()
        assert not monitor.needs_recovery()
        monitor.plan_failed()
        assert monitor.needs_recovery()
        kinds.append(monitor.next_recovery())
        assert not monitor.needs_recovery()  # the count starts over
    assert kinds == [RecoveryKind.LOOK_AROUND, RecoveryKind.WANDER, RecoveryKind.RETREAT,
                     RecoveryKind.LOOK_AROUND]
    monitor.progress_made(np.zeros(3))
    monitor.plan_failed()
    monitor.plan_failed()
    assert monitor.next_recovery() == RecoveryKind.LOOK_AROUND


def test_a_plan_that_never_moves_the_agent_does_not_reset_the_escalation() -> None:
    """Plans found where the agent stands, whose first move never happens, are no
    progress: the next stall escalates to wander; once it has moved, it starts over."""
    monitor = ProgressMonitor(RecoveryConfig(window=5, min_motion_m=0.2))
    here = np.array([1.0, 1.0, 1.0])
    for _ in range(5):
        monitor.record(here, 0.1)
    assert monitor.next_recovery() == RecoveryKind.LOOK_AROUND
    monitor.progress_made(here + [0.05, 0.0, 0.0])  # a plan, but the agent has not moved
    assert monitor.next_recovery() == RecoveryKind.WANDER
    monitor.progress_made(here + [0.5, 0.0, 0.0])
    assert monitor.next_recovery() == RecoveryKind.LOOK_AROUND


def test_failed_goals_are_forgotten_after_the_memory() -> None:
    monitor = ProgressMonitor(RecoveryConfig(failed_goal_memory_frames=5))
    monitor.goal_failed(np.ones(3))
    assert len(monitor.recent_failed_goals()) == 1
    for _ in range(6):
        monitor.record(np.zeros(3), 0.0)
    assert len(monitor.recent_failed_goals()) == 0


def test_retreat_goes_back_along_the_trajectory_in_small_steps() -> None:
    monitor = ProgressMonitor(RecoveryConfig(retreat_m=0.5))
    for x in np.linspace(0.0, 2.0, 21):
        monitor.record(np.array([x, 0.0, 1.0]), 0.0)
    path = monitor.retreat_path(np.array([2.0, 0.0, 1.0]))
    assert np.allclose(path[0], [2.0, 0.0, 1.0])
    assert path[-1][0] == pytest.approx(1.5, abs=1e-9)
    assert np.all(np.linalg.norm(np.diff(path, axis=0), axis=1) <= 0.1 + 1e-9)
    assert len(ProgressMonitor(RecoveryConfig()).retreat_path(np.zeros(3))) == 1


def test_densify_and_look_around() -> None:
    path = densify(np.array([[0.0, 0, 0], [1.0, 0, 0]]), 0.3)
    assert len(path) == 5 and np.allclose(path[-1], [1, 0, 0])
    targets = look_around_targets(np.zeros(3), views=8, pitch_deg=25.0)
    azimuth = np.degrees(np.arctan2(targets[:, 1], targets[:, 0])) % 360
    assert np.allclose(np.sort(azimuth), np.arange(0, 360, 45))
    assert np.allclose(np.linalg.norm(targets, axis=1), 1.0)


def test_blocked_points_read_as_obstacles() -> None:
    sdf = SdfVolume(np.full((20, 20, 20), 0.5), np.zeros(3), 0.1)
    blocked = BlockedSpace(radius_m=0.05)
    assert blocked.apply(sdf) is sdf
    blocked.add(np.array([1.0, 1.0, 1.0]))
    result = blocked.apply(sdf)
    assert result.sample(np.array([[1.0, 1.0, 1.0]]))[0] < 0
    assert result.sample(np.array([[1.5, 1.0, 1.0]]))[0] == pytest.approx(0.5)
    assert np.all(sdf.values == 0.5)  # the input is left alone


def test_blocked_space_forgets_only_guesses_near_a_point() -> None:
    """What the agent blocked on its own readings can be forgotten near a point; what the
    env refused, and guesses farther away, stay."""
    blocked = BlockedSpace(radius_m=0.05)
    here = np.array([1.0, 1.0, 1.0])
    blocked.add(here + [0.6, 0.0, 0.0], 0.5, guessed=True)  # surface 0.1 m away
    blocked.add(here + [0.0, 0.6, 0.0], 0.5)  # the env refused it
    blocked.add(here + [2.0, 0.0, 0.0], 0.5, guessed=True)  # surface 1.5 m away
    assert blocked.forget_guesses_near(here, 0.4) == 1
    assert blocked.guessed == [False, True]
    assert np.allclose(blocked.points[0], here + [0.0, 0.6, 0.0])
    assert blocked.forget_guesses_near(here, 0.4) == 0
    assert blocked.forget_guesses_near(here, np.inf) == 1
    assert blocked.guessed == [False] and len(blocked.radii) == 1


def _first_move(reason: str, offset: np.ndarray | None = None):
    """An agent on two_rooms, its first move (or, with ``offset``, a move by that much from
    where it stands), and the agent after the env refused it."""
    env = gym.make("NarutoRecon-v0", scene="two_rooms", image_scale=0.1,
                   max_episode_steps=1000)
    policy = NarutoPolicy(mapper="tsdf", device="cpu")
    policy.bind(EnvContext.from_env(env.unwrapped))
    observation, info = env.reset(seed=0)
    policy.reset(observation, info, seed=0)
    for _ in range(200):
        action = policy.act(observation, info)
        position = np.asarray(observation["pose"])[:3, 3]
        if np.linalg.norm(action[:3] - position) > 1e-3:
            break
    target = action[:3].astype(np.float64)
    if offset is not None:
        target = position + offset
        policy._commanded = target.copy()
    # Tell the agent the env refused that move.
    policy.act(observation, {**info, "collided": True, "collision_reason": reason})
    env.close()
    return policy, observation, info, position, target


def test_a_refused_move_blocks_its_target_and_is_not_repeated() -> None:
    policy, observation, info, _, target = _first_move("surface")
    assert len(policy.blocked.points) == 1
    assert np.allclose(policy.blocked.points[0], target, atol=1e-5)
    assert policy.blocked.radii == [policy.config.recovery.blocked_radius_m]
    assert policy.sdf.sample(target[None])[0] < 0
    # No later action moves to the refused target again.
    for _ in range(40):
        action = policy.act(observation, info)
        assert np.linalg.norm(action[:3] - target) > 0.02


def test_an_escape_refusal_blocks_the_space_beyond_the_refused_point() -> None:
    policy, observation, info, position, target = _first_move("escape", np.array([0.1, 0, 0]))
    radius = policy.config.recovery.escape_blocked_radius_m
    direction = (target - position) / np.linalg.norm(target - position)
    assert np.allclose(policy.blocked.points[0], target + radius * direction, atol=1e-5)
    assert policy.blocked.radii == [radius]
    beyond = target + direction * np.array([[0.2], [0.5], [0.8]])
    assert np.all(policy.sdf.sample(beyond) < 0)
    # The agent's own side stays as its map had it: it is not walled in.
    behind = position - 0.2 * direction
    assert policy.sdf.sample(behind[None])[0] > 0
    for _ in range(40):
        action = policy.act(observation, info)
        assert np.linalg.norm(action[:3] - target) > 0.02


def test_an_agent_hemmed_in_by_its_own_edge_guesses_forgets_them_and_plans_again() -> None:
    """Seen on ``replica_like_room:no_ceiling+holes``, seed 6: beside the floor hole's rim
    the panorama held move after move, and the balls blocked past them put the agent within
    its clearance with no way out, so no plan started again (0.4 m in 300 steps). The next
    plan forgets the guesses around it (what the env refused stays) and goes on."""
    policy, observation, info, position, _ = _first_move("surface")
    refused = len(policy.blocked.points)
    for way in np.vstack([np.eye(3), -np.eye(3)]):
        policy._block_past_edge(position, position + 0.05 * way, goal_failed=False,
                                guessed=True)
    assert policy.sdf.sample(position[None])[0] <= policy.config.planner.clearance_m
    assert policy._escape(position) is None  # hemmed in, as the agent was
    plan = policy._plan(position, np.asarray(observation["pose"])[:3, :3])
    assert policy.plans[-1].get("forgot_guesses")
    assert policy.plans[-1]["outcome"] != "start not free"
    assert plan is not None
    assert len(policy.blocked.points) == refused and not any(policy.blocked.guessed)


def test_a_refused_climb_sets_a_ceiling_above_the_agent() -> None:
    """Seen on ``two_rooms:no_ceiling``, seed 0: refused climbing at the open top, the agent
    blocked a ball beside the refused point and climbed again 6 steps later, elsewhere."""
    policy, observation, info, position, target = _first_move("escape", np.array([0, 0, 0.1]))
    assert policy.blocked.ceiling_z == pytest.approx(position[2])
    assert len(policy.blocked.points) == 0
    above = position + np.array([[0.5, 0.0, 0.15], [-0.5, 0.3, 0.3], [0.0, 0.0, 0.2]])
    assert np.all(policy.sdf.sample(above) < 0)
    assert policy.sdf.sample((position - [0, 0, 0.3])[None])[0] > 0  # below stays free
    for _ in range(40):
        action = policy.act(observation, info)
        assert action[2] <= position[2] + 0.02
    # A steep sideways climb from over measured floor is the top too; a level move is not.
    assert policy._refused_climb(position, position + [0.1, 0.0, 0.05]) == bool(
        policy.mapper.observed_space.sectors_seen_below(position[None])[0])
    assert not policy._refused_climb(position, position + [0.1, 0.0, 0.0])


def _scenes() -> list:
    shipped = ["replica_like_room", "two_rooms", "apartment"]
    procedural = [("room", seed) for seed in (3, 11, 27, 40, 58)] + [
        ("apartment", seed) for seed in (5, 19, 33, 64, 71)
    ]
    return shipped + procedural


@pytest.mark.slow
@pytest.mark.parametrize("scene", _scenes(), ids=lambda s: s if isinstance(s, str)
                         else f"{s[0]}_{s[1]}")
def test_randomised_episodes_never_stall(scene) -> None:
    steps = 120
    mesh = make_random_scene(scene[1], kind=scene[0]) if isinstance(scene, tuple) else scene
    seed = 7 if isinstance(scene, str) else scene[1]
    env = gym.make("NarutoRecon-v0", scene=mesh, image_scale=0.1, panorama_shape=(32, 64),
                   max_episode_steps=steps + 1)
    policy = NarutoPolicy(mapper="tsdf", device="cpu")
    policy.bind(EnvContext.from_env(env.unwrapped, step_budget=steps))
    observation, info = env.reset(seed=seed)
    policy.reset(observation, info, seed=seed)
    coverage = [info["coverage"]]
    space = env.action_space
    for _ in range(steps):
        action = policy.act(observation, info)
        assert np.all(np.isfinite(action)) and space.contains(action)
        observation, _, terminated, truncated, info = env.step(action)
        coverage.append(info["coverage"])
        assert not terminated and not truncated
    last_quarter = coverage[-steps // 4 - 1]
    assert coverage[-1] > last_quarter or coverage[-1] > 0.9, (
        f"coverage stalled at {coverage[-1]:.3f} ({policy.recoveries})"
    )
    env.close()


@pytest.mark.slow
def test_on_an_open_scan_goals_stay_inside_the_scanned_space() -> None:
    """Without a ceiling, rays over the wall tops measure free space outside the room; the
    agent neither aims there nor keeps asking the env to go there."""
    steps = 150
    env = gym.make("NarutoRecon-v0", scene="replica_like_room:no_ceiling", image_scale=0.1,
                   coverage_samples=2000, max_episode_steps=steps + 1)
    policy = NarutoPolicy(mapper="tsdf", device="cpu")
    policy.bind(EnvContext.from_env(env.unwrapped, step_budget=steps))
    observation, info = env.reset(seed=0)
    policy.reset(observation, info, seed=0)
    escapes = 0
    for _ in range(steps):
        observation, _, _, _, info = env.step(policy.act(observation, info))
        escapes += info["collision_reason"] == "escape"
    goals = np.array([plan["goal"] for plan in policy.plans if "goal" in plan]).reshape(-1, 3)
    assert len(goals) >= 2
    scanned = env.unwrapped.collision.scanned_space
    assert scanned.contains_many(goals).all(), goals[~scanned.contains_many(goals)]
    assert escapes <= 2
    assert info["coverage"] > 0.5
    env.close()


def test_escape_from_inside_a_blocked_ball_takes_a_line_the_move_check_accepts() -> None:
    """The agent stands within its clearance, next to the blocked ball of a move refused a
    step ahead (+x), with a wall close behind it (-x): the escape ends well inside free
    space and every node of it passes the agent's own move check (else it is refused at
    every try and the agent never moves)."""
    values = np.full((30, 30, 30), 0.5)
    values[:10] = -0.1  # a wall up to x = 0.95 m
    values[10] = 0.04  # the voxels at x = 1.0 m: inside the agent's clearance
    sdf = SdfVolume(values, np.zeros(3), 0.1)
    agent = np.array([1.02, 1.5, 1.0])
    blocked = BlockedSpace(radius_m=0.05)
    blocked.add(agent + [0.1, 0.0, 0.0])
    policy = NarutoPolicy(mapper="tsdf", device="cpu")
    policy.sdf = blocked.apply(sdf)
    start = float(policy.sdf.sample(agent[None])[0])
    assert start <= policy.config.planner.clearance_m  # trapped, as the agent was
    path = policy._escape(agent)
    assert path is not None and np.allclose(path[0], agent)
    assert policy.sdf.sample(path[-1][None])[0] > policy.config.planner.clearance_m
    assert all(policy._move_is_free(a, b) for a, b in zip(path[:-1], path[1:], strict=True))


def test_goals_may_stay_as_high_as_the_agent_stands_over_a_low_scan() -> None:
    """Goals lie ``scan_top_margin_m`` below the measured top, but never lower than the
    agent stands: over a scan that is mostly floor the top can lie below the agent, and
    without this it had no goal at all and never moved."""
    env = gym.make("NarutoRecon-v0", scene="replica_like_room:no_ceiling", image_scale=0.1,
                   coverage_samples=2000, max_episode_steps=20)
    policy = NarutoPolicy(mapper="tsdf", device="cpu")
    policy.bind(EnvContext.from_env(env.unwrapped, step_budget=20))
    observation, info = env.reset(seed=0)
    policy.reset(observation, info, seed=0)
    for _ in range(10):
        observation, _, _, _, info = env.step(policy.act(observation, info))
    observed = policy.mapper.observed_space
    position = np.asarray(observation["pose"], np.float64)[:3, 3]
    top = observed.scan_top_z() - policy.config.scan_top_margin_m
    column = np.array([[position[0], position[1], z] for z in np.arange(0.2, 6.0, 0.1)])
    supported = observed.sample(observed.supported(), column)
    low = policy._inside_scan(column, np.array([*position[:2], 0.0]))
    assert np.array_equal(low, supported & (column[:, 2] <= top))
    high = policy._inside_scan(column, np.array([*position[:2], top + 1.0]))
    assert np.array_equal(high, supported & (column[:, 2] <= top + 1.0))
    assert (high & ~low).any()  # the agent's own height admits more
    env.close()


def test_after_an_escape_refusal_goals_need_measured_surface_in_every_sector_below() -> None:
    """Once the env has refused a move for leaving the scan, the agent's goals must also pass
    the env's cone test on its own map; a surface refusal (as on every closed scene) leaves
    the coarse test alone."""
    for reason, strict in (("escape", True), ("surface", False)):
        policy, observation, _, position, _ = _first_move(reason)
        assert policy._scan_open == strict
        observed = policy.mapper.observed_space
        points = policy.sdf.grid_points()
        top = max(observed.scan_top_z() - policy.config.scan_top_margin_m, position[2])
        coarse = observed.sample(observed.supported(), points) & (points[:, 2] <= top)
        inside = policy._inside_scan(points, position)
        if strict:
            expected = coarse.copy()
            expected[coarse] = observed.sectors_seen_below(points[coarse])
            assert np.array_equal(inside, expected)
            assert (coarse & ~inside).any() and inside.any()
        else:
            assert np.array_equal(inside, coarse)


def test_sectors_seen_below_over_a_floor_with_a_hole() -> None:
    """Every sector of the downward cone meets the floor from above its middle; not past its
    edge, nor low over a hole; high over the hole the cone's outer rays meet the floor all
    around (the env's rule, on the agent's grid)."""
    space = ObservedSpace(np.array([[-3.0, -3.0, -0.5], [3.0, 3.0, 3.0]]))
    xs = np.arange(-1.95, 2.0, 0.1)
    floor = np.array([[x, y, 0.0] for x in xs for y in xs if max(abs(x), abs(y)) > 0.5])
    space.grid.mark_occupied(floor)
    assert space.sectors_seen_below(np.array([[1.2, 1.2, 1.0], [0.0, 0.0, 1.5]])).all()
    assert not space.sectors_seen_below(np.array([[2.3, 0.0, 1.0]]))[0]  # past the edge
    assert not space.sectors_seen_below(np.array([[0.0, 0.0, 0.2]]))[0]  # low over the hole
    assert len(space.sectors_seen_below(np.zeros((0, 3)))) == 0


def _agent_after(scene: str, steps: int) -> NarutoPolicy:
    env = gym.make("NarutoRecon-v0", scene=scene, image_scale=0.1, coverage_samples=2000,
                   max_episode_steps=steps)
    policy = NarutoPolicy(mapper="tsdf", device="cpu")
    policy.bind(EnvContext.from_env(env.unwrapped, step_budget=steps))
    observation, info = env.reset(seed=0)
    policy.reset(observation, info, seed=0)
    for _ in range(steps):
        observation, _, _, _, info = env.step(policy.act(observation, info))
    env.close()
    return policy


def test_the_sky_in_a_depth_frame_tells_the_scan_is_open() -> None:
    """Without a ceiling the first look-around's upward pixels hit nothing; a closed room's
    never miss, so the agent there is as before."""
    assert _agent_after("replica_like_room:no_ceiling", 12)._scan_open
    assert not _agent_after("replica_like_room:fragments", 12)._scan_open


def test_steep_miss_share_counts_only_steep_pixels() -> None:
    from naruto_agent.policies.panorama_clearance import steep_miss_share
    from naruto_gym.geometry.transforms import look_at_rotation, make_pose
    from naruto_gym.sensors.pinhole import PinholeCamera

    camera = PinholeCamera().scaled(0.1)
    eye = np.array([1.0, 1.0, 1.0])
    level = make_pose(look_at_rotation(eye, eye + [1.0, 0.0, 0.0]), eye)
    up = make_pose(look_at_rotation(eye, eye + [1.0, 0.0, 3.0]), eye)
    empty = np.zeros((camera.height, camera.width), np.float32)
    assert steep_miss_share(empty, up, camera) == 1.0
    assert steep_miss_share(np.ones_like(empty), up, camera) == 0.0
    # Pitched 20 degrees up, only the top rows look 35 degrees or more up: misses elsewhere
    # (a doorway far away, beyond the sensor's range) do not count.
    tilted = make_pose(look_at_rotation(eye, eye + [1.0, 0.0, np.tan(np.deg2rad(20.0))]), eye)
    top_rows = np.ones_like(empty)
    top_rows[:4] = 0.0
    assert 0.0 < steep_miss_share(top_rows, tilted, camera, stride=1) < 1.0
    bottom_rows = np.ones_like(empty)
    bottom_rows[-20:] = 0.0
    assert steep_miss_share(bottom_rows, tilted, camera, stride=1) == 0.0
    assert steep_miss_share(empty, level, camera) == 0.0  # nothing looks that steeply


def test_a_move_towards_the_scans_edge_is_refused_on_the_agents_map() -> None:
    """Once the scan is known open, a move whose probe lies past the measured floor's edge is
    refused before the env sees it, and the space past it is blocked; a move inside passes."""
    policy, *_ = _first_move("surface")
    observed = policy.mapper.observed_space
    observed.grid.log_odds[:] = 0.0
    observed.grid.observed[:] = False
    xs = np.arange(0.05, 2.0, 0.1)
    observed.grid.mark_occupied(np.array([[x, y, 0.05] for x in xs for y in xs]))
    policy._scan_open = True
    blocked = len(policy.blocked.points)
    assert policy._stays_in_scan(np.array([1.0, 1.0, 1.0]), np.array([1.1, 1.0, 1.0]))
    assert len(policy.blocked.points) == blocked
    start, end = np.array([1.8, 1.0, 1.0]), np.array([1.9, 1.0, 1.0])
    assert not policy._stays_in_scan(start, end)
    assert len(policy.blocked.points) == blocked + 1
    assert policy.blocked.points[-1][0] > end[0]  # beyond the move's end, not behind it
    # From a point the test already fails, the agent may move (it has to get back in).
    assert policy._stays_in_scan(np.array([2.5, 1.0, 1.0]), np.array([2.6, 1.0, 1.0]))


def test_config_rejects_bad_open_scan_settings() -> None:
    from naruto_agent.naruto import NarutoConfig

    with pytest.raises(ValueError, match="open_sky_share"):
        NarutoConfig(open_sky_share=0.0)
    with pytest.raises(ValueError, match="edge_probe_m"):
        NarutoConfig(edge_probe_m=-0.1)
    with pytest.raises(ValueError, match="margin_climb_m"):
        NarutoConfig(margin_climb_m=-0.1)


def _agent_on_a_free_map(panorama: np.ndarray, agent: np.ndarray) -> NarutoPolicy:
    """An agent bound to two_rooms whose map is free everywhere (kept: no planner view is
    read) and whose last panorama, ``panorama``, was taken at ``agent``."""
    policy = NarutoPolicy(mapper="tsdf", device="cpu")
    env = gym.make("NarutoRecon-v0", scene="two_rooms", image_scale=0.1)
    policy.bind(EnvContext.from_env(env.unwrapped))
    env.close()
    policy.sdf = SdfVolume(np.full((30, 30, 30), 0.5), np.zeros(3), 0.1)
    policy._read_view = lambda: None
    policy._panorama = (panorama, agent.copy())
    return policy


def test_a_move_the_panorama_shows_blocked_is_not_sent_and_its_surface_is_blocked() -> None:
    """The agent stands 7 cm from a surface that its 0.1 m map does not show in the way: the
    panorama taken where it stands shows it, so the move towards it is refused before the env
    sees it, the surface point is blocked in the map, and the goal stays."""
    agent = np.array([1.5, 1.5, 1.0])
    policy = _agent_on_a_free_map(wall_panorama(-0.07), agent)  # a wall at y = 1.43 m
    assert policy._move_is_free(agent, agent + [0.1, 0.0, 0.0])  # along the wall
    assert len(policy.blocked.points) == 0
    assert not policy._move_is_free(agent, agent + [0.06, -0.05, 0.07])
    assert len(policy.blocked.points) == 1
    assert policy.blocked.points[0][1] == pytest.approx(1.43, abs=1e-3)
    assert policy.sdf.sample(policy.blocked.points[0][None])[0] < 0
    # Taken elsewhere, the panorama says nothing about this move.
    assert policy._move_is_free(agent + [1.0, 0.02, 0.0], agent + [1.0, -0.03, 0.0])
    policy.config = replace(policy.config, check_moves_on_panorama=False)
    assert policy._move_is_free(agent, agent + [0.06, -0.05, 0.07])


def test_on_an_open_scan_a_move_the_panorama_shows_leaving_the_scan_is_refused() -> None:
    """The floor under the agent ends 0.3 m ahead (+x): once the scan is known open, a move
    to 5 cm before that edge is refused on the panorama and the space past it blocked; a
    move back inside passes, and on a closed scan the check does not run."""
    agent = np.array([1.5, 1.5, 1.0])
    policy = _agent_on_a_free_map(floor_panorama(edge_x_m=0.3), agent)
    towards_edge = agent + [0.25, 0.0, 0.0]
    assert policy._panorama_keeps_to_scan(agent, agent + [-0.1, 0.0, 0.0])
    assert len(policy.blocked.points) == 0
    policy._scan_open = False
    assert policy._move_is_free(agent, towards_edge)  # closed: no cone check
    policy._scan_open = True
    assert not policy._panorama_keeps_to_scan(agent, towards_edge)
    assert len(policy.blocked.points) == 1 and policy.blocked.points[0][0] > towards_edge[0]


def test_on_an_open_scan_a_climb_above_the_scans_top_is_refused_and_lowers_the_ceiling() -> None:
    """Walls measured up to about 2.6 m and no ceiling: once the scan is known open, a climb
    that ends above the measured top less the agent's radius is refused (the map alone let
    such nodes through) and sets the flight ceiling there; level and descending moves pass,
    and on a closed scan the check does not run."""
    space = ObservedSpace(np.array([[0.0, 0.0, 0.0], [3.0, 3.0, 3.0]]))
    heights = np.arange(0.05, 2.6, 0.1)
    space.grid.mark_occupied(np.array([[x, 0.05, z] for x in np.arange(0.05, 3.0, 0.1)
                                       for z in heights]))
    agent = np.array([1.5, 1.5, 2.0])
    policy = _agent_on_a_free_map(floor_panorama(height_m=2.0), agent)
    policy.mapper = SimpleNamespace(observed_space=space)  # the agent's measured space only
    limit = space.scan_top_z() - policy.context.agent_radius_m
    assert 2.5 < limit < 2.7
    below, above = agent + [0.0, 0.0, limit - 2.01], agent + [0.0, 0.0, limit - 1.95]
    policy._scan_open = False
    assert policy._move_is_free(agent, above)  # closed: the top is the ceiling the map shows
    policy._scan_open = True
    assert policy._stays_below_top(agent, below)
    assert not policy._stays_below_top(agent, above)
    assert policy.blocked.ceiling_z == pytest.approx(limit)
    assert policy.sdf.sample(above[None])[0] < 0  # the next plan stays under it
    assert policy._stays_below_top(above, above + [0.1, 0.0, 0.0])  # level, already above
    assert policy._stays_below_top(above, below)


def test_in_a_tight_spot_a_move_held_for_a_surface_goes_to_the_env_after_max_held_moves():
    """7 cm from a wall, within the panorama's margin of it: moves towards it are held
    (the surface blocked in the map, the goal kept), but after ``max_held_moves`` holds in a
    row at one spot the next is sent and the env decides, then the count starts again."""
    agent = np.array([1.5, 1.5, 1.0])
    policy = _agent_on_a_free_map(wall_panorama(-0.07), agent)
    towards_wall = agent + [0.06, -0.05, 0.07]
    for _ in range(policy.config.max_held_moves):
        assert not policy._move_is_free(agent, towards_wall)
    assert len(policy.blocked.points) == policy.config.max_held_moves
    assert policy._move_is_free(agent, towards_wall)
    assert not policy._move_is_free(agent, towards_wall)


def test_naruto_hands_a_move_to_the_env_after_max_held_moves_holds_at_one_spot() -> None:
    """Low over a floor hole every way out can look like leaving the scan on the panorama:
    after ``max_held_moves`` moves held back in a row at one spot the next is sent (the env
    decides) when the agent cannot climb out of the margin (``margin_climb_m=0`` here), and
    a new spot starts counting again. A held move blocks the space past the edge but keeps
    the plan's goal (the env never refused it)."""
    agent = np.array([1.5, 1.5, 1.0])
    policy = _agent_on_a_free_map(floor_panorama(edge_x_m=0.3), agent)
    policy.config = replace(policy.config, margin_climb_m=0.0)
    policy._scan_open = True
    failed: list[np.ndarray] = []
    policy.monitor.goal_failed = failed.append
    policy.machine.plan = SimpleNamespace(goal=agent + [1.0, 0.0, 0.0], info={})
    towards_edge = agent + [0.25, 0.0, 0.0]
    for _ in range(policy.config.max_held_moves):
        assert not policy._panorama_keeps_to_scan(agent, towards_edge)
    assert policy._panorama_keeps_to_scan(agent, towards_edge)
    assert len(policy.blocked.points) == policy.config.max_held_moves
    assert failed == []
    # The count starts again: the next move from here is checked (and held) again.
    assert not policy._panorama_keeps_to_scan(agent, towards_edge)
    elsewhere = agent + [0.0, 0.05, 0.0]
    policy._panorama = (floor_panorama(edge_x_m=0.3), elsewhere)
    assert not policy._panorama_keeps_to_scan(elsewhere, elsewhere + [0.25, 0.0, 0.0])


def _agent_under_walls_to(top_m: float, panorama: np.ndarray, agent: np.ndarray) -> NarutoPolicy:
    """:func:`_agent_on_a_free_map` on an open scan whose measured walls reach ``top_m``."""
    space = ObservedSpace(np.array([[0.0, 0.0, 0.0], [3.0, 3.0, 3.0]]))
    space.grid.mark_occupied(np.array([[x, 0.05, z] for x in np.arange(0.05, 3.0, 0.1)
                                       for z in np.arange(0.05, top_m, 0.1)]))
    policy = _agent_on_a_free_map(panorama, agent)
    policy.mapper = SimpleNamespace(observed_space=space)
    policy._scan_open = True
    policy.plans.append({})  # past the first plan's look-around
    return policy


def test_when_the_holds_run_out_at_the_scans_edge_naruto_climbs_instead_of_leaving() -> None:
    """Every way from a spot 1 m over a floor whose edge is 0.3 m ahead reads as leaving
    the scan: after ``max_held_moves`` holds the flagged move is not sent; the next plan is
    a climb of ``margin_climb_m`` straight up (the env's support cone reaches further from
    higher up), trusted, then a look around. Under the scan's top the climb is cut short,
    and with less than 2 cm left the move goes to the env as before."""
    agent = np.array([1.5, 1.5, 1.0])
    towards_edge = agent + [0.25, 0.0, 0.0]
    policy = _agent_under_walls_to(2.6, floor_panorama(edge_x_m=0.3), agent)
    for _ in range(policy.config.max_held_moves + 1):
        assert not policy._panorama_keeps_to_scan(agent, towards_edge)
    plan = policy._plan(agent, np.eye(3))
    assert plan.info == {"recovery": "climb", "trusted": True}
    np.testing.assert_allclose(plan.path[0], agent)
    np.testing.assert_allclose(plan.path[-1], agent + [0.0, 0.0, policy.config.margin_climb_m])
    assert np.all(np.diff(plan.path[:, 2]) > 0) and np.allclose(plan.path[:, :2], agent[:2])
    policy.machine.plan = plan
    assert policy._move_is_free(plan.path[0], plan.path[1])  # trusted: checked already
    assert policy._climb is None  # used once

    # A surface 0.2 m overhead (under a table): the climb stops short of it.
    floor = floor_panorama(edge_x_m=0.3)
    overhead = np.flipud(floor_panorama(height_m=0.2))
    policy = _agent_under_walls_to(2.6, np.where(overhead > 0, overhead, floor), agent)
    for _ in range(policy.config.max_held_moves + 1):
        assert not policy._panorama_keeps_to_scan(agent, towards_edge)
    assert 0.1 < policy._climb[-1][2] - agent[2] < 0.2 - policy.context.agent_radius_m

    # The scan's top (measured top 2.6 m less scan_top_margin_m) leaves 0.12 m: cut short.
    high = np.array([1.5, 1.5, 2.18])
    policy = _agent_under_walls_to(2.6, floor_panorama(height_m=2.18, edge_x_m=0.3), high)
    top = policy.mapper.observed_space.scan_top_z() - policy.config.scan_top_margin_m
    for _ in range(policy.config.max_held_moves + 1):
        assert not policy._panorama_keeps_to_scan(high, high + [0.25, 0.0, 0.0])
    assert policy._climb[-1][2] == pytest.approx(top)
    # No room left to climb: the move is sent and the env decides.
    policy = _agent_under_walls_to(2.6, floor_panorama(height_m=top - 0.01, edge_x_m=0.3),
                                   np.array([1.5, 1.5, top - 0.01]))
    start = np.array([1.5, 1.5, top - 0.01])
    for _ in range(policy.config.max_held_moves):
        assert not policy._panorama_keeps_to_scan(start, start + [0.25, 0.0, 0.0])
    assert policy._panorama_keeps_to_scan(start, start + [0.25, 0.0, 0.0])
    assert policy._climb is None
