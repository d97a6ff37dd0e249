"""The batched env sharded over worker processes: its shutdown paths leave no process and no
shared memory behind (its observations are checked against SyncVectorEnv step by step in
test_vector_env.py)."""

from __future__ import annotations

import os
import signal
import threading
import time

import numpy as np
import pytest

from naruto_gym.sensors.pinhole import PinholeCamera
from naruto_gym.vector import NarutoReconVectorEnv, ShardedVectorEnv, make_vector_env
from naruto_gym.vector.sharded import StepTimes, WorkerError
from tests.process_checks import alive

TINY = {
    "action_mode": "discrete",
    "camera": PinholeCamera(16, 16, 8, 8, 7.5, 7.5),
    "coverage_samples": 500,
    "panorama_shape": None,
}


def shared_memory_entries() -> set[str]:
    """The shared-memory files and segments in /dev/shm, but named semaphores: the env
    makes none, and other processes of a shared machine come and go with theirs."""
    if not os.path.isdir("/dev/shm"):
        return set()
    return {name for name in os.listdir("/dev/shm") if not name.startswith("sem.")}


def assert_gone(pids: list[int], shm_before: set[str]) -> None:
    deadline = time.monotonic() + 10
    while any(alive(pid) for pid in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not [pid for pid in pids if alive(pid)]
    assert shared_memory_entries() - shm_before == set()


@pytest.fixture(scope="module")
def env_and_shm():
    shm_before = shared_memory_entries()
    env = ShardedVectorEnv(3, workers=2, max_episode_steps=5, **TINY)
    yield env, shm_before
    env.close()


def test_close_stops_the_workers_and_leaves_no_shared_memory(env_and_shm):
    env, shm_before = env_and_shm
    pids = env.worker_pids
    assert len(pids) == 2 and all(alive(pid) for pid in pids)
    assert env.num_workers == 2
    observations, _ = env.reset(seed=0)
    assert observations["rgb"].shape == (3, 16, 16, 3)
    held = {key: value.copy() for key, value in observations.items()}
    env.step(np.array([0, 1, 2]))
    for key in held:  # the handed-out arrays are the caller's: the next step leaves them
        np.testing.assert_array_equal(observations[key], held[key])
    with pytest.raises(RuntimeError, match="worker processes"):
        env.scene_runtimes  # noqa: B018
    with pytest.raises(ValueError, match="discrete actions"):  # checked before the workers
        env.step(np.array([0, 1]))
    env.step(np.array([0, 1, 2]))  # still usable
    env.close()
    env.close()
    assert_gone(pids, shm_before)
    with pytest.raises(RuntimeError, match="closed"):
        env.step(np.array([0, 1, 2]))


def test_step_times_split_the_step_between_workers_handover_and_caller():
    env = ShardedVectorEnv(4, workers=2, max_episode_steps=50, **TINY)
    try:
        env.reset(seed=0)
        assert env.step_times.steps == 0  # resets are not counted
        for _ in range(5):
            env.step(np.array([0, 1, 2, 3]))
        times = env.step_times
        assert times.steps == 5
        assert 0.0 < times.mean_worker_s <= times.slowest_worker_s < times.seconds
        assert 0.0 < times.caller_s < times.seconds and times.handover_s > 0.0
        ms = times.per_step_ms()
        assert ms["step"] == pytest.approx(ms["slowest_worker"] + ms["caller"] + ms["handover"])
        env.step_times = StepTimes()  # start over
        env.step(np.array([0, 1, 2, 3]))
        assert env.step_times.steps == 1 and StepTimes().per_step_ms() == {}
    finally:
        env.close()


def test_bad_input_in_a_worker_is_raised_with_its_traceback_and_the_env_stays_usable():
    shm_before = shared_memory_entries()
    env = ShardedVectorEnv(3, workers=2, **TINY)
    pids = env.worker_pids
    env.reset(seed=0)
    far = np.eye(4)
    far[:3, 3] = 100.0  # outside the room: the workers' scenes refuse the start
    with pytest.raises(ValueError, match="outside") as raised:  # as with one process
        env.reset(options={"pose": far})
    cause = raised.value.__cause__
    assert isinstance(cause, WorkerError)
    assert "ValueError" in str(cause) and "the worker's traceback" in str(cause)
    assert "File " in str(cause)
    assert all(alive(pid) for pid in pids)  # bad input: the workers keep running
    observations, _ = env.reset(seed=1)  # and the same env resets and steps
    assert observations["rgb"].shape == (3, 16, 16, 3)
    env.step(np.array([0, 1, 2]))
    env.close()
    assert_gone(pids, shm_before)


def test_a_worker_that_dies_is_reported_and_the_others_stopped():
    shm_before = shared_memory_entries()
    env = ShardedVectorEnv(3, workers=2, **TINY)
    pids = env.worker_pids
    env.reset(seed=0)
    os.kill(pids[1], signal.SIGKILL)
    with pytest.raises(WorkerError, match="died"):
        env.step(np.array([0, 1, 2]))
    assert_gone(pids, shm_before)


def test_keyboard_interrupt_while_stepping_stops_the_workers():
    """Ctrl-C reaches the caller (the workers ignore SIGINT); the workers stop, whether the
    interrupt came while they stepped (the env closes itself) or between steps (the caller's
    ``close``, as a ``with`` block or ``finally`` gives it)."""
    shm_before = shared_memory_entries()
    env = ShardedVectorEnv(3, workers=2, **TINY)
    pids = env.worker_pids
    env.reset(seed=0)
    # Python's own Ctrl-C handling, whatever an earlier test in this process installed
    # (Ray's driver, for one, replaces the SIGINT handler).
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGINT))
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            for _ in range(100_000):
                env.step(np.array([0, 1, 2]))
        assert all(alive(pid) for pid in pids) or env.workers_stopped
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
        env.close()
    assert_gone(pids, shm_before)


