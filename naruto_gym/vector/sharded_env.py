"""``ShardedVectorEnv``: the batched env's agents stepped in worker processes.

The front of :class:`~naruto_gym.vector.sharded.ShardedAgents`: it takes the keywords of
:class:`~naruto_gym.vector.vector_env.NarutoReconVectorEnv`, checks them, the reset arguments
and the actions in the caller (as the in-process env does, through
:class:`~naruto_gym.vector.base.BatchedEnvBase`), and hands each worker process its share of the
agents, which the worker steps as a ``NarutoReconVectorEnv``. The observations, rewards and
infos are those of one ``NarutoReconVectorEnv`` over every agent.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode

from naruto_gym.envs.scene_runtime import observation_space
from naruto_gym.vector.base import BatchedEnvBase
from naruto_gym.vector.sharded import (
    ShardedAgents,
    StepTimes,
    resolve_workers,
    several_scenes,
)
from naruto_gym.vector.vector_env import NarutoReconVectorEnv

__all__ = ["ShardedVectorEnv"]


class ShardedVectorEnv(BatchedEnvBase):
    """``NarutoReconVectorEnv``'s agents sharded over ``workers`` processes.

    Each worker steps a contiguous share of the agents as a ``NarutoReconVectorEnv`` with
    ``threads / workers`` threads and writes the observations into shared memory: the same
    observations, rewards and infos as one process, where the GIL-bound parts of a step run in
    parallel too. Workers start with ``spawn`` and stop on ``close()``, on a
    ``KeyboardInterrupt`` in the caller and at the caller's exit; bad input a worker refuses
    (such as a reset pose outside the scene) is raised in the caller and leaves the env usable
    (see :mod:`naruto_gym.vector.sharded`).

    ``num_envs``, ``scene``, ``max_episode_steps``, ``autoreset_mode``, ``scene_cache_size``
    and ``render_mode`` are ``NarutoReconVectorEnv``'s.

    Args:
        workers: the processes (None: chosen from the CPUs and ``num_envs``,
            :func:`~naruto_gym.vector.sharded.default_workers`); at most ``num_envs``.
        **env_kwargs: every other keyword of ``NarutoReconVectorEnv`` (``threads`` are the
            CPUs split between the workers).

    The scenes live in the workers: ``scene_pool`` and ``scene_runtimes`` are there only on a
    ``NarutoReconVectorEnv`` (``workers=1`` in :func:`~naruto_gym.vector.make_vector_env`).
    """

    def __init__(
        self,
        num_envs: int = 1,
        scene: Any = None,
        max_episode_steps: int | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        scene_cache_size: int = 8,
        render_mode: str | None = None,
        workers: int | None = None,
        **env_kwargs: Any,
    ) -> None:
        self._agents: ShardedAgents | None = None
        super().__init__(
            num_envs,
            max_episode_steps,
            autoreset_mode,
            scene_cache_size,
            render_mode,
            dict(env_kwargs),
            "ShardedVectorEnv",
        )
        workers = resolve_workers(workers, self.num_envs, self.thread_count)
        scenes = self._agent_scenes(scene)
        self._check_pose_actions(several_scenes(scenes))
        single_observation = observation_space(self.settings)
        shares = {
            **env_kwargs,
            "max_episode_steps": max_episode_steps,
            "autoreset_mode": self.autoreset_mode,
            "scene_cache_size": scene_cache_size,
        }
        self._agents = ShardedAgents(
            NarutoReconVectorEnv,
            self.num_envs,
            scenes,
            shares,
            single_observation,
            workers,
            self.thread_count,
        )
        self._set_spaces(single_observation, self._agents.single_action_space())

    # -- views -------------------------------------------------------------------------------
    @property
    def num_workers(self) -> int:
        """The worker processes."""
        return self._agents.workers

    @property
    def worker_pids(self) -> list[int]:
        """The process ids of the worker processes."""
        return self._agents.pids

    @property
    def workers_stopped(self) -> bool:
        """Whether the worker processes were stopped (by ``close()``, or by a failure or a
        ``KeyboardInterrupt`` while they stepped)."""
        return self._agents.closed

    @property
    def step_times(self) -> StepTimes:
        """Where the steps' wall time went so far: the slowest worker's stepping, the
        hand-over through the pipes and this process's merge and copy
        (:class:`~naruto_gym.vector.sharded.StepTimes`); assign a new ``StepTimes()`` to
        start over."""
        return self._agents.step_times

    @step_times.setter
    def step_times(self, times: StepTimes) -> None:
        self._agents.step_times = times

    @property
    def poses(self) -> np.ndarray:
        """(N, 4, 4) every agent's camera-to-world pose (a copy)."""
        return self._agents.poses()

    @property
    def rays_cast(self) -> int:
        """Rays cast so far by every worker for frames, panoramas and escape checks."""
        return self._agents.rays_cast()

    @property
    def scene_pool(self) -> Any:
        """Not here: the scenes live in the worker processes."""
        raise self._in_workers("scene_pool")

    @property
    def scene_runtimes(self) -> Any:
        """Not here: the scenes live in the worker processes."""
        raise self._in_workers("scene_runtimes")

    def _in_workers(self, name: str) -> RuntimeError:
        return RuntimeError(
            f"{name} lives in the worker processes of a ShardedVectorEnv (workers="
            f"{self.num_workers}); make a NarutoReconVectorEnv (make_vector_env(..., "
            "workers=1)) to reach it"
        )

    # -- gymnasium API -----------------------------------------------------------------------
    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        seeds, mask, options = self._reset_arguments(seed, options)
        observations, infos = self._agents.reset(seeds, mask, options)
        self._started = True
        return observations, infos

    def step(
        self, actions: Any
    ) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        self._validated_actions(actions)
        return self._agents.step(np.asarray(actions))

    def close_extras(self, **kwargs: Any) -> None:
        # Also reached from __del__ of an env whose constructor raised.
        agents = getattr(self, "_agents", None)
        if agents is not None:
            agents.close()
