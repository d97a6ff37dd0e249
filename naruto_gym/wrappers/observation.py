"""Observation transforms for learning, on batches: pure functions of arrays (plus the
per-episode top-down map), shared by the single-env and the vector-env wrappers.

Every transform maps a ``Dict`` observation space to a new one (:meth:`space`) and a batch of
observations (arrays with a leading env axis) to a batch of new ones (:meth:`apply`). Keys it
does not touch pass through unchanged.
"""

from __future__ import annotations

from typing import Any, Literal

import numba
import numpy as np
from gymnasium import spaces

from naruto_gym.geometry.egocentric import crop_cell, heading_axes

__all__ = [
    "MAP_OCCUPIED",
    "MAP_SEEN",
    "DepthFormat",
    "DepthTransform",
    "DropKeys",
    "LearningObservation",
    "MapTransform",
    "ObservationTransform",
    "PoseTransform",
    "ResizeTransform",
    "pose_to_vector",
]

DepthFormat = Literal["uint8", "float"]


class ObservationTransform:
    """Base class: a stateless map of the observation (see the module docstring)."""

    def space(self, space: spaces.Dict) -> spaces.Dict:
        raise NotImplementedError

    def apply(
        self, batch: dict[str, np.ndarray], envs: np.ndarray | None = None
    ) -> dict[str, np.ndarray]:
        raise NotImplementedError

    def bind(self, camera: Any, num_envs: int) -> None:
        """The env's camera and number of envs (stateless transforms ignore them)."""

    def reset_envs(self, bounds: list[np.ndarray], envs: np.ndarray) -> None:
        """New episodes in ``envs`` with their scene bounds (stateless transforms ignore it)."""


def _require(space: spaces.Dict, key: str, what: str) -> spaces.Box:
    if not isinstance(space, spaces.Dict) or key not in space.spaces:
        raise ValueError(
            f"{what} needs a Dict observation with {key!r}; got {space}. Put it closer to the "
            "env in the wrapper chain"
        )
    return space.spaces[key]


def _replace(space: spaces.Dict, **new: spaces.Space) -> spaces.Dict:
    return spaces.Dict({**space.spaces, **new})


class ResizeTransform(ObservationTransform):
    """``rgb`` and ``depth`` resized to ``size x size`` (nearest pixel, so depth edges never
    blend a wall with what lies behind it). Non-square frames are stretched.

    Args:
        size: output side in pixels (64 or 128 are typical).
    """

    def __init__(self, size: int = 64) -> None:
        if size < 1:
            raise ValueError(f"size must be a positive number of pixels, got {size}")
        self.size = int(size)
        self._rows: np.ndarray | None = None
        self._columns: np.ndarray | None = None

    def space(self, space: spaces.Dict) -> spaces.Dict:
        rgb = _require(space, "rgb", "ResizeFrames")
        height, width = rgb.shape[:2]
        # Pixel centres of the output, mapped back to the input.
        self._rows = np.minimum(
            ((np.arange(self.size) + 0.5) * height / self.size).astype(int), height - 1
        )
        self._columns = np.minimum(
            ((np.arange(self.size) + 0.5) * width / self.size).astype(int), width - 1
        )
        new: dict[str, spaces.Space] = {
            "rgb": spaces.Box(0, 255, (self.size, self.size, 3), np.uint8)
        }
        if "depth" in space.spaces:
            depth = space.spaces["depth"]
            shape = (self.size, self.size, *depth.shape[2:])
            new["depth"] = spaces.Box(
                float(depth.low.min()), float(depth.high.max()), shape, depth.dtype
            )
        return _replace(space, **new)

    def apply(
        self, batch: dict[str, np.ndarray], envs: np.ndarray | None = None
    ) -> dict[str, np.ndarray]:
        out = dict(batch)
        index = np.ix_(self._rows, self._columns)
        for key in ("rgb", "depth"):
            if key in batch:
                out[key] = np.ascontiguousarray(batch[key][(slice(None), *index)])
        return out


