"""``SharedSceneStreams``: agents in groups on shared generated scenes, each kept for a number
of episodes: a group's agents share one runtime (one ray cast a step), a group's scene is
replaced after its episodes, the draws follow the reset seed, the train mix's closed and open
variants of both classes are all there, and a sharded env gives the same episodes."""

from __future__ import annotations

import numpy as np
import pytest

from naruto_gym.rl.explorer_env import TRAIN_MIX
from naruto_gym.sensors.pinhole import PinholeCamera
from naruto_gym.vector import NarutoReconVectorEnv, SharedSceneStreams, make_vector_env

TINY = {
    "action_mode": "discrete",
    "camera": PinholeCamera(16, 16, 8, 8, 7.5, 7.5),
    "coverage_samples": 1500,
    "panorama_shape": (8, 16),
    "threads": 1,
}
TURNS = np.array([6, 7, 6, 7, 6, 7, 6, 7])  # turn in place: no move, no escape check


def names(env) -> list[str]:
    return [runtime.scene.name for runtime in env.scene_runtimes]


def rooms(agents_per_scene: int = 2, episodes_per_scene: int = 2) -> SharedSceneStreams:
    return SharedSceneStreams(
        ("procedural:room:train", "procedural:room:train:no_ceiling+holes"),
        agents_per_scene=agents_per_scene,
        episodes_per_scene=episodes_per_scene,
    )


def test_a_groups_agents_share_one_runtime_and_one_ray_cast_a_step():
    env = NarutoReconVectorEnv(8, scene=rooms(), **TINY)
    env.reset(seed=0)
    runtimes = env.scene_runtimes
    for k in range(0, 8, 2):
        assert runtimes[k] is runtimes[k + 1]
    assert len({id(runtime) for runtime in runtimes}) == 4
    casts: list[int] = []
    for runtime in env.scene_pool.distinct():
        cast = runtime.raycaster.cast_packed

        def counted(rays, cast=cast):  # counts the calls, casts as before
            casts.append(len(rays))
            return cast(rays)

        runtime.raycaster.cast_packed = counted
    env.step(TURNS)
    frame_rays = env.rays_cast
    assert len(casts) == 4  # one cast per scene, not per agent
    assert sum(casts) <= frame_rays
    env.close()


def test_a_group_keeps_its_scene_for_its_episodes_then_draws_the_next():
    env = NarutoReconVectorEnv(4, scene=rooms(episodes_per_scene=2), max_episode_steps=2, **TINY)
    env.reset(seed=1)
    seen = [names(env)]
    for _ in range(3 * 3):  # an episode is 2 steps; the next step resets (NextStep)
        env.step(TURNS[:4])
        seen.append(names(env))
    episode_starts = [seen[0], seen[3], seen[6], seen[9]]
    # Two episodes in a scene, then a new one, for both groups at once.
    assert episode_starts[0] == episode_starts[1] != episode_starts[2] == episode_starts[3]
    for start in episode_starts:
        assert start[0] == start[1] and start[2] == start[3] and start[0] != start[2]
    assert "no_ceiling" in episode_starts[2][2] and "no_ceiling" not in episode_starts[2][0]
    env.close()


def test_an_agent_reset_alone_joins_its_groups_scene_whatever_the_cache_keeps():
    env = NarutoReconVectorEnv(4, scene=rooms(), scene_cache_size=0, **TINY)
    env.reset(seed=2)
    before = env.scene_runtimes
    env.reset(options={"reset_mask": np.array([False, True, False, False])})
    after = env.scene_runtimes
    assert after[1] is after[0] is before[0]  # the same runtime, not a second build
    env.close()


def test_the_reset_seed_gives_the_same_scenes_and_episodes():
    runs = []
    for seed in (3, 3, 4):
        env = NarutoReconVectorEnv(
            4, scene=rooms(episodes_per_scene=1), max_episode_steps=2, **TINY
        )
        observation, _ = env.reset(seed=seed)
        run = [(names(env), observation["pose"])]
        for _ in range(4):
            observation, *_ = env.step(TURNS[:4])
            run.append((names(env), observation["pose"]))
        runs.append(run)
        env.close()
    for (names_a, pose_a), (names_b, pose_b) in zip(runs[0], runs[1], strict=True):
        assert names_a == names_b
        np.testing.assert_array_equal(pose_a, pose_b)
    assert runs[0][0][0] != runs[2][0][0]


def test_the_train_mix_puts_closed_and_open_small_and_flat_scenes_in_the_pool():
    shared = SharedSceneStreams(TRAIN_MIX, agents_per_scene=1, episodes_per_scene=3)
    assert shared.agent_streams(4) == list(TRAIN_MIX)
    env = NarutoReconVectorEnv(4, scene=shared, **TINY)
    env.reset(seed=0)
    kinds = {(name.split("_")[0], "no_ceiling" in name) for name in names(env)}
    assert kinds == {("small", False), ("small", True), ("flat", False), ("flat", True)}
    env.close()


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"streams": ()}, "at least one"),
        ({"streams": ("procedural:room:7",)}, "scene streams"),
        ({"streams": ("replica_room0",)}, "scene streams"),
        ({"streams": TRAIN_MIX, "agents_per_scene": 0}, "agents_per_scene"),
        ({"streams": TRAIN_MIX, "episodes_per_scene": 1.5}, "episodes_per_scene"),
    ],
)
def test_bad_shared_scenes_are_refused_with_what_to_pass(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SharedSceneStreams(**kwargs)


def test_pose_actions_are_refused_across_shared_scenes():
    with pytest.raises(ValueError, match="discrete"):
        NarutoReconVectorEnv(2, scene=rooms(), **{**TINY, "action_mode": "pose"})


@pytest.mark.slow  # starts worker processes
def test_a_sharded_env_gives_the_same_episodes_and_refuses_a_split_group():
    kwargs = {**TINY, "scene": rooms(episodes_per_scene=1), "max_episode_steps": 2}
    with pytest.raises(ValueError, match="agents_per_scene"):
        make_vector_env(6, workers=2, **kwargs)  # 3 agents a worker split a group of 2
    envs = [make_vector_env(4, workers=workers, **kwargs) for workers in (1, 2)]
    results = [env.reset(seed=4)[0] for env in envs]
    for _ in range(4):
        for key in results[0]:
            np.testing.assert_array_equal(results[0][key], results[1][key], err_msg=key)
        results = [env.step(TURNS[:4])[0] for env in envs]
    for env in envs:
        env.close()
