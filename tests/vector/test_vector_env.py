"""NarutoReconVectorEnv against N single envs in Gymnasium's SyncVectorEnv, step by step."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import naruto_gym  # noqa: F401  (registers the ids)
from naruto_gym import NarutoReconEnv
from naruto_gym.scenes.catalogue import resolve_scene
from naruto_gym.scenes.mesh_scene import Scene
from naruto_gym.sensors.pinhole import PinholeCamera
from naruto_gym.vector import (
    BatchedEnvBase,
    NarutoReconVectorEnv,
    ShardedVectorEnv,
    make_vector_env,
)
from naruto_gym.vector.scheduling import balanced_shares, share_bounds
from naruto_gym.wrappers import FinalReconstructionMetrics

SMALL: dict[str, Any] = {
    "action_mode": "discrete",
    "camera": PinholeCamera(24, 24, 12, 12, 11.5, 11.5),
    "coverage_samples": 3000,
    "panorama_shape": (8, 16),
    # One frame method for both: at 7 triangles per pixel "auto" rasterizes batched frames
    # and ray-casts single ones, whose depths differ by float rounding.
    "pinhole_backend": "raycast",
}


def open_room() -> Scene:
    """The default room without its ceiling and one wall: escape checks refuse moves there."""
    scene = resolve_scene("replica_like_room")
    centroids = scene.vertices[scene.faces].mean(axis=1)
    high = scene.bounds[1]
    keep = (centroids[:, 2] < high[2] - 0.2) & (centroids[:, 0] < high[0] - 0.3)
    return Scene(scene.vertices, scene.faces[keep], scene.corner_colours[keep], "open_room")


def assert_same(vector: Any, sync: Any, where: str) -> None:
    if isinstance(vector, dict):
        assert set(vector) == set(sync), (where, set(vector) ^ set(sync))
        for key in vector:
            assert_same(vector[key], sync[key], f"{where}/{key}")
        return
    vector, sync = np.asarray(vector), np.asarray(sync)
    if vector.dtype == object:
        assert len(vector) == len(sync), where
        for k, (a, b) in enumerate(zip(vector, sync, strict=True)):
            assert_same(a, b, f"{where}[{k}]") if isinstance(a, dict) else None
            if not isinstance(a, dict):
                assert a == b, (where, k, a, b)
        return
    assert vector.dtype == sync.dtype, (where, vector.dtype, sync.dtype)
    assert vector.shape == sync.shape, (where, vector.shape, sync.shape)
    np.testing.assert_allclose(vector, sync, atol=1e-6, err_msg=where)


def run_both(
    num_envs: int,
    steps: int,
    actions: Any,
    autoreset: AutoresetMode = AutoresetMode.NEXT_STEP,
    budget: int = 12,
    seed: int = 3,
    split: bool = False,
    workers: int = 1,
    **kwargs: Any,
) -> tuple[list[str], BatchedEnvBase]:
    settings = {**SMALL, **kwargs}
    vector = make_vector_env(
        num_envs, max_episode_steps=budget, autoreset_mode=autoreset, workers=workers, **settings
    )
    assert isinstance(vector, ShardedVectorEnv if workers > 1 else NarutoReconVectorEnv)
    if split:  # each step in two shares, one per thread, however few the agents and frames
        vector.thread_count, vector._min_agents_per_part, vector._split_steps = 2, 1, True
    sync = gym.vector.SyncVectorEnv(
        [lambda: gym.make("NarutoRecon-v0", max_episode_steps=budget, **settings)] * num_envs,
        autoreset_mode=autoreset,
    )
    assert_same(vector.reset(seed=seed), sync.reset(seed=seed), "reset")
    reasons: list[str] = []
    for step in range(steps):
        action = actions(step)
        got, expected = vector.step(action), sync.step(action)
        for name, a, b in zip(
            ("obs", "reward", "term", "trunc", "info"), got, expected, strict=True
        ):
            assert_same(a, b, f"step {step} {name}")
        reasons += [r for r in got[4]["collision_reason"] if r]
    sync.close()
    vector.close()
    return reasons, vector


# In one process (its step in one piece, or split in shares between threads) and sharded over
# worker processes (agent counts that the workers do not divide).
SPLIT_OR_WORKERS = [(False, 1), (True, 1), (False, 2)]


@pytest.mark.parametrize(("split", "workers"), SPLIT_OR_WORKERS)
def test_matches_sync_vector_env_with_autoreset_next_step(split, workers):
    rng = np.random.default_rng(0)
    # Mostly forward and down, so that agents reach walls and the floor within the test.
    weights = np.array([4, 1, 1, 1, 0, 12, 1, 0, 0, 0]) / 20
    reasons, vector = run_both(
        3, 34, lambda _: rng.choice(10, 3, p=weights), budget=25, split=split, workers=workers
    )
    assert vector.single_observation_space["rgb"].shape == (24, 24, 3)
    assert reasons, "no collision happened: the collision path went untested"


@pytest.mark.parametrize(("split", "workers"), SPLIT_OR_WORKERS)
def test_matches_sync_vector_env_same_step_autoreset(split, workers):
    rng = np.random.default_rng(1)
    run_both(
        3,
        16,
        lambda _: rng.integers(0, 10, 3),
        AutoresetMode.SAME_STEP,
        budget=7,
        split=split,
        workers=workers,
    )


@pytest.mark.parametrize(("split", "workers"), SPLIT_OR_WORKERS)
@pytest.mark.parametrize("rule", ["published", "scanned_space"])
def test_matches_sync_in_open_scene_where_escapes_are_refused(rule, split, workers):
    rng = np.random.default_rng(0)
    # Mostly forward, sometimes sideways, up or turning: some agents reach the open side.
    reasons, _ = run_both(
        3,
        60,
        lambda step: np.zeros(3, int) if step % 3 else rng.choice([0, 2, 3, 4, 6], 3),
        budget=80,
        seed=0,
        split=split,
        workers=workers,
        scene=open_room(),
        escape_rule=rule,
    )
    assert "surface" in reasons
    if rule == "published":
        assert "escape" in reasons


@pytest.mark.parametrize(("split", "workers"), [*SPLIT_OR_WORKERS, (False, 3)])
def test_matches_sync_with_rasterized_frames(split, workers):
    """Frames of many agents drawn in parallel (one rasterizer per thread, or each share of
    the step in its thread) are each agent's single-env rasterized frame."""
    rng = np.random.default_rng(5)
    run_both(
        5,
        30,
        lambda step: rng.integers(0, 10, 5),
        split=split,
        workers=workers,
        pinhole_backend="raster",
    )


