"""Goal actions: the candidate goals and the planner over the agent's own map, and the
wrappers that walk their paths (refused moves under 1 per 100 steps on generated rooms with
random candidates)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from naruto_gym.rl.egocentric_map import (
    EgocentricMapBuilder,
    EgocentricMapObservation,
    VectorEgocentricMapObservation,
)
from naruto_gym.rl.egocentric_map_kernels import FREE, OCCUPIED, SEEN, TRAIL
from naruto_gym.rl.explorer_env import (
    EXPLORER_ENV,
    EXPLORER_PANORAMA_HORIZON_DEG,
    shared_train_mix,
    wrap_explorer,
)
from naruto_gym.rl.goal_actions import GoalActions, VectorGoalActions
from naruto_gym.rl.goal_candidates import (
    CANDIDATE_FEATURES,
    INTERVAL_FEATURES,
    find_candidates,
    path_lengths,
    wander_goal,
)
from naruto_gym.rl.goal_planner import (
    MOVE_BACKWARD,
    MOVE_FORWARD,
    MOVE_LEFT,
    MOVE_RIGHT,
    REACHED,
    TURN_LEFT,
    TURN_RIGHT,
    WALKING,
    follow_path,
    plan_path,
    traversable,
)
from naruto_gym.rl.goal_walker import (
    FACE,
    IDLE,
    IDLE_SEARCH_EVERY,
    LOOK_DOWN,
    LOOK_UP,
    MOVE_DOWN,
    MOVE_UP,
    OPPOSITE_TURN,
    WALK,
    GoalWalker,
)
from naruto_gym.sensors.pinhole import PinholeCamera
from naruto_gym.vector import NarutoReconVectorEnv, make_vector_env

CAMERA = PinholeCamera(16, 16, 8, 8, 7.5, 7.5)
ENV = {
    "action_mode": "discrete",
    "camera": CAMERA,
    "panorama_shape": (32, 64),
    "coverage_samples": 1000,
}
ORIGIN = np.zeros(2)


def _room_with_wall() -> np.ndarray:
    """A 40 x 40 grid of 0.1 m cells: free inside a border, a wall across x = 2 m with a gap
    at y in [3.0, 3.5) m; the cells beyond y = 3.8 m unknown."""
    grid = np.zeros((4, 40, 40), np.uint8)
    grid[FREE, 1:39, 1:38] = 255
    grid[OCCUPIED, 20, :] = 255
    grid[OCCUPIED, 20, 30:35] = 0
    grid[FREE, 20, :] = 0
    grid[FREE, 20, 30:35] = 255
    return grid


def test_the_path_goes_through_the_gap_and_never_near_an_obstacle():
    grid = _room_with_wall()
    path = np.zeros((256, 2), np.int64)
    length = plan_path(
        grid, ORIGIN, 0.1, np.array([0.55, 0.55]), np.array([3.55, 0.55]), 40, 1, path
    )
    cells = path[:length]
    assert tuple(cells[0]) == (5, 5) and tuple(cells[-1]) == (35, 5)
    assert all(traversable(grid, i, j, 1) for i, j in cells[1:])
    crossing = cells[cells[:, 0] == 20]
    assert len(crossing) and np.all((crossing[:, 1] >= 31) & (crossing[:, 1] <= 33))
    assert np.all(np.abs(np.diff(cells, axis=0)).max(axis=1) == 1)  # one cell per move


def test_an_unreachable_goal_leads_to_the_nearest_reachable_cell():
    grid = _room_with_wall()
    grid[OCCUPIED, 20, 30:35] = 255  # close the gap
    path = np.zeros((256, 2), np.int64)
    length = plan_path(
        grid, ORIGIN, 0.1, np.array([0.55, 0.55]), np.array([3.55, 0.55]), 40, 1, path
    )
    assert path[length - 1, 0] == 18  # beside the (inflated) wall, on the start's side
    unknown = plan_path(
        grid, ORIGIN, 0.1, np.array([0.55, 0.55]), np.array([0.55, 3.95]), 40, 1, path
    )
    assert path[unknown - 1, 1] == 37  # the last free cell: never into the unknown ones


def test_following_a_path_turns_towards_it_then_moves_forward():
    grid = _room_with_wall()
    path = np.zeros((256, 2), np.int64)
    length = plan_path(
        grid, ORIGIN, 0.1, np.array([0.55, 0.55]), np.array([1.55, 0.55]), 40, 1, path
    )
    pose = np.eye(4)
    pose[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]  # optical axis +x
    pose[:2, 3] = [0.55, 0.55]
    cursor = np.zeros(1, np.int64)
    assert follow_path(grid, ORIGIN, 0.1, pose, path, length, cursor, 0.1, np.deg2rad(20), 1) == (
        MOVE_FORWARD,
        WALKING,
    )
    facing_away = pose.copy()
    facing_away[:3, :3] = [[0, 0, -1], [1, 0, 0], [0, -1, 0]]  # optical axis -x
    move, status = follow_path(
        grid, ORIGIN, 0.1, facing_away, path, length, cursor, 0.1, np.deg2rad(20), 1
    )
    assert status == WALKING and move != MOVE_FORWARD
    at_goal = pose.copy()
    at_goal[:2, 3] = [1.55, 0.55]
    walked = np.array([length - 3])  # the path index reached while walking there
    assert follow_path(
        grid, ORIGIN, 0.1, at_goal, path, length, walked, 0.1, np.deg2rad(20), 1
    ) == (TURN_LEFT, REACHED)


def test_a_carrot_a_little_over_half_a_turn_off_is_walked_to_while_that_is_safe():
    """Headings come a whole turn apart, so a path between two of them would be walked in a
    zigzag (turn, step, turn back, step): a carrot up to three quarters of a turn off is
    walked towards where the step is safe, and turned to where it is not."""
    grid = np.zeros((4, 40, 40), np.uint8)
    grid[FREE, 1:39, 1:39] = 255
    pose = np.eye(4)
    pose[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]  # optical axis +x
    pose[:2, 3] = [0.55, 0.55 - 0.6 * np.tan(np.deg2rad(13))]  # the carrot 13 deg left
    path = np.zeros((256, 2), np.int64)
    cells = [(5 + k, 5) for k in range(12)]  # along +x, 0.6 m ahead of it the carrot
    path[: len(cells)] = cells

    def follow(turn_deg: float) -> tuple[int, int]:
        cursor = np.zeros(1, np.int64)
        return follow_path(grid, ORIGIN, 0.1, pose, path, len(cells), cursor, 0.1,
                           np.deg2rad(turn_deg), 1)  # fmt: skip

    assert follow(20) == (MOVE_FORWARD, WALKING)  # 13 degrees: over half a 20-degree turn
    assert follow(16) == (TURN_LEFT, WALKING)  # over three quarters of a 16-degree turn
    grid[OCCUPIED, 7, 3] = 255  # the step ahead would end beside an obstacle
    assert follow(20) == (TURN_LEFT, WALKING)


def test_where_the_path_turns_by_a_corner_a_sideways_step_follows_it():
    """Facing the carrot within half a turn, a forward step that ends beside the path in an
    inflated cell would make the walker turn and re-plan the same path forever: it steps
    sideways onto the path instead."""
    grid = np.zeros((4, 40, 40), np.uint8)
    grid[FREE, 1:39, 1:39] = 255
    grid[OCCUPIED, 21, 22] = 255  # (21, 20) lies within the inflation, row 19 does not
    path = np.zeros((256, 2), np.int64)
    cells = [(20, 20), (20, 19), (21, 19), (22, 19), (23, 19), (24, 19), (25, 19), (26, 19)]
    path[: len(cells)] = cells
    pose = np.eye(4)
    pose[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]  # optical axis +x
    pose[:2, 3] = [2.05, 2.005]  # just inside cell (20, 20)
    cursor = np.zeros(1, np.int64)
    move, status = follow_path(grid, ORIGIN, 0.1, pose, path, len(cells), cursor, 0.1,
                               np.deg2rad(15), 2)  # fmt: skip
    assert (move, status) == (MOVE_RIGHT, WALKING)
    assert traversable(grid, 20, 19, 2) and not traversable(grid, 21, 20, 2)


def _coarse(grid: np.ndarray, factor: int = 4) -> np.ndarray:
    layers, side = grid.shape[0], grid.shape[1] // factor
    return grid.reshape(layers, side, factor, side, factor).max(axis=(2, 4))


def _candidates(grid: np.ndarray, x: float, y: float, done: np.ndarray | None = None):
    pose = np.eye(4)
    pose[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]  # optical axis +x
    pose[:2, 3] = [x, y]
    done = np.zeros((5, 5), bool) if done is None else done
    table = np.zeros((8, len(CANDIDATE_FEATURES)), np.float32)
    viewpoints, centres = np.zeros((8, 2)), np.zeros((8, 2))
    clusters = np.zeros((8, 2), np.int64)
    radius = 40
    count = find_candidates(
        grid, _coarse(grid), 4, ORIGIN, 0.1, pose, radius, 1, 2, 1, 2.0, 0.6, done,
        np.zeros((2 * radius + 1, 2 * radius + 1)), table, viewpoints, centres, clusters,
    )  # fmt: skip
    return count, table, viewpoints, centres, clusters


def test_candidate_0_is_the_nearest_by_path_not_by_straight_distance():
    grid = _room_with_wall()
    known = (grid[FREE] == 0) & (grid[OCCUPIED] == 0)
    grid[OCCUPIED][known] = 255  # closed all around: no free-space edge
    grid[SEEN] = grid[OCCUPIED]  # every obstacle seen: no target yet
    grid[OCCUPIED, 24:26, 4:6] = 255  # unseen: 0.7 m away in a straight line, behind the wall
    grid[OCCUPIED, 4:6, 24:26] = 255  # unseen: 1.9 m away, on the agent's side
    count, table, viewpoints, centres, clusters = _candidates(grid, 1.75, 0.55)
    assert count == 2 and table[:2, 0].tolist() == [1, 1] and not table[2:].any()
    assert np.allclose(centres[0], [0.6, 2.6], atol=0.25)  # the one on the agent's side
    assert np.allclose(centres[1], [2.6, 0.6], atol=0.25)  # through the gap in the wall
    assert table[0, 1] < table[1, 1]  # path lengths (tens of metres), nearest first
    assert table[1, 2] < table[0, 2]  # though the second is nearer in a straight line
    assert table[0, 6] == 1.0  # unseen obstacles, no free-space edge
    out_of_sight = CANDIDATE_FEATURES.index("out_of_sight")
    assert table[:2, out_of_sight].tolist() == [0.0, 1.0]  # in the open; round the wall
    # Every viewpoint is reachable and within 2 m of its cluster, on the path's side.
    for k in range(2):
        assert np.hypot(*(viewpoints[k] - centres[k])) <= 2.0 + 1e-9
        i, j = np.floor(viewpoints[k] / 0.1).astype(int)
        assert traversable(grid, i, j, 1)
    # A viewed cluster is not offered again.
    done = np.zeros((5, 5), bool)
    done[tuple(clusters[0])] = True
    count, _, _, again, _ = _candidates(grid, 1.75, 0.55, done)
    assert count == 1 and np.allclose(again[0], centres[1])


def test_with_no_candidate_it_wanders_to_the_reachable_place_farthest_from_its_trail():
    grid = _room_with_wall()
    grid[OCCUPIED, 20, 30:35] = 255  # the gap closed
    grid[TRAIL, 3:8, 3:8] = 255  # it stood near (0.5, 0.5) m
    grid[SEEN, :, 4:] = 255  # the floor seen everywhere but along y < 0.4 m
    lengths = np.zeros((81, 81))
    path_lengths(grid, 5, 5, 40, 1, lengths)
    i, j = wander_goal(grid, _coarse(grid), 4, lengths, 5, 5, 40, 1)
    assert traversable(grid, i, j, 1) and lengths[i - 5 + 40, j - 5 + 40] > 0
    assert i < 20  # on its side of the wall ...
    assert np.hypot(i - 5, j - 5) > 25  # ... and far from where it stood
    assert j >= 4  # never where it saw no floor
    # Through the gap, the far side of the wall is reachable: farther from the trail there.
    grid[OCCUPIED, 20, 30:35] = 0
    path_lengths(grid, 5, 5, 40, 1, lengths)
    far_i, far_j = wander_goal(grid, _coarse(grid), 4, lengths, 5, 5, 40, 1)
    assert far_i > 20 and lengths[far_i - 5 + 40, far_j - 5 + 40] > 0


def test_a_free_space_edge_is_walked_up_to():
    grid = _room_with_wall()
    grid[SEEN] = grid[OCCUPIED]
    # The cells beyond y = 3.8 m are unknown: the free cells beside them are edges.
    count, table, viewpoints, centres, _ = _candidates(grid, 0.55, 0.55)
    assert count >= 1 and table[:count, 6].max() == 0.0  # free-space edges only
    nearest = int(np.argmin(np.hypot(*(viewpoints[:count] - centres[:count]).T)))
    assert np.hypot(*(viewpoints[nearest] - centres[nearest])) <= 0.6 + 1e-9


@pytest.mark.parametrize(
    ("scene", "primitive_actions"),
    [
        ("procedural:room", False),
        ("procedural:small:train:no_ceiling+holes", False),
        ("procedural:room", True),  # random candidates and guarded discrete moves
    ],
)
def test_random_candidates_are_refused_under_once_per_100_steps(scene, primitive_actions):
    envs = VectorGoalActions(
        VectorEgocentricMapObservation(
            NarutoReconVectorEnv(
                4, scene=scene, max_episode_steps=100, autoreset_mode="SameStep", **ENV
            )
        ),
        steps_per_goal=10,
        primitive_actions=primitive_actions,
    )
    try:
        envs.reset(seed=3)
        rng = np.random.default_rng(0)
        refusals = 0
        for _ in range(15):  # 150 steps per agent, a new episode after 100
            _, _, _, _, infos = envs.step(rng.integers(0, envs.single_action_space.n, 4))
            refusals += int(infos["refusals"].sum())
        path_m = infos["path_length_m"]
        assert refusals / (4 * 150) < 0.01
        assert path_m.mean() > 1.0  # the agents walked (the last 50 steps of the episode)
    finally:
        envs.close()


def test_single_env_goal_actions_take_k_steps_and_sum_the_rewards():
    env = GoalActions(
        EgocentricMapObservation(
            gym.make("NarutoRecon-v0", scene="procedural:room:5", max_episode_steps=25, **ENV)
        ),
        steps_per_goal=10,
    )
    try:
        observation, _ = env.reset(seed=0)
        assert env.action_space.n == 8 + 10
        assert env.observation_space.contains(observation)
        assert observation["candidates"].shape == (8, len(INTERVAL_FEATURES))
        assert observation["candidates"][0, 0] == 1  # a room has something to look at
        observation, reward, _, truncated, info = env.step(7)  # an empty slot: candidate 0
        assert info["primitive_steps"] == 10 and info["refusals"] == 0 and not truncated
        assert reward > 0  # walking and looking finds new surface
        env.step(8 + 6)  # turn_left, repeated
        _, _, _, truncated, info = env.step(0)
        assert truncated and info["primitive_steps"] == 5  # the episode ends first
        with pytest.raises(ValueError, match="goal actions are 0..17"):
            env.step(18)
    finally:
        env.close()


def test_goal_actions_refuse_envs_they_cannot_walk():
    with pytest.raises(ValueError, match="action_mode='discrete'"):
        GoalActions(
            EgocentricMapObservation(
                gym.make(
                    "NarutoRecon-v0", scene="procedural:room:5", **{**ENV, "action_mode": "delta"}
                )
            )
        )
    with pytest.raises(ValueError, match="EgocentricMapObservation"):
        GoalActions(gym.make("NarutoRecon-v0", scene="procedural:room:5", **ENV))
    with pytest.raises(ValueError, match="multiple of steps_per_goal"):
        VectorGoalActions(
            VectorEgocentricMapObservation(
                NarutoReconVectorEnv(
                    1,
                    scene="procedural:room:5",
                    max_episode_steps=25,
                    autoreset_mode="SameStep",
                    **ENV,
                )
            ),
            steps_per_goal=10,
        )


def test_a_goal_is_walked_with_the_camera_level():
    env = GoalActions(
        EgocentricMapObservation(gym.make("NarutoRecon-v0", scene="procedural:room:5", **ENV)),
        steps_per_goal=3,
    )
    try:
        env.reset(seed=0)
        env.step(8 + 8)  # look_up, three times: the camera pitched up 60 degrees
        assert env.unwrapped.pose[2, 2] > 0.8
        env.step(0)  # a candidate: the walker levels the camera before it walks
        assert abs(env.unwrapped.pose[2, 2]) < 0.2
    finally:
        env.close()


class _Moves(gym.Wrapper):
    """Keeps every move sent to the env."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.moves: list[int] = []
        self.phases: list[tuple[int, int, int]] = []  # the walker's phase and cluster
        self.walker = None

    def step(self, action):
        self.moves.append(int(action))
        cluster = self.walker.target_clusters[0]
        self.phases.append((int(self.walker.phases[0]), int(cluster[0]), int(cluster[1])))
        return self.env.step(action)


