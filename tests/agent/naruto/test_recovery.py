"""Never stuck: stall detection, recovery steps, refused moves, and randomised episodes."""

from __future__ import annotations

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


def test_moves_held_again_and_again_in_one_place_ask_for_a_recovery_that_moves() -> None:
    """A plan whose first move is held at once, frame after frame, leaves the agent standing:
    the third hold within the stay radius of where the first was asks for a recovery that
    moves (not a look-around); holds spread over the room do not."""
    monitor = ProgressMonitor(RecoveryConfig())
    here = np.array([1.0, 1.0, 1.5])
    assert not monitor.move_held(here)
    assert not monitor.move_held(here + [0.2, 0.0, 0.0])
    assert monitor.move_held(here + [0.0, 0.3, -0.1])
    assert monitor.needs_recovery() and monitor.next_recovery() == RecoveryKind.WANDER
    spread = ProgressMonitor(RecoveryConfig())
    assert not any(spread.move_held(here + [0.6 * k, 0.0, 0.0]) for k in range(6))
    assert not spread.needs_recovery()


def test_a_spot_whose_plans_keep_being_held_fails_at_every_height() -> None:
    """Plans to goals within 0.5 m of each other across, at any height, held three times:
    the goal search would choose that spot again and again, so each fails for where it lies
    (the goal search skips 0.5 m around each at every height); a hold elsewhere does not
    count."""
    monitor = ProgressMonitor(RecoveryConfig())
    goals = np.array([[10.53, 6.93, 1.65], [10.33, 6.93, 2.15], [10.53, 7.33, 1.15]])
    assert not monitor.goal_held(goals[0])
    assert not monitor.goal_held(np.array([5.0, 5.0, 1.5]))  # elsewhere
    assert not monitor.goal_held(goals[1])
    assert len(monitor.recent_failed_goals()) == 0
    assert monitor.goal_held(goals[2])
    failed, radii = monitor.recent_failed(columns=True)
    np.testing.assert_allclose(failed, goals)
    np.testing.assert_allclose(radii, [0.5, 0.5, 0.5])
    monitor.goal_failed(np.zeros(3))  # an ordinary failure keeps the ordinary radius
    assert monitor.recent_failed()[1][-1] == RecoveryConfig().failed_goal_radius_m


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


