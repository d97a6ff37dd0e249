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
infos.
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from naruto_gym.envs.scene_runtime import SceneRuntime, observation_space
from naruto_gym.envs.settings import EnvSettings
from naruto_gym.envs.validation import check_keyword_names, check_vector_keywords
from naruto_gym.evaluation.scoring import EpisodeReconstruction
from naruto_gym.geometry.transforms import validate_pose
from naruto_gym.sensors.panorama import EquirectangularCamera
from naruto_gym.utils.threads import resolve_threads
from naruto_gym.vector.batch_coverage import BatchCoverage
from naruto_gym.vector.frames import FrameDrawer
from naruto_gym.vector.infos import agent_info, agents_mask, batch_infos, overwrite_agents
from naruto_gym.vector.moves import Mover, Moves
from naruto_gym.vector.scene_pool import ScenePool
from naruto_gym.vector.scheduling import StepShares
from naruto_gym.vector.sharded import ShardedAgents, resolve_workers, several_scenes

__all__ = ["NarutoReconVectorEnv", "agent_info", "make_vector_env"]


class NarutoReconVectorEnv(gym.vector.VectorEnv):
    """Batched ``NarutoReconEnv``: ``num_envs`` agents in one process.

    ## Description
    ``num_envs`` agents, each exploring its own scene (or a shared one) as a
    ``NarutoReconEnv`` does, stepped together: the same observations, rewards, infos and
    autoreset semantics as ``NarutoReconEnv`` instances in a ``SyncVectorEnv`` on the same
    seeds, with each step's ray casts, collision queries and coverage updates batched per
    scene.

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
      episode's seeded generator (see :mod:`naruto_gym.scenes.stream`).
    * ``max_episode_steps``: episodes are truncated after this many steps (None: never).
    * ``autoreset_mode``: ``AutoresetMode.NEXT_STEP`` (Gymnasium's default) or
      ``AutoresetMode.SAME_STEP`` (the final observation and info go in ``info["final_obs"]``
      / ``info["final_info"]``, as Stable-Baselines3 expects).
    * ``scene_cache_size``: generated scenes kept in memory for reuse (stream scenes only).
    * ``pinhole_backend``: as for ``NarutoReconEnv``, but ``"auto"`` by default: the
      rasterizer up to ``AUTO_RASTER_MAX_TRIANGLES_PER_PIXEL_BATCHED`` triangles per pixel (a
      higher limit than for one frame, as drawing many frames at once pays off on denser
      meshes), else the ray cast: the same frames as the single env's reference ray cast up
      to exact edge ties. Pass ``"raycast"`` for frames equal bit for bit to a default
      ``NarutoReconEnv``'s.
    * ``workers``: processes the agents are sharded over (None: chosen from the CPUs and
      ``num_envs``, :func:`~naruto_gym.vector.sharded.default_workers`; one on fewer than 4
      CPUs). Each worker steps a contiguous share of the agents in its own process with
      ``threads / workers`` threads and writes the observations into shared memory: the same
      observations, rewards and infos as one process, where the GIL-bound parts of a step
      run in parallel too. ``scene_pool`` and ``scene_runtimes`` are only there with one.
    * ``threads``: CPUs the env's compiled loops use, split between the workers (None: the
      ``NARUTO_GYM_THREADS`` environment variable, else every CPU the process may run on;
      see :func:`~naruto_gym.utils.threads.default_thread_count`).
    * every other keyword is ``NarutoReconEnv``'s (``action_mode``, ``camera``,
      ``panorama_shape``, ``reconstruct``, ...). With ``reconstruct=True`` the info of each
      agent's last step (truncated) carries ``"reconstruction"``, as for the single env.

    ## Version History
    * v0: initial release.
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

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
        self._sharded: ShardedAgents | None = None
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or (
            num_envs < 1
        ):
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        check_vector_keywords(max_episode_steps, scene_cache_size)
        if render_mode is not None:
            raise ValueError(
                "the batched vector env does not render; use "
                "gymnasium.make_vec(..., vectorization_mode='sync', render_mode='rgb_array')"
            )
        try:
            self.autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError as error:
            raise ValueError(
                f"autoreset_mode must be 'NextStep' or 'SameStep', got {autoreset_mode!r}"
            ) from error
        if self.autoreset_mode == AutoresetMode.DISABLED:
            raise ValueError("autoreset_mode DISABLED is not supported; use NextStep or SameStep")
        self.metadata = {**self.metadata, "autoreset_mode": self.autoreset_mode}
        self.num_envs = int(num_envs)
        self.max_episode_steps = max_episode_steps
        self.render_mode = None
        # Rasterized frames where they are cheaper (small frames of meshes of moderate size),
        # as RL wants; the single env's default is the reference ray cast.
        env_kwargs = {"pinhole_backend": "auto", **env_kwargs}
        self._reconstruct = bool(env_kwargs.pop("reconstruct", False))
        env_kwargs.pop("render_mode", None)
        accepted = (
            {item.name for item in dataclasses.fields(EnvSettings)}
            | set(inspect.signature(NarutoReconVectorEnv.__init__).parameters)
            | {"reconstruct"}
        ) - {"self", "env_kwargs"}
        check_keyword_names(
            env_kwargs, accepted, "NarutoReconVectorEnv",
            "The episode length is max_episode_steps (step_budget is the single env's).")
        self.settings = EnvSettings(**env_kwargs)
        # Compiled loops (ray filling, shading, coverage) split agents between this many
        # threads; Open3D's casts use the process's default count.
        self._threads = resolve_threads(self.settings.threads)
        self.num_workers = resolve_workers(workers, self.num_envs, self._threads)

        scenes = scene if isinstance(scene, (list, tuple)) else [scene] * self.num_envs
        if len(scenes) != self.num_envs:
            raise ValueError(f"scene list has {len(scenes)} entries for num_envs={num_envs}")
        self._discrete_zeros = np.zeros(self.num_envs, np.int64)
        self._continuous_zeros = np.zeros((self.num_envs, 7))
        self._started = False
        if self.num_workers > 1:
            self._start_workers(scenes, {
                **env_kwargs, "max_episode_steps": max_episode_steps,
                "autoreset_mode": self.autoreset_mode, "scene_cache_size": scene_cache_size,
                "reconstruct": self._reconstruct, "workers": 1,
            })
            return
        self._pool = ScenePool(scenes, self.settings, scene_cache_size)
        template = self._pool.template()
        self.action_mode: str = self.settings.action_mode
        if self.action_mode == "pose" and (
            self._pool.has_streams or len(self._pool.distinct()) > 1
        ):
            raise ValueError(
                "action_mode='pose' bounds actions by one scene's box; use 'discrete' or "
                "'delta' with several scenes or a procedural stream"
            )
        self.camera = template.camera
        self.panorama_camera = template.panorama_camera
        self.max_depth_m = float(self.settings.max_depth_m)
        self.single_observation_space = template.observation_space()
        self.single_action_space = template.action_space()
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)

        n = self.num_envs
        self._poses = np.tile(np.eye(4), (n, 1, 1))
        self._path_length = np.zeros(n)
        # Each agent's distance to the nearest surface where it stands (nan: not known yet).
        self._clearances = np.full(n, np.nan, np.float32)
        self._steps = np.zeros(n, np.int64)
        self._mover = Mover(
            self._pool, self.action_mode, self.settings.max_translation_m,
            self.settings.max_rotation_rad, self._poses, self._clearances, self._steps,
        )
        self._frames = FrameDrawer(
            n, self.camera, self.panorama_camera, self.max_depth_m, self._poses
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

    def _start_workers(self, scenes: list[Any], kwargs: dict[str, Any]) -> None:
        """Shard the agents over ``num_workers`` processes (:mod:`naruto_gym.vector.sharded`),
        each stepping its share as an in-process batched env built with ``kwargs``."""
        self.action_mode = self.settings.action_mode
        if self.action_mode == "pose" and several_scenes(scenes):
            raise ValueError(
                "action_mode='pose' bounds actions by one scene's box; use 'discrete' or "
                "'delta' with several scenes or a procedural stream"
            )
        self.single_observation_space = observation_space(self.settings)
        self._sharded = ShardedAgents(
            NarutoReconVectorEnv, self.num_envs, scenes, kwargs, self.single_observation_space,
            self.num_workers, self._threads,
        )
        self.camera = self.settings.pinhole_camera
        shape = self.settings.panorama_shape
        self.panorama_camera = EquirectangularCamera(*shape) if shape is not None else None
        self.max_depth_m = float(self.settings.max_depth_m)
        self.single_action_space = self._sharded.single_action_space()
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)

    # -- public views ----------------------------------------------------------------------
    @property
    def poses(self) -> np.ndarray:
        """(N, 4, 4) every agent's camera-to-world pose (a copy)."""
        if self._sharded is not None:
            return self._sharded.poses()
        return self._poses.copy()

    @property
    def rays_cast(self) -> int:
        """Rays cast so far for frames, panoramas and escape checks."""
        if self._sharded is not None:
            return self._sharded.rays_cast()
        return self._frames.rays_cast

    @property
    def scene_pool(self) -> ScenePool:
        """The agents' scenes and the cache of generated ones (in-process envs only)."""
        return self._in_process("scene_pool")._pool

    @property
    def scene_runtimes(self) -> list[SceneRuntime | None]:
        """Per agent, the runtime of its current scene (ray caster, renderer, coverage
        samples, ...); agents in one scene share it (in-process envs only)."""
        return self._in_process("scene_runtimes")._pool.runtimes

    @property
    def scene_envs(self) -> list[SceneRuntime | None]:
        """The earlier name of :attr:`scene_runtimes` (the runtimes have the ``scene``,
        ``bounds``, ``raycaster`` and ``renderer`` its callers read)."""
        return self._in_process("scene_envs")._pool.runtimes

    @property
    def worker_pids(self) -> list[int]:
        """The process ids of the worker processes (empty with ``workers=1``)."""
        return [] if self._sharded is None else self._sharded.pids

    def _in_process(self, name: str) -> NarutoReconVectorEnv:
        if self._sharded is not None:
            raise RuntimeError(
                f"{name} lives in the worker processes of an env with workers="
                f"{self.num_workers}; make the env with workers=1 to reach it"
            )
        return self

    # -- gymnasium API ---------------------------------------------------------------------
    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        if seed is None:
            seeds: list[int | None] = [None] * self.num_envs
        elif isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            seeds = [int(seed) + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(
                    f"seed list has length {len(seeds)}; it must match num_envs={self.num_envs}"
                )
        options = dict(options or {})
        mask = options.pop("reset_mask", None)
        if mask is None:
            mask = np.ones(self.num_envs, bool)
        elif not (
            isinstance(mask, np.ndarray) and mask.dtype == np.bool_
            and mask.shape == (self.num_envs,) and mask.any()
        ):
            raise ValueError(
                f"options['reset_mask'] must be a bool numpy array of shape ({self.num_envs},) "
                "with at least one True"
            )
        indices = np.flatnonzero(mask)
        if self._sharded is not None:
            self._validate_reset_options(options, np.zeros(0, np.int64))
            observations, infos = self._sharded.reset(seeds, mask, options)
            self._started = True
            return observations, infos
        self._validate_reset_options(options, indices)
        self._reset_agents(indices, [seeds[i] for i in indices], options)
        others = np.flatnonzero(~mask)
        self._frames.renew(keep=None if self._started else ~mask)
        if self._started and len(others):
            # The frames of the agents not reset were handed out with the last observations
            # (the caller may have changed them): drawn again, the same frames.
            for group in self._pool.groups(others, np.ones(len(others), bool)):
                members = others[group]
                self._frames.draw(self._pool[members[0]], members, np.zeros(len(group), bool),
                                  self._threads)
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
        if not self._started:
            raise RuntimeError("call reset() before step()")
        discrete, continuous = self._validated_actions(actions)
        if self._sharded is not None:
            return self._sharded.step(np.asarray(actions))
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
        if self._reconstruct:
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
            reset_infos = self._infos(done, reset_gains, np.zeros(n, bool),
                                      np.full(n, "", dtype=object))
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
        sharded = getattr(self, "_sharded", None)
        if sharded is not None:
            sharded.close()
        pool = getattr(self, "_pool", None)
        if pool is not None:
            pool.clear()

    # -- per-agent reset -------------------------------------------------------------------
    def _validate_reset_options(self, options: dict[str, Any], indices: np.ndarray) -> None:
        unknown = set(options) - {"pose"}
        if unknown:
            raise ValueError(f"unknown reset options {sorted(unknown)}; supported: ['pose']")
        if "pose" in options:
            pose = validate_pose(options["pose"], "options['pose']")
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
        self._pool.draw_scenes(agents, [self._rngs[i] for i in agents], self._threads)
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
        if self._reconstruct:
            self._reconstructions[i] = EpisodeReconstruction(self.camera)

    def _reconstruction_metrics(self, i: int) -> dict[str, Any]:
        return self._pool[i].reconstruction_metrics(self._reconstructions[i])

    # -- actions ---------------------------------------------------------------------------
    def _validated_actions(self, actions: Any) -> tuple[np.ndarray, np.ndarray]:
        n = self.num_envs
        if self.action_mode == "discrete":
            array = np.asarray(actions)
            if array.shape not in ((n,), (n, 1)) or not np.issubdtype(array.dtype, np.integer):
                raise ValueError(
                    f"discrete actions must be {n} integers in [0, "
                    f"{self.single_action_space.n}), got {actions!r}"
                )
            array = array.reshape(n).astype(np.int64)
            if np.any(array < 0) or np.any(array >= self.single_action_space.n):
                raise ValueError(
                    f"discrete actions must lie in [0, {self.single_action_space.n}), got "
                    f"{array.tolist()}"
                )
            return array, self._continuous_zeros
        try:
            array = np.asarray(actions, dtype=np.float64)
        except (TypeError, ValueError) as error:
            raise ValueError(f"actions must be a numeric array, got {actions!r}") from error
        expected = (n, *self.single_action_space.shape)
        if array.shape != expected:
            raise ValueError(f"{self.action_mode} actions must have shape {expected}, got "
                             f"{array.shape}")
        if not np.all(np.isfinite(array)):
            raise ValueError("actions contain NaN or inf")
        low, high = self.single_action_space.low, self.single_action_space.high
        if np.any(array < low - 1e-5) or np.any(array > high + 1e-5):
            raise ValueError(f"{self.action_mode} actions lie outside the action space "
                             f"[{low.tolist()}, {high.tolist()}]")
        if self.action_mode == "pose" and np.any(np.linalg.norm(array[:, 3:7], axis=1) < 1e-6):
            raise ValueError(
                "pose action quaternion (x, y, z, w) has zero norm; pass a unit quaternion"
            )
        padded = np.zeros((n, 7))
        padded[:, : array.shape[1]] = array
        return self._discrete_zeros, padded

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
        parts = 1 if self._reconstruct or not pays else max(
            1, min(self._threads, n // self._min_agents_per_part)
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
        self, agents: np.ndarray, moves: Moves | None, part: int | None = None,
        frames_start: Callable[[], None] | None = None,
    ) -> np.ndarray:
        """Render ``agents`` at their poses (one cast per scene, with the escape rays of the
        agents ``moves`` flags), undo refused moves, update path length and coverage.
        Returns each agent's coverage gain. ``part``: the share of the step this runs as
        (its compiled loops then stay in the calling thread); ``frames_start``: called once,
        as the first frames are drawn."""
        threads = self._threads if part is None else 1
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
            refused += self._frames.draw(self._pool[members[0]], members, escape[members],
                                         threads, part, frames_start)
            frames_start = None
        if refused:
            # A refused move stays at its start (with the new rotation): render it there.
            lookup = {int(a): k for k, a in enumerate(moves.agents)}
            for agent in refused:
                self._mover.undo(moves, lookup[agent])
            again = np.array(refused)
            for group in self._pool.groups(again, np.ones(len(refused), bool)):
                members = again[group]
                self._frames.draw(self._pool[members[0]], members, np.zeros(len(group), bool),
                                  threads, part)
        if moves is not None and len(moves.agents):
            self._path_length[moves.agents] += np.linalg.norm(
                self._poses[moves.agents, :3, 3] - moves.starts, axis=1
            )
        for group in self._pool.groups(agents, np.ones(len(agents), bool)):
            members = agents[group]
            gains[group] = self._coverage.update(
                members, self._pool[members[0]].coverage, self._poses, self._frames.depth,
                threads,
            )
        if self._reconstruct:
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
        no_hit = (self._frames.panorama_no_hit_shares() if self.panorama_camera is not None
                  else None)
        return batch_infos(self.num_envs, agents, columns, self._intrinsic_columns, no_hit)


def make_vector_env(num_envs: int = 1, **kwargs: Any) -> NarutoReconVectorEnv:
    """Vector entry point of the registered ids (``gymnasium.make_vec``)."""
    return NarutoReconVectorEnv(num_envs=num_envs, **kwargs)