def test_the_nearest_candidate_turns_at_a_goal_only_as_far_as_it_needs():
    moves = _Moves(
        gym.make("NarutoRecon-v0", scene="procedural:small:1000000", max_episode_steps=120, **ENV)
    )
    env = GoalActions(EgocentricMapObservation(moves), steps_per_goal=20)
    moves.walker = env.walker
    try:
        env.reset(seed=0)
        coverage = []
        for _ in range(6):
            _, _, _, _, info = env.step(0)
            coverage.append(info["coverage"])
        turns: dict[tuple[int, int], int] = {}
        glances = []  # each look down at a goal, with the move after it
        for k, (move, (phase, *cluster)) in enumerate(zip(moves.moves, moves.phases, strict=True)):
            if phase == FACE and move in (TURN_LEFT, TURN_RIGHT):
                turns[tuple(cluster)] = turns.get(tuple(cluster), 0) + 1
            if phase == FACE and move == LOOK_DOWN and k + 1 < len(moves.moves):
                glances.append(moves.moves[k + 1])
        # At a goal the walker turns towards the cluster: half a turn at most (9 steps of
        # 20 degrees), never a full spin; then it glances down once and levels again (the
        # next goal may be set in between: it levels first).
        assert len(turns) >= 2 and max(turns.values()) <= 9
        assert glances and all(after == LOOK_UP for after in glances)
        assert coverage[-1] > coverage[0] + 0.1  # it goes somewhere new
    finally:
        env.close()


