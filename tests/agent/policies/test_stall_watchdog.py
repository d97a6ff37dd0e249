"""The stall watchdog (naruto_agent.policies.watchdog) and every shipped policy's recovery:
held on one spot, each policy notices the stall, recovers, and moves on."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import naruto_gym  # noqa: F401
from naruto_agent.policies import (
    EnvContext,
    Policy,
    StallWatchdog,
    StallWatchdogConfig,
    make_policy,
    pose_action,
)
from naruto_agent.policies.watchdog import StallEvent, longest_stay


def _feed(watchdog: StallWatchdog, positions, refused=False, progress=None):
    return [
        watchdog.observe(p, refused, None if progress is None else progress(i))
        for i, p in enumerate(positions)
    ]


def test_spinning_in_place_is_a_stall_after_one_window():
    watchdog = StallWatchdog(StallWatchdogConfig(window_steps=20))
    events = _feed(watchdog, [np.zeros(3)] * 45)
    fired = [i for i, event in enumerate(events) if event is not None]
    assert fired == [19, 39]
    assert watchdog.events[0].kind == "spin" and watchdog.events[0].step == 20
    assert watchdog.stalled_steps == 26  # every step from the 20th on


def test_walking_is_no_stall():
    watchdog = StallWatchdog()
    line = [np.array([0.1 * i, 0.0, 1.0]) for i in range(100)]
    assert not any(_feed(watchdog, line)) and watchdog.stalled_steps == 0


def test_repeating_a_refused_move_is_a_refused_stall():
    watchdog = StallWatchdog()
    events = _feed(watchdog, [np.ones(3)] * 20, refused=True)
    assert events[-1] is not None and events[-1].kind == "refused"


def test_oscillating_between_two_poses_is_a_stall():
    """Back and forth along 1 m (farther than the stay radius)."""
    watchdog = StallWatchdog()
    swing = [np.array([0.1 * k, 0.0, 1.0]) for k in (*range(11), *range(9, 0, -1))]
    events = _feed(watchdog, swing * 3)
    kinds = [event.kind for event in events if event is not None]
    assert kinds and kinds[0] == "oscillation"


def test_walking_about_within_the_radius_is_a_stall_only_once_the_stay_lasts():
    """A random walk bouncing between the walls of a corner: 0.1 m steps back and forth along
    0.4 m stay within 0.5 m but walk 2 m a window; the walk's own rules get
    ``max_stay_steps`` to lead it away, then it is an oscillation."""
    config = StallWatchdogConfig(window_steps=20, max_stay_steps=24)
    watchdog = StallWatchdog(config)
    bounce = [np.array([0.1 * k, 0.0, 1.0]) for k in (0, 1, 2, 3, 4, 3, 2, 1)]
    events = _feed(watchdog, bounce * 4)
    fired = [(i, event.kind) for i, event in enumerate(events) if event is not None]
    assert fired == [(23, "oscillation")]


def test_a_stay_goes_on_across_a_recovery_that_did_not_leave():
    """A look-around that keeps learning is cut at ``max_stay_steps``; when the agent is
    still there once the window has filled again, the stay counts from where it began, so
    the next trigger comes at once (not ``max_stay_steps`` later)."""
    watchdog = StallWatchdog(StallWatchdogConfig(window_steps=20, max_stay_steps=24))
    events = _feed(watchdog, [np.zeros(3)] * 60, progress=lambda i: float(2**i))
    fired = [(i, event.kind) for i, event in enumerate(events) if event is not None]
    assert fired == [(23, "lingering"), (43, "lingering")]


def test_creeping_less_than_a_walk_is_still_a_spin():
    """Steps of 2 cm (1 m would take 50) are standing, not walking."""
    watchdog = StallWatchdog(StallWatchdogConfig(window_steps=20, min_walk_m=1.0))
    creep = [np.array([0.02 * (k % 5), 0.0, 1.0]) for k in range(20)]
    events = _feed(watchdog, creep)
    assert events[-1] is not None and events[-1].kind == "spin"


def test_longest_stay_counts_steps_within_the_radius_below_the_coverage_bound():
    """0.3 m steps, a stand of 30 steps at x = 3 m (steps 10-39), 0.3 m steps again: the
    step before the stand lies within 0.5 m of it, the steps after leave at once."""
    x = [0.3 * i for i in range(10)] + [3.0] * 30 + [3.0 + 0.3 * i for i in range(1, 11)]
    positions = np.stack([x, np.zeros(len(x)), np.ones(len(x))], axis=1)
    assert longest_stay(positions, np.full(len(x), 0.5)) == 30
    assert longest_stay(positions, np.full(len(x), 0.95)) == 0  # covered: no stall
    with pytest.raises(ValueError, match="one coverage per position"):
        longest_stay(positions, np.full(10, 0.5))


def test_a_look_around_that_learns_is_no_stall_until_it_lingers():
    config = StallWatchdogConfig(window_steps=20, max_stay_steps=24)
    watchdog = StallWatchdog(config)
    events = _feed(watchdog, [np.zeros(3)] * 30, progress=lambda i: 100.0 * 1.05**i)
    fired = [(i, event.kind) for i, event in enumerate(events) if event is not None]
    assert fired == [(23, "lingering")]


@pytest.mark.parametrize(
    "bad",
    [
        dict(window_steps=1),
        dict(radius_m=0.0),
        dict(refused_share=1.5),
        dict(max_stay_steps=5),
        dict(min_progress_gain=-1.0),
        dict(min_walk_m=0.0),
    ],
)
def test_bad_settings_are_refused_with_the_field_named(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        StallWatchdogConfig(**bad)


class _StandStill(Policy):
    """A user's policy that never moves, with the watchdog switched on."""

    def __init__(self, recovers: bool) -> None:
        super().__init__()
        self.recovers = recovers
        self.use_stall_watchdog()

    def act(self, observation, info=None):
        self.check_stall(observation, info)
        return pose_action(observation["pose"])