def test_auto_frames_are_rasterized_where_cheaper():
    settings = {**SMALL, "pinhole_backend": "auto"}
    settings["camera"] = PinholeCamera(16, 16, 8, 8, 7.5, 7.5)
    vector = NarutoReconVectorEnv(2, **settings)
    # 16 x 16 pixels: more than 16 triangles of the default room per pixel, so ray cast.
    assert vector.scene_runtimes[0].renderer.frame_backend == "raycast"
    # 24 x 24: 7 per pixel, rasterized when drawn many at once, ray-cast one at a time.
    settings["camera"] = PinholeCamera(24, 24, 12, 12, 11.5, 11.5)
    assert NarutoReconVectorEnv(2, **settings).scene_runtimes[0].renderer.frame_backend == "raster"
    single = gym.make("NarutoRecon-v0", **settings)
    assert single.unwrapped.renderer.frame_backend == "raycast"
    single.close()
    settings["camera"] = PinholeCamera(64, 64, 32, 32, 31.5, 31.5)
    assert NarutoReconVectorEnv(2, **settings).scene_runtimes[0].renderer.frame_backend == "raster"


@pytest.mark.parametrize("workers", [1, 2])
def test_matches_sync_with_delta_actions(workers):
    rng = np.random.default_rng(2)
    run_both(
        3,
        10,
        lambda _: rng.uniform(-1, 1, (3, 6)).astype(np.float32),
        action_mode="delta",
        panorama_shape=None,
        workers=workers,
    )


def test_partial_reset_mask_and_seeds_list():
    vector = NarutoReconVectorEnv(3, max_episode_steps=5, **SMALL)
    first, _ = vector.reset(seed=[5, 6, 7])
    vector.step(np.array([0, 6, 7]))
    mask = np.array([False, True, False])
    after, infos = vector.reset(seed=[None, 6, None], options={"reset_mask": mask})
    np.testing.assert_array_equal(after["pose"][1], first["pose"][1])
    assert infos["_step"].tolist() == [False, True, False]
    assert not np.allclose(after["pose"][2], first["pose"][2])