class _PassThrough(gym.vector.VectorWrapper):
    """A wrapper between the goal and the map wrappers: it hides the map's ``advance``."""


def test_steps_inside_a_goal_skip_the_observation_and_change_nothing():
    """The goal wrapper's inner steps use the map's ``advance`` (no learning observation);
    with a wrapper between them it steps instead: the same observations, rewards and maps,
    across an episode end."""

    def chain(hidden: bool) -> VectorGoalActions:
        maps = VectorEgocentricMapObservation(
            NarutoReconVectorEnv(
                3, scene="procedural:room", max_episode_steps=40, autoreset_mode="SameStep", **ENV
            )
        )
        return VectorGoalActions(_PassThrough(maps) if hidden else maps, steps_per_goal=10)

    fast, plain = chain(False), chain(True)
    try:
        assert hasattr(fast.env, "advance") and not hasattr(plain.env, "advance")
        runs = {}
        for name, envs in (("fast", fast), ("plain", plain)):
            observations, _ = envs.reset(seed=5)
            rng = np.random.default_rng(1)
            steps = [observations]
            for _ in range(6):  # 60 steps per agent: one episode end
                observations, rewards, terminated, truncated, _ = envs.step(
                    rng.integers(0, envs.single_action_space.n, 3)
                )
                steps.append({**observations, "reward": rewards, "done": terminated | truncated})
            runs[name] = steps
        assert any(step["done"].any() for step in runs["fast"][1:])
        for fast_step, plain_step in zip(runs["fast"], runs["plain"], strict=True):
            for key, value in plain_step.items():
                np.testing.assert_array_equal(fast_step[key], value, err_msg=key)
    finally:
        fast.close()
        plain.close()