class _Recovering(_StandStill):
    def recover_from_stall(self, event):
        return "asked to recover"


def _context(env):
    return EnvContext.from_env(env, max_episode_steps=50)


def test_a_users_policy_opts_in_and_its_recovery_is_logged():
    env = gym.make(
        "NarutoRecon-v0", scene="replica_like_room", image_scale=0.05, panorama_shape=None
    )
    policy = _Recovering(recovers=True)
    policy.bind(_context(env))
    observation, info = env.reset(seed=0)
    policy.reset(observation, info)
    for _ in range(25):
        observation, _, _, _, info = env.step(policy.act(observation, info))
    assert [e.recovery for e in policy.stall_events] == ["asked to recover"]
    assert policy.stall_events[0].as_dict()["step"] == 20
    policy.reset(observation, info)
    assert policy.stall_events == [] and policy.stalled_steps == 0
    env.close()


def test_a_watchdog_without_a_recovery_says_what_to_implement():
    with pytest.raises(NotImplementedError, match=r"walk_out\(position, goal\)"):
        _StandStill(recovers=False)


class _WalksOut(Policy):
    """A user's policy that stands still and walks only the shared recovery's way out."""

    def __init__(self) -> None:
        super().__init__()
        self.use_stall_watchdog()
        self.goal = None

    def walk_out(self, position, goal):
        self.goal = goal
        return "straight"

    def act(self, observation, info=None):
        self.check_stall(observation, info)
        pose = np.array(observation["pose"], np.float64)
        if self.walking_out:
            move = self.goal - pose[:3, 3]
            pose[:3, 3] += move / max(np.linalg.norm(move), 1e-9) * min(
                self.context.max_translation_m, np.linalg.norm(move))
        return pose_action(pose)


def test_a_users_policy_gets_the_shared_way_out_past_the_stay_and_leaves():
    """A policy that implements only ``walk_out`` stands still until the watchdog fires;
    the shared recovery sends it to a place past the stay (read from the panorama), and it
    gets there without a refusal."""
    policy = _WalksOut()
    env = _small_room(policy)
    policy.bind(_context(env))
    observation, info = env.reset(seed=0)
    policy.reset(observation, info)
    start = observation["pose"][:3, 3].copy()
    refused, positions = 0, []
    for _ in range(60):
        observation, _, _, _, info = env.step(policy.act(observation, info))
        refused += bool(info["collided"])
        positions.append(observation["pose"][:3, 3])
    event = policy.stall_events[0]
    assert event.recovery.startswith("walk out to") and event.recovery.endswith("straight")
    _, radius = policy.stay_of(event)
    assert np.linalg.norm(policy.goal - start) > radius
    reached = np.linalg.norm(np.array(positions) - policy.goal, axis=1).min()
    assert reached <= policy.stall_recovery.config.arrival_m and refused == 0, (reached, refused)
    env.close()


class _IgnoresFirstWayOut(_WalksOut):
    """A user's policy whose own rules keep it standing on the first way out it is given."""

    def __init__(self) -> None:
        super().__init__()
        self.goals: list[np.ndarray] = []

    def walk_out(self, position, goal):
        self.goals.append(goal)
        self.goal = position if len(self.goals) == 1 else goal  # the first: it stands
        return "ignored" if len(self.goals) == 1 else "straight"


