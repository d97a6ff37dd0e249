"""``NarutoReconVectorEnv``: N agents stepped together in one process, rays cast in one call.

Each agent has its own scene, pose, coverage and random stream, exactly as N
``NarutoReconEnv`` in a ``gymnasium.vector.SyncVectorEnv`` would (same observations, rewards,
infos and autoreset semantics, step by step on the same seeds), but a step is batched:

1. one compiled loop turns every action into a bounded pose (the single env's kernels);
2. collision checking asks one closest-distance query and one segment ray cast per scene for
   all agents that move;
3. one ray cast per scene holds every agent's pinhole rays, the escape-check panorama rays of
   every agent that moved (only as many rays as can decide the check; the rest only when
   those leave it open) and the observation panorama rays;
4. one compiled loop updates every agent's coverage.

Agents that share a scene share its ray-casting structure, surface samples and free-space
sampling, so 64 agents in one scene cast their rays in a single Embree call. Agents in
different scenes (a list of scenes, or ``"procedural:..."`` streams) are grouped by scene.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from naruto_gym.coverage import COVERAGE_TOLERANCE_M
from naruto_gym.envs.naruto_recon_env import NarutoReconEnv
from naruto_gym.evaluation.scoring import EpisodeReconstruction
from naruto_gym.geometry.transforms import validate_pose
from naruto_gym.motion.actions import MAX_DISCRETE_PITCH_RAD
from naruto_gym.motion.pose_kernels import (
    MODE_DELTA,
    MODE_DISCRETE,
    MODE_POSE,
    step_poses_kernel,
)
from naruto_gym.scenes.stream import (
    LruCache,
    ProceduralSceneSpec,
    is_procedural_name,
    parse_procedural_name,
)
from naruto_gym.sensors.kernels import fill_panorama_rays
from naruto_gym.sensors.pinhole import AUTO_RASTER_MAX_TRIANGLES_PER_PIXEL_BATCHED
from naruto_gym.utils.threads import default_thread_count, run_parallel
from naruto_gym.vector.batch_kernels import (
    PROVABLY_CLEAR_SLACK_M,
    fill_pinhole_rays,
    mark_visible_batch,
    no_hit_counts,
    plan_sweeps,
    sweep_distance_queries,
    sweep_stops,
)

_MODES = {"pose": MODE_POSE, "delta": MODE_DELTA, "discrete": MODE_DISCRETE}


class _Moves:
    """What :meth:`NarutoReconVectorEnv._move` decided for the stepping agents."""

    def __init__(self, agents: np.ndarray) -> None:
        self.agents = agents
        self.starts = np.zeros((len(agents), 3))
        self.collided = np.zeros(len(agents), bool)
        self.reasons = np.full(len(agents), "", dtype=object)
        self.check_escape = np.zeros(len(agents), bool)
        # Surface distance of each start (float32, as the distance query gives it).
        self.start_clearances = np.full(len(agents), np.nan, np.float32)

    @classmethod
    def joined(cls, shares: list[_Moves]) -> _Moves:
        """The outcome of several shares' moves of a step, in order, as one: the agents,
        whether each collided and why (what the step reports; the shares have been
        observed already)."""
        moves = cls(np.concatenate([share.agents for share in shares]))
        moves.collided = np.concatenate([share.collided for share in shares])
        moves.reasons = np.concatenate([share.reasons for share in shares])
        return moves


def _in_threads(work: Any, count: int, threads: int) -> None:
    """``work(part)`` over ``count`` agents split in up to ``threads`` contiguous slices,
    run in parallel (the compiled kernels release the GIL)."""
    parts = max(1, min(threads, count // 8))
    if parts == 1:  # one agent's scene at a time with scene streams: no per-call set-up
        work(slice(0, count))
        return
    bounds = np.linspace(0, count, parts + 1).astype(int)
    run_parallel(lambda k: work(slice(int(bounds[k]), int(bounds[k + 1]))), parts)


def share_bounds(shares: np.ndarray, count: int) -> np.ndarray:
    """Contiguous parts of ``count`` agents in proportion to ``shares`` (summing to 1): the
    (P + 1,) bounds, every part at least one agent."""
    parts = len(shares)
    bounds = [0] * (parts + 1)
    cumulative = 0.0
    for part in range(1, parts):  # at least one agent per part, from both ends
        cumulative += float(shares[part - 1])
        bounds[part] = min(max(round(cumulative * count), bounds[part - 1] + 1),
                           count - (parts - part))
    bounds[parts] = count
    return np.array(bounds, np.int64)


def balanced_shares(shares: np.ndarray, finished: np.ndarray, minimum: float) -> np.ndarray:
    """Shares for the next step: each part's grows or shrinks with how much earlier or later
    than the average it finished (damped by half, so timing noise does not make them swing),
    none below ``minimum``."""
    # Plain Python over the few parts: this runs at every split step, after the frames have
    # pushed NumPy's dispatch out of the caches.
    times = [float(value) for value in finished]
    if min(times) <= 0.0:
        return shares
    mean = sum(times) / len(times)
    updated = [float(share) * math.sqrt(mean / time) for share, time in zip(shares, times,
                                                                               strict=True)]
    total = sum(updated)
    updated = [share / total for share in updated]
    low = [False] * len(updated)
    # Pin the smallest at the minimum.
    while any(share < minimum - 1e-12 for share in updated) and not all(low):
        low = [pinned or share < minimum for pinned, share in zip(low, updated, strict=True)]
        free = sum(share for pinned, share in zip(low, updated, strict=True) if not pinned)
        scale = (1.0 - minimum * sum(low)) / free if free > 0.0 else 0.0
        updated = [minimum if pinned else share * scale
                   for pinned, share in zip(low, updated, strict=True)]
    return np.array(updated)


def _escape_rule(checker: Any) -> str:
    """The collision checker's escape rule (checkers without rules use the published one)."""
    default = "off" if checker.escape_no_hit_threshold is None else "published"
    return getattr(checker, "escape_rule", default)