def _level_walker(position: list[float]) -> tuple[EgocentricMapBuilder, GoalWalker, np.ndarray]:
    """One agent's map and walker (no glance at a goal: these tests' poses never pitch), its
    camera level at ``position`` with the optical axis along +x, the map reset there."""
    builder = EgocentricMapBuilder(1, CAMERA, (32, 64))
    walker = GoalWalker(builder, step_m=0.1, turn_rad=np.deg2rad(20), glance_steps=0)
    pose = np.eye(4)
    pose[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]
    pose[:3, 3] = position
    builder.reset(np.zeros(1, np.int64), pose[None])
    walker.reset()
    return builder, walker, pose


def _observe(builder: EgocentricMapBuilder, pose: np.ndarray, panorama: np.ndarray) -> None:
    """The map takes one observation: ``pose``, ``panorama`` and an empty depth frame."""
    builder.update({
        "depth": np.zeros((1, 16, 16), np.float32),
        "pose": pose[None].copy(),
        "panorama": panorama[None].copy(),
    })  # fmt: skip


def _turn(pose: np.ndarray, move: int) -> None:
    """Turn ``pose`` in place as the env turns the agent: 20 degrees about +z."""
    angle = np.deg2rad(20) * (1 if move == TURN_LEFT else -1)
    turn = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0],
                     [0, 0, 1]])  # fmt: skip
    pose[:3, :3] = turn @ pose[:3, :3]