def test_a_way_out_the_policy_does_not_walk_is_followed_at_once_by_the_next():
    """The policy stands on its first way out: after ``max_idle_steps`` steps (not the next
    stall, a window later) the shared recovery gives it another, elsewhere, and it is past
    the stay within 8 steps more."""
    policy = _IgnoresFirstWayOut()
    env = _small_room(policy)
    policy.bind(_context(env))
    observation, info = env.reset(seed=0)
    policy.reset(observation, info)
    positions = []
    for _ in range(40):
        observation, _, _, _, info = env.step(policy.act(observation, info))
        positions.append(observation["pose"][:3, 3])
    event = policy.stall_events[0]
    idle = policy.stall_recovery.config.max_idle_steps
    assert event.recovery.endswith("straight")
    assert f"; failed at step {event.step + idle}, then" in event.recovery, event.recovery
    failed_radius = policy.stall_recovery.config.failed_radius_m
    assert np.linalg.norm(policy.goals[1] - policy.goals[0]) > failed_radius
    spots, radius = policy.stay_of(event)
    after = np.array(positions[event.step + idle : event.step + idle + 8])
    assert (np.linalg.norm(after[:, None] - spots[None], axis=2).min(axis=1) > radius).any()
    env.close()


class _DeclinesOrIgnores(_WalksOut):
    """A user's policy that declines its first way out of each stay (no path to it) and
    stands on every other one, and counts its own recoveries."""

    def __init__(self) -> None:
        super().__init__()
        self.offered: list[np.ndarray] = []
        self.own_recoveries = 0

    def walk_out(self, position, goal):
        self.offered.append(goal)
        if len(self.offered) == 1:
            return None
        self.goal = position  # it stands
        return "ignored"

    def no_way_out(self, event):
        self.own_recoveries += 1
        return "own recovery"


def test_a_declined_place_is_replaced_at_once_and_failed_ways_out_end_in_the_own_recovery():
    """The first place is declined (no step spent: the second is offered in the same step);
    the policy then stands on every way out, and after ``max_failed_ways_out`` failed ones
    its own recovery (``no_way_out``) takes over, once."""
    policy = _DeclinesOrIgnores()
    env = _small_room(policy)
    policy.bind(_context(env))
    observation, info = env.reset(seed=0)
    policy.reset(observation, info)
    for _ in range(20):
        observation, _, _, _, info = env.step(policy.act(observation, info))
    event = policy.stall_events[0]
    assert event.step == 20 and len(policy.offered) == 2
    assert event.recovery.startswith(f"walk out to ({policy.offered[1][0]:.2f}")
    config = policy.stall_recovery.config
    for _ in range((config.max_failed_ways_out + 1) * config.max_idle_steps + 1):
        observation, _, _, _, info = env.step(policy.act(observation, info))
    assert event.recovery.count("; failed at step") == config.max_failed_ways_out + 1
    assert event.recovery.endswith("then own recovery") and policy.own_recoveries == 1
    assert len(policy.offered) == 2 + config.max_failed_ways_out
    assert all(np.linalg.norm(a - b) > config.failed_radius_m
               for k, a in enumerate(policy.offered) for b in policy.offered[:k])
    env.close()


def _small_room(policy: Policy) -> gym.Env:
    """The catalogue's room at small frames, with the panorama, in ``policy``'s action mode."""
    return gym.make(
        "NarutoRecon-v0",
        scene="replica_like_room",
        image_scale=0.05,
        coverage_samples=500,
        panorama_shape=(32, 64),
        action_mode=policy.preferred_action_mode,
    )


@pytest.mark.parametrize("name", ["passive", "random", "frontier", "naruto"])
def test_every_shipped_policy_recovers_from_a_stall_and_moves_again(name):
    """The env is sent the agent's own pose, whatever the policy asks (as if each of its
    moves were refused in place), until the watchdog fires (within 20 steps); the policy's
    recovery then leaves the spot by more than 0.5 m within 15 steps."""
    policy = make_policy(name, stall_watchdog=True)
    env = _small_room(policy)
    policy.bind(EnvContext.from_env(env, max_episode_steps=200))
    observation, info = env.reset(seed=3, options=policy.reset_options())
    policy.reset(observation, info, seed=3)
    for _ in range(12):  # under way first
        observation, _, _, _, info = env.step(policy.act(observation, info))
    before = len(policy.stall_events)
    spot = observation["pose"][:3, 3].copy()
    for _ in range(21):
        action = policy.act(observation, info)
        if len(policy.stall_events) > before:
            break
        observation, _, _, _, info = env.step(pose_action(observation["pose"]))
    assert len(policy.stall_events) == before + 1, policy.stall_events
    assert policy.stall_events[-1].recovery
    farthest = 0.0
    for _ in range(15):
        observation, _, _, _, info = env.step(action)
        farthest = max(farthest, float(np.linalg.norm(observation["pose"][:3, 3] - spot)))
        action = policy.act(observation, info)
    assert farthest > 0.5, (name, policy.stall_events[-1])
    env.close()


