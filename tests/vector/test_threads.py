"""How many threads the compiled loops use: the keyword, the environment variable, the
worker-process rule and the machine's CPUs, in that order."""

from __future__ import annotations

import multiprocessing
import os

import pytest

from naruto_gym.sensors.pinhole import PinholeCamera
from naruto_gym.utils import threads as threads_module
from naruto_gym.utils.threads import (
    THREADS_ENV_VAR,
    available_cpus,
    default_thread_count,
    resolve_threads,
)
from naruto_gym.vector.sharded import default_workers, resolve_workers


@pytest.fixture
def clean_env(monkeypatch):
    for name in (THREADS_ENV_VAR, "OMP_NUM_THREADS", "RAY_RAYLET_PID"):
        monkeypatch.delenv(name, raising=False)
    return monkeypatch


def test_the_default_is_every_cpu_the_process_may_run_on(clean_env):
    assert available_cpus() == len(os.sched_getaffinity(0))
    assert default_thread_count() == available_cpus()
    assert resolve_threads(None) == available_cpus()
    # OMP_NUM_THREADS alone does not cap the main process (it is torch's, and often set low
    # for data loaders).
    clean_env.setenv("OMP_NUM_THREADS", "1")
    assert default_thread_count() == available_cpus()


def test_keyword_beats_environment_variable_beats_the_machine(clean_env):
    clean_env.setenv(THREADS_ENV_VAR, "7")
    assert default_thread_count() == 7
    assert resolve_threads(None) == 7
    assert resolve_threads(3) == 3
    clean_env.setenv(THREADS_ENV_VAR, "zero")
    with pytest.raises(ValueError, match=THREADS_ENV_VAR):
        default_thread_count()
    for bad in (0, -1, 1.5, True):
        with pytest.raises(ValueError, match="threads"):
            resolve_threads(bad)


def test_worker_processes_default_to_one_thread_or_omp_num_threads(clean_env):
    clean_env.setattr(threads_module, "is_worker_process", lambda: True)
    assert default_thread_count() == 1
    clean_env.setenv("OMP_NUM_THREADS", "2")
    assert default_thread_count() == min(2, available_cpus())
    clean_env.setenv(THREADS_ENV_VAR, "5")  # the variable still wins
    assert default_thread_count() == 5


def test_a_ray_worker_and_a_multiprocessing_child_are_worker_processes(clean_env):
    assert not threads_module.is_worker_process()
    clean_env.setenv("RAY_RAYLET_PID", "1")
    assert threads_module.is_worker_process()
    clean_env.delenv("RAY_RAYLET_PID")
    context = multiprocessing.get_context("spawn")
    with context.Pool(1) as pool:
        assert pool.apply(default_thread_count) == 1


def test_renderer_and_env_take_the_keyword(clean_env):
    from naruto_gym import NarutoReconEnv

    env = NarutoReconEnv(camera=PinholeCamera(16, 16, 8, 8, 7.5, 7.5), panorama_shape=None,
                         coverage_samples=500, threads=3)
    assert env.renderer.threads == 3
    env.close()
    with pytest.raises(ValueError, match="threads"):
        NarutoReconEnv(threads=0)


def test_default_workers_follow_cpus_and_agents():
    assert default_workers(256, 1) == 1
    assert default_workers(256, 2) == 1  # one process with two threads on two CPUs
    assert default_workers(256, 16) == 8
    assert default_workers(256, 64) == 16  # at least 16 agents per worker
    assert default_workers(8, 16) == 1
    assert resolve_workers(3, 5, 2) == 3
    for bad in (0, 1.5, True):
        with pytest.raises(ValueError, match="workers"):
            resolve_workers(bad, 5, 2)
    with pytest.raises(ValueError, match="num_envs"):
        resolve_workers(6, 5, 2)
