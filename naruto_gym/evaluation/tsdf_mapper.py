"""Reference mapper: TSDF fusion of posed RGB-D frames (Open3D ``VoxelBlockGrid``).

It gives every policy a reconstruction, including policies with no map of their own, so that
all of them are scored the same way. The grid is sparse (16^3-voxel blocks allocated where
depth lands, growing as needed), colour is fused with the same weights as the SDF, and the
mesh is the marching-cubes zero level set.

Conventions: depth is z-depth in metres (0 = invalid), poses are camera-to-world with OpenCV
axes; Open3D wants the *world-to-camera* extrinsic, which :meth:`TsdfFusionMapper.integrate`
computes. The truncation distance is ``truncation_m``; Open3D stores it as a multiple of the
voxel size, so ``truncation_m / voxel_size_m`` need not be an integer.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import trimesh

if TYPE_CHECKING:
    import open3d as o3d
    import open3d.core as o3c

from naruto_gym.evaluation.tsdf_kernels import behind_surface_bounds
from naruto_gym.sensors.pinhole import PinholeCamera


def open3d_module():
    """Open3D, imported at first use: its import takes a second or more (most of it its plotly
    viewer's dependencies), and an env that never fuses a reconstruction should not pay it."""
    import open3d
    import open3d.core  # noqa: F401 (the ``open3d.core`` attribute below)

    return open3d


class PreparedFrame(NamedTuple):
    """A checked frame in the form Open3D fuses: float colour in [0, 1], depth with invalid
    pixels at 0, the camera-to-world pose and the 3x3 intrinsic matrix."""

    colour: np.ndarray
    depth: np.ndarray
    camera_to_world: np.ndarray
    intrinsic: np.ndarray


def resolve_open3d_device(device: str = "auto") -> o3c.Device:
    """Open3D device for a setting: ``"auto"`` (CUDA:0 when Open3D has CUDA and a GPU is
    present, else CPU:0), ``"cpu"``, ``"cuda"`` or an explicit ``"CUDA:1"``/``"CPU:0"``."""
    o3c = open3d_module().core
    name = device.strip().lower()
    if name == "auto":
        return o3c.Device("CUDA:0") if o3c.cuda.is_available() else o3c.Device("CPU:0")
    if name == "cpu":
        return o3c.Device("CPU:0")
    if name == "cuda":
        name = "cuda:0"
    if name.startswith("cuda") and not o3c.cuda.is_available():
        raise ValueError(
            f"device {device!r} asked for CUDA but this Open3D build has no CUDA or no GPU is "
            "visible; use device='auto' or 'cpu'"
        )
    try:
        return o3c.Device(name.upper())
    except Exception as error:  # Open3D raises RuntimeError with an unhelpful message
        raise ValueError(f"unknown device {device!r}; use 'auto', 'cpu' or 'cuda:N'") from error


class TsdfFusionMapper:
    """Truncated-SDF fusion of posed RGB-D frames into a sparse voxel grid.

    Args:
        voxel_size_m: voxel edge length (2 cm by default).
        truncation_m: truncation distance of the SDF (8 cm by default).
        max_depth_m: depth beyond this is ignored when fusing (5 m, as the published system).
        device: ``"auto"``, ``"cpu"`` or ``"cuda[:N]"`` (see :func:`resolve_open3d_device`).
        min_weight: a voxel takes part in meshing / SDF queries once its accumulated weight
            reaches this (1 = seen by one frame).
        block_resolution: voxels per block edge.
        initial_block_count: initial hash-map capacity in blocks; it grows on demand.

    Example:
        >>> mapper = TsdfFusionMapper(voxel_size_m=0.02, truncation_m=0.08)
        >>> mapper.integrate(rgb, depth, camera_to_world, camera)  # doctest: +SKIP
        >>> mesh = mapper.extract_mesh()  # doctest: +SKIP
    """

    def __init__(
        self,
        voxel_size_m: float = 0.02,
        truncation_m: float = 0.08,
        max_depth_m: float = 5.0,
        device: str = "auto",
        min_weight: float = 1.0,
        block_resolution: int = 16,
        initial_block_count: int = 1000,
    ) -> None:
        if not voxel_size_m > 0.0:
            raise ValueError(f"voxel_size_m must be positive, got {voxel_size_m}")
        if not truncation_m >= voxel_size_m:
            raise ValueError(
                f"truncation_m ({truncation_m}) must be at least one voxel ({voxel_size_m}); "
                "a typical choice is 3-5 voxels"
            )
        if not max_depth_m > 0.0:
            raise ValueError(f"max_depth_m must be positive, got {max_depth_m}")
        if min_weight <= 0.0:
            raise ValueError(f"min_weight must be positive, got {min_weight}")
        self.voxel_size_m = float(voxel_size_m)
        self.truncation_m = float(truncation_m)
        self.max_depth_m = float(max_depth_m)
        self.min_weight = float(min_weight)
        self.block_resolution = int(block_resolution)
        self.initial_block_count = int(initial_block_count)
        self.device = resolve_open3d_device(device)
        self.num_frames = 0
        self._grid: o3d.t.geometry.VoxelBlockGrid | None = None
        self._sdf_index: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        self._touched_blocks: list[np.ndarray] = []
        self.reset()

    @property
    def _trunc_multiplier(self) -> float:
        return self.truncation_m / self.voxel_size_m

    @property
    def _open3d_weight_threshold(self) -> float:
        # Open3D keeps voxels with weight strictly above the threshold; every frame adds a
        # weight of 1, so this makes "seen by at least min_weight frames" inclusive.
        return self.min_weight - 1e-3

    def reset(self) -> None:
        """Forget everything fused so far."""
        o3d = open3d_module()
        o3c = o3d.core
        self._grid = o3d.t.geometry.VoxelBlockGrid(
            attr_names=("tsdf", "weight", "color"),
            attr_dtypes=(o3c.float32, o3c.float32, o3c.float32),
            attr_channels=((1), (1), (3)),
            voxel_size=self.voxel_size_m,
            block_resolution=self.block_resolution,
            block_count=self.initial_block_count,
            device=self.device,
        )
        self.num_frames = 0
        self._sdf_index = None
        self._touched_blocks = []

    def integrate(
        self,
        rgb: np.ndarray | None,
        depth: np.ndarray,
        camera_to_world: np.ndarray,
        camera: PinholeCamera,
    ) -> None:
        """Fuse one frame.

        Args:
            rgb: (H, W, 3) uint8 colour, or None to fuse geometry only (grey colour).
            depth: (H, W) float z-depth in metres, 0 where invalid.
            camera_to_world: 4x4 pose, OpenCV camera axes.
            camera: intrinsics of the frame (its size must match ``depth``).
        """
        self.fuse(self.prepare_frame(rgb, depth, camera_to_world, camera))

    def prepare_frame(
        self,
        rgb: np.ndarray | None,
        depth: np.ndarray,
        camera_to_world: np.ndarray,
        camera: PinholeCamera,
    ) -> PreparedFrame | None:
        """Check one frame and convert it to what :meth:`fuse` takes (arrays of its own, so
        the caller may overwrite its buffers at once); ``None`` when no depth is in range.

        Raises:
            ValueError: the frame's shapes do not match the camera, or the pose is not a
                finite 4x4 matrix.
        """
        depth = np.asarray(depth, dtype=np.float32)
        if depth.shape != (camera.height, camera.width):
            raise ValueError(
                f"depth has shape {depth.shape} but the camera is {camera.height} x "
                f"{camera.width}; pass the camera the frame was rendered with"
            )
        if rgb is None:
            colour = np.full((*depth.shape, 3), 0.5, dtype=np.float32)
        else:
            rgb = np.asarray(rgb)
            if rgb.shape != (*depth.shape, 3):
                raise ValueError(f"rgb has shape {rgb.shape}, expected {(*depth.shape, 3)}")
            # Open3D fuses float depth only together with float colour.
            colour = rgb.astype(np.float32) / 255.0
        pose = np.array(camera_to_world, dtype=np.float64)
        if pose.shape != (4, 4) or not np.isfinite(pose).all():
            raise ValueError(f"camera_to_world must be a finite 4x4 matrix, got {pose.shape}")
        depth = np.where(np.isfinite(depth) & (depth > 0.0), depth, 0.0).astype(np.float32)
        if not ((depth > 0.0) & (depth <= self.max_depth_m)).any():
            return None  # nothing within range to fuse; still a valid frame (empty space)
        return PreparedFrame(colour, depth, pose, np.asarray(camera.matrix, dtype=np.float64))

    def fuse(self, frame: PreparedFrame | None) -> None:
        """Fuse a frame :meth:`prepare_frame` made (``None``: nothing to fuse)."""
        if frame is None:
            return
        o3d = open3d_module()
        o3c = o3d.core
        extrinsic = o3c.Tensor(np.linalg.inv(frame.camera_to_world), o3c.float64)
        intrinsic = o3c.Tensor(frame.intrinsic, o3c.float64)
        depth_image = o3d.t.geometry.Image(o3c.Tensor(frame.depth)).to(self.device)
        colour_image = o3d.t.geometry.Image(o3c.Tensor(frame.colour)).to(self.device)
        try:
            blocks = self._grid.compute_unique_block_coordinates(
                depth_image, intrinsic, extrinsic, 1.0, self.max_depth_m, self._trunc_multiplier
            )
        except RuntimeError as error:
            # A frame with a handful of depth pixels (in an open scan, the sky with a far
            # fragment in a corner) may touch no block: Open3D samples the image sparsely and
            # refuses it. There is nothing to fuse then, as for an empty frame.
            if "No block is touched" not in str(error):
                raise
            return
        self._grid.integrate(
            blocks,
            depth_image,
            colour_image,
            intrinsic,
            intrinsic,
            extrinsic,
            1.0,
            self.max_depth_m,
            self._trunc_multiplier,
        )
        self.num_frames += 1
        self._sdf_index = None
        self._touched_blocks.append(blocks.cpu().numpy().astype(np.int64).reshape(-1, 3))

    def pop_touched_blocks(self) -> np.ndarray:
        """(K, 3) block coordinates that frames fused since the last call wrote to.

        With :meth:`points_near_blocks`, a user that keeps a coarse view of the SDF (the
        agent's planner) re-evaluates only what changed.
        """
        touched = self._touched_blocks
        self._touched_blocks = []
        if not touched:
            return np.zeros((0, 3), np.int64)
        return np.unique(np.concatenate(touched), axis=0)

    def points_near_blocks(self, points: np.ndarray, blocks: np.ndarray) -> np.ndarray:
        """(N,) bool: which points have an interpolation corner in one of ``blocks``
        (so their :meth:`sdf` may have changed when those blocks did)."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        blocks = np.asarray(blocks, dtype=np.int64).reshape(-1, 3)
        near = np.zeros(len(points), dtype=bool)
        if len(blocks) == 0 or len(points) == 0:
            return near
        low = blocks.min(axis=0)
        table = np.zeros(blocks.max(axis=0) - low + 2, dtype=bool)
        table[tuple((blocks - low).T)] = True
        # A point's corners lie in its base cell's block or the next one along each axis.
        base = np.floor_divide(np.floor(points / self.voxel_size_m).astype(np.int64),
                               self.block_resolution) - low
        for offset in np.ndindex(2, 2, 2):
            index = base + np.array(offset)
            inside = np.all((index >= 0) & (index < np.asarray(table.shape)), axis=1)
            index[~inside] = 0
            near |= inside & table[index[:, 0], index[:, 1], index[:, 2]]
        return near

    def grid_near_blocks(
        self, origin: np.ndarray, spacing: float, shape: tuple[int, int, int], blocks: np.ndarray
    ) -> np.ndarray:
        """(nx, ny, nz) bool over the regular grid of points ``origin + spacing * index``:
        exactly :meth:`points_near_blocks` of those points, without visiting each point.

        The test is separable: a point concerns block b when, along every axis, its base
        cell's block is b - 1 or b. Along an axis the base blocks of the grid's points do not
        decrease, so each block marks one box of indices.
        """
        origin = np.asarray(origin, dtype=np.float64).reshape(3)
        spans = []
        for axis in range(3):
            # The same arithmetic as SdfVolume.voxel_to_world and points_near_blocks.
            coordinate = origin[axis] + spacing * np.arange(shape[axis], dtype=np.float64)
            base = np.floor_divide(np.floor(coordinate / self.voxel_size_m).astype(np.int64),
                                   self.block_resolution)
            spans.append((base, base + 1))
        return _mark_block_spans(shape, blocks, spans)

    # -- persistence -------------------------------------------------------------------
    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the fused grid to ``path`` in Open3D's ``VoxelBlockGrid`` format (``.npz``).

        The file holds the grid only: :attr:`num_frames` and the settings stay with the caller,
        which restores them next to :meth:`load`.
        """
        self._grid.save(os.fspath(path))

    def load(self, path: str | os.PathLike[str]) -> None:
        """Replace the fused grid with one written by :meth:`save`, on this mapper's device.

        The blocks touched before are forgotten (:meth:`pop_touched_blocks` starts empty),
        since a user's coarse view of the old grid is no guide to the new one.
        """
        self._grid = open3d_module().t.geometry.VoxelBlockGrid.load(os.fspath(path)).to(self.device)
        self._sdf_index = None
        self._touched_blocks = []

    # -- outputs -----------------------------------------------------------------------
    @property
    def is_empty(self) -> bool:
        return self._grid.hashmap().size() == 0

    def extract_mesh(self) -> trimesh.Trimesh:
        """Marching-cubes mesh of the fused SDF with per-vertex colours (uint8 RGBA).

        Returns an empty ``trimesh.Trimesh`` when nothing was fused.
        """
        if self.is_empty:
            return trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
        threshold = self._open3d_weight_threshold
        mesh = self._grid.extract_triangle_mesh(weight_threshold=threshold).cpu()
        vertices = mesh.vertex.positions.numpy().astype(np.float64)
        if len(vertices) == 0 or "indices" not in mesh.triangle:
            return trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
        faces = mesh.triangle.indices.numpy().astype(np.int64)
        colours = np.clip(mesh.vertex.colors.numpy() * 255.0 + 0.5, 0, 255).astype(np.uint8)
        rgba = np.concatenate([colours, np.full((len(colours), 1), 255, np.uint8)], axis=1)
        return trimesh.Trimesh(vertices, faces, vertex_colors=rgba, process=False)

    def extract_point_cloud(self) -> tuple[np.ndarray, np.ndarray]:
        """Zero-crossing surface points and their colours: ((N, 3) float64, (N, 3) uint8)."""
        if self.is_empty:
            return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.uint8)
        threshold = self._open3d_weight_threshold
        cloud = self._grid.extract_point_cloud(weight_threshold=threshold).cpu()
        if "positions" not in cloud.point or len(cloud.point.positions) == 0:
            return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.uint8)
        points = cloud.point.positions.numpy().astype(np.float64)
        colours = np.clip(cloud.point.colors.numpy() * 255.0 + 0.5, 0, 255).astype(np.uint8)
        return points, colours

    def _block_table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """A dense table of the allocated blocks' buffer slots over their bounding box.

        Returns (table (bx, by, bz) int64 with -1 where no block is allocated, the table's
        lowest block coordinate, tsdf (capacity, r, r, r) and weight arrays). On a CPU the
        attribute arrays are views of Open3D's buffers: nothing is copied, so a query costs
        the points asked for, not the size of the map.
        """
        hashmap = self._grid.hashmap()
        active = hashmap.active_buf_indices().cpu().numpy().astype(np.int64)
        keys = hashmap.key_tensor().cpu().numpy()[active].astype(np.int64)
        low = keys.min(axis=0)
        table = np.full(keys.max(axis=0) - low + 1, -1, dtype=np.int64)
        table[tuple((keys - low).T)] = active
        resolution = self.block_resolution
        shape = (-1, resolution, resolution, resolution)
        tsdf = self._grid.attribute("tsdf").cpu().numpy().reshape(shape)
        weight = self._grid.attribute("weight").cpu().numpy().reshape(shape)
        return table, low, tsdf, weight

    def behind_surface_bounds(self, centres: np.ndarray, half_extent_m: float) -> np.ndarray:
        """(N,) upper bounds of the signed distance at ``centres`` from the voxels behind a
        measured surface nearby: the least ``s(p) + |p - c|`` over the observed voxels ``p``
        with negative SDF within ``half_extent_m`` of the centre ``c`` along every axis (+inf
        where there is none).

        A signed distance field is 1-Lipschitz, so ``s(c) <= s(p) + |p - c|``; the fused
        field is not where it meets unobserved space. A wall seen from one side fuses into a
        band of negative values a few voxels thick with "unknown" (read as +truncation)
        behind it, and samples of :meth:`sdf` on a grid coarser than the band (a planner's
        10 cm) often fall on either side of it: the wall vanishes. The bound restores it.
        """
        centres = np.ascontiguousarray(np.asarray(centres, dtype=np.float64).reshape(-1, 3))
        if self.is_empty or len(centres) == 0:
            return np.full(len(centres), np.inf)
        if self._sdf_index is None:
            self._sdf_index = self._block_table()
        table, low, tsdf, weights = self._sdf_index
        return behind_surface_bounds(centres, float(half_extent_m), table, low, tsdf, weights,
                                     self.block_resolution, self.voxel_size_m,
                                     self.truncation_m, self.min_weight)

    def grid_cells_near_blocks(
        self, origin: np.ndarray, spacing: float, shape: tuple[int, int, int],
        blocks: np.ndarray, half_extent_m: float,
    ) -> np.ndarray:
        """(nx, ny, nz) bool over the grid ``origin + spacing * index``: the points whose box
        of ``half_extent_m`` (the voxels :meth:`behind_surface_bounds` reads) or whose
        interpolation corners (:meth:`grid_near_blocks`) reach into one of ``blocks``."""
        origin = np.asarray(origin, dtype=np.float64).reshape(3)
        spans = []
        for axis in range(3):
            coordinate = origin[axis] + spacing * np.arange(shape[axis], dtype=np.float64)
            first = np.ceil((coordinate - half_extent_m) / self.voxel_size_m).astype(np.int64)
            last = np.floor((coordinate + half_extent_m) / self.voxel_size_m).astype(np.int64)
            # Blocks of the box's first and last voxels; both rise along the axis.
            spans.append((np.floor_divide(first, self.block_resolution),
                          np.floor_divide(last, self.block_resolution)))
        return (self.grid_near_blocks(origin, spacing, shape, blocks)
                | _mark_block_spans(shape, blocks, spans))

    def sdf(self, points: np.ndarray) -> np.ndarray:
        """Signed distance of the fused map at world points, metres (positive in free space).

        Trilinear interpolation over the observed voxels around each point; corners that were
        never observed are left out and the rest re-weighted. Points with no observed corner
        get ``+truncation_m`` (unknown space reads as "at least a truncation away"), so the
        result is always finite and clamped to [-truncation_m, truncation_m].

        Args:
            points: (N, 3) world points, metres.

        Returns:
            (N,) float64 signed distances.
        """
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        result = np.full(len(points), self.truncation_m)
        if self.is_empty or len(points) == 0:
            return result
        if self._sdf_index is None:
            self._sdf_index = self._block_table()
        table, low, tsdf, weights = self._sdf_index
        resolution = self.block_resolution
        grid = points / self.voxel_size_m
        base = np.floor(grid).astype(np.int64)
        fraction = grid - base
        total = np.zeros(len(points))
        weight_sum = np.zeros(len(points))
        for corner in np.ndindex(2, 2, 2):
            offset = np.array(corner)
            cells = base + offset
            block = np.floor_divide(cells, resolution)
            local = cells - block * resolution
            block -= low
            inside = np.all((block >= 0) & (block < np.asarray(table.shape)), axis=1)
            block[~inside] = 0
            slot = np.where(inside, table[block[:, 0], block[:, 1], block[:, 2]], -1)
            found = slot >= 0
            slot[~found] = 0
            # Open3D stores a block's voxels as [z, y, x].
            index = (slot, local[:, 2], local[:, 1], local[:, 0])
            found &= weights[index] >= self.min_weight
            weight = np.prod(np.where(offset == 1, fraction, 1.0 - fraction), axis=1) * found
            total += weight * (tsdf[index].astype(np.float64) * self.truncation_m)
            weight_sum += weight
        known = weight_sum > 1e-12
        result[known] = total[known] / weight_sum[known]
        return result


def _mark_block_spans(
    shape: tuple[int, int, int], blocks: np.ndarray,
    spans: list[tuple[np.ndarray, np.ndarray]],
) -> np.ndarray:
    """(nx, ny, nz) bool: the grid points that reach into one of ``blocks`` (K, 3), where
    along each axis a point reaches the blocks ``spans[axis][0][i] .. spans[axis][1][i]``
    (both non-decreasing along the axis), so that each block marks one box of indices."""
    blocks = np.asarray(blocks, dtype=np.int64).reshape(-1, 3)
    near = np.zeros(shape, dtype=bool)
    if len(blocks) == 0:
        return near
    low = [np.searchsorted(last, blocks[:, axis], side="left")
           for axis, (_, last) in enumerate(spans)]
    high = [np.searchsorted(first, blocks[:, axis], side="right")
            for axis, (first, _) in enumerate(spans)]
    for x0, x1, y0, y1, z0, z1 in zip(low[0], high[0], low[1], high[1], low[2], high[2],
                                      strict=True):
        near[x0:x1, y0:y1, z0:z1] = True
    return near