class DepthTransform(ObservationTransform):
    """``depth`` in metres -> ``(H, W, 1)`` in [0, 1] of ``max_depth_m``, as uint8 (0..255,
    an image Stable-Baselines3 normalises and transposes itself) or float32. 0 stays "no hit".

    Args:
        max_depth_m: the depth mapped to 1 (the env's sensor range if None).
        dtype: ``"uint8"`` (default) or ``"float"``.
    """

    def __init__(self, max_depth_m: float | None = None, dtype: DepthFormat = "uint8") -> None:
        if dtype not in ("uint8", "float"):
            raise ValueError(f"dtype must be 'uint8' or 'float', got {dtype!r}")
        if max_depth_m is not None and max_depth_m <= 0:
            raise ValueError(f"max_depth_m must be positive, got {max_depth_m}")
        self.max_depth_m = max_depth_m
        self.dtype = dtype

    def space(self, space: spaces.Dict) -> spaces.Dict:
        depth = _require(space, "depth", "NormalizeDepth")
        if self.max_depth_m is None:
            self.max_depth_m = float(depth.high.max())
            if not np.isfinite(self.max_depth_m):
                raise ValueError("NormalizeDepth needs max_depth_m for an unbounded depth space")
        shape = (*depth.shape[:2], 1)
        if self.dtype == "uint8":
            return _replace(space, depth=spaces.Box(0, 255, shape, np.uint8))
        return _replace(space, depth=spaces.Box(0.0, 1.0, shape, np.float32))

    def apply(
        self, batch: dict[str, np.ndarray], envs: np.ndarray | None = None
    ) -> dict[str, np.ndarray]:
        out = dict(batch)
        scaled = np.clip(
            batch["depth"].reshape(*batch["depth"].shape[:3], 1) / self.max_depth_m, 0.0, 1.0
        )
        if self.dtype == "uint8":
            out["depth"] = np.rint(scaled * 255.0).astype(np.uint8)
        else:
            out["depth"] = scaled.astype(np.float32)
        return out


def pose_to_vector(pose: np.ndarray) -> np.ndarray:
    """(..., 4, 4) camera-to-world -> (..., 9) float32: position, then the first two columns
    of the rotation (the continuous 6D rotation representation of Zhou et al., CVPR 2019)."""
    pose = np.asarray(pose)
    rotation = pose[..., :3, :3]
    return np.concatenate(
        [pose[..., :3, 3], rotation[..., :, 0], rotation[..., :, 1]], axis=-1
    ).astype(np.float32)


class PoseTransform(ObservationTransform):
    """``pose`` 4x4 -> ``(9,)`` float32: position + 6D rotation (see :func:`pose_to_vector`)."""

    def space(self, space: spaces.Dict) -> spaces.Dict:
        _require(space, "pose", "FlatPose")
        return _replace(space, pose=spaces.Box(-np.inf, np.inf, (9,), np.float32))

    def apply(
        self, batch: dict[str, np.ndarray], envs: np.ndarray | None = None
    ) -> dict[str, np.ndarray]:
        return {**batch, "pose": pose_to_vector(batch["pose"])}


# Channels of the egocentric map.
MAP_SEEN, MAP_OCCUPIED = 0, 1