@pytest.mark.parametrize(
    ("name", "settings"),
    [
        ("passive", StallWatchdogConfig()),
        ("random", StallWatchdogConfig()),
        ("frontier", StallWatchdogConfig(max_stay_steps=22)),
        ("naruto", StallWatchdogConfig()),
    ],
)
def test_the_watchdog_is_on_in_every_shipped_policy(name, settings):
    """On by default, with the default settings (frontier, whose walk away from a stay
    takes longer, cuts a stay that learns at 22 steps: no stay over 30 steps); the setting
    ``stall_watchdog=False`` turns it off."""
    watchdog = make_policy(name).stall_watchdog
    assert watchdog is not None and watchdog.config == settings
    assert make_policy(name, stall_watchdog=False).stall_watchdog is None


def test_naruto_cuts_a_long_look_around_short_and_walks_out():
    """NARUTO's first look-around (8 views, alternately up and down) learns all along but
    lasts over 30 steps: the watchdog cuts it at ``max_stay_steps`` as lingering, and the
    shared recovery's way out takes the agent past the stay radius, 0.5 m away within
    30 steps of the start."""
    policy = make_policy("naruto", mapper_kind="tsdf")
    env = gym.make(
        "NarutoRecon-v0",
        scene="replica_like_room",
        image_scale=0.05,
        coverage_samples=500,
        action_mode=policy.preferred_action_mode,
    )
    policy.bind(EnvContext.from_env(env, max_episode_steps=200))
    observation, info = env.reset(seed=3)
    policy.reset(observation, info, seed=3)
    start = observation["pose"][:3, 3].copy()
    positions = []
    for _ in range(30):
        observation, _, _, _, info = env.step(policy.act(observation, info))
        positions.append(observation["pose"][:3, 3].copy())
    event = policy.stall_events[0]
    assert (event.kind, event.step) == ("lingering", policy.stall_watchdog.config.max_stay_steps)
    assert event.recovery.startswith("walk out to")
    assert np.linalg.norm(positions[-1] - start) > 0.5
    env.close()


@pytest.mark.parametrize("seed", range(4))
def test_random_leaves_a_stall_in_a_corner_along_a_way_the_panorama_shows_clear(seed):
    """0.45 m from two walls of a room, most headings are blocked within a few steps: a new
    run that is clear for one step ends in the next redraw, and the walk bounces in the
    corner. The shared recovery sends a run to a place past the stay that the panorama shows
    clear all the way, whichever seed."""
    policy = make_policy("random", seed=seed)
    env = _small_room(policy)
    context = EnvContext.from_env(env, max_episode_steps=200)
    policy.bind(context)
    pose = np.eye(4)
    pose[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]
    pose[:3, 3] = [context.bounds[0, 0] + 0.45, context.bounds[0, 1] + 0.45, 1.3]
    observation, info = env.reset(seed=seed, options={"pose": pose})
    policy.reset(observation, info, seed=seed)
    policy.act(observation, info)  # the panorama the recovery reads
    panorama = policy.guard.panorama(observation)
    event = StallEvent(step=20, position=pose[:3, 3], kind="oscillation")
    assert "a straight run" in policy.recover_from_stall(event)
    goal = policy.stall_recovery.goal
    _, radius = policy.stay_of(event)
    assert np.linalg.norm(goal - pose[:3, 3]) > radius
    heading = np.array([*policy.direction[:2], 0.0]) / np.linalg.norm(policy.direction[:2])
    assert not policy.guard.way_blocked(panorama, goal - pose[:3, 3])
    np.testing.assert_allclose(heading * np.linalg.norm(goal - pose[:3, 3]), goal - pose[:3, 3],
                               atol=1e-9)
    env.close()


@pytest.mark.slow
def test_frontier_walks_elsewhere_when_its_walk_away_from_a_stay_is_refused_and_no_plan_moves():
    """On this open small-class scan frontier's walk away from a stay is refused at its first
    step, and every first move of the plan made on the refused spot is held by the panorama:
    it walks elsewhere instead of turning all around on that spot, and no stay lasts over 30
    steps."""
    policy = make_policy("frontier")
    env = gym.make("NarutoRecon-v0", scene="procedural:small:1000005:no_ceiling+holes",
                   image_scale=0.125, action_mode=policy.preferred_action_mode,
                   max_episode_steps=200)
    policy.bind(EnvContext.from_env(env, max_episode_steps=200))
    observation, info = env.reset(seed=0, options=policy.reset_options())
    policy.reset(observation, info, seed=0)
    positions, coverage = [], []
    for _ in range(200):
        observation, _, _, _, info = env.step(policy.act(observation, info))
        positions.append(observation["pose"][:3, 3].copy())
        coverage.append(info["coverage"])
    env.close()
    assert longest_stay(np.array(positions), np.array(coverage)) <= 30
