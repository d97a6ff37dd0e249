"""Per-episode procedural scenes: seeded draws, disjoint splits, bounded memory."""

from __future__ import annotations

import resource

import numpy as np
import pytest

from naruto_gym.scenes.catalogue import resolve_scene
from naruto_gym.scenes.stream import SPLIT_SEEDS, parse_procedural_name, split_of_seed
from naruto_gym.sensors.pinhole import PinholeCamera
from naruto_gym.vector import NarutoReconVectorEnv

STREAM = {
    "action_mode": "discrete",
    "camera": PinholeCamera(16, 16, 8, 8, 7.5, 7.5),
    "coverage_samples": 1500,
    "panorama_shape": None,
}


def test_names_splits_and_fixed_scenes():
    assert parse_procedural_name("procedural:room").split == "train"
    assert parse_procedural_name("procedural:apartment:test").split == "test"
    assert parse_procedural_name("procedural:room:42").seed == 42
    (train_low, train_high), (test_low, test_high) = SPLIT_SEEDS["train"], SPLIT_SEEDS["test"]
    assert train_high <= test_low or test_high <= train_low
    assert split_of_seed(train_low) == "train" and split_of_seed(test_low) == "test"
    for bad in ("procedural:castle", "procedural:room:val", "procedural:room:1:2",
                "procedural:room:1:no_ceiling:2"):
        with pytest.raises(ValueError, match="procedural"):
            parse_procedural_name(bad)
    assert resolve_scene("procedural:room:42").name == "room_42"
    with pytest.raises(ValueError, match="stream"):
        resolve_scene("procedural:room")


def test_stream_draws_a_new_seeded_scene_every_episode():
    env = NarutoReconVectorEnv(2, scene="procedural:room:test", max_episode_steps=2, **STREAM)
    first, _ = env.reset(seed=7)
    names = [scene.scene.name for scene in env.scene_runtimes]
    assert names[0] != names[1]
    assert all(split_of_seed(int(name.split("_")[1])) == "test" for name in names)
    for _ in range(3):  # the episode ends after 2 steps; the next step starts a new one
        env.step(np.array([6, 6]))
    assert [scene.scene.name for scene in env.scene_runtimes] != names
    again, _ = env.reset(seed=7)
    assert [scene.scene.name for scene in env.scene_runtimes] == names
    np.testing.assert_array_equal(again["pose"], first["pose"])


@pytest.mark.slow
def test_memory_stays_bounded_with_a_new_scene_every_reset():
    env = NarutoReconVectorEnv(
        2, scene="procedural:room", max_episode_steps=1, scene_cache_size=2, **STREAM
    )
    env.reset(seed=0)
    rss = []
    for step in range(60):  # a new scene for each env every other step: 60 scenes
        env.step(np.array([0, 6]))
        if step % 10 == 9:
            rss.append(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
    assert env.scene_pool.cached <= 2
    # Peak resident memory (MiB) may grow while allocators warm up, then levels off.
    assert rss[-1] - rss[1] < 40, rss


def test_a_reset_wave_builds_its_new_scenes_in_threads_with_the_one_by_one_result():
    """Agents that start their episodes together each need a new scene. Built in two threads
    (the default) they are the scenes, start poses and frames of a one-thread build, at the
    first reset and at the autoreset, and each is built once."""

    def run(threads: int) -> tuple[list[list[str]], list[dict], int]:
        env = NarutoReconVectorEnv(4, scene="procedural:room", max_episode_steps=2, **STREAM)
        env._threads = threads
        builds = []
        make = env.scene_pool.build
        env.scene_pool.build = lambda scene: builds.append(scene.name) or make(scene)
        observation, _ = env.reset(seed=3)
        names = [[scene.scene.name for scene in env.scene_runtimes]]
        observations = [observation]
        for _ in range(3):  # the episodes end after 2 steps; the third step starts new ones
            observations.append(env.step(np.array([6, 6, 2, 2]))[0])
        names.append([scene.scene.name for scene in env.scene_runtimes])
        return names, observations, len(builds)

    one_names, one, one_builds = run(1)
    two_names, two, two_builds = run(2)
    assert two_names == one_names and one_names[0] != one_names[1]
    assert two_builds == one_builds == 8
    for a, b in zip(one, two, strict=True):
        for key in a:
            np.testing.assert_array_equal(a[key], b[key])


def test_a_split_step_on_a_stream_gives_the_one_piece_step():
    """Agents each in their own generated room, stepped in two shares that move in turn and
    draw their frames into the observation rows: the same observations, rewards and infos
    as the step in one piece, across resets to new rooms."""

    def run(split: bool) -> list[tuple]:
        env = NarutoReconVectorEnv(
            6, scene="procedural:room", camera=PinholeCamera(32, 32, 16.0, 16.0, 15.5, 15.5),
            panorama_shape=None, action_mode="discrete", max_episode_steps=25,
            coverage_samples=2000,
        )
        env._threads, env._min_agents_per_part, env._split_steps = (
            (2, 1, True) if split else (1, 8, False)
        )
        env.reset(seed=4)
        rng = np.random.default_rng(0)
        steps = []
        for _ in range(60):
            observations, rewards, _, _, infos = env.step(rng.integers(0, 10, 6))
            steps.append((observations["rgb"], observations["depth"], observations["pose"],
                          rewards, infos["coverage"], infos["collision_reason"]))
        env.close()
        return steps

    for whole, split in zip(run(False), run(True), strict=True):
        for a, b in zip(whole, split, strict=True):
            np.testing.assert_array_equal(a, b)
