"""The env on open scans: positions never leave the scanned space, moves inside the room are not
refused for a missing ceiling, resets start inside, and the published rule is unchanged."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils import seeding

import naruto_gym  # noqa: F401
from naruto_gym.envs.scene_runtime import START_CANDIDATES
from naruto_gym.observability import sample_free_positions
from naruto_gym.scenes.catalogue import catalogue_entry
from naruto_gym.scenes.open_scans import building_envelope
from naruto_gym.sensors.panorama import EquirectangularCamera, no_hit_share, render_panorama
from tests.conftest import SAMPLE_MESHES, SHARED_SCENES

TINY = {"image_scale": 0.05, "coverage_samples": 500, "panorama_shape": None}
OPEN_VARIANTS = [
    "replica_like_room:no_ceiling",
    "replica_like_room:no_ceiling+holes",
    "replica_like_room:no_ceiling+missing_wall",
    "two_rooms:holes+missing_wall",
]
ROLLOUT_STEPS = 300


def _make(scene: str, **kwargs) -> gym.Env:
    return gym.make("NarutoRecon-v0", scene=scene, **{**TINY, **kwargs}).unwrapped


def _envelope(scene: str) -> np.ndarray:
    return building_envelope(catalogue_entry(scene.partition(":")[0]).layout())


def _far_target(env, rng: np.random.Generator) -> np.ndarray:
    """A pose anywhere in the (widened) bounds: most lie outside the building, so the
    agent keeps pushing through the openings, the open top and down the floor hole."""
    position = rng.uniform(env.bounds[0], env.bounds[1])
    quaternion = rng.normal(size=4)
    return np.concatenate([position, quaternion / np.linalg.norm(quaternion)]).astype(np.float32)


@pytest.mark.slow
@pytest.mark.parametrize("scene", OPEN_VARIANTS)
def test_random_rollouts_never_leave_the_scanned_space(scene):
    env = _make(scene, action_mode="pose")
    envelope = _envelope(scene)
    assert np.all(env.bounds[0] < envelope[0] - 1.0) and np.all(env.bounds[1] > envelope[1] + 1.0)
    blocked = 0
    for seed in (0, 1):
        env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        target = _far_target(env, rng)
        for step in range(ROLLOUT_STEPS // 2):
            if step % 15 == 0:
                target = _far_target(env, rng)
            _, _, _, _, info = env.step(target)
            blocked += info["collided"]
            position = env.pose[:3, 3]
            # Independent of the env's rule: inside the closed building it was cut from.
            assert np.all(position >= envelope[0]) and np.all(position <= envelope[1]), position
            assert not env.collision.sees_escape(position)
            assert env.collision.clearance(position) >= env.settings.agent_radius_m - 1e-4
    assert blocked > 0


def _approaches(env, layout, boxes: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """(clear start inside the room, outward direction) in front of every opening."""
    centre_of_room = np.array([*np.array(layout.size[:2]) / 2, 1.2])
    out = []
    for low, high in boxes:
        centre = (low + high) / 2
        axis = int(np.argmin(high - low))
        outward = np.zeros(3)
        outward[axis] = np.sign(centre[axis] - centre_of_room[axis])
        if axis == 2 and outward[2] > 0:  # the open top: from 0.5 m under it
            candidates = [
                np.array([*centre_of_room[:2] + offset, low[2] - 0.5])
                for offset in (0.4, -0.6, 1.0)
            ]
        elif axis == 2:  # the floor hole: from 1.2 m above it
            candidates = [np.array([centre[0], centre[1], 1.2])]
        else:  # a wall hole or the missing wall: 0.5 m inside, along the opening
            along = 1 - axis
            candidates = []
            for fraction in (0.5, 0.3, 0.7, 0.15, 0.85, 0.4, 0.6):
                for z in (1.2, 1.5, 0.9, 1.8):
                    start = centre.copy()
                    start[axis] -= outward[axis] * 0.5
                    start[along] = low[along] + fraction * (high[along] - low[along])
                    start[2] = float(np.clip(z, low[2] + 0.15, high[2] - 0.15))
                    candidates.append(start)
        # A start from which the straight way out through the opening is free of furniture.
        clear = [
            c
            for c in candidates
            if env.raycaster.unsigned_distance(c[None])[0] >= 0.15
            and env.raycaster.free_fraction_of_segment(c, c + 1.2 * outward, 0.06) == 1.0
        ]
        if clear:
            out.append((clear[0], outward))
    return out


@pytest.mark.slow
@pytest.mark.parametrize("base", ["replica_like_room", "two_rooms"])
def test_pushing_out_through_every_opening_is_refused(base):
    scene = f"{base}:no_ceiling+holes+missing_wall"
    env = _make(scene, action_mode="pose")
    env.reset(seed=0)
    layout = catalogue_entry(base).layout()
    envelope = _envelope(scene)
    from naruto_gym.scenes.open_scans import opening_boxes

    boxes = opening_boxes(layout, scene.partition(":")[2])
    approaches = _approaches(env, layout, boxes)
    assert len(approaches) == len(boxes) == 5
    tried = 0
    for start, outward in approaches:
        pose = env.pose
        pose[:3, 3] = start
        env.reset(options={"pose": pose})
        tried += 1
        reasons = set()
        rng = np.random.default_rng(tried)
        for _ in range(40):
            wobble = np.append(rng.normal(scale=0.3, size=3) * (outward == 0), 0.0)
            goal = env.pose[:3, 3] + 3.0 * outward + wobble[:3]
            goal = np.clip(goal, env.bounds[0], env.bounds[1])
            _, _, _, _, info = env.step(np.concatenate([goal, [0, 0, 0, 1]]).astype(np.float32))
            reasons.add(info["collision_reason"])
            position = env.pose[:3, 3]
            assert np.all(position >= envelope[0]) and np.all(position <= envelope[1]), position
        assert "escape" in reasons, (start, outward, reasons)


def test_moves_inside_the_room_are_not_refused_for_a_missing_ceiling():
    """Every small move between clear points inside the room is allowed in the open scan, as in
    the closed one (same scene with its ceiling); the published rule is shown to differ."""
    opened = _make("replica_like_room:no_ceiling")
    closed = _make("replica_like_room:fragments")
    for env in (opened, closed):
        env.reset(seed=0)
    height = _envelope("replica_like_room")[1, 2] - 0.1
    rng = np.random.default_rng(0)
    starts = rng.uniform([0.3, 0.3, 0.3], [4.7, 4.7, height - 0.3], size=(600, 3))
    starts = starts[closed.raycaster.unsigned_distance(starts) >= 0.2]
    assert len(starts) > 200
    steps = rng.normal(size=starts.shape)
    ends = starts + 0.1 * steps / np.linalg.norm(steps, axis=1, keepdims=True)
    for start, end in zip(starts, ends, strict=True):
        assert closed.collision.move(start, end).reason == ""
        assert opened.collision.move(start, end).reason == "", (start, end)


@pytest.mark.parametrize("scene", OPEN_VARIANTS)
def test_reset_starts_inside_the_scanned_room(scene):
    env = _make(scene)
    envelope = _envelope(scene)
    width, depth, height = catalogue_entry(scene.partition(":")[0]).size
    for seed in range(6):
        observation, _ = env.reset(seed=seed)
        position = observation["pose"][:3, 3].astype(np.float64)
        assert np.all(position[:2] > 0) and position[0] < width and position[1] < depth
        assert 0 < position[2] < height
        assert np.all(position > envelope[0])
        assert env.collision.scanned_space.is_inside(position)
        assert env.collision.clearance(position) >= env.settings.start_clearance_m - 1e-4


def test_closed_and_open_versions_start_alike():
    """Same bounds, same candidates: a start differs only where the cut surface (here the
    ceiling) kept the closed scene's candidate from being clear."""
    closed = _make("replica_like_room:fragments")
    opened = _make("replica_like_room:no_ceiling+holes")
    same = 0
    for seed in range(6):
        closed_start = closed.reset(seed=seed)[0]["pose"][:3, 3].astype(np.float64)
        open_start = opened.reset(seed=seed)[0]["pose"][:3, 3].astype(np.float64)
        if np.allclose(closed_start, open_start):
            same += 1
        else:
            clearance = closed.raycaster.unsigned_distance(open_start[None])[0]
            assert clearance < closed.settings.start_clearance_m
    assert same >= 3


