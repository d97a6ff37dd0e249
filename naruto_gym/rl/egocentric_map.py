"""An egocentric multi-channel map for learning to explore, built from the episode's own depth
frames and poses only (never the scene's mesh), for the single env and the batched env.

Each agent keeps a world grid for the episode, centred on its start position (``world_m``
metres square, cells of ``cell_m``): obstacles at the agent's height (hits within ``band_m``
of the camera's height), space the panorama's near-horizontal rays crossed at that height
(free), surface the pinhole camera has seen at any height, and the cells it stood in (trail).
The observation resamples that grid around the agent, its heading up the image, at two scales:

* near: ``cells x cells`` cells of ``cell_m`` (3.2 m across by default);
* far: ``cells x cells`` cells of ``cell_m * far_factor`` (12.8 m across by default);

five channels per scale (:data:`MAP_CHANNELS`: occupied, free, seen surface, frontier (free
cells beside unknown ones), trail), channel-first uint8 ``(10, cells, cells)``, near first.
The observation also holds the depth panorama (every second row and column, in [0, 255] of the
sensor range, ``(1, H/2, W/2)``) and the pose relative to the episode's start (position and
the 6D rotation in the start's heading frame, ``(9,)`` float32).

    env = EgocentricMapObservation(gym.make("NarutoRecon-v0", action_mode="discrete"))
    envs = VectorEgocentricMapObservation(NarutoReconVectorEnv(16, action_mode="discrete"))

The panorama carves the free space (``panorama_shape`` must not be None); the pinhole depth
adds the seen surface and near obstacles. :class:`EgocentricMapBuilder` is the same map
without a wrapper, for a policy that builds it from the observations it is handed.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector.utils import batch_space

from naruto_gym.rl.egocentric_map_kernels import (
    FREE,
    LAYERS,
    MAP_CHANNELS,
    OCCUPIED,
    crop_all,
    update_grids,
)
from naruto_gym.sensors.panorama import EquirectangularCamera
from naruto_gym.utils.threads import resolve_threads, run_parallel

__all__ = [
    "LAYERS",
    "MAP_CHANNELS",
    "EgocentricMapBuilder",
    "EgocentricMapObservation",
    "VectorEgocentricMapObservation",
    "relative_pose_vector",
]


def relative_pose_vector(start: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """(9,) float32: ``pose`` (4x4) in the frame of ``start``'s position and heading (yaw
    only, z stays up): position, then the first two columns of the rotation."""
    heading = np.arctan2(start[1, 2], start[0, 2])
    cos, sin = np.cos(heading), np.sin(heading)
    to_start = np.array([[cos, sin, 0.0], [-sin, cos, 0.0], [0.0, 0.0, 1.0]])
    position = to_start @ (pose[:3, 3] - start[:3, 3])
    rotation = to_start @ pose[:3, :3]
    return np.concatenate([position, rotation[:, 0], rotation[:, 1]]).astype(np.float32)


class EgocentricMapBuilder:
    """The egocentric map of ``num_envs`` agents, updated from their raw observations.

    Args:
        num_envs: agents.
        camera: the pinhole camera of the ``depth`` observations (``fx, fy, cx, cy``).
        panorama_shape: (H, W) of the env's panorama.
        max_depth_m: the sensor range (scales the panorama observation).
        cells: side of each crop, in cells.
        cell_m: near cell side, metres.
        far_factor: far cell side in near cells.
        world_m: side of the world grid around the start (the agent's map ends there).
        band_m: height band around the camera in which hits are obstacles.
        horizon_deg: panorama rows within this elevation of the horizon carve free space.
        depth_stride: every n-th pixel of the depth frame is projected.
        panorama_stride: every n-th panorama column is read at a step (in turn, so
            successive steps read them all).
        threads: threads a batch's agents are split between (None: every CPU this process may
            use, see :func:`~naruto_gym.utils.threads.default_thread_count`).

    Raises:
        ValueError: a size or distance that is not positive, or no panorama.
    """

    def __init__(
        self,
        num_envs: int,
        camera: Any,
        panorama_shape: tuple[int, int] | None,
        max_depth_m: float = 10.0,
        cells: int = 32,
        cell_m: float = 0.1,
        far_factor: int = 4,
        world_m: float = 40.0,
        band_m: float = 0.3,
        horizon_deg: float = 30.0,
        depth_stride: int = 2,
        panorama_stride: int = 4,
        threads: int | None = None,
    ) -> None:
        if panorama_shape is None:
            raise ValueError(
                "the egocentric map carves free space with the depth panorama: make the env "
                "with panorama_shape=(H, W) (e.g. the default (64, 128)), not None"
            )
        for name, value in (
            ("num_envs", num_envs),
            ("cells", cells),
            ("cell_m", cell_m),
            ("far_factor", far_factor),
            ("world_m", world_m),
            ("band_m", band_m),
            ("depth_stride", depth_stride),
            ("panorama_stride", panorama_stride),
        ):
            if not value > 0:
                raise ValueError(f"{name} must be positive, got {value}")
        self.num_envs = int(num_envs)
        self.cells = int(cells)
        self.cell_m = float(cell_m)
        self.far_factor = int(far_factor)
        self.band_m = float(band_m)
        self.max_depth_m = float(max_depth_m)
        self.depth_stride = int(depth_stride)
        self.panorama_stride = int(panorama_stride)
        self.threads = resolve_threads(threads)
        side = int(np.ceil(world_m / cell_m / far_factor)) * far_factor
        self.grids = np.zeros((self.num_envs, len(LAYERS), side, side), np.uint8)
        self.coarse = np.zeros(
            (self.num_envs, len(LAYERS), side // far_factor, side // far_factor), np.uint8
        )
        self.origins = np.zeros((self.num_envs, 2))
        self.start_poses = np.tile(np.eye(4), (self.num_envs, 1, 1))
        self.poses = np.tile(np.eye(4), (self.num_envs, 1, 1))
        self.steps = np.zeros(self.num_envs, np.int64)
        #: Free space straight above and below each agent at its last observation (the
        #: nearest hit of the panorama's top and bottom rows; 0 where a ray there hit
        #: nothing, as nothing is known of it).
        self.clearance_up = np.zeros(self.num_envs)
        self.clearance_down = np.zeros(self.num_envs)
        #: Whether no ray of the panorama's top row hit anything at the last observation:
        #: nothing above within range, as over an open scan (no ceiling), or a top row that
        #: was not cast (``panorama_horizon_deg``).
        self.open_above = np.zeros(self.num_envs, bool)
        #: Height the obstacle and free layers of each agent's grid were built at, and how
        #: many times they restarted this episode (see :meth:`update`).
        self.slice_heights = np.zeros(self.num_envs)
        self.slice_restarts = np.zeros(self.num_envs, np.int64)
        self._started = np.zeros(self.num_envs, bool)
        self._intrinsics = np.array([camera.fx, camera.fy, camera.cx, camera.cy], np.float64)
        panorama = EquirectangularCamera(*panorama_shape)
        self.panorama_shape = (panorama.height, panorama.width)
        self._panorama_directions = panorama.ray_directions.astype(np.float64)
        elevation = np.pi / 2 - np.pi * (np.arange(panorama.height) + 0.5) / panorama.height
        near = np.flatnonzero(np.abs(elevation) <= np.deg2rad(horizon_deg))
        self._rows = (int(near.min()), int(near.max()) + 1)

    # -- spaces ------------------------------------------------------------------------------
    @property
    def observation_space(self) -> spaces.Dict:
        """One agent's observation: ``map``, ``panorama`` and ``pose`` (module docstring)."""
        height, width = self.panorama_shape
        return spaces.Dict(
            {
                "map": spaces.Box(
                    0, 255, (2 * len(MAP_CHANNELS), self.cells, self.cells), np.uint8
                ),
                "panorama": spaces.Box(0, 255, (1, (height + 1) // 2, (width + 1) // 2), np.uint8),
                "pose": spaces.Box(-np.inf, np.inf, (9,), np.float32),
            }
        )

    @property
    def far_cell_m(self) -> float:
        """Side of a far-scale cell, metres."""
        return self.cell_m * self.far_factor

    # -- episodes ----------------------------------------------------------------------------
    def reset(self, envs: np.ndarray, poses: np.ndarray) -> None:
        """New episodes for ``envs`` starting at ``poses`` (n, 4, 4): their maps start empty,
        centred on the start."""
        envs = np.asarray(envs, np.int64)
        side_m = self.grids.shape[-1] * self.cell_m
        for row, i in enumerate(envs):
            self.grids[i] = 0
            self.coarse[i] = 0
            pose = np.asarray(poses[row], np.float64)
            self.origins[i] = pose[:2, 3] - side_m / 2
            self.start_poses[i] = pose
            self.steps[i] = 0
            self.slice_heights[i] = pose[2, 3]
            self.slice_restarts[i] = 0
            self._started[i] = True

    def update(self, observations: dict[str, np.ndarray], envs: np.ndarray | None = None) -> None:
        """Add a batch of raw observations (``depth``, ``pose``, ``panorama`` with a leading
        axis over ``envs``, default all) to the agents' maps.

        The obstacle and free layers are one slice at the agent's height: when the camera is
        more than half the band above or below the height they were built at, they restart
        empty at the new height (the seen surface and the trail are kept), so that an agent
        that climbs or sinks (e.g. below a doorway's lintel) does not keep the obstacles of
        another height.

        Raises:
            RuntimeError: an agent has no episode started (call :meth:`reset` first).
            KeyError: an observation key is missing.
        """
        envs = np.arange(self.num_envs) if envs is None else np.asarray(envs, np.int64)
        if not self._started[envs].all():
            raise RuntimeError(
                "the egocentric map got an observation before its episode's "
                "reset: call reset(envs, poses) at every episode start"
            )
        poses = np.ascontiguousarray(observations["pose"], np.float64)
        panorama = observations["panorama"]
        moved = np.abs(poses[:, 2, 3] - self.slice_heights[envs]) > 0.5 * self.band_m
        for row in np.flatnonzero(moved):
            i = envs[row]
            self.grids[i, [OCCUPIED, FREE]] = 0
            self.coarse[i, [OCCUPIED, FREE]] = 0
            self.slice_heights[i] = poses[row, 2, 3]
            self.slice_restarts[i] += 1
        depth = observations.get("depth")
        depths = (
            np.zeros((len(envs), 0, 0), np.float32)
            if depth is None
            else np.ascontiguousarray(depth, np.float32)
        )
        panoramas = np.ascontiguousarray(panorama, np.float32)
        phases = self.steps[envs]  # a copy (indexed by an array)
        # Agents in contiguous parts, one compiled call per part, the parts in threads.
        parts = max(1, min(self.threads, len(envs)))
        bounds = np.linspace(0, len(envs), parts + 1).astype(np.int64)

        def update_part(part: int) -> None:
            update_grids(
                self.grids,
                self.coarse,
                self.far_factor,
                self.origins,
                self.cell_m,
                poses,
                depths,
                self._intrinsics,
                self.depth_stride,
                panoramas,
                self._panorama_directions,
                self._rows[0],
                self._rows[1],
                self.panorama_stride,
                self.band_m,
                phases,
                envs,
                int(bounds[part]),
                int(bounds[part + 1]),
            )

        run_parallel(update_part, parts)
        self.poses[envs] = poses
        self.steps[envs] += 1
        top, bottom = panorama[:, 0], panorama[:, -1]
        self.clearance_up[envs] = np.where((top > 0).all(axis=1), top.min(axis=1), 0.0)
        self.open_above[envs] = (top <= 0).all(axis=1)
        self.clearance_down[envs] = np.where((bottom > 0).all(axis=1), bottom.min(axis=1), 0.0)

    def cell_of(self, env: int, xy: Any) -> tuple[int, int]:
        """The fine cell of agent ``env``'s world grid that holds world ``xy`` (x, y)."""
        i, j = np.floor((np.asarray(xy, np.float64)[:2] - self.origins[env]) / self.cell_m)
        return int(i), int(j)

    def mark_blocked(self, env: int, x: float, y: float) -> None:
        """Mark the cell at world ``(x, y)`` an obstacle for agent ``env``: the env refused a
        move into it (e.g. out of an open scan's scanned space, where no surface shows). The
        cell the agent stands in is never marked (a short move may end in it): an obstacle
        there would leave the agent no traversable cell to start a path from."""
        i, j = self.cell_of(env, (x, y))
        if (i, j) == self.cell_of(env, self.poses[env][:2, 3]):
            return
        if 0 <= i < self.grids.shape[-2] and 0 <= j < self.grids.shape[-1]:
            self.grids[env, OCCUPIED, i, j] = 255
            self.grids[env, FREE, i, j] = 0
            self.coarse[env, OCCUPIED, i // self.far_factor, j // self.far_factor] = 255

    def observe(
        self, observations: dict[str, np.ndarray], envs: np.ndarray | None = None
    ) -> dict[str, np.ndarray]:
        """The learning observations of ``envs`` (default all) for raw observations already
        passed to :meth:`update`: ``map``, ``panorama`` and ``pose`` (module docstring)."""
        envs = np.arange(self.num_envs) if envs is None else np.asarray(envs, np.int64)
        poses = np.asarray(observations["pose"], np.float64)
        maps = np.empty((len(envs), 2 * len(MAP_CHANNELS), self.cells, self.cells), np.uint8)
        crop_all(
            self.grids,
            self.coarse,
            self.origins,
            self.cell_m,
            self.far_factor,
            np.ascontiguousarray(poses),
            envs,
            maps,
        )
        panorama = np.asarray(observations["panorama"])[:, None, ::2, ::2]
        scaled = np.clip(panorama * (255.0 / self.max_depth_m), 0.0, 255.0)
        pose = np.stack(
            [relative_pose_vector(self.start_poses[i], poses[row]) for row, i in enumerate(envs)]
        )
        return {"map": maps, "panorama": scaled.astype(np.uint8), "pose": pose}


def _builder_for(env: Any, num_envs: int, options: dict[str, Any]) -> EgocentricMapBuilder:
    base = env.unwrapped
    settings = getattr(base, "settings", None)
    if getattr(base, "camera", None) is None or settings is None:
        raise ValueError(
            f"the egocentric map needs a NarutoReconEnv or NarutoReconVectorEnv (its camera and "
            f"settings), got {type(base).__name__}"
        )
    return EgocentricMapBuilder(
        num_envs, base.camera, settings.panorama_shape, max_depth_m=settings.max_depth_m, **options
    )


class EgocentricMapObservation(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """A ``NarutoReconEnv``'s observation as the egocentric map, the depth panorama and the
    relative pose (module docstring).

    Args:
        env: the env (any action mode; the panorama on).
        **options: :class:`EgocentricMapBuilder` keywords (``cells``, ``cell_m``, ...).

    Attributes:
        map_builder: the map (read by :class:`~naruto_gym.rl.goal_actions.GoalActions`).
    """

    def __init__(self, env: gym.Env, **options: Any) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, **options)
        gym.ObservationWrapper.__init__(self, env)
        self.map_builder = _builder_for(env, 1, options)
        self.observation_space = self.map_builder.observation_space

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        observation, info = self.env.reset(seed=seed, options=options)
        self.map_builder.reset(np.zeros(1, np.int64), np.asarray(observation["pose"])[None])
        return self.observation(observation), info

    def observation(self, observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        batch = {key: np.asarray(value)[None] for key, value in observation.items()}
        self.map_builder.update(batch)
        return {key: value[0] for key, value in self.map_builder.observe(batch).items()}


class VectorEgocentricMapObservation(gym.vector.VectorWrapper):
    """The batched env's observations as the egocentric map, the depth panorama and the
    relative pose (module docstring), for both autoreset modes.

    With ``SAME_STEP`` autoreset the finished episodes' ``info["final_obs"]`` are mapped too
    (on their episode's map) before the new episodes' maps start.

    Args:
        env: a ``NarutoReconVectorEnv`` (possibly wrapped), the panorama on.
        **options: :class:`EgocentricMapBuilder` keywords.

    Attributes:
        map_builder: the map of every agent.
    """

    def __init__(self, env: gym.vector.VectorEnv, **options: Any) -> None:
        super().__init__(env)
        self.map_builder = _builder_for(env, env.num_envs, options)
        self.single_observation_space = self.map_builder.observation_space
        self.observation_space = batch_space(self.single_observation_space, env.num_envs)

    def reset(self, *, seed: Any = None, options: dict[str, Any] | None = None):
        observations, infos = self.env.reset(seed=seed, options=options)
        mask = (options or {}).get("reset_mask")
        envs = np.arange(self.num_envs) if mask is None else np.flatnonzero(mask)
        self.map_builder.reset(envs, np.asarray(observations["pose"])[envs])
        return self._observe(observations), infos

    def step(self, actions: Any):
        observations, rewards, terminations, truncations, infos = self.advance(actions)
        return self.map_builder.observe(observations), rewards, terminations, truncations, infos

    def advance(self, actions: Any):
        """:meth:`step` without the learning observation: the env steps and every agent's
        map takes the new frame, and the env's own observations come back. For a caller that
        takes several steps per decision and reads the observation after the last one only
        (:class:`~naruto_gym.rl.goal_actions.VectorGoalActions`): cropping the maps is most of
        a step's map work."""
        observations, rewards, terminations, truncations, infos = self.env.step(actions)
        starts = np.flatnonzero(np.asarray(infos["_step"]) & (np.asarray(infos["step"]) == 0))
        if "final_obs" in infos and len(starts):
            infos = dict(infos)
            final = np.array(infos["final_obs"], dtype=object)
            for i in np.flatnonzero(infos["_final_obs"]):
                batch = {key: np.asarray(value)[None] for key, value in final[i].items()}
                self.map_builder.update(batch, np.array([i]))
                mapped = self.map_builder.observe(batch, np.array([i]))
                final[i] = {key: value[0] for key, value in mapped.items()}
            infos["final_obs"] = final
        if len(starts):
            self.map_builder.reset(starts, np.asarray(observations["pose"])[starts])
        self.map_builder.update(observations)
        return observations, rewards, terminations, truncations, infos

    def _observe(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        self.map_builder.update(observations)
        return self.map_builder.observe(observations)