@pytest.mark.parametrize("split", [False, True])
def test_observations_handed_out_never_change_afterwards(split):
    """The env hands out its frame buffers without copying them and draws every step into
    new ones: what a caller holds (a rollout buffer, the final observations of ended
    episodes) stays as it was returned, and a caller changing it changes nothing the env
    returns later."""
    vector = NarutoReconVectorEnv(
        3,
        max_episode_steps=4,
        autoreset_mode=AutoresetMode.SAME_STEP,
        **{**SMALL, "pinhole_backend": "auto"},
    )
    if split:
        vector._threads, vector._min_agents_per_part, vector._split_steps = 2, 1, True
    rng = np.random.default_rng(4)
    held = [vector.reset(seed=1)[0]]
    finals = []
    for _ in range(9):
        observation, _, terminated, truncated, infos = vector.step(rng.integers(0, 10, 3))
        held.append(observation)
        if (terminated | truncated).any():
            finals += [final for final in infos["final_obs"] if final is not None]
    assert finals, "no episode ended: the final observations went untested"
    copies = [{key: value.copy() for key, value in obs.items()} for obs in held]
    final_copies = [{key: value.copy() for key, value in obs.items()} for obs in finals]
    for _ in range(3):
        vector.step(rng.integers(0, 10, 3))
    for obs, copy in zip(held + finals, copies + final_copies, strict=True):
        for key in obs:
            np.testing.assert_array_equal(obs[key], copy[key], err_msg=key)
    # A caller scribbling over the last observations: a partial reset redraws the others.
    last = held[-1]
    expected = {key: value.copy() for key, value in vector.step(np.zeros(3, int))[0].items()}
    after_step = vector._observations()
    for key in ("rgb", "depth", "panorama"):
        after_step[key][...] = 0
    after, _ = vector.reset(seed=[None, 8, None], options={"reset_mask": np.array([0, 1, 0], bool)})
    for key in ("rgb", "depth", "panorama"):
        np.testing.assert_array_equal(after[key][[0, 2]], expected[key][[0, 2]], err_msg=key)
        assert after[key] is not after_step[key]
    assert not np.array_equal(last["pose"], after["pose"])


def test_make_vec_vector_entry_point_returns_batched_env():
    env = gym.make_vec(
        "NarutoRecon-v0", num_envs=2, vectorization_mode="vector_entry_point", **SMALL
    )
    assert isinstance(env, NarutoReconVectorEnv)
    assert env.max_episode_steps == 2000
    observations, infos = env.reset(seed=0)
    assert observations["rgb"].shape == (2, 24, 24, 3)
    assert infos["coverage"].shape == (2,)


def test_bad_actions_raise_and_leave_env_usable():
    vector = NarutoReconVectorEnv(2, **SMALL)
    vector.reset(seed=0)
    for bad in ([0], [0, 10], [0.5, 1.0], [[0, 1]]):
        with pytest.raises(ValueError, match="discrete actions"):
            vector.step(np.array(bad))
    observations, *_ = vector.step(np.array([0, 1]))
    assert observations["depth"].shape == (2, 24, 24)
    with pytest.raises(ValueError, match="num_envs"):
        NarutoReconVectorEnv(0, **SMALL)
    with pytest.raises(ValueError, match="pose"):
        NarutoReconVectorEnv(2, scene="procedural:room", action_mode="pose")


def _cheap_metrics(env: gym.Env) -> gym.Env:
    """The env with its (slow) reference-map scoring replaced by a marker: these tests check
    on which step the metrics come, not what they are."""
    env.unwrapped.reconstruction_metrics = lambda: {"scored": True}
    return env


def _episodes_end_at(env: gym.Env, budget: int) -> None:
    """Two episodes (one after a reset) are truncated on step ``budget``, whose info alone
    carries the reference map's metrics."""
    for _ in range(2):
        env.reset(seed=0)
        steps = [env.step(0) for _ in range(budget)]
        assert [step[3] for step in steps] == [False] * (budget - 1) + [True]
        assert ["reconstruction" in step[4] for step in steps] == [False] * (budget - 1) + [True]
    env.close()