@numba.njit(cache=True, nogil=True)
def _accumulate_map(
    grid: np.ndarray,
    origin_x: float,
    origin_y: float,
    cell_m: float,
    depth: np.ndarray,
    pose: np.ndarray,
    intrinsics: np.ndarray,
    stride: int,
    floor: np.ndarray,
    obstacle_m: float,
) -> None:
    """Mark the cells under every (strided) depth pixel's hit as seen, and as occupied when
    the hit stands ``obstacle_m`` above the lowest hit so far (the floor estimate)."""
    height, width = depth.shape
    fx, fy, cx, cy = intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]
    points = np.empty((((height + stride - 1) // stride) * ((width + stride - 1) // stride), 3))
    count = 0
    for v in range(0, height, stride):
        for u in range(0, width, stride):
            d = depth[v, u]
            if d <= 0:
                continue
            x = (u - cx) / fx * d
            y = (v - cy) / fy * d
            for axis in range(3):
                points[count, axis] = (
                    pose[axis, 0] * x + pose[axis, 1] * y + pose[axis, 2] * d + pose[axis, 3]
                )
            floor[0] = min(floor[0], points[count, 2])
            count += 1
    rows, columns = grid.shape[1], grid.shape[2]
    for k in range(count):
        i = int(np.floor((points[k, 0] - origin_x) / cell_m))
        j = int(np.floor((points[k, 1] - origin_y) / cell_m))
        if i < 0 or j < 0 or i >= rows or j >= columns:
            continue
        grid[MAP_SEEN, i, j] = 255
        if points[k, 2] > floor[0] + obstacle_m:
            grid[MAP_OCCUPIED, i, j] = 255


@numba.njit(cache=True, nogil=True)
def _egocentric_crop(
    grid: np.ndarray,
    origin_x: float,
    origin_y: float,
    cell_m: float,
    pose: np.ndarray,
    out: np.ndarray,
) -> None:
    """Resample the world grid around the agent: row 0 ahead of it, the agent at the centre,
    its heading (optical axis in the horizontal plane) pointing up the image."""
    cells = out.shape[0]
    axes = heading_axes(pose)
    rows, columns = grid.shape[1], grid.shape[2]
    for r in range(cells):
        for c in range(cells):
            i, j = crop_cell(pose, axes, origin_x, origin_y, cell_m, cells, r, c)
            if i < 0 or j < 0 or i >= rows or j >= columns:
                out[r, c, 0] = 0
                out[r, c, 1] = 0
            else:
                out[r, c, 0] = grid[MAP_SEEN, i, j]
                out[r, c, 1] = grid[MAP_OCCUPIED, i, j]


class MapTransform(ObservationTransform):
    """Adds ``"map"``: an egocentric top-down map ``(cells, cells, 2)`` uint8 of what this
    episode's frames have seen (channel 0) and of what is occupied (channel 1: hits standing
    more than ``obstacle_m`` above the lowest hit seen, the floor estimate), the agent at the
    centre looking up the image. It is built from the observations alone (depth, pose and the
    camera intrinsics), as exploration policies in the literature learn from.

    Must see the env's raw ``depth`` (metres) and ``pose``: it comes before the resize, depth
    and pose transforms in a chain.

    Args:
        cells: map side in cells.
        cell_m: cell side in metres.
        stride: every ``stride``-th pixel of the depth frame is projected.
        obstacle_m: height above the floor estimate from which a hit is an obstacle.
    """

    def __init__(
        self, cells: int = 32, cell_m: float = 0.15, stride: int = 2, obstacle_m: float = 0.15
    ) -> None:
        if cells < 2 or cell_m <= 0 or stride < 1:
            raise ValueError(
                f"need cells >= 2, cell_m > 0 and stride >= 1, got {cells}, {cell_m}, {stride}"
            )
        self.cells = int(cells)
        self.cell_m = float(cell_m)
        self.stride = int(stride)
        self.obstacle_m = float(obstacle_m)
        self._grids: list[np.ndarray | None] = []
        self._origins: list[tuple[float, float]] = []
        self._floors: list[np.ndarray] = []
        self._intrinsics = np.zeros(4)

    def space(self, space: spaces.Dict) -> spaces.Dict:
        _require(space, "depth", "EgocentricMap")
        _require(space, "pose", "EgocentricMap")
        return _replace(space, map=spaces.Box(0, 255, (self.cells, self.cells, 2), np.uint8))

    def bind(self, camera: Any, num_envs: int) -> None:
        """The camera intrinsics and number of envs (called by the wrappers)."""
        self._intrinsics = np.array([camera.fx, camera.fy, camera.cx, camera.cy], np.float64)
        self._grids = [None] * num_envs
        self._origins = [(0.0, 0.0)] * num_envs
        self._floors = [np.full(1, np.inf) for _ in range(num_envs)]

    def reset_envs(self, bounds: list[np.ndarray], envs: np.ndarray) -> None:
        """New episodes in ``envs``, with the scene bounds of each (sizes the world grid)."""
        for i in envs:
            low, high = np.asarray(bounds[i])[:, :2]
            shape = np.ceil((high - low) / self.cell_m).astype(int) + 1
            self._grids[i] = np.zeros((2, *shape), np.uint8)
            self._origins[i] = (float(low[0]), float(low[1]))
            self._floors[i][0] = np.inf

    def apply(
        self, batch: dict[str, np.ndarray], envs: np.ndarray | None = None
    ) -> dict[str, np.ndarray]:
        count = len(batch["depth"])
        envs = np.arange(count) if envs is None else envs
        maps = np.zeros((count, self.cells, self.cells, 2), np.uint8)
        for row, i in enumerate(envs):
            grid = self._grids[i]
            if grid is None:
                raise RuntimeError("the map wrapper saw a step before its env's reset")
            pose = np.ascontiguousarray(batch["pose"][row], np.float64)
            ox, oy = self._origins[i]
            _accumulate_map(
                grid,
                ox,
                oy,
                self.cell_m,
                np.ascontiguousarray(batch["depth"][row], np.float32),
                pose,
                self._intrinsics,
                self.stride,
                self._floors[i],
                self.obstacle_m,
            )
            _egocentric_crop(grid, ox, oy, self.cell_m, pose, maps[row])
        return {**batch, "map": maps}


class DropKeys(ObservationTransform):
    """Removes observation keys (absent keys are ignored)."""

    def __init__(self, keys: tuple[str, ...]) -> None:
        self.keys = tuple(keys)

    def space(self, space: spaces.Dict) -> spaces.Dict:
        return spaces.Dict({k: v for k, v in space.spaces.items() if k not in self.keys})

    def apply(
        self, batch: dict[str, np.ndarray], envs: np.ndarray | None = None
    ) -> dict[str, np.ndarray]:
        return {key: value for key, value in batch.items() if key not in self.keys}


class LearningObservation:
    """Callable mapping one raw env observation to the learning observation of
    :func:`~naruto_gym.wrappers.learning.for_learning` (optional egocentric map, resize, depth, flat
    pose, panorama dropped): what a model trained on that chain is given at evaluation, e.g.
    as ``SB3Policy(model, observation_transform=LearningObservation(64))``.

    With ``top_down_map`` the map accumulates over an episode: call :meth:`start_episode`
    with the camera and the scene bounds at every reset (``PPOExplorer`` does).

    Args:
        size: square frame side.
        depth: ``"uint8"`` or ``"float"``.
        max_depth_m: sensor range the depth was normalised by.
        top_down_map: add the egocentric top-down map (:class:`MapTransform`'s defaults).
    """

    def __init__(
        self,
        size: int = 64,
        depth: DepthFormat = "uint8",
        max_depth_m: float = 10.0,
        top_down_map: bool = False,
    ) -> None:
        self.size = size
        self.depth = depth
        self.max_depth_m = max_depth_m
        self.map = MapTransform() if top_down_map else None
        self._episode_started = False
        self._transforms: list[ObservationTransform] | None = None

    def start_episode(self, camera: Any, bounds: np.ndarray) -> None:
        """A new episode in a scene with these (2, 3) bounds, seen by ``camera``: the map
        starts empty."""
        if self.map is not None:
            self.map.bind(camera, 1)
            self.map.reset_envs([np.asarray(bounds)], np.array([0]))
        self._episode_started = True

    def __call__(self, observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        if self.map is not None and not self._episode_started:
            raise RuntimeError("call start_episode() at every reset when top_down_map is on")
        if self._transforms is None:
            space = spaces.Dict({key: _box_like(value) for key, value in observation.items()})
            space = spaces.Dict(
                {
                    **space.spaces,
                    "depth": spaces.Box(
                        0.0, self.max_depth_m, np.shape(observation["depth"]), np.float32
                    ),
                }
            )
            transforms: list[ObservationTransform] = [] if self.map is None else [self.map]
            self._transforms = transforms + [
                ResizeTransform(self.size),
                DepthTransform(self.max_depth_m, self.depth),
                PoseTransform(),
                DropKeys(("panorama",)),
            ]
            for transform in self._transforms:
                space = transform.space(space)
        batch = {key: np.asarray(value)[None] for key, value in observation.items()}
        for transform in self._transforms:
            batch = transform.apply(batch)
        return {key: value[0] for key, value in batch.items()}


def _box_like(value: np.ndarray) -> spaces.Box:
    """An unbounded box (0..255 for uint8) of ``value``'s shape and dtype."""
    value = np.asarray(value)
    if value.dtype == np.uint8:
        return spaces.Box(0, 255, value.shape, np.uint8)
    return spaces.Box(-np.inf, np.inf, value.shape, value.dtype)