def test_published_rule_behaves_as_before_when_selected():
    """Start poses come from the whole-sphere test with the 0.5 share, and a move is refused
    exactly when the 32 x 64 panorama at its end sees more than half no-hit pixels."""
    scene = "replica_like_room:no_ceiling+missing_wall"
    env = _make(scene, action_mode="discrete", escape_rule="published")
    for seed in (0, 3):
        env.reset(seed=seed)
        expected = sample_free_positions(
            env.raycaster,
            env.scene.face_normals,
            env.bounds,
            1,
            env.settings.start_clearance_m,
            seeding.np_random(seed)[0],
            0.5,
            max_candidates=START_CANDIDATES,
        )[0]
        np.testing.assert_allclose(env.pose[:3, 3], expected)
    camera = EquirectangularCamera(32, 64)
    rng = np.random.default_rng(3)
    escapes = 0
    for step in range(200):
        before = env.pose[:3, 3].copy()
        action = 4 if step < 40 else int(rng.integers(0, 6))  # up to the open top first
        _, _, _, _, info = env.step(action)
        if info["collision_reason"] == "escape":
            escapes += 1
            np.testing.assert_allclose(env.pose[:3, 3], before)
        else:
            after = env.pose[:3, 3]
            if not np.allclose(after, before):
                assert no_hit_share(render_panorama(env.raycaster, camera, after)) <= 0.5
    assert escapes > 0