def test_an_idle_walker_over_furniture_steps_down_after_a_full_turn():
    """Nothing in reach and the floor (a table top, say) 1.1 m below: above the doorways'
    lintels every room looks closed. After a full turn in place the walker steps down, and
    its walking-height rule does not lift it back while it has no goal."""
    builder, walker, pose = _level_walker([1.0, 1.0, 2.3])
    panorama = np.zeros((32, 64), np.float32)  # no surface around at the agent's height
    moves = []
    for _ in range(30):
        panorama[0], panorama[-1] = 2.65 - pose[2, 3], pose[2, 3] - 1.2  # ceiling, table top
        _observe(builder, pose, panorama)
        move = int(walker.next_moves()[0])
        moves.append(move)
        if move in (TURN_LEFT, TURN_RIGHT):
            _turn(pose, move)
        elif move == MOVE_DOWN:
            pose[2, 3] -= 0.1
    first_down = moves.index(MOVE_DOWN)
    assert first_down >= 18 and set(moves[:first_down]) <= {TURN_LEFT, TURN_RIGHT}  # a turn
    assert MOVE_UP not in moves and pose[2, 3] < 2.1  # below the lintels, and not back up


def test_a_low_walker_under_an_open_sky_climbs_until_the_env_refuses():
    """An open scan: the panorama's top row hits nothing. A walker that starts 0.44 m above
    the floor climbs towards the walking height (nothing measured above is not a lack of
    room: walking a whole episode that low, furniture fences in its map's slice); once the
    env refuses a climb, it climbs no more there."""
    builder, walker, pose = _level_walker([1.0, 1.0, 0.44])
    panorama = np.zeros((32, 64), np.float32)
    moves = []
    for _ in range(12):
        panorama[-1] = pose[2, 3]  # the floor at z = 0 straight down; nothing above
        _observe(builder, pose, panorama)
        move = int(walker.next_moves()[0])
        moves.append(move)
        if move == MOVE_UP and pose[2, 3] < 0.8:  # the env refuses climbs from 0.84 m
            pose[2, 3] += 0.1
        elif move in (TURN_LEFT, TURN_RIGHT):
            _turn(pose, move)
    assert moves[:5] == [MOVE_UP] * 5  # 0.44 -> 0.84, then the refused one
    assert MOVE_UP not in moves[5:] and walker.climb_ceilings[0] == pytest.approx(0.84)


