"""The NARUTO agent acting in the env (shipped ``replica_like_room``, small images)."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
import pytest

import naruto_gym  # noqa: F401  (registers the env)
from naruto_agent.naruto import TRANSITIONS, NarutoPolicy, Plan, State, build_config
from naruto_agent.policies import EnvContext, make_policy, pose_action
from naruto_agent.policies.watchdog import StallEvent
from naruto_gym.geometry.transforms import rotation_angle_between

SCENE = "replica_like_room"
SCALE = 0.2
STEPS = 150


@dataclass
class Episode:
    policy: NarutoPolicy
    env: gym.Env
    actions: np.ndarray
    poses: np.ndarray
    coverage: np.ndarray
    collisions: int


def run_episode(steps: int, seed: int = 0, policy: NarutoPolicy | None = None,
                **settings) -> Episode:
    # One step more than run, so no truncation triggers the 200,000-sample final scoring;
    # reconstruct=True fuses the env's reference TSDF map to compare the agent's own with.
    env = gym.make("NarutoRecon-v0", scene=SCENE, image_scale=SCALE, panorama_shape=None,
                   max_episode_steps=steps + 1, reconstruct=True)
    policy = policy or NarutoPolicy(mapper_kind="tsdf", device="cpu", **settings)
    policy.bind(EnvContext.from_env(env))
    observation, info = env.reset(seed=seed, options=policy.reset_options())
    policy.reset(observation, info, seed=seed)
    actions, poses, coverage, collisions = [], [observation["pose"]], [info["coverage"]], 0
    for _ in range(steps):
        action = policy.act(observation, info)
        actions.append(action)
        observation, _, terminated, truncated, info = env.step(action)
        poses.append(observation["pose"])
        coverage.append(info["coverage"])
        collisions += int(info["collided"])
        if terminated or truncated:
            break
    return Episode(policy, env, np.array(actions), np.array(poses, np.float64),
                   np.array(coverage), collisions)


@pytest.fixture(scope="module")
def episode() -> Episode:
    return run_episode(STEPS)


def test_coverage_grows_clearly_and_beats_standing_still(episode):
    # A policy that stays still (commands its start pose) keeps the start view's coverage.
    env = gym.make("NarutoRecon-v0", scene=SCENE, image_scale=SCALE, panorama_shape=None)
    observation, info = env.reset(seed=0)
    for _ in range(5):
        _, _, _, _, info = env.step(pose_action(observation["pose"]))
    still_coverage = info["coverage"]
    assert still_coverage == pytest.approx(episode.coverage[0])
    assert episode.coverage[-1] > episode.coverage[0] + 0.25
    assert episode.coverage[-1] > still_coverage + 0.2
    assert episode.collisions <= 2


def test_actions_are_finite_pose_actions_in_the_space(episode):
    assert episode.actions.shape == (STEPS, 7) and episode.actions.dtype == np.float32
    assert np.all(np.isfinite(episode.actions))
    assert all(episode.env.action_space.contains(a) for a in episode.actions)


def test_turns_stay_within_the_step_limit_and_moves_within_a_step(episode):
    rotations = episode.poses[:, :3, :3]
    angles = [rotation_angle_between(a, b) for a, b in zip(rotations[:-1], rotations[1:],
                                                            strict=True)]
    limit = episode.policy.config.max_rotation_step_deg
    assert limit == 20.0  # the env's limit (published: 10)
    assert max(angles) <= np.deg2rad(limit) + 1e-3  # float32 poses
    assert max(angles) > np.deg2rad(10.5)  # the larger steps are used
    moves = np.linalg.norm(np.diff(episode.poses[:, :3, 3], axis=0), axis=1)
    assert moves.max() <= 0.1 + 1e-4


def test_states_run_in_the_published_order(episode):
    machine = episode.policy.machine
    assert all(b in TRANSITIONS[a] for a, b in machine.transitions)
    assert machine.transitions[:4] == [
        (State.STAYING, State.PLANNING),
        (State.PLANNING, State.ROTATING_AT_START),
        (State.ROTATING_AT_START, State.MOVING),
        (State.MOVING, State.ROTATING_AT_GOAL),
    ]
    # A look-around ends in planning, unless the stall watchdog cut it short (the first one
    # lasts longer than a stay may), which goes through staying to the way out.
    events = episode.policy.stall_watchdog.events
    assert len(machine.interruptions) == len(events) >= 1
    assert events[0].kind == "lingering"
    for index, (before, after) in enumerate(machine.transitions):
        if before == State.ROTATING_AT_GOAL:
            expected = State.STAYING if index in machine.interruptions else State.PLANNING
            assert after == expected
        if index in machine.interruptions:
            assert machine.transitions[index + 1] == (State.STAYING, State.PLANNING)
    counts = Counter(machine.history)
    assert counts[State.MOVING] >= 20 and counts[State.ROTATING_AT_GOAL] >= 10
    planned = [plan for plan in episode.policy.plans if plan["outcome"] == "planned"]
    assert len(planned) >= 2
    assert all(plan["score"] > 0 for plan in planned)
    assert set(episode.policy.timings) == {"mapping", "planner_view", "goal_search", "rrt",
                                           "control"}


def test_the_agents_mesh_scores_in_the_env(episode):
    mesh = episode.policy.mesh()
    assert len(mesh.faces) > 1000
    metrics = episode.env.unwrapped.evaluate(mesh, num_samples=20_000)
    reference = episode.env.unwrapped.reconstruction_metrics(num_samples=20_000)
    assert metrics["completion_ratio_pct"] > 20.0
    # The agent maps the same frames as the env's reference TSDF, so it scores about as well.
    assert metrics["completion_ratio_pct"] > reference["completion_ratio_pct"] - 3.0
    assert metrics["accuracy_cm"] < reference["accuracy_cm"] + 1.0


def test_same_seed_same_actions(episode):
    again = run_episode(40)
    assert np.array_equal(again.actions, episode.actions[:40])


def test_settings_and_errors():
    policy = make_policy("naruto_agent.naruto:NarutoPolicy", goal_attempts=1,
                         goal_search={"top_k": 2}, planner={"time_limit_s": 1.0})
    assert isinstance(policy, NarutoPolicy)
    assert policy.config.goal_attempts == 1 and policy.config.planner.time_limit_s == 1.0
    assert build_config().goal_search.target_subset == 300
    assert isinstance(make_policy("naruto"), NarutoPolicy)  # the harness's registry name
    with pytest.raises(ValueError, match="mapper_kind"):
        NarutoPolicy(mapper_kind="octomap")
    with pytest.raises(ValueError, match="renamed: pass mapper_kind='neural'"):
        NarutoPolicy(mapper="neural")
    with pytest.raises(ValueError, match="unknown NARUTO settings"):
        NarutoPolicy(speed=3)
    with pytest.raises(ValueError, match="shortcut_margin_m"):
        NarutoPolicy(shortcut_margin_m=-0.01)
    with pytest.raises(ValueError, match="unknown goal_search settings"):
        NarutoPolicy(goal_search={"radius": 1})
    with pytest.raises(RuntimeError, match="reset"):
        NarutoPolicy().act({"rgb": None, "depth": None, "pose": np.eye(4)})
    env = gym.make("NarutoRecon-v0", scene=SCENE, image_scale=0.1, action_mode="discrete")
    with pytest.raises(ValueError, match="pose"):
        NarutoPolicy().bind(EnvContext.from_env(env))


def test_public_seams_wrap_the_move_check_refresh_the_view_and_learn_refusals(episode):
    """A wrapped move check sees every check and changes nothing; the view can be read on
    demand; a refusal told by hand blocks its target, which only a trusted plan passes."""
    checked = []

    def counting(check):
        def wrapped(start, end):
            checked.append(end.copy())
            return check(start, end)
        return wrapped

    policy = NarutoPolicy(mapper_kind="tsdf", device="cpu")
    policy.wrap_move_check(counting)
    run = run_episode(60, policy=policy)
    assert np.array_equal(run.actions, episode.actions[:60])
    moves = np.linalg.norm(np.diff(run.poses[:, :3, 3], axis=0), axis=1) > 1e-6
    assert len(checked) >= moves.sum() > 0
    policy.refresh_view()
    assert policy.sdf is not None and policy.uncertainty is not None
    position = run.poses[-1, :3, 3].astype(np.float64)
    target = position + np.array([0.05, 0.0, 0.0])
    policy.learn_refusal(position, target, "surface")
    assert np.allclose(policy.blocked.points[-1], target) and not policy.scan_open
    policy.machine.plan = Plan(np.array([position, target]), target[None], target, {})
    assert not policy.move_is_free(position, target)
    policy.machine.plan.info["trusted"] = True  # a retreat or a climb: checked already
    assert policy.move_is_free(position, target)
    # A goal refused at a surface fails where it is; one refused past an open scan's edge
    # (sideways, not a climb at the open top) fails at every height.
    policy.machine.plan = Plan(np.array([position, target]), target[None], target, {})
    policy.learn_refusal(position, target, "surface")
    assert len(policy.monitor.recent_failed_goals(columns=True)) == 0
    policy.learn_refusal(position, target, "escape")
    assert np.allclose(policy.monitor.recent_failed_goals(columns=True), [target])
    with pytest.raises(RuntimeError, match="reset"):
        NarutoPolicy().move_is_free(position, target)


def test_a_held_move_is_planned_around_at_the_next_frame():
    """A move the agent's own checks hold cuts the plan short and blocks the space in the
    map; the agent plans again at the next frame instead of standing until the next mapping
    step (a wait of up to a mapping period, five frames, for each hold). Without the stall
    watchdog: no stay is cut short, where a hold is planned around in its own frame."""
    held: list[int] = []  # the frames of the held moves
    plans_held: set[int] = set()

    def hold_first_move_of_each_plan(check):
        def wrapped(start, end):
            plan = policy.machine.plan
            frame = len(policy.machine.history)
            if (len(held) < 4 and np.linalg.norm(end - start) > 1e-6 and plan is not None
                    and id(plan) not in plans_held and len(policy.plans) >= 2
                    and (not held or frame > held[-1] + 3)):
                plans_held.add(id(plan))
                held.append(frame)
                return False
            return check(start, end)
        return wrapped

    policy = NarutoPolicy(mapper_kind="tsdf", device="cpu", stall_watchdog=False)
    policy.wrap_move_check(hold_first_move_of_each_plan)
    run = run_episode(80, policy=policy)
    assert len(held) >= 2, held
    history = run.policy.machine.history
    assert all(history[frame] == State.STAYING for frame in held)  # the held moves' frames
    assert all(history[frame + 1] != State.STAYING for frame in held), (
        [history[frame + 1] for frame in held])
    # ... and sets off without turning first (each new path would cost a turn in place).
    assert all(history[frame + 1] != State.ROTATING_AT_START for frame in held), (
        [history[frame + 1] for frame in held])


def _hold_plans_from(frame_held: int, kinds: tuple[str | None, ...] = (None,),
                     watchdog: bool = True):
    """An episode whose agent's checks hold every move of a plan of the recovery ``kinds``
    (None: a normal plan) from ``frame_held`` on (as next to a wall top on an open scan),
    until a recovery that moves (the agent's own or a way out of a stall) is under way.
    Returns the policy, the env, the last observation, the frame the recovery was under way
    (None: not within 80 frames) and the moves held until then."""
    holding = False

    def hold_plans(check):
        def wrapped(start, end):
            plan = policy.machine.plan
            if holding and plan is not None and plan.info.get("recovery") in kinds:
                return False
            return check(start, end)
        return wrapped

    policy = NarutoPolicy(mapper_kind="tsdf", device="cpu", stall_watchdog=watchdog)
    policy.wrap_move_check(hold_plans)
    env = gym.make("NarutoRecon-v0", scene=SCENE, image_scale=SCALE, panorama_shape=None,
                   max_episode_steps=200)
    policy.bind(EnvContext.from_env(env))
    observation, info = env.reset(seed=0)
    policy.reset(observation, info, seed=0)
    held_before = 0
    for frame in range(1, 80):
        if frame == frame_held + 1:
            held_before = policy.machine.collisions
        holding = frame > frame_held
        action = policy.act(observation, info)
        plan = policy.machine.plan
        moving = plan is not None and plan.info.get("recovery") in ("wander", "retreat", "way_out")
        if holding and moving and policy.state in (State.ROTATING_AT_START, State.MOVING):
            return policy, env, observation, frame, policy.machine.collisions - held_before
        observation, _, _, _, info = env.step(action)
    return policy, env, observation, None, policy.machine.collisions - held_before


def test_moves_held_in_one_place_lead_to_a_recovery_that_moves():
    """From frame 30 on, the agent's checks hold every move of a normal plan: after three
    holds in one place the next plan is a recovery that moves (the agent's own: the
    watchdog is off)."""
    policy, env, _, under_way, held = _hold_plans_from(30, watchdog=False)
    assert under_way is not None and under_way <= 30 + 12, under_way
    assert held == 3
    env.close()


def test_a_held_way_out_of_a_stall_is_followed_at_once_by_the_next_elsewhere():
    """The watchdog fires and the shared recovery plans a way out; the agent's checks hold
    its first move: that way out counts as failed, and at the next step the shared recovery
    sends the agent to another way out of the same stay (not to the agent's own recovery,
    which would walk back along its trail into the stay)."""
    policy, env, observation, _, _ = _hold_plans_from(0, kinds=("way_out",))
    goals, walk_out = [], policy.walk_out
    policy.walk_out = lambda position, goal: (goals.append(goal), walk_out(position, goal))[1]
    event = StallEvent(step=40, position=observation["pose"][:3, 3].copy(), kind="oscillation")
    assert policy.recover_from_stall(event).startswith("walk out to")
    policy.act(observation, {})  # the way out's first move is held
    assert policy.stall_recovery.goal is None and policy.stall_recovery.walk_failed
    policy.act(observation, {})
    assert "failed at step" in event.recovery and not policy.monitor.requested
    failed_radius = policy.stall_recovery.config.failed_radius_m
    assert len(goals) >= 2 and np.linalg.norm(goals[1] - goals[0]) > failed_radius
    env.close()


@pytest.mark.parametrize("looks", [4.0, 0.0])
def test_a_reached_goal_counts_looks_at_every_target_it_was_chosen_for(looks):
    """When the agent starts a new plan at the goal of the last one, the targets the goal
    search saw from that goal get ``unresolved_visit_looks`` looks (none when it is 0), and
    the planner view's uncertainty there falls to ``1 / (1 + look_weight * looks)``."""
    run = run_episode(100, unresolved_visit_looks=looks)
    policy = run.policy
    if looks == 0:
        assert policy.visit_looks is None
        return
    looked = np.argwhere(policy.visit_looks > 0)
    assert len(looked) and np.all(np.mod(policy.visit_looks[tuple(looked.T)], looks) == 0)
    # The looks come at planning requests made at the last plan's goal: the visited
    # targets lie within the goal search's range of a planned goal.
    planned = [plan for plan in policy.plans if plan.get("outcome") == "planned"]
    goals = np.array([plan["goal"] for plan in planned])
    points = policy.sdf.origin + looked * policy.sdf.voxel_size
    reach = np.linalg.norm(points[:, None, :] - goals[None, :, :], axis=2)
    assert np.all(np.any(reach < 2.0 + policy.sdf.voxel_size, axis=1))
    # The damping applies to whatever the mapper's view holds there, surface or frontier.
    _, raw = policy.mapper.planner_view(policy.config.planner_voxel_m)
    weight = policy.mapper.observed_space.config.look_weight
    damped = policy.agent_map.damp_visited(raw)
    index = tuple(looked.T)
    np.testing.assert_allclose(
        damped.values[index],
        raw.values[index] / (1.0 + weight * policy.visit_looks[index]), rtol=1e-6)
    untouched = policy.visit_looks == 0
    np.testing.assert_array_equal(damped.values[untouched], raw.values[untouched])


@pytest.mark.slow
def test_neural_mapper_runs_the_same_loop():
    """The published mapper, cut down to run in seconds on a CPU."""
    env = gym.make("NarutoRecon-v0", scene=SCENE, image_scale=0.1, panorama_shape=None)
    policy = NarutoPolicy(
        mapper_kind="neural", device="cpu", initial_look_around=False,
        neural={"first_frame_iterations": 10, "iterations_per_step": 2, "rays_per_iteration": 256,
                "current_frame_rays": 32, "active_top_rays": 64, "hash_log2_table_size": 12,
                "active_score": "surface"},
    )
    policy.bind(EnvContext.from_env(env))
    observation, info = env.reset(seed=0)
    policy.reset(observation, info, seed=0)
    start = info["coverage"]
    for _ in range(15):
        action = policy.act(observation, info)
        assert np.all(np.isfinite(action))
        observation, _, _, _, info = env.step(action)
    assert policy.plans and policy.plans[0]["outcome"] == "planned"
    assert State.MOVING in policy.machine.history
    assert info["coverage"] > start
    assert len(policy.mesh(voxel_size=0.1).faces) > 0