def test_blocked_space_holds_the_points_within_a_ball() -> None:
    blocked = BlockedSpace(radius_m=0.05)
    assert not blocked.holds(np.zeros(3))
    blocked.add(np.array([1.0, 1.0, 1.0]))
    blocked.add(np.array([2.0, 1.0, 1.0]), 0.3)
    assert blocked.holds(np.array([1.04, 1.0, 1.0]))
    assert not blocked.holds(np.array([1.06, 1.0, 1.0]))
    assert blocked.holds(np.array([2.0, 1.29, 1.0]))


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
    where it stands), and the agent after the env refused it. The env is not stepped until
    then, so the stall watchdog, which would read that as standing, is off."""
    env = gym.make("NarutoRecon-v0", scene="two_rooms", image_scale=0.1,
                   max_episode_steps=1000)
    policy = NarutoPolicy(mapper_kind="tsdf", device="cpu", stall_watchdog=False)
    policy.bind(EnvContext.from_env(env.unwrapped))
    observation, info = env.reset(seed=0)
    policy.reset(observation, info, seed=0)
    for _ in range(200):
        action = policy.act(observation, info)
        position = np.asarray(observation["pose"])[:3, 3]
        if np.linalg.norm(action[:3] - position) > 1e-3:
            break
    target = action[:3].astype(np.float64)
    if offset is None:
        # Tell the agent the env refused that move.
        policy.act(observation, {**info, "collided": True, "collision_reason": reason})
    else:
        target = position + offset
        policy.learn_refusal(position.astype(np.float64), target, reason)
        policy.act(observation, info)  # the agent did not arrive: the machine stays
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
        policy.agent_map.block_past_edge(position, position + 0.05 * way, guessed=True)
    assert policy.sdf.sample(position[None])[0] <= policy.config.planner.clearance_m
    assert policy.goal_planner.escape(position) is None  # hemmed in, as the agent was
    plan = policy.goal_planner.plan(position)
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
    assert policy.scan_checks.refused_climb(position, position + [0.1, 0.0, 0.05]) == bool(
        policy.mapper.observed_space.sectors_seen_below(position[None])[0])
    assert not policy.scan_checks.refused_climb(position, position + [0.1, 0.0, 0.0])


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
    policy = NarutoPolicy(mapper_kind="tsdf", device="cpu")
    policy.bind(EnvContext.from_env(env.unwrapped, max_episode_steps=steps))
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
    policy = NarutoPolicy(mapper_kind="tsdf", device="cpu")
    policy.bind(EnvContext.from_env(env.unwrapped, max_episode_steps=steps))
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


def test_goals_may_stay_as_high_as_the_agent_stands_over_a_low_scan() -> None:
    """Goals lie ``scan_top_margin_m`` below the measured top, but never lower than the
    agent stands: over a scan that is mostly floor the top can lie below the agent, and
    without this it had no goal at all and never moved."""
    env = gym.make("NarutoRecon-v0", scene="replica_like_room:no_ceiling", image_scale=0.1,
                   coverage_samples=2000, max_episode_steps=20)
    policy = NarutoPolicy(mapper_kind="tsdf", device="cpu")
    policy.bind(EnvContext.from_env(env.unwrapped, max_episode_steps=20))
    observation, info = env.reset(seed=0)
    policy.reset(observation, info, seed=0)
    for _ in range(10):
        observation, _, _, _, info = env.step(policy.act(observation, info))
    observed = policy.mapper.observed_space
    position = np.asarray(observation["pose"], np.float64)[:3, 3]
    top = observed.scan_top_z() - policy.config.scan_top_margin_m
    column = np.array([[position[0], position[1], z] for z in np.arange(0.2, 6.0, 0.1)])
    supported = observed.sample(observed.supported(), column)
    low = policy.scan_checks.inside_scan(column, np.array([*position[:2], 0.0]))
    assert np.array_equal(low, supported & (column[:, 2] <= top))
    high = policy.scan_checks.inside_scan(column, np.array([*position[:2], top + 1.0]))
    assert np.array_equal(high, supported & (column[:, 2] <= top + 1.0))
    assert (high & ~low).any()  # the agent's own height admits more
    env.close()


def test_after_an_escape_refusal_goals_need_measured_surface_in_every_sector_below() -> None:
    """Once the env has refused a move for leaving the scan, the agent's goals must also pass
    the env's cone test on its own map; a surface refusal (as on every closed scene) leaves
    the coarse test alone."""
    for reason, strict in (("escape", True), ("surface", False)):
        policy, observation, _, position, _ = _first_move(reason)
        assert policy.scan_open == strict
        observed = policy.mapper.observed_space
        points = policy.sdf.grid_points()
        top = max(observed.scan_top_z() - policy.config.scan_top_margin_m, position[2])
        coarse = observed.sample(observed.supported(), points) & (points[:, 2] <= top)
        inside = policy.scan_checks.inside_scan(points, position)
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
    policy = NarutoPolicy(mapper_kind="tsdf", device="cpu")
    policy.bind(EnvContext.from_env(env.unwrapped, max_episode_steps=steps))
    observation, info = env.reset(seed=0)
    policy.reset(observation, info, seed=0)
    for _ in range(steps):
        observation, _, _, _, info = env.step(policy.act(observation, info))
    env.close()
    return policy


def test_the_sky_in_a_depth_frame_tells_the_scan_is_open() -> None:
    """Without a ceiling the first look-around's upward pixels hit nothing; a closed room's
    never miss, so the agent there is as before."""
    assert _agent_after("replica_like_room:no_ceiling", 12).scan_open
    assert not _agent_after("replica_like_room:fragments", 12).scan_open


def test_steep_miss_share_counts_only_steep_pixels() -> None:
    from naruto_agent.guards.panorama_clearance import steep_miss_share
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
    policy.guard.note_escape()
    blocked = len(policy.blocked.points)
    assert policy.scan_checks.stays_in_scan(np.array([1.0, 1.0, 1.0]), np.array([1.1, 1.0, 1.0]))
    assert len(policy.blocked.points) == blocked
    start, end = np.array([1.8, 1.0, 1.0]), np.array([1.9, 1.0, 1.0])
    assert not policy.scan_checks.stays_in_scan(start, end)
    assert len(policy.blocked.points) == blocked + 1
    assert policy.blocked.points[-1][0] > end[0]  # beyond the move's end, not behind it
    # From a point the test already fails, the agent may move (it has to get back in).
    assert policy.scan_checks.stays_in_scan(np.array([2.5, 1.0, 1.0]), np.array([2.6, 1.0, 1.0]))


def test_config_rejects_bad_open_scan_settings() -> None:
    from naruto_agent.naruto import NarutoConfig

    with pytest.raises(ValueError, match="open_sky_share"):
        NarutoPolicy(open_sky_share=0.0)
    with pytest.raises(ValueError, match="edge_probe_m"):
        NarutoPolicy(edge_probe_m=-0.1)
    with pytest.raises(ValueError, match="margin_climb_m"):
        NarutoConfig(margin_climb_m=-0.1)