@pytest.mark.parametrize("glance_steps", [-1, 1.5])
def test_a_glance_that_is_not_a_whole_count_is_refused(glance_steps):
    builder = EgocentricMapBuilder(1, CAMERA, (32, 64))
    with pytest.raises(ValueError, match="glance_steps"):
        GoalWalker(builder, glance_steps=glance_steps)


def test_walking_over_a_table_does_not_lift_the_walker_above_the_lintels():
    """The walking height is kept above the floor (the lowest surface seen straight down), not
    above whatever is below now: over a 0.8 m table the walker stays put instead of climbing
    1.3 m above the table top, where every doorway looks closed."""
    builder, walker, pose = _level_walker([1.0, 1.0, 1.3])
    panorama = np.zeros((32, 64), np.float32)
    moves = []
    for step in range(12):
        surface = 0.0 if step < 4 else 0.8  # the floor, then a table top below the agent
        panorama[0], panorama[-1] = 2.6 - pose[2, 3], pose[2, 3] - surface
        _observe(builder, pose, panorama)
        moves.append(int(walker.next_moves()[0]))
    assert MOVE_UP not in moves and MOVE_DOWN not in moves
    assert walker.floor_heights[0] == pytest.approx(0.0, abs=1e-6)


def test_a_walker_turning_back_the_way_it_turned_last_walks_on():
    """A carrot between two headings a turn apart, each too far off it to walk on, would
    make the walker turn left and right in place for as long as it stood there: after a
    turn, the opposite turn becomes a forward step where that is safe."""
    builder, walker, pose = _level_walker([2.05, 2.05, 1.3])
    builder.grids[0, FREE] = 255  # open floor all around
    builder.poses[0] = pose
    start = np.floor((pose[:2, 3] - builder.origins[0]) / builder.cell_m).astype(np.int64)
    cells = [start + [k, -round(k * np.tan(np.deg2rad(25)))] for k in range(15)]  # 21 deg right
    walker.paths[0, : len(cells)] = cells
    walker.lengths[0] = len(cells)
    walker.phases[0], walker.wandering[0], walker.cursors[0] = WALK, False, 0
    walker.last_moves[0] = -1
    first = int(walker.next_moves()[0])
    assert first in (TURN_LEFT, TURN_RIGHT)  # the carrot is more than half a turn off
    walker.cursors[0], walker.last_moves[0] = 0, OPPOSITE_TURN[first]
    assert int(walker.next_moves()[0]) == MOVE_FORWARD  # it turned the other way last


def _set_coarse(builder: EgocentricMapBuilder) -> None:
    builder.coarse[0] = _coarse(builder.grids[0], builder.far_factor)


def _unseen_block(builder: EgocentricMapBuilder, x: float, y: float) -> None:
    """An obstacle of 3 x 3 cells around world (x, y) on agent 0's map, not yet seen."""
    i, j = builder.cell_of(0, (x, y))
    builder.grids[0, OCCUPIED, i - 1 : i + 2, j - 1 : j + 2] = 255
    builder.grids[0, FREE, i - 1 : i + 2, j - 1 : j + 2] = 0


def _walker_between_two_blocks() -> tuple[EgocentricMapBuilder, GoalWalker, np.ndarray]:
    """A walker at (5.05, 5.05) m facing +x on open floor, an unseen block 0.7 m to its left
    (viewed from where it stands) and one 3 m behind it; candidates found."""
    builder, walker, pose = _level_walker([5.05, 5.05, 1.3])
    builder.grids[0, FREE] = 255
    _unseen_block(builder, 5.05, 5.75)
    _unseen_block(builder, 2.05, 5.05)
    _observe(builder, pose, np.zeros((32, 64), np.float32))
    _set_coarse(builder)
    walker.refresh_candidates()
    return builder, walker, pose