def _allclose_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise ``np.allclose(a[i], b[i])`` (same tolerances)."""
    return np.all(np.abs(a - b) <= 1e-8 + 1e-5 * np.abs(b), axis=1)


class NarutoReconVectorEnv(gym.vector.VectorEnv):
    """Batched ``NarutoReconEnv``: ``num_envs`` agents in one process.

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
    * ``pinhole_backend``: as for ``NarutoReconEnv``, but ``"auto"`` by default (the
      rasterizer up to ``AUTO_RASTER_MAX_TRIANGLES_PER_PIXEL_BATCHED`` triangles per pixel,
      16, where drawing many frames at once beats the ray cast: 64 x 64 frames of the default
      room or of a 50,000-triangle scan): the same frames as the single env's reference ray
      cast up to exact edge ties. Pass ``"raycast"`` for frames equal bit for bit to a
      default ``NarutoReconEnv``'s.
    * every other keyword is passed to ``NarutoReconEnv`` (``action_mode``, ``camera``,
      ``panorama_shape``, ``reconstruct``, ...). With ``reconstruct=True`` the info of each
      agent's last step (truncated) carries ``"reconstruction"``, as for the single env.

    ## Spaces
    ``single_observation_space`` / ``single_action_space`` are those of ``NarutoReconEnv``;
    ``observation_space`` / ``action_space`` batch them. Streams and scene lists need
    ``action_mode="discrete"`` or ``"delta"`` (pose actions are bounded by one scene's box).

    ## Observations
    Each reset and step returns new arrays, drawn into directly (no copy is made); the env
    never writes to arrays it has returned, so a caller may keep or change them.

    ## Infos
    The keys of ``NarutoReconEnv``'s info as arrays with ``_key`` masks, as
    ``SyncVectorEnv`` gathers them.
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
        **env_kwargs: Any,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or (
            num_envs < 1
        ):
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        if max_episode_steps is not None and max_episode_steps < 1:
            raise ValueError(f"max_episode_steps must be >= 1 or None, got {max_episode_steps}")
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
        self._env_kwargs = {"pinhole_backend": "auto", **env_kwargs}
        self._reconstruct = bool(self._env_kwargs.pop("reconstruct", False))
        self._env_kwargs.pop("render_mode", None)
        self._streams: list[ProceduralSceneSpec | None] = []
        self._scene_cache: LruCache[NarutoReconEnv] = LruCache(scene_cache_size)
        # Per agent: the env instance whose building blocks (ray caster, samples, checker)
        # serve its current scene; agents in one scene share it.
        self._scenes: list[NarutoReconEnv | None] = [None] * self.num_envs

        scenes = scene if isinstance(scene, (list, tuple)) else [scene] * self.num_envs
        if len(scenes) != self.num_envs:
            raise ValueError(f"scene list has {len(scenes)} entries for num_envs={num_envs}")
        fixed: dict[int, NarutoReconEnv] = {}
        for index, item in enumerate(scenes):
            if is_procedural_name(item):
                spec = parse_procedural_name(item)
                self._streams.append(spec if spec.is_stream else None)
                if not spec.is_stream:
                    self._scenes[index] = self._scene_env(("fixed", item), item)
                continue
            self._streams.append(None)
            key = id(item)
            if key not in fixed:
                fixed[key] = self._make_scene_env(item)
            self._scenes[index] = fixed[key]
        template = next((env for env in self._scenes if env is not None), None)
        if template is None:
            # Only streams: spaces come from one generated scene (they do not depend on it).
            spec = next(s for s in self._streams if s is not None)
            template = self._scene_env((spec.kind, spec.draw_seed(np.random.default_rng(0))),
                                       spec)
        self.action_mode: str = template.action_mode
        distinct = {id(env) for env in self._scenes if env is not None}
        if self.action_mode == "pose" and (any(self._streams) or len(distinct) > 1):
            raise ValueError(
                "action_mode='pose' bounds actions by one scene's box; use 'discrete' or "
                "'delta' with several scenes or a procedural stream"
            )
        self.camera = template.camera
        self.panorama_camera = template.panorama_camera
        self.max_depth_m = template.max_depth_m
        self.single_observation_space = template.observation_space
        self.single_action_space = template.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)

        height, width = self.camera.height, self.camera.width
        n = self.num_envs
        self._poses = np.tile(np.eye(4), (n, 1, 1))
        self._rgb = np.zeros((n, height, width, 3), np.uint8)
        self._depth = np.zeros((n, height, width), np.float32)
        self._panorama = (
            np.zeros((n, self.panorama_camera.height, self.panorama_camera.width), np.float32)
            if self.panorama_camera is not None else None
        )
        # Seen flags of each agent's scene samples (row i, the first len(samples) columns):
        # one array, so the coverage kernel updates them in place.
        self._seen = np.zeros((n, 0), bool)
        self._unseen_in_cell = np.zeros((n, 0), np.int64)  # per agent and coverage cell
        self._seen_counts = np.zeros(n, np.int64)
        self._path_length = np.zeros(n)
        # Each agent's distance to the nearest surface where it stands (nan: not known yet),
        # carried over from the sweep that brought it there: that point is one of the
        # sweep's samples, whose distance was queried, so its next sweep need not ask again.
        self._clearances = np.full(n, np.nan, np.float32)
        self._steps = np.zeros(n, np.int64)
        self._rngs: list[np.random.Generator | None] = [None] * n
        self._reconstructions: list[EpisodeReconstruction | None] = [None] * n
        self._autoreset = np.zeros(n, bool)
        self._started = False
        # Compiled loops (ray filling, shading, coverage) split agents between this many
        # threads; Embree's cast has its own.
        self._threads = default_thread_count()
        # Rays cast for frames, panoramas and escape checks (benchmarks report rays/s).
        self.rays_cast = 0
        self._rays_lock = threading.Lock()
        # A step is split into shares of at least this many agents (_move_and_observe),
        # where that pays (None) or always (True: the tests run both ways).
        self._min_agents_per_part = 8
        self._split_steps: bool | None = None
        # Shares of the agents per part of a split step, adapted step by step so that the
        # parts finish together (:func:`share_bounds`, :func:`balanced_shares`).
        self._shares: np.ndarray | None = None
        self._intrinsic_columns = {
            key: np.full(n, value, type(value)) for key, value in self.camera.as_dict().items()
        }
        # Coverage samples of each agent's scene (set at its reset; 1 before any).
        self._sample_totals = np.ones(n, np.int64)
        self._discrete_zeros = np.zeros(n, np.int64)
        self._continuous_zeros = np.zeros((n, 7))

    # -- scenes ----------------------------------------------------------------------------
    def _make_scene_env(self, scene: Any) -> NarutoReconEnv:
        env = NarutoReconEnv(scene=scene, **self._env_kwargs)
        # Many frames at a time: "auto" rasterizes denser meshes than for one frame.
        env.renderer.auto_max_triangles_per_pixel = AUTO_RASTER_MAX_TRIANGLES_PER_PIXEL_BATCHED
        env.coverage  # noqa: B018 - builds the samples (and observable surface) now
        return env

    def _scene_env(
        self, key: tuple, spec: ProceduralSceneSpec | str,
        built: dict[tuple, NarutoReconEnv] | None = None,
    ) -> NarutoReconEnv:
        """The cached env of scene ``key``, made when missing (taken from ``built`` when it
        was made there already)."""
        return self._scene_cache.get(
            key, lambda: built.pop(key) if built and key in built
            else self._build_scene_env(key, spec)
        )

    def _build_scene_env(self, key: tuple, spec: ProceduralSceneSpec | str) -> NarutoReconEnv:
        return self._make_scene_env(spec if isinstance(spec, str) else spec.scene(key[1]))

    @property
    def scene_envs(self) -> list[NarutoReconEnv | None]:
        """Per agent, the ``NarutoReconEnv`` holding its current scene's building blocks."""
        return list(self._scenes)

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
        self._validate_reset_options(options, indices)
        self._reset_agents(indices, [seeds[i] for i in indices], options)
        others = np.flatnonzero(~mask)
        self._new_frame_buffers(keep=None if self._started else ~mask)
        if self._started and len(others):
            # The frames of the agents not reset were handed out with the last observations
            # (the caller may have changed them): drawn again, the same frames.
            for group in _groups(self._scenes, others, np.ones(len(others), bool)):
                self._render(others[group], np.zeros(len(group), bool))
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
        n = self.num_envs
        everyone = np.arange(n)
        if self.autoreset_mode == AutoresetMode.NEXT_STEP and self._autoreset.any():
            resetting, stepping = everyone[self._autoreset], everyone[~self._autoreset]
            self._reset_agents(resetting, [None] * len(resetting), {})
        else:
            stepping = everyone
        self._new_frame_buffers()  # every agent's frame is drawn anew
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
                moves.collided, self._collision_penalty, 0.0
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
            self._new_frame_buffers(keep=~_mask(n, done))
            reset_gains = np.zeros(n)
            reset_gains[done] = self._observe(done, None)
            reset_infos = self._infos(done, reset_gains, np.zeros(n, bool),
                                      np.full(n, "", dtype=object))
            infos = _overwrite_agents(infos, reset_infos, done)
            if "_reconstruction" in infos:
                infos["_reconstruction"][done] = False
                if not infos["_reconstruction"].any():
                    del infos["reconstruction"], infos["_reconstruction"]
            infos["final_obs"], infos["_final_obs"] = final_obs, _mask(n, done)
            infos["final_info"], infos["_final_info"] = final_infos, _mask(n, done)
            observations = self._observations()
        self._autoreset = terminated | truncated
        return observations, rewards, terminated, truncated, infos

    def close_extras(self, **kwargs: Any) -> None:
        # Also reached from __del__ of an env whose constructor raised.
        self._scenes = [None] * getattr(self, "num_envs", 0)

    # -- per-agent reset -------------------------------------------------------------------
    @property
    def _collision_penalty(self) -> float:
        return next(env for env in self._scenes if env is not None).collision_penalty

    def _validate_reset_options(self, options: dict[str, Any], indices: np.ndarray) -> None:
        unknown = set(options) - {"pose"}
        if unknown:
            raise ValueError(f"unknown reset options {sorted(unknown)}; supported: ['pose']")
        if "pose" in options:
            pose = validate_pose(options["pose"], "options['pose']")
            for i in indices:
                env = self._scenes[i]
                bounds = env.bounds if env is not None else None
                if bounds is not None and not np.all(
                    (pose[:3, 3] >= bounds[0]) & (pose[:3, 3] <= bounds[1])
                ):
                    raise ValueError(
                        f"options['pose'] position {pose[:3, 3].tolist()} lies outside the "
                        f"scene bounds {bounds.tolist()}"
                    )

    def _reset_agents(
        self, agents: np.ndarray, seeds: list[int | None], options: dict[str, Any]
    ) -> None:
        """Reset ``agents`` (with their ``seeds``). On a scene stream every agent's new scene
        is drawn first, and the scenes not cached yet are built two or more at a time (one
        per thread of :func:`run_parallel`; the ray casts and compiled loops of a build
        release the GIL): agents that start their episodes together, as in RL training,
        need a new scene each. Each scene is a function of its draw alone, so the result is
        the one-by-one reset's."""
        keys: list[tuple | None] = []
        for i, seed in zip(agents, seeds, strict=True):
            if seed is not None or self._rngs[i] is None:
                self._rngs[i], _ = seeding.np_random(seed)
            stream = self._streams[i]
            keys.append(None if stream is None else (stream.kind, stream.draw_seed(self._rngs[i])))
        missing = {key: self._streams[i] for i, key in zip(agents, keys, strict=True)
                   if key is not None and key not in self._scene_cache}
        built: dict[tuple, NarutoReconEnv] = {}
        if len(missing) > 1 and self._threads > 1:
            order = iter(list(missing))  # claimed one key at a time by whichever thread is free

            def build(_: int) -> None:
                for key in order:
                    built[key] = self._build_scene_env(key, missing[key])

            run_parallel(build, min(self._threads, len(missing)))
        for i, key in zip(agents, keys, strict=True):
            if key is not None:
                self._scenes[i] = self._scene_env(key, self._streams[i], built)
            self._reset_state(int(i), options)

    def _reset_state(self, i: int, options: dict[str, Any]) -> None:
        """Start agent ``i``'s episode in its scene (its generator and, on a stream, its new
        scene are set by :meth:`_reset_agents`)."""
        rng = self._rngs[i]
        env = self._scenes[i]
        if "pose" in options:
            pose = np.array(options["pose"], dtype=np.float64)
        else:
            # The scene env's own start sampler, driven by this agent's generator.
            env.np_random = rng
            pose = env._sample_start_pose()
        self._poses[i] = pose
        self._seen = _widened(self._seen, len(env.coverage.samples_world))
        self._sample_totals[i] = len(env.coverage.samples_world)
        self._seen[i] = False
        sizes = env.coverage.cell_sizes
        self._unseen_in_cell = _widened(self._unseen_in_cell, len(sizes))
        self._unseen_in_cell[i, :len(sizes)] = sizes
        self._seen_counts[i] = 0
        self._path_length[i] = 0.0
        self._clearances[i] = np.nan
        self._steps[i] = 0
        if self._reconstruct:
            self._reconstructions[i] = EpisodeReconstruction(self.camera)

    def _reconstruction_metrics(self, i: int) -> dict[str, Any]:
        env = self._scenes[i]
        env.reconstruction = self._reconstructions[i]
        try:
            return env.reconstruction_metrics()
        finally:
            env.reconstruction = None

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

    # -- motion ----------------------------------------------------------------------------
    def _move_and_observe(
        self, stepping: np.ndarray, discrete: np.ndarray, continuous: np.ndarray
    ) -> tuple[_Moves, np.ndarray]:
        """Move ``stepping`` agents and observe every agent; returns the moves and each
        agent's coverage gain.

        With many agents the step is split into contiguous shares, one per thread, each moved
        and observed start to finish in its thread: the compiled loops (frames, colours,
        coverage) release the GIL, so one share's frames are drawn while the other share moves,
        where a step split phase by phase would wait at every phase for its slowest thread and
        run everything between the phases on one core. The shares move in turn and are sized
        to finish together (:func:`balanced_shares`). Agents never share
        state, so the result is the same as in one piece. Only where the frames are
        rasterized and no observation panorama is cast: a step that casts rays for every
        agent does better with one cast for all, as the ray caster already uses every core
        (two shares casting at once: 0.8-0.9x, measured).
        """
        n = self.num_envs
        scenes = {id(env): env for env in self._scenes if env is not None}.values()
        casts_frames = self.panorama_camera is not None or any(
            env.renderer.frame_backend != "raster" for env in scenes
        )
        pays = not casts_frames if self._split_steps is None else self._split_steps
        parts = 1 if self._reconstruct or not pays else max(
            1, min(self._threads, n // self._min_agents_per_part)
        )
        if parts == 1:
            moves = self._move(stepping, discrete, continuous)
            return moves, self._observe(np.arange(n), moves)
        if self._shares is None or len(self._shares) != parts:
            self._shares = np.full(parts, 1.0 / parts)
        bounds = share_bounds(self._shares, n)
        for env in scenes:
            env.renderer.prepare_workers(parts)
        # The parts move one after another, in order: moving is mostly Python and distance
        # queries that hold the GIL, so two parts moving at once only wait for each other
        # (measured: 2.6 ms of wall for 1.5 ms of work each); this way a part moves while the
        # ones before it draw their frames, which release the GIL. The first parts, which wait
        # less, get more agents (adapted from the parts' finishing times).
        moved = [threading.Event() for _ in range(parts)]
        started = time.perf_counter()
        finished = np.zeros(parts)

        def run(part: int) -> tuple[_Moves, np.ndarray]:
            agents = np.arange(bounds[part], bounds[part + 1])
            if part:
                moved[part - 1].wait()
            try:
                moves = self._move(
                    stepping[(stepping >= bounds[part]) & (stepping < bounds[part + 1])],
                    discrete, continuous,
                )
                # The next part moves once this one's frames start (they release the GIL):
                # its Python until then would only wait for this part's.
                gains = self._observe(agents, moves, part, frames_start=moved[part].set)
            finally:
                moved[part].set()
            finished[part] = time.perf_counter() - started
            return moves, gains

        shares = run_parallel(run, parts)
        self._shares = balanced_shares(self._shares, finished, self._min_agents_per_part / n)
        return _Moves.joined([moves for moves, _ in shares]), np.concatenate(
            [gains for _, gains in shares]
        )

    def _count_rays(self, count: int) -> None:
        with self._rays_lock:  # the shares of a step count from their threads
            self.rays_cast += count

    def _move(self, agents: np.ndarray, discrete: np.ndarray, continuous: np.ndarray) -> _Moves:
        """Bounded pose step and collision sweep of ``agents``; their poses become the
        candidate poses. The escape check of those that moved is left to :meth:`_observe`,
        whose cast carries its rays."""
        moves = _Moves(agents)
        if len(agents) == 0:
            return moves
        env0 = self._scenes[agents[0]]
        limited = np.empty((len(agents), 4, 4))
        step_poses_kernel(
            np.ascontiguousarray(self._poses[agents]), _MODES[self.action_mode],
            np.ascontiguousarray(discrete[agents]), np.ascontiguousarray(continuous[agents]),
            env0.max_translation_m, env0.max_rotation_rad, float(MAX_DISCRETE_PITCH_RAD), limited,
        )
        moves.starts = self._poses[agents, :3, 3].copy()
        moves.start_clearances = self._clearances[agents]
        targets = limited[:, :3, 3].copy()
        positions = moves.starts.copy()
        moving = ~_allclose_rows(moves.starts, targets)
        end_clearances = np.full(len(agents), np.nan)
        for group in _groups(self._scenes, agents, moving):
            self._sweep(agents[group], group, moves, targets, positions, end_clearances)
        moved = ~_allclose_rows(positions, moves.starts)
        # Where each agent stands after the sweep: its stop's distance, else its start's.
        self._clearances[agents] = np.where(
            np.isnan(end_clearances), moves.start_clearances, end_clearances
        )
        for group in _groups(self._scenes, agents, moved):
            checker = self._scenes[agents[group[0]]].collision
            rule = _escape_rule(checker)
            if rule == "published":
                # Their panorama rays ride along with the frame's cast (see _render).
                moves.check_escape[group] = True
                continue
            if rule == "off":
                continue
            if rule == "scanned_space":
                # One lattice lookup for all: an end inside the scanned space is never
                # refused, so only the others need the exact per-move rule.
                inside = checker.scanned_space.contains_many(
                    positions[group], end_clearances[group]
                )
                group = group[~inside]
            for k in group:
                if checker.refuses_escape(moves.starts[k], positions[k]):
                    positions[k] = moves.starts[k]
                    self._clearances[agents[k]] = moves.start_clearances[k]
                    moves.collided[k] = True
                    moves.reasons[k] = "escape"
        limited[:, :3, 3] = positions
        self._poses[agents] = limited
        self._steps[agents] += 1
        return moves

    def _sweep(
        self, members: np.ndarray, group: np.ndarray, moves: _Moves, targets: np.ndarray,
        positions: np.ndarray, end_clearances: np.ndarray,
    ) -> None:
        """``CollisionChecker.move``'s box clip and sphere sweep for moving agents of one
        scene (``group`` indexes ``moves``), with one distance query for all their samples
        and one cast for all their segment rays. Where each sweep stops is one of its
        samples, so its distance to the surface (for the escape rule) comes with it."""
        env = self._scenes[members[0]]
        checker = env.collision
        raycaster = env.raycaster
        start = np.ascontiguousarray(moves.starts[group])
        start_clearances = moves.start_clearances[group]
        unknown = np.isnan(start_clearances)
        if unknown.any():
            start_clearances[unknown] = raycaster.unsigned_distance(start[unknown])
            moves.start_clearances[group] = start_clearances
        # From a start closer than the radius (an exact start pose) the sphere may move on as
        # long as it gets no closer than it already is.
        box, end, clearances, lengths, offsets, fractions, points = plan_sweeps(
            start, np.ascontiguousarray(targets[group]), checker.box_min, checker.box_max,
            start_clearances, float(checker.radius_m),
        )
        # Only samples whose distance could block are queried, and only segments that could
        # reach a surface are cast: the outcome is the full sweep's (sweep_distance_queries).
        needed, distances = sweep_distance_queries(
            start_clearances, offsets, fractions, lengths, clearances
        )
        if needed.any():
            distances[needed] = raycaster.unsigned_distance(points[needed])
        walls = np.full(len(group), np.inf)
        along = (lengths > 0) & ~(
            start_clearances >= lengths + clearances + PROVABLY_CLEAR_SLACK_M
        )
        if along.any():
            directions = (end[along] - start[along]) / lengths[along, None]
            walls[along] = raycaster.cast_distance(start[along], directions)
        stops, stop_clearances = sweep_stops(
            fractions, offsets, lengths, distances, walls, clearances
        )
        positions[group] = start + stops[:, None] * (end - start)
        # A sweep stopped before its end, at a sample only bounded: ask for that distance.
        bounded = np.isinf(stop_clearances)
        if bounded.any():
            stop_clearances[bounded] = raycaster.unsigned_distance(positions[group][bounded])
        end_clearances[group] = stop_clearances
        reasons = np.where(stops < 1.0, "surface", np.where(box < 1.0, "bounds", ""))
        moves.reasons[group] = reasons
        moves.collided[group] = reasons != ""

    # -- observation -----------------------------------------------------------------------
    def _observe(
        self, agents: np.ndarray, moves: _Moves | None, part: int | None = None,
        frames_start: Callable[[], None] | None = None,
    ) -> np.ndarray:
        """Render ``agents`` at their poses (one cast per scene, with the escape rays of the
        agents ``moves`` flags), undo refused moves, update path length and coverage.
        Returns each agent's coverage gain. ``part``: the share of the step this runs as
        (:meth:`_move_and_observe`; its compiled loops then stay in the calling thread);
        ``frames_start``: called once, as the first frames are drawn."""
        threads = self._threads if part is None else 1
        agents = np.asarray(agents, np.int64)
        gains = np.zeros(len(agents))
        if len(agents) == 0:
            return gains
        escape = np.zeros(self.num_envs, bool)
        if moves is not None and len(moves.agents):
            escape[moves.agents[moves.check_escape]] = True
        refused: list[int] = []
        for group in _groups(self._scenes, agents, np.ones(len(agents), bool)):
            members = agents[group]
            refused += self._render(members, escape[members], part, frames_start)
            frames_start = None
        if refused:
            # A refused move stays at its start (with the new rotation): render it there.
            lookup = {int(a): k for k, a in enumerate(moves.agents)}
            for agent in refused:
                k = lookup[agent]
                self._poses[agent, :3, 3] = moves.starts[k]
                self._clearances[agent] = moves.start_clearances[k]
                moves.collided[k] = True
                moves.reasons[k] = "escape"
            for group in _groups(self._scenes, np.array(refused), np.ones(len(refused), bool)):
                self._render(np.array(refused)[group], np.zeros(len(group), bool), part)
        if moves is not None and len(moves.agents):
            self._path_length[moves.agents] += np.linalg.norm(
                self._poses[moves.agents, :3, 3] - moves.starts, axis=1
            )
        for group in _groups(self._scenes, agents, np.ones(len(agents), bool)):
            members = agents[group]
            env = self._scenes[members[0]]
            coverage = env.coverage
            added = np.zeros(len(members), np.int64)

            _in_threads(
                lambda part, coverage=coverage, members=members, added=added: (
                    mark_visible_batch(
                        coverage.samples_world, *coverage.cells, self._seen,
                        self._unseen_in_cell, members[part],
                        self._poses, coverage.intrinsics, self._depth, coverage.max_range_m,
                        COVERAGE_TOLERANCE_M, added[part],
                    )
                ),
                len(members), threads,
            )
            total = len(coverage.samples_world)
            before = self._seen_counts[members] / total
            self._seen_counts[members] += added
            gains[group] = self._seen_counts[members] / total - before
        if self._reconstruct:
            for i in agents:
                self._reconstructions[i].add_frame(self._rgb[i], self._depth[i], self._poses[i])
        return gains

    def _render(
        self, members: np.ndarray, escape: np.ndarray, part: int | None = None,
        frames_start: Callable[[], None] | None = None,
    ) -> list[int]:
        """Render agents of one scene (``members``, in increasing order) with one cast that
        carries their pinhole rays, their observation panorama rays and the first escape-check
        rays of the agents flagged in ``escape``; returns the agents whose move the escape
        check refuses.

        With the rasterizing pinhole backend the frames are rasterized (the single env's
        renderer) and the cast carries only the panorama rays. ``part``: as for
        :meth:`_observe` (the frames are drawn in the calling thread with that share's
        rasterizer); ``frames_start``: as for :meth:`_observe`.
        """
        env = self._scenes[members[0]]
        camera = self.camera
        count = len(members)
        pixels = camera.width * camera.height
        threads = self._threads if part is None else 1
        raster = getattr(env.renderer, "frame_backend", "raycast") == "raster"
        cast_pixels = 0 if raster else pixels
        poses32 = self._poses[members].astype(np.float32)
        positions32 = np.ascontiguousarray(poses32[:, :3, 3])
        checker = env.collision
        escapers = members[escape]
        first, order = _escape_ray_plan(checker) if len(escapers) else (0, None)
        panorama = self.panorama_camera
        panorama_rays = panorama.height * panorama.width if panorama is not None else 0
        escape_offset = count * (cast_pixels + panorama_rays)
        rays = np.empty((escape_offset + len(escapers) * first, 6), np.float32)
        if not raster:
            def fill(part: slice) -> None:
                fill_pinhole_rays(camera.ray_directions, poses32[part], rays,
                                  (part.start or 0) * pixels)

            _in_threads(fill, count, threads)
        if panorama is not None:
            fill_panorama_rays(panorama.ray_directions, positions32, rays, count * cast_pixels)
        if len(escapers):
            fill_panorama_rays(order[:first], np.ascontiguousarray(positions32[escape]), rays,
                               escape_offset)
        if frames_start is not None:
            frames_start()
        hits = env.raycaster.cast_packed(rays) if len(rays) else None
        self._count_rays(len(rays))

        # Agents with consecutive indices (one scene, or a share of a split step) get their
        # frames drawn and coloured straight into the observation rows.
        rows = slice(int(members[0]), int(members[0]) + count)
        # Members come in increasing order: consecutive when they span exactly their count.
        in_place = raster and int(members[-1]) - int(members[0]) == count - 1
        if raster:
            frames = env.renderer.render_hits_many(
                self._poses[members], worker=part,
                depth_out=self._depth[rows] if in_place else None,
                barycentric_faces=env.scene.faces_needing_barycentrics,
            )
            depth = frames.depth.reshape(-1)
            triangle_ids, barycentric_uv = frames.triangle_ids, frames.barycentric_uv
        else:
            frame = slice(0, count * pixels)
            depth = hits.distance[frame].copy()
            # As RgbdRenderer: hits beyond the range are misses (depth 0, black).
            depth[~(depth <= self.max_depth_m)] = 0.0
            triangle_ids = np.where(depth > 0, hits.triangle_ids[frame], -1).astype(np.int32)
            barycentric_uv = hits.barycentric_uv[frame]
        rgb = (self._rgb[rows].reshape(-1, 3) if in_place
               else np.empty((len(triangle_ids), 3), np.uint8))

        def shade(part: slice) -> None:
            pixels_of = slice((part.start or 0) * pixels, part.stop * pixels)
            env.scene.colour_at(triangle_ids[pixels_of], barycentric_uv[pixels_of],
                                out=rgb[pixels_of])

        _in_threads(shade, count, threads)
        if not in_place:
            self._depth[members] = depth.reshape(count, camera.height, camera.width)
            self._rgb[members] = rgb.reshape(count, camera.height, camera.width, 3)
        if panorama is not None:
            distance = hits.distance[count * cast_pixels: escape_offset]
            self._panorama[members] = np.where(np.isfinite(distance), distance, 0.0).astype(
                np.float32).reshape(count, panorama.height, panorama.width)
        if not len(escapers):
            return []
        total = len(order)
        threshold = checker.escape_no_hit_threshold
        misses = no_hit_counts(hits.distance, escape_offset, first, len(escapers))
        # Undecided: the rays not cast yet could still push the no-hit share over the limit.
        undecided = (total - first + misses) / total > threshold
        if not undecided.any():
            return []
        rest = order[first:]
        extra = np.empty((int(undecided.sum()) * len(rest), 6), np.float32)
        fill_panorama_rays(rest, np.ascontiguousarray(positions32[escape][undecided]), extra, 0)
        more = no_hit_counts(env.raycaster.cast_packed(extra).distance, 0, len(rest),
                             int(undecided.sum()))
        self._count_rays(len(extra))
        shares = (misses[undecided] + more) / total
        return [int(a) for a in escapers[undecided][shares > threshold]]

    def _observations(self) -> dict[str, np.ndarray]:
        """The agents' observations: the frame buffers themselves, handed out (every reset
        and step draws into new ones, :meth:`_new_frame_buffers`, so what the caller holds
        never changes)."""
        observations = {
            "rgb": self._rgb,
            "depth": self._depth,
            "pose": self._poses.astype(np.float32),
        }
        if self._panorama is not None:
            observations["panorama"] = self._panorama
        return observations

    def _new_frame_buffers(self, keep: np.ndarray | None = None) -> None:
        """New frame buffers (those of the last observations belong to the caller now), with
        the frames of the agents ``keep`` flags copied over."""
        buffers = [self._rgb, self._depth] + ([self._panorama] if self._panorama is not None
                                              else [])
        fresh = [np.empty_like(buffer) for buffer in buffers]
        if keep is not None:
            for old, new in zip(buffers, fresh, strict=True):
                new[keep] = old[keep]
        self._rgb, self._depth = fresh[0], fresh[1]
        if self._panorama is not None:
            self._panorama = fresh[2]

    # -- infos -----------------------------------------------------------------------------
    def _infos(
        self, agents: np.ndarray, gains: np.ndarray, collided: np.ndarray, reasons: np.ndarray
    ) -> dict[str, Any]:
        """Infos of ``agents`` as ``SyncVectorEnv`` gathers single-env infos (arrays plus
        ``_key`` masks); the other arguments are per-env arrays of length ``num_envs``."""
        n = self.num_envs
        every = len(agents) == n  # a step's infos: every agent's, no masking to do
        mask = np.ones(n, bool) if every else _mask(n, agents)

        def column(values: np.ndarray, dtype: Any) -> np.ndarray:
            if every:
                return np.array(values, dtype)
            array = np.full(n, None, object) if dtype is object else np.zeros(n, dtype)
            array[mask] = np.asarray(values)[mask]
            return array

        infos: dict[str, Any] = {
            "coverage": column(self._seen_counts / self._sample_totals, float),
            "coverage_gain": column(gains, float),
            "collided": column(collided, bool),
            "collision_reason": column(reasons, object),
            "path_length_m": column(self._path_length, float),
            "intrinsics": {},
            "step": column(self._steps, int),
        }
        for key, value in self._intrinsic_columns.items():
            infos["intrinsics"][key] = column(value, value.dtype)
            infos["intrinsics"][f"_{key}"] = mask.copy()
        if self._panorama is not None:
            infos["panorama_no_hit_share"] = column(
                np.mean(self._panorama <= 0.0, axis=(1, 2)), float
            )
        for key in list(infos):
            if not key.startswith("_"):
                infos[f"_{key}"] = mask.copy()
        return infos


# -- helpers -------------------------------------------------------------------------------
def _mask(n: int, agents: np.ndarray) -> np.ndarray:
    mask = np.zeros(n, bool)
    mask[np.asarray(agents, np.int64)] = True
    return mask


def _widened(array: np.ndarray, columns: int) -> np.ndarray:
    """``array`` (a row per agent) with at least ``columns`` columns, the new ones zero: a
    stream's next scene may have more samples or cells than any before."""
    if columns <= array.shape[1]:
        return array
    wider = np.zeros((len(array), columns), array.dtype)
    wider[:, :array.shape[1]] = array
    return wider


def _groups(scenes: list, agents: np.ndarray, selected: np.ndarray) -> list[np.ndarray]:
    """Indices into ``agents`` (where ``selected``), grouped by the agents' scene, groups in
    the order of their first agent."""
    picked = np.flatnonzero(selected)
    if len(picked) == 0:
        return []
    envs = [scenes[agent] for agent in np.asarray(agents)[picked].tolist()]
    first = envs[0]
    if all(env is first for env in envs):  # one scene for all: no dictionary per agent
        return [picked.astype(np.int64)]
    groups: dict[int, list[int]] = {}
    for k, env in zip(picked.tolist(), envs, strict=True):
        groups.setdefault(id(env), []).append(k)
    return [np.array(group, np.int64) for group in groups.values()]


_ESCAPE_PLANS: dict[tuple[int, int, float], tuple[int, np.ndarray]] = {}


def _escape_ray_plan(checker: Any) -> tuple[int, np.ndarray]:
    """How the published escape check's panorama is cast: ``(k, directions)`` with the
    directions reordered so that any prefix spreads over the whole sphere (bit-reversed
    pixel order), and ``k`` the fewest of them whose all hitting proves the no-hit share
    cannot exceed the threshold, even if every remaining ray missed. Only undecided agents
    cast the rest. The shares are computed as the check computes them."""
    camera = checker.escape_panorama
    threshold = float(checker.escape_no_hit_threshold)
    key = (camera.height, camera.width, threshold)
    if key not in _ESCAPE_PLANS:
        total = camera.height * camera.width
        first = next(k for k in range(total + 1) if (total - k) / total <= threshold)
        bits = max(int(np.ceil(np.log2(max(total, 2)))), 1)
        keys = [int(f"{i:0{bits}b}"[::-1], 2) for i in range(total)]
        order = np.argsort(np.array(keys), kind="stable")
        _ESCAPE_PLANS[key] = (first, np.ascontiguousarray(camera.ray_directions[order]))
    return _ESCAPE_PLANS[key]


def agent_info(infos: dict[str, Any], i: int) -> dict[str, Any]:
    """One agent's info dict back out of vector infos."""
    single: dict[str, Any] = {}
    for key, value in infos.items():
        if key.startswith("_") or not infos.get(f"_{key}", np.zeros(i + 1, bool))[i]:
            continue
        if isinstance(value, dict):
            single[key] = agent_info(value, i)
        else:
            item = value[i]
            single[key] = item.item() if isinstance(item, np.generic) else item
    return single


def _overwrite_agents(
    infos: dict[str, Any], update: dict[str, Any], agents: np.ndarray
) -> dict[str, Any]:
    for key, value in update.items():
        if key.startswith("_"):
            continue
        if isinstance(value, dict):
            infos[key] = _overwrite_agents(infos.get(key, {}), value, agents)
        else:
            infos[key][agents] = value[agents]
    return infos


def make_vector_env(num_envs: int = 1, **kwargs: Any) -> NarutoReconVectorEnv:
    """Vector entry point of the registered ids (``gymnasium.make_vec``)."""
    return NarutoReconVectorEnv(num_envs=num_envs, **kwargs)


