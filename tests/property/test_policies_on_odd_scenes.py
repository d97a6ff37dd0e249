"""The policies on odd but valid scenes: an episode finishes, or stops with one clear error,
within a time bound; it never hangs."""

from __future__ import annotations

import importlib.util
import signal
import time
from contextlib import contextmanager

import numpy as np
import pytest
import trimesh

from naruto_agent.policies import EnvContext, make_policy
from naruto_gym.envs.naruto_recon_env import NarutoReconEnv
from naruto_gym.geometry.transforms import make_pose
from naruto_gym.scenes.mesh_scene import Scene
from tests.property.scenes import CHEAP, room_mesh

#: Every shipped policy; the map-and-goal explorer where Stable-Baselines3 is installed.
POLICIES = ["naruto", "frontier", "random", "passive"] + (
    ["explorer"] if importlib.util.find_spec("stable_baselines3") else []
)
STEPS = 25
#: The most an episode of ``STEPS`` steps may take here (seconds), set-up included.
EPISODE_SECONDS = 120


@contextmanager
def time_bound(seconds: int):
    """Raise ``TimeoutError`` in the block after ``seconds`` (a hang fails, not blocks)."""

    def expire(signum, frame):
        raise TimeoutError(f"the episode took more than {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def _scene(kind: str) -> Scene:
    mesh = room_mesh()
    vertices, faces = np.array(mesh.vertices), np.array(mesh.faces)
    if kind == "open_shell":  # no ceiling and no wall at the largest x
        centres = vertices[faces].mean(axis=1)
        faces = faces[(centres[:, 2] < vertices[:, 2].max() - 0.05)
                      & (centres[:, 0] < vertices[:, 0].max() - 0.05)]
    elif kind == "disconnected":  # the room and a copy of it 10 m away
        vertices = np.concatenate([vertices, vertices + [10.0, 0.0, 0.0]])
        faces = np.concatenate([faces, faces + len(mesh.vertices)])
    elif kind == "degenerate_and_duplicate":
        faces = np.concatenate([faces, faces[:200], np.repeat(faces[:50, :1], 3, axis=1)])
    elif kind == "large":  # the room 100 times larger (300 m)
        vertices = vertices * 100.0
    elif kind == "single_box":  # a closed box, nothing in it
        box = trimesh.creation.box((2.0, 2.0, 2.0))
        vertices, faces = np.array(box.vertices), np.array(box.faces)[:, ::-1]
    return Scene(vertices, faces, np.full((len(faces), 3, 3), 170), name=kind)


def _episode(policy, env: NarutoReconEnv) -> None:
    policy.bind(EnvContext.from_env(env, max_episode_steps=STEPS))
    try:
        observation, info = env.reset(seed=0, options=policy.reset_options())
    except RuntimeError as error:
        assert "no free start position" in str(error)
        pose = make_pose(np.eye(3), env.bounds.mean(axis=0))
        observation, info = env.reset(seed=0, options={"pose": pose})
    policy.reset(observation, info, seed=0)
    for _ in range(STEPS):
        observation, _, _, _, info = env.step(policy.act(observation, info))
    assert len(env.trajectory) == STEPS + 1


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["open_shell", "disconnected", "degenerate_and_duplicate",
                                  "large", "single_box"])
@pytest.mark.parametrize("name", POLICIES)
def test_an_episode_finishes_or_stops_with_a_clear_error(name, kind):
    started = time.perf_counter()
    with time_bound(EPISODE_SECONDS):
        policy = make_policy(name)
        # the explorer's model reads the panorama it was trained on (32 x 64)
        cheap = {**CHEAP, "panorama_shape": (32, 64)} if name == "explorer" else CHEAP
        env = NarutoReconEnv(_scene(kind), action_mode=policy.preferred_action_mode, **cheap)
        try:
            _episode(policy, env)
        except ValueError as error:  # a clear error (a map too large for the scene, ...)
            assert "too large" in str(error) or "needs" in str(error), str(error)
            env.reset(seed=0, options={"pose": make_pose(np.eye(3), env.bounds.mean(axis=0))})
            env.step(env.action_space.sample())  # the env goes on
    assert time.perf_counter() - started < EPISODE_SECONDS


@pytest.mark.parametrize("name", ["naruto", "frontier"])
def test_a_map_too_large_for_the_machine_is_refused_before_it_is_allocated(name):
    """On the room scaled to 300 m, NARUTO's SDF volume and frontier's occupancy map would
    need about 106 GiB each: refused with a ValueError before any allocation."""
    policy = make_policy(name)
    env = NarutoReconEnv(_scene("large"), action_mode=policy.preferred_action_mode, **CHEAP)
    with pytest.raises(ValueError, match="too large for this voxel size"):
        _episode(policy, env)
