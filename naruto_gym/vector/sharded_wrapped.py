"""A wrapper chain over the batched env, with the agents sharded over worker processes.

A learner's observation and action wrappers (an egocentric map, goal actions walked by a
planner) do per-agent work in Python that one process runs on one core, while the batched env
beneath them uses the others only for its compiled loops. :class:`ShardedWrappedEnv` runs the
whole chain, ``wrap(NarutoReconVectorEnv(share))``, in each of ``workers`` processes on a
contiguous share of the agents (as :class:`~naruto_gym.vector.sharded_env.ShardedVectorEnv`
runs the bare env, through the same :class:`~naruto_gym.vector.sharded.ShardedAgents`): the
wrappers' work runs in parallel too, and only the chain's own observations cross the
processes. Every agent keeps its scene, seed and random stream, so a chain without
randomness of its own gives the observations, rewards and infos of one process.

    from functools import partial
    from naruto_gym.rl.explorer_env import wrap_explorer
    env = ShardedWrappedEnv(partial(wrap_explorer, steps_per_goal=20), num_envs=64,
                            workers=2, scene=shared_train_mix(16), **EXPLORER_ENV, ...)
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector.utils import batch_space

from naruto_gym.utils.threads import resolve_threads
from naruto_gym.vector.base import agent_scenes, agent_seeds
from naruto_gym.vector.sharded import ShardedAgents, resolve_workers
from naruto_gym.vector.shared_scenes import SharedSceneStreams
from naruto_gym.vector.vector_env import NarutoReconVectorEnv

__all__ = ["ShardedWrappedEnv", "WrappedShare"]

#: ``wrap(env) -> env``: the chain over a share's batched env (picklable: a module-level
#: function or a ``functools.partial`` of one).
Wrap = Callable[[gym.vector.VectorEnv], gym.vector.VectorEnv]


class WrappedShare:
    """Builds a share's chain from the batched env's keywords: ``wrap(NarutoReconVectorEnv(
    **kwargs))`` (what a worker process calls; picklable when ``wrap`` is)."""

    def __init__(self, wrap: Wrap) -> None:
        self.wrap = wrap

    def __call__(self, **kwargs: Any) -> gym.vector.VectorEnv:
        env = NarutoReconVectorEnv(**kwargs)
        try:
            return self.wrap(env)
        except BaseException:
            env.close()
            raise


class ShardedWrappedEnv(gym.vector.VectorEnv):
    """``wrap(NarutoReconVectorEnv(...))`` with its agents sharded over ``workers`` processes.

    Args:
        wrap: the chain over a share's batched env (picklable, see :data:`Wrap`); it must
            keep the batched env's ``reset(seed=list, options={"reset_mask": ...})``.
        num_envs: the agents.
        workers: the processes (at most ``num_envs``; a ``SharedSceneStreams`` scene needs
            each share to hold whole groups).
        scene: each agent's scene, as ``NarutoReconVectorEnv`` takes it.
        threads: CPUs split between the workers (None: every CPU this process may use).
        **env_kwargs: every other keyword of ``NarutoReconVectorEnv``.

    The chain's spaces are read from one chain of a single agent built here on agent 0's
    scene (and closed) before the workers start.

    Raises:
        ValueError: a bad ``workers``, or any keyword the env or the chain refuses.
    """

    def __init__(
        self,
        wrap: Wrap,
        num_envs: int,
        workers: int,
        scene: Any,
        threads: int | None = None,
        **env_kwargs: Any,
    ) -> None:
        self.num_envs = int(num_envs)
        self.thread_count = resolve_threads(threads)
        count = resolve_workers(workers, self.num_envs, self.thread_count)
        scenes = agent_scenes(scene, self.num_envs)
        # Agent 0's scene (its stream, for shared scene streams).
        first = scenes.agent_streams(1)[0] if isinstance(scenes, SharedSceneStreams) else scenes[0]
        build = WrappedShare(wrap)
        probe = build(num_envs=1, scene=first, **{**env_kwargs, "threads": 1})
        try:
            self.single_observation_space = probe.single_observation_space
            self.metadata = dict(probe.metadata)
        finally:
            probe.close()
        self._agents = ShardedAgents(
            build,
            self.num_envs,
            scenes,
            env_kwargs,
            self.single_observation_space,
            count,
            self.thread_count,
        )
        self.single_action_space = self._agents.single_action_space()
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)

    @property
    def num_workers(self) -> int:
        """The worker processes."""
        return self._agents.workers

    @property
    def worker_pids(self) -> list[int]:
        """The process ids of the worker processes."""
        return self._agents.pids

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Every agent's reset: ``seed`` an int (agent ``i`` gets ``seed + i``, as one
        process), a list of one per agent, or None; ``options`` go to every share."""
        seeds = agent_seeds(seed, self.num_envs)
        options = dict(options or {})
        if "reset_mask" in options:
            raise ValueError(
                "ShardedWrappedEnv resets every agent together (the chain's episodes start "
                "together): drop options['reset_mask']"
            )
        return self._agents.reset(seeds, np.ones(self.num_envs, bool), options)

    def step(
        self, actions: Any
    ) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Every agent's step with its action (one row per agent)."""
        actions = np.asarray(actions)
        if len(actions) != self.num_envs:
            raise ValueError(
                f"expected {self.num_envs} actions (one per agent), got {len(actions)}"
            )
        return self._agents.step(actions)

    def close_extras(self, **kwargs: Any) -> None:
        agents = getattr(self, "_agents", None)
        if agents is not None:
            agents.close()