def test_start_outside_the_scanned_space_is_not_a_trap():
    env = _make("replica_like_room:no_ceiling+missing_wall", action_mode="pose")
    env.reset(seed=0)
    envelope = _envelope("replica_like_room")
    outside = np.array([envelope[0, 0] - 0.6, 2.5, 1.0])  # beyond the west side, in the air
    space = env.collision.scanned_space
    if space.is_inside(outside):  # the missing wall may be elsewhere: use the east side
        outside = np.array([envelope[1, 0] + 0.6, 2.5, 1.0])
    assert not space.is_inside(outside)
    pose = env.pose
    pose[:3, 3] = outside
    env.reset(options={"pose": pose})
    inward = np.sign(2.5 - outside[0])
    target = np.concatenate([outside + [inward * 0.1, 0, 0], [0, 0, 0, 1]]).astype(np.float32)
    _, _, _, _, info = env.step(target)
    assert info["collision_reason"] != "escape"
    target = np.concatenate([env.pose[:3, 3] - [inward * 0.1, 0, 0], [0, 0, 0, 1]])
    _, _, _, _, info = env.step(target.astype(np.float32))
    assert info["collision_reason"] == "escape"


@pytest.mark.skipif(not SHARED_SCENES.is_dir(), reason="../shared/scenes is absent")
def test_habitat_sample_room_without_walls_or_ceiling():
    """A scanned floor with a table and a cube, nothing else. Walking straight ahead (turning
    when refused), the published rule keeps the agent next to the cube (only there does the
    cube hide enough of the empty sky); the scanned-space rule lets it cross the floor."""
    relative, up_axis = SAMPLE_MESHES["habitat_simple_room"]
    path = str(SHARED_SCENES / relative)
    reach = {}
    for rule in ("scanned_space", "published"):
        env = _make(path, up_axis=up_axis, action_mode="discrete", escape_rule=rule)
        start = env.reset(seed=0)[0]["pose"][:3, 3]
        low, high = env.bounds
        reach[rule] = 0.0
        turning = 0
        for _ in range(200):
            action = 6 if turning else 0  # turn left for a while after a refusal, else walk
            turning = max(turning - 1, 0)
            _, _, _, _, info = env.step(action)
            if info["collided"]:
                turning = 3
            position = env.pose[:3, 3]
            reach[rule] = max(reach[rule], float(np.linalg.norm(position[:2] - start[:2])))
            assert np.all(position[:2] > low[:2]) and np.all(position[:2] < high[:2])
            assert position[2] > 0.15  # above the floor's top
    assert reach["scanned_space"] > 4.0, reach
    assert reach["published"] < 0.5 * reach["scanned_space"], reach


def test_reference_map_takes_frames_with_nothing_in_range():
    """Looking up out of a scan without a ceiling, only far fragments (or a few pixels) are in
    view: the reference TSDF map skips such a frame instead of failing (Open3D refuses a
    frame that touches no block)."""
    from naruto_gym.evaluation.tsdf_mapper import TsdfFusionMapper
    from naruto_gym.sensors.pinhole import PinholeCamera

    camera = PinholeCamera().scaled(0.05)
    mapper = TsdfFusionMapper(max_depth_m=5.0)
    far = np.full((camera.height, camera.width), 0.0, np.float32)
    far[:3, :3] = 7.5  # a fragment beyond the fusion range
    mapper.integrate(None, far, np.eye(4), camera)
    assert mapper.num_frames == 0
    few = np.zeros((camera.height, camera.width), np.float32)
    few[5, 7] = 1.9  # a handful of pixels in range, too few for Open3D to touch a block
    mapper.integrate(None, few, np.eye(4), camera)
    near = np.full((camera.height, camera.width), 2.0, np.float32)
    mapper.integrate(None, near, np.eye(4), camera)
    assert mapper.num_frames == 1