def _walk_out(
    builder: EgocentricMapBuilder,
    walker: GoalWalker,
    pose: np.ndarray,
    radius_m: float,
    most: int,
    floor_below_m: float = 0.0,
) -> list[int]:
    """The walker's moves, each carried out on ``pose`` as the env would (steps of 0.1 m,
    turns of 20 degrees, climbs of 0.1 m) and observed, until it stands ``radius_m`` from
    where it started or ``most`` moves were made; ``floor_below_m``: the panorama sees the
    floor that far below the agent's start height (0: nothing)."""
    start = pose[:3, 3].copy()
    panorama = np.zeros((32, 64), np.float32)
    directions = {MOVE_FORWARD: 0.0, MOVE_LEFT: 0.5 * np.pi, MOVE_BACKWARD: np.pi,
                  MOVE_RIGHT: -0.5 * np.pi}  # fmt: skip
    moves: list[int] = []
    while np.hypot(*(pose[:2, 3] - start[:2])) <= radius_m and len(moves) < most:
        move = int(walker.next_moves()[0])
        moves.append(move)
        heading = np.arctan2(pose[1, 2], pose[0, 2])
        if move in (TURN_LEFT, TURN_RIGHT):
            _turn(pose, move)
        elif move in directions:
            way = heading + directions[move]
            pose[:2, 3] += 0.1 * np.array([np.cos(way), np.sin(way)])
        elif move in (MOVE_UP, MOVE_DOWN):
            pose[2, 3] += 0.1 if move == MOVE_UP else -0.1
        if floor_below_m > 0:
            panorama[-1] = floor_below_m - (start[2] - pose[2, 3])
        _observe(builder, pose, panorama)
    return moves


def _walk_out_behind(walker, start: np.ndarray) -> None:
    """A stall recovery's way out (:meth:`GoalWalker.walk_out`) to the viewpoint of the
    block 3 m behind the agent, out of a stay of 0.6 m around ``start``."""
    behind = walker.viewpoints[0, : walker.counts[0]][:, 0].argmin()
    assert walker.walk_out(0, walker.viewpoints[0, behind], start, 0.6)


def test_out_of_a_stay_the_walker_goes_past_it_without_turning_on_the_spot_first():
    """A stall watchdog's recovery (:meth:`GoalWalker.walk_out`) to a place 3 m behind the
    agent: the walker steps backward out of the stay instead of turning half a circle on
    the spot first."""
    builder, walker, pose = _walker_between_two_blocks()
    start = pose[:2, 3].copy()
    _walk_out_behind(walker, start)
    assert walker.phases[0] == WALK and walker.targets[0][0] < start[0] - 0.6  # the one behind
    assert _walk_out(builder, walker, pose, 0.6, 12) == [MOVE_BACKWARD] * 7


def test_out_of_a_stay_with_no_step_towards_the_path_the_walker_turns_only_until_one_is():
    """An obstacle right behind the walker: its path out of the stay leads round it, and
    soon no step (forward, backward or sideways) brings the path's carrot nearer. The
    walker turns until one does, a turn or two, instead of turning round to face the path
    (eight turns on the spot) before it steps out."""
    builder, walker, pose = _walker_between_two_blocks()
    _unseen_block(builder, 4.75, 5.05)  # 0.3 m behind
    _walk_out_behind(walker, pose[:2, 3].copy())
    moves = _walk_out(builder, walker, pose, 0.6, 20)
    turns = sum(move in (TURN_LEFT, TURN_RIGHT) for move in moves)
    assert 1 <= turns <= 2 and len(moves) <= 12


def test_out_of_a_stay_the_walker_never_undoes_its_last_step():
    """The path's carrot moves with the agent: one lying between two places a step apart
    would send the walker right and left between them (the open-scans page has the episode).
    The step back out of the stay is not taken right after a step forward; the walker turns
    towards the carrot instead."""
    builder, walker, pose = _walker_between_two_blocks()
    _walk_out_behind(walker, pose[:2, 3].copy())
    assert int(walker.next_moves()[0]) == MOVE_BACKWARD  # the way out, as above
    walker.last_moves[0] = MOVE_FORWARD  # as if it had just stepped forward (not refused)
    walker.last_positions[0] = pose[:3, 3] - [0.1, 0.0, 0.0]
    assert int(walker.next_moves()[0]) in (TURN_LEFT, TURN_RIGHT)


