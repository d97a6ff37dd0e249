"""``NarutoReconVectorEnv``: N agents stepped together in one process, rays cast in one call.

Each agent has its own scene, pose, coverage and random stream, exactly as N
``NarutoReconEnv`` in a ``gymnasium.vector.SyncVectorEnv`` would (same observations, rewards,
infos and autoreset semantics, step by step on the same seeds), but a step is batched:

1. one compiled loop turns every action into a bounded pose, and one closest-distance query
   and one segment ray cast per scene check the moves of all agents that move
   (:mod:`naruto_gym.vector.moves`);
2. one ray cast per scene holds every agent's pinhole rays, the escape-check panorama rays of
   every agent that moved and the observation panorama rays (:mod:`naruto_gym.vector.frames`);
3. one compiled loop updates every agent's coverage (:mod:`naruto_gym.vector.batch_coverage`).

Agents that share a scene share its :class:`~naruto_gym.envs.scene_runtime.SceneRuntime`
(ray-casting structure, surface samples, free-space sampling; see
:mod:`naruto_gym.vector.scene_pool`), so 64 agents in one scene cast their rays in a single
Embree call. This module holds the Gymnasium ``VectorEnv`` API: resets, steps, autoreset and
infos (the parts the sharded front shares live in :mod:`naruto_gym.vector.base`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode

from naruto_gym.envs.scene_runtime import SceneRuntime
from naruto_gym.evaluation.scoring import EpisodeReconstruction
from naruto_gym.vector.base import BatchedEnvBase
from naruto_gym.vector.batch_coverage import BatchCoverage
from naruto_gym.vector.frames import FrameDrawer
from naruto_gym.vector.infos import agent_info, agents_mask, batch_infos, overwrite_agents
from naruto_gym.vector.moves import Mover, Moves
from naruto_gym.vector.scene_pool import ScenePool
from naruto_gym.vector.scheduling import StepShares

__all__ = ["NarutoReconVectorEnv", "agent_info"]


class NarutoReconVectorEnv(BatchedEnvBase):
    """Batched ``NarutoReconEnv``: ``num_envs`` agents in one process.

    ## Description
    ``num_envs`` agents, each exploring its own scene (or a shared one) as a
    ``NarutoReconEnv`` does, stepped together: the same observations, rewards, infos and
    autoreset semantics as ``NarutoReconEnv`` instances in a ``SyncVectorEnv`` on the same
    seeds, with each step's ray casts, collision queries and coverage updates batched per
    scene. The frames are equal where both draw them the same way: ``pinhole_backend="auto"``
    rasterizes denser meshes in a batched env than in one env, and the two methods' depths
    differ by float rounding; ``"raycast"`` (the default) or ``"raster"`` fixes the method.

    ## Action Space
    ``single_action_space`` is ``NarutoReconEnv``'s for ``action_mode``; ``action_space``
    batches it. Scene lists and streams need ``action_mode="discrete"`` or ``"delta"`` (pose
    actions are bounded by one scene's box).

    ## Observation Space
    ``single_observation_space`` is ``NarutoReconEnv``'s; ``observation_space`` batches it.
    Each reset and step returns new arrays, drawn into directly (no copy is made); the env
    never writes to arrays it has returned, so a caller may keep or change them.

    The infos hold the keys of ``NarutoReconEnv``'s info as arrays with ``_key`` masks, as
    ``SyncVectorEnv`` gathers them.

    ## Rewards
    Each agent's, as ``NarutoReconEnv`` rewards it.

    ## Starting State
    As ``NarutoReconEnv``'s, per agent. ``reset(seed=s)`` seeds agent ``i`` with ``s + i``
    (or takes a list of seeds); ``options={"reset_mask": mask}`` resets only the agents
    ``mask`` flags, and ``options={"pose": c2w}`` starts the reset agents at one pose.

    ## Episode End
    Episodes never terminate; they are truncated after ``max_episode_steps`` steps, and the
    agent is reset as ``autoreset_mode`` says.

    ## Arguments
    * ``num_envs``: number of agents.
    * ``scene``: what each agent explores: a scene as ``NarutoReconEnv`` takes it (shared by
      all agents), a list of ``num_envs`` such scenes, or a stream name
      ``"procedural:room"`` / ``"procedural:apartment"`` (``":train"`` or ``":test"`` split
      appended, default train): a new generated scene for every episode, drawn from the
      episode's seeded generator (see :mod:`naruto_gym.scenes.stream`); or a
      :class:`~naruto_gym.vector.shared_scenes.SharedSceneStreams`: agents in groups, each
      group on one scene of a stream for several episodes (a scene built once for many
      episodes, a group's rays cast in one call), as RL training on many scenes wants.
    * ``max_episode_steps``: episodes are truncated after this many steps (None: never).
    * ``autoreset_mode``: ``AutoresetMode.NEXT_STEP`` (Gymnasium's default) or
      ``AutoresetMode.SAME_STEP`` (the final observation and info go in ``info["final_obs"]``
      / ``info["final_info"]``, as Stable-Baselines3 expects).
    * ``scene_cache_size``: generated scenes kept in memory for reuse (stream scenes only;
      a ``SharedSceneStreams`` group holds its current scene besides).
    * ``pinhole_backend``: as for ``NarutoReconEnv`` (default ``"raycast"``, the reference
      frames). ``"auto"`` is the setting for throughput (the learning entry points of
      ``naruto_gym.rl`` pass it): it rasterizes up to
      ``AUTO_RASTER_MAX_TRIANGLES_PER_PIXEL_BATCHED`` triangles per pixel (a higher limit
      than for one frame, as drawing many frames at once pays off on denser meshes), else
      ray-casts; its depths are the reference's up to float rounding and exact edge ties.
      ``scene_runtimes[i].renderer.frame_backend`` says which method agent ``i``'s frames
      use.
    * ``threads``: CPUs the env's compiled loops use (None: the ``NARUTO_GYM_THREADS``
      environment variable, else every CPU the process may run on; see
      :func:`~naruto_gym.utils.threads.default_thread_count`).
    * every other keyword is ``NarutoReconEnv``'s (``action_mode``, ``camera``,
      ``panorama_shape``, ``reconstruct``, ...). With ``reconstruct=True`` the info of each
      agent's last step (truncated) carries ``"reconstruction"``, as for the single env.

    Its agents step in this process. :func:`~naruto_gym.vector.make_vector_env` (and
    ``gymnasium.make_vec(..., vectorization_mode="vector_entry_point")``) takes ``workers``
    and, for more than one, gives a :class:`~naruto_gym.vector.sharded_env.ShardedVectorEnv`
    instead, which runs a ``NarutoReconVectorEnv`` for a share of the agents in each worker
    process: the same observations, rewards and infos.

    ## Version History
    * v0: initial release.
    """

    def __init__(
        self,
        num_envs: int = 1,
        scene: Any = None,
        max_episode_steps: int | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        scene_cache_size: int = 8,
        render_mode: str | None = None,
        **env_kwargs: Any,
    ) -> None:
        if "workers" in env_kwargs:
            raise ValueError(
                "NarutoReconVectorEnv steps its agents in this process and takes no workers=; "
                "for worker processes use naruto_gym.vector.make_vector_env(num_envs, "
                f"workers={env_kwargs['workers']!r}, ...) or gymnasium.make_vec(..., "
                "vectorization_mode='vector_entry_point', workers=...)"
            )
        super().__init__(
            num_envs,
            max_episode_steps,
            autoreset_mode,
            scene_cache_size,
            render_mode,
            env_kwargs,
            "NarutoReconVectorEnv",
        )
        self._pool = ScenePool(
            self._agent_scenes(scene), self.settings, scene_cache_size, self.num_envs
        )
        template = self._pool.template()
        self._check_pose_actions(self._pool.has_streams or len(self._pool.distinct()) > 1)
        self._set_spaces(template.observation_space(), template.action_space())

        n = self.num_envs
        self._poses = np.tile(np.eye(4), (n, 1, 1))
        self._path_length = np.zeros(n)
        # Each agent's distance to the nearest surface where it stands (nan: not known yet).
        self._clearances = np.full(n, np.nan, np.float32)
        self._steps = np.zeros(n, np.int64)
        self._mover = Mover(
            self._pool,
            self.settings.action_mode,
            self.settings.max_translation_m,
            self.settings.max_rotation_rad,
            self._poses,
            self._clearances,
            self._steps,
        )
        self._frames = FrameDrawer(
            n, self.camera, self.panorama_camera, self.settings.max_depth_m, self._poses
        )
        self._coverage = BatchCoverage(n)
        self._rngs: list[np.random.Generator | None] = [None] * n
        self._reconstructions: list[EpisodeReconstruction | None] = [None] * n
        self._autoreset = np.zeros(n, bool)
        # A step is split into shares of at least this many agents (_move_and_observe),
        # where that pays (None) or always (True: the tests run both ways).
        self._min_agents_per_part = 8
        self._split_steps: bool | None = None
        self._step_shares = StepShares()
        self._intrinsic_columns = {
            key: np.full(n, value, type(value)) for key, value in self.camera.as_dict().items()
        }

    # -- public views ----------------------------------------------------------------------
    @property
    def poses(self) -> np.ndarray:
        """(N, 4, 4) every agent's camera-to-world pose (a copy)."""
        return self._poses.copy()

    @property
    def rays_cast(self) -> int:
        """Rays cast so far for frames, panoramas and escape checks."""
        return self._frames.rays_cast

    @property
    def scene_pool(self) -> ScenePool:
        """The agents' scenes and the cache of generated ones."""
        return self._pool

    @property
    def scene_runtimes(self) -> list[SceneRuntime | None]:
        """Per agent, the runtime of its current scene (ray caster, renderer, coverage
        samples, ...); agents in one scene share it."""
        return self._pool.runtimes

    # -- gymnasium API ---------------------------------------------------------------------
    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        seeds, mask, options = self._reset_arguments(seed, options)
        indices = np.flatnonzero(mask)
        self._check_start_pose(options, indices)
        self._reset_agents(indices, [seeds[i] for i in indices], options)
        others = np.flatnonzero(~mask)
        self._frames.renew(keep=None if self._started else ~mask)
        if self._started and len(others):
            # The frames of the agents not reset were handed out with the last observations
            # (the caller may have changed them): drawn again, the same frames.
            for group in self._pool.groups(others, np.ones(len(others), bool)):
                members = others[group]
                self._frames.draw(
                    self._pool[members[0]], members, np.zeros(len(group), bool), self.thread_count
                )
        gains = np.zeros(self.num_envs)
        gains[indices] = self._observe(indices, None)
        self._autoreset[indices] = False
        self._started = True
        infos = self._infos(
            indices, gains, np.zeros(self.num_envs, bool), np.full(self.num_envs, "", object)
        )
        return self._observations(), infos

    def step(
        self, actions: Any
    ) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        discrete, continuous = self._validated_actions(actions)
        n = self.num_envs
        everyone = np.arange(n)
        if self.autoreset_mode == AutoresetMode.NEXT_STEP and self._autoreset.any():
            resetting, stepping = everyone[self._autoreset], everyone[~self._autoreset]
            self._reset_agents(resetting, [None] * len(resetting), {})
        else:
            stepping = everyone
        self._frames.renew()  # every agent's frame is drawn anew
        moves, gains = self._move_and_observe(stepping, discrete, continuous)
        collided = np.zeros(n, bool)
        reasons = np.full(n, "", dtype=object)
        rewards = np.zeros(n)
        terminated = np.zeros(n, bool)
        truncated = np.zeros(n, bool)
        if len(stepping):
            collided[stepping] = moves.collided
            reasons[stepping] = moves.reasons
            rewards[stepping] = 100.0 * gains[stepping] - np.where(
                moves.collided, float(self.settings.collision_penalty), 0.0
            )
            if self.max_episode_steps is not None:
                truncated[stepping] = self._steps[stepping] >= self.max_episode_steps
        infos = self._infos(everyone, gains, collided, reasons)
        done = everyone[terminated | truncated]
        if self.reconstruct:
            for i in done:
                infos = self._add_info(
                    infos, {"reconstruction": self._reconstruction_metrics(int(i))}, int(i)
                )
        observations = self._observations()
        if self.autoreset_mode == AutoresetMode.SAME_STEP and len(done):
            final_obs = np.full(n, None, dtype=object)
            final_infos: dict[str, Any] = {}
            for i in done:
                final_obs[i] = {key: value[i] for key, value in observations.items()}
                final_infos = self._add_info(final_infos, agent_info(infos, int(i)), int(i))
            self._reset_agents(done, [None] * len(done), {})
            # The final observations stay as they are: the new episodes' first frames go
            # into new buffers, the other agents' frames copied over.
            self._frames.renew(keep=~agents_mask(n, done))
            reset_gains = np.zeros(n)
            reset_gains[done] = self._observe(done, None)
            reset_infos = self._infos(
                done, reset_gains, np.zeros(n, bool), np.full(n, "", dtype=object)
            )
            infos = overwrite_agents(infos, reset_infos, done)
            if "_reconstruction" in infos:
                infos["_reconstruction"][done] = False
                if not infos["_reconstruction"].any():
                    del infos["reconstruction"], infos["_reconstruction"]
            infos["final_obs"], infos["_final_obs"] = final_obs, agents_mask(n, done)
            infos["final_info"], infos["_final_info"] = final_infos, agents_mask(n, done)
            observations = self._observations()
        self._autoreset = terminated | truncated
        return observations, rewards, terminated, truncated, infos

    def close_extras(self, **kwargs: Any) -> None:
        # Also reached from __del__ of an env whose constructor raised.
        pool = getattr(self, "_pool", None)
        if pool is not None:
            pool.clear()

    # -- per-agent reset -------------------------------------------------------------------
    def _check_start_pose(self, options: dict[str, Any], indices: np.ndarray) -> None:
        """Refuse a reset pose outside the scene of an agent that resets."""
        if "pose" in options:
            pose = np.asarray(options["pose"], dtype=np.float64)
            for i in indices:
                runtime = self._pool[i]
                if runtime is not None:
                    runtime.check_start_pose(pose)

    def _reset_agents(
        self, agents: np.ndarray, seeds: list[int | None], options: dict[str, Any]
    ) -> None:
        """Reset ``agents`` (with their ``seeds``): on a scene stream each draws its new
        scene from its generator first (see :meth:`ScenePool.draw_scenes`)."""
        for i, seed in zip(agents, seeds, strict=True):
            if seed is not None or self._rngs[i] is None:
                self._rngs[i], _ = seeding.np_random(seed)
        self._pool.draw_scenes(agents, [self._rngs[i] for i in agents], self.thread_count, seeds)
        for i in agents:
            self._reset_state(int(i), options)

    def _reset_state(self, i: int, options: dict[str, Any]) -> None:
        """Start agent ``i``'s episode in its scene (its generator and, on a stream, its new
        scene are set by :meth:`_reset_agents`)."""
        runtime = self._pool[i]
        if "pose" in options:
            pose = np.array(options["pose"], dtype=np.float64)
        else:
            pose = runtime.sample_start_pose(self._rngs[i])
        self._poses[i] = pose
        self._coverage.reset_agent(i, runtime.coverage)
        self._path_length[i] = 0.0
        self._clearances[i] = np.nan
        self._steps[i] = 0
        if self.reconstruct:
            # Agents share the process's threads already: fuse in the step's thread.
            self._reconstructions[i] = EpisodeReconstruction(self.camera, fuse_in_background=False)

    def _reconstruction_metrics(self, i: int) -> dict[str, Any]:
        return self._pool[i].reconstruction_metrics(self._reconstructions[i])

    # -- a step ----------------------------------------------------------------------------
    def _move_and_observe(
        self, stepping: np.ndarray, discrete: np.ndarray, continuous: np.ndarray
    ) -> tuple[Moves, np.ndarray]:
        """Move ``stepping`` agents and observe every agent; returns the moves and each
        agent's coverage gain.

        With many agents the step is split into contiguous shares, one per thread, each moved
        and observed start to finish in its thread (:class:`StepShares`): one share's frames
        are drawn while the next share moves, where a step split phase by phase would wait at
        every phase for its slowest thread. Agents never share state, so the result is the
        same as in one piece. Only where the frames are rasterized and no observation
        panorama is cast: a step that casts rays for every agent does better with one cast
        for all, as the ray caster already uses every core.
        """
        n = self.num_envs
        runtimes = self._pool.distinct()
        casts_frames = self.panorama_camera is not None or any(
            runtime.renderer.frame_backend != "raster" for runtime in runtimes
        )
        pays = not casts_frames if self._split_steps is None else self._split_steps
        parts = (
            1
            if self.reconstruct or not pays
            else max(1, min(self.thread_count, n // self._min_agents_per_part))
        )
        if parts == 1:
            moves = self._mover.move(stepping, discrete, continuous)
            return moves, self._observe(np.arange(n), moves)
        for runtime in runtimes:
            runtime.renderer.prepare_workers(parts)

        def move(start: int, stop: int) -> Moves:
            share = stepping[(stepping >= start) & (stepping < stop)]
            return self._mover.move(share, discrete, continuous)

        def observe(
            part: int, start: int, stop: int, moves: Moves, frames_start: Callable[[], None]
        ) -> np.ndarray:
            return self._observe(np.arange(start, stop), moves, part, frames_start)

        shares = self._step_shares.run(n, parts, self._min_agents_per_part, move, observe)
        return Moves.joined([moves for moves, _ in shares]), np.concatenate(
            [gains for _, gains in shares]
        )

    def _observe(
        self,
        agents: np.ndarray,
        moves: Moves | None,
        part: int | None = None,
        frames_start: Callable[[], None] | None = None,
    ) -> np.ndarray:
        """Render ``agents`` at their poses (one cast per scene, with the escape rays of the
        agents ``moves`` flags), undo refused moves, update path length and coverage.
        Returns each agent's coverage gain. ``part``: the share of the step this runs as
        (its compiled loops then stay in the calling thread); ``frames_start``: called once,
        as the first frames are drawn."""
        threads = self.thread_count if part is None else 1
        agents = np.asarray(agents, np.int64)
        gains = np.zeros(len(agents))
        if len(agents) == 0:
            return gains
        escape = np.zeros(self.num_envs, bool)
        if moves is not None and len(moves.agents):
            escape[moves.agents[moves.check_escape]] = True
        refused: list[int] = []
        for group in self._pool.groups(agents, np.ones(len(agents), bool)):
            members = agents[group]
            refused += self._frames.draw(
                self._pool[members[0]], members, escape[members], threads, part, frames_start
            )
            frames_start = None
        if refused:
            # A refused move stays at its start (with the new rotation): render it there.
            lookup = {int(a): k for k, a in enumerate(moves.agents)}
            for agent in refused:
                self._mover.undo(moves, lookup[agent])
            again = np.array(refused)
            for group in self._pool.groups(again, np.ones(len(refused), bool)):
                members = again[group]
                self._frames.draw(
                    self._pool[members[0]], members, np.zeros(len(group), bool), threads, part
                )
        if moves is not None and len(moves.agents):
            self._path_length[moves.agents] += np.linalg.norm(
                self._poses[moves.agents, :3, 3] - moves.starts, axis=1
            )
        for group in self._pool.groups(agents, np.ones(len(agents), bool)):
            members = agents[group]
            gains[group] = self._coverage.update(
                members,
                self._pool[members[0]].coverage,
                self._poses,
                self._frames.depth,
                threads,
            )
        if self.reconstruct:
            for i in agents:
                self._reconstructions[i].add_frame(
                    self._frames.rgb[i], self._frames.depth[i], self._poses[i]
                )
        return gains

    def _observations(self) -> dict[str, np.ndarray]:
        """The agents' observations: the frame buffers themselves (see
        :meth:`FrameDrawer.observations`)."""
        return self._frames.observations()

    def _infos(
        self, agents: np.ndarray, gains: np.ndarray, collided: np.ndarray, reasons: np.ndarray
    ) -> dict[str, Any]:
        """Infos of ``agents`` as ``SyncVectorEnv`` gathers single-env infos (arrays plus
        ``_key`` masks); the other arguments are per-env arrays of length ``num_envs``."""
        columns = {
            "coverage": (self._coverage.coverage(), float),
            "coverage_gain": (gains, float),
            "collided": (collided, bool),
            "collision_reason": (reasons, object),
            "path_length_m": (self._path_length, float),
            "step": (self._steps, int),
        }
        no_hit = self._frames.panorama_no_hit_shares() if self.panorama_camera is not None else None
        return batch_infos(self.num_envs, agents, columns, self._intrinsic_columns, no_hit)