@pytest.mark.parametrize("budget", [1, 3])
def test_env_truncates_at_its_max_episode_steps_with_the_final_metrics(budget):
    """Given its episode length, the env ends the episode itself on the step that reaches it
    and puts the reference map's metrics into that step's info (no wrapper needed, which
    make_vec's vector entry point forbids)."""
    env = _cheap_metrics(NarutoReconEnv(max_episode_steps=budget, reconstruct=True, **SMALL))
    assert env.max_episode_steps == budget
    _episodes_end_at(env, budget)
    assert gym.spec("NarutoRecon-v0").additional_wrappers == ()
    with pytest.raises(ValueError, match="max_episode_steps must be an integer of at least 1"):
        NarutoReconEnv(max_episode_steps=0, **SMALL)


@pytest.mark.parametrize("budget", [1, 3])
def test_a_made_env_ends_at_its_time_limit_with_the_final_metrics_under_the_wrapper(budget):
    """gymnasium.make(..., max_episode_steps=N) keeps N for its TimeLimit and does not pass it
    on (the env's spec says None), so the env cannot know where the episode ends;
    FinalReconstructionMetrics, around the TimeLimit, adds the metrics there."""
    made = _cheap_metrics(
        gym.make("NarutoRecon-v0", max_episode_steps=budget, reconstruct=True, **SMALL)
    )
    assert made.spec.max_episode_steps == budget
    assert made.unwrapped.max_episode_steps is None
    assert made.unwrapped.spec.max_episode_steps is None
    _episodes_end_at(FinalReconstructionMetrics(made), budget)
    bare = _cheap_metrics(
        gym.make("NarutoRecon-v0", max_episode_steps=2, reconstruct=True, **SMALL)
    )
    bare.reset(seed=0)
    assert ["reconstruction" in bare.step(0)[4] for _ in range(2)] == [False, False]


def test_split_steps_share_the_agents_so_that_the_parts_finish_together():
    """The parts of a split step cover every agent once, at least one each, and the next
    step gives more agents to a part that finished early, never fewer than the minimum."""
    np.testing.assert_array_equal(share_bounds(np.array([0.5, 0.5]), 64), [0, 32, 64])
    np.testing.assert_array_equal(share_bounds(np.array([0.6, 0.4]), 64), [0, 38, 64])
    np.testing.assert_array_equal(share_bounds(np.array([0.98, 0.01, 0.01]), 3), [0, 1, 2, 3])
    shares = np.array([0.5, 0.5])
    for _ in range(30):  # part 0 does a third of the work per agent of part 1
        bounds = share_bounds(shares, 64)
        work = np.diff(bounds) * np.array([1.0, 3.0])
        shares = balanced_shares(shares, work, 8 / 64)
    assert 0.7 < shares[0] < 0.8  # balanced: 0.75
    np.testing.assert_allclose(shares.sum(), 1.0)
    assert balanced_shares(np.array([0.5, 0.5]), np.array([1.0, 1e6]), 0.2)[1] >= 0.2 - 1e-12
    # Unmeasured parts (a part that raised) leave the shares as they were.
    np.testing.assert_array_equal(balanced_shares(shares, np.array([0.0, 1.0]), 0.1), shares)


@pytest.mark.parametrize("rule", ["scanned_space", "published"])
def test_the_clearances_carried_between_steps_are_those_a_query_gives(rule):
    """Each agent's surface distance, kept from the sweep that brought it where it stands
    (its stop, or its start after a refused or blocked move), is the distance a fresh query
    gives there, to the bit: the next sweep starts from it instead of asking again."""
    env = NarutoReconVectorEnv(
        16,
        scene=resolve_scene("two_rooms"),
        camera=PinholeCamera(16, 16, 8.0, 8.0, 7.5, 7.5),
        panorama_shape=None,
        action_mode="discrete",
        max_episode_steps=40,
        escape_rule=rule,
    )
    env.reset(seed=5)
    rng = np.random.default_rng(0)
    checked = 0
    for _ in range(60):
        env.step(rng.integers(0, env.single_action_space.n, env.num_envs))
        known = ~np.isnan(env._clearances)
        positions = env.poses[known, :3, 3]
        fresh = env.scene_runtimes[0].raycaster.unsigned_distance(positions)
        np.testing.assert_array_equal(env._clearances[known], fresh)
        checked += int(known.sum())
    assert checked > 500
    env.close()