def test_make_vec_shards_a_scene_stream_with_the_same_episodes():
    """Through ``gym.make_vec``'s vector entry point, on a scene stream with autoresets: the
    agents' generated scenes, observations and rewards are those of one process."""
    import gymnasium as gym

    kwargs = {**TINY, "scene": "procedural:room:test", "max_episode_steps": 2}
    envs = [
        gym.make_vec(
            "NarutoRecon-v0",
            num_envs=3,
            vectorization_mode="vector_entry_point",
            workers=workers,
            **kwargs,
        )
        for workers in (1, 2)
    ]
    assert [env.num_workers for env in envs] == [1, 2]
    results = [env.reset(seed=4)[0] for env in envs]
    for key in results[0]:
        np.testing.assert_array_equal(results[0][key], results[1][key], err_msg=key)
    rng = np.random.default_rng(0)
    for _ in range(5):  # episodes end every other step: new scenes at the resets
        action = rng.integers(0, 10, 3)
        one, sharded = (env.step(action) for env in envs)
        for key in one[0]:
            np.testing.assert_array_equal(one[0][key], sharded[0][key], err_msg=key)
        np.testing.assert_array_equal(one[1], sharded[1])
        np.testing.assert_array_equal(one[3], sharded[3])
        np.testing.assert_array_equal(one[4]["coverage"], sharded[4]["coverage"])
    for env in envs:
        env.close()


def test_make_vector_env_picks_the_class_from_workers_and_the_in_process_env_takes_none():
    one = make_vector_env(3, workers=1, **TINY)
    assert type(one) is NarutoReconVectorEnv and one.num_workers == 1 and one.worker_pids == []
    one.close()
    with pytest.raises(ValueError, match=r"make_vector_env\(num_envs, workers=2"):
        NarutoReconVectorEnv(3, workers=2, **TINY)
    with pytest.raises(ValueError, match="workers must be a positive integer"):
        make_vector_env(3, workers=0, **TINY)
    with pytest.raises(ValueError, match="more than num_envs"):
        make_vector_env(3, workers=4, **TINY)
    with pytest.raises(ValueError, match="scene_envs"):  # the old alias: an unknown keyword
        make_vector_env(3, workers=2, scene_envs=None, **TINY)
    assert not hasattr(NarutoReconVectorEnv, "scene_envs")