def test_a_walk_out_of_a_stay_stays_one_when_the_map_restarts_at_a_new_height():
    """The map's slice restarts when the agent changes height (the goal in hand was found on
    the old slice): a walk out of a stay then plans again to the same way out, not to the
    nearest candidate."""
    builder, walker, pose = _walker_between_two_blocks()
    start = pose[:2, 3].copy()
    _walk_out_behind(walker, start)
    builder.slice_restarts[0] += 1
    assert int(walker.next_moves()[0]) == MOVE_BACKWARD
    assert walker.phases[0] == WALK and walker.targets[0][0] < start[0] - 0.6  # the same
    np.testing.assert_allclose(walker.stays[0], [*start, 0.6])


def test_a_walk_out_of_a_stay_leaves_before_it_changes_height():
    """Out of a stay 1.9 m above the floor (above the walking height): a step down first would
    restart the map's slice and empty the map the way out was planned on. The walker steps
    out of the stay first."""
    builder, walker, pose = _walker_between_two_blocks()
    panorama = np.zeros((32, 64), np.float32)
    panorama[-1] = 1.9  # the floor straight down
    _observe(builder, pose, panorama)
    _walk_out_behind(walker, pose[:2, 3].copy())
    moves = _walk_out(builder, walker, pose, 0.6, 12, floor_below_m=1.9)
    assert moves == [MOVE_BACKWARD] * 7
    assert int(walker.next_moves()[0]) == MOVE_DOWN  # past the stay, the height comes next


def test_a_walk_out_of_a_stay_that_found_nothing_tries_again_out_of_the_same_stay():
    """A walk out of a stay that found nothing reachable (the map had just restarted at a new
    height) turns in place; at its next search it plans again to the same way out, not to
    the nearest candidate (which would lead back into the stay)."""
    builder, walker, pose = _walker_between_two_blocks()
    start = pose[:2, 3].copy()
    _walk_out_behind(walker, start)
    walker.phases[0] = IDLE  # as if nothing had been reachable after the restart
    walker.idle_steps[0] = IDLE_SEARCH_EVERY - 1  # the next move searches again
    assert int(walker.next_moves()[0]) == MOVE_BACKWARD
    assert walker.phases[0] == WALK and walker.targets[0][0] < start[0] - 0.6  # the one behind
    np.testing.assert_allclose(walker.stays[0], [*start, 0.6])


def test_a_refused_step_never_blocks_the_cell_the_walker_stands_in():
    """A step shorter than a cell may end in the cell it started from: the refused step's
    cell marked blocked would then be the agent's own, and no path could start from it."""
    builder, walker, pose = _level_walker([5.001, 5.05, 1.3])
    builder.grids[0, FREE] = 255
    pose[:3, :3] = [[0, 0, -1], [1, 0, 0], [0, -1, 0]]  # optical axis -x: a 0.1 m step ...
    pose[0, 3] = 5.099  # ... from near the cell's far side ends in the same cell
    _observe(builder, pose, np.zeros((32, 64), np.float32))
    own = tuple(np.floor((pose[:2, 3] - builder.origins[0]) / builder.cell_m).astype(int))
    walker.last_moves[0], walker.last_positions[0] = MOVE_FORWARD, pose[:3, 3]
    walker.phases[0] = WALK
    walker.next_moves()  # sees the forward move refused (it did not move)
    assert builder.grids[0, OCCUPIED][own] == 0
    assert builder.grids[0, OCCUPIED, own[0] - 1, own[1]] == 255  # the cell it led into
    builder.mark_blocked(0, *pose[:2, 3])
    assert builder.grids[0, OCCUPIED][own] == 0


def test_an_agents_walk_does_not_depend_on_the_other_agents_of_its_batch():
    """Each agent's candidates, wander and moves are its own: the first four agents of a
    batch of eight walk as a batch of those four does (an agent's wander reads the path
    lengths of its own candidate search, not those of the agent searched last), on the
    training mix's scenes."""
    settings = {
        **EXPLORER_ENV,
        "max_episode_steps": 40,
        "autoreset_mode": "SameStep",
        "panorama_horizon_deg": EXPLORER_PANORAMA_HORIZON_DEG,
    }

    def moves_of(num_envs: int) -> list[np.ndarray]:
        envs = wrap_explorer(
            make_vector_env(num_envs, workers=1, scene=shared_train_mix(2, 2), **settings)
        )
        taken = []
        next_moves = envs.walker.next_moves

        def recorded() -> np.ndarray:
            moves = next_moves()
            taken.append(np.concatenate([moves[:4], envs.unwrapped.poses[:4, :3, 3].ravel()]))
            return moves

        envs.walker.next_moves = recorded
        try:
            envs.reset(seed=3)
            rng = np.random.default_rng(0)
            for _ in range(3):
                envs.step(rng.integers(0, envs.single_action_space.n, 8)[:num_envs])
        finally:
            envs.close()
        return taken

    np.testing.assert_array_equal(np.array(moves_of(8)), np.array(moves_of(4)))
