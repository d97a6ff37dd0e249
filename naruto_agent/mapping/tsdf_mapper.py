"""The fast alternative: TSDF fusion plus an uncertainty grid derived from observation counts.

Same interface as :class:`~naruto_agent.mapping.NeuralMapper`, for users who want speed over
fidelity, and as an ablation. The geometry is the project's reference
:class:`~naruto_gym.evaluation.TsdfFusionMapper` (Open3D); on top of it this module keeps a
coarse count grid (the planner's 0.1 m voxels) of how many frames saw each voxel near the
measured surface. The derived variance of a voxel is ``initial_variance / (1 + n)``: the
neural mapper's initial variance (softplus(3.0) + 0.01) for a surface never seen, halving
with the second view, and so on, which is the shape the NLL-trained grid takes too (a surface
seen often is certain).

Two additions give the uncertainty the published meaning beyond seen surfaces (both
switchable):

* ``unknown_space``: an :class:`~naruto_agent.mapping.observed_space.ObservedSpace` of every
  frame's rays marks the frontier between measured free space and space nothing has
  measured; frontier voxels get the initial (largest) variance, so the goal search heads
  into unexplored rooms before it polishes what it has.
* ``grazing_weighting``: an observation counts by the cosine between the viewing ray and the
  surface normal (from the depth image), so a surface seen only at grazing angles stays
  uncertain.
"""

from __future__ import annotations

import math
import os
import tempfile
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch
import trimesh

from naruto_agent.mapping.base import check_bounds, check_frame, resolve_device
from naruto_agent.mapping.meshing import mesh_from_sdf_function
from naruto_agent.mapping.observed_space import (
    ObservedSpace,
    ObservedSpaceConfig,
    add_unknown_space_uncertainty,
)
from naruto_agent.mapping.sdf_volume import SdfVolume
from naruto_gym.evaluation.tsdf_mapper import TsdfFusionMapper, open3d_module
from naruto_gym.sensors.pinhole import PinholeCamera
from naruto_gym.utils.checks import check_bool, check_integer, check_number


@dataclass
class TsdfMapperConfig:
    """Settings of :class:`TsdfUncertaintyMapper`.

    Attributes:
        voxel_size_m: TSDF voxel (2 cm: the final-mesh resolution of the neural mapper).
        truncation_m: TSDF truncation (8 cm).
        max_depth_m: depth range fused (5 m, as the published mapper).
        integrate_every: fuse every n-th frame (1 = all).
        map_every: how often ``integrate`` reports a changed map (5, the neural cadence).
        uncertainty_voxel_m: voxel of the count grid / planner grid (0.1 m).
        initial_variance: variance of a never-observed voxel (softplus(3.0) + 0.01).
        surface_band_m: voxels within this of a measured depth count as seeing the surface
            (half a voxel of the count grid).
        planner_surface_m: the uncertainty volume keeps voxels with SDF in [0, this]
            (half the neural mapper's truncation, 0.05 m).
        device: "auto", "cpu" or "cuda[:N]" (Open3D's device for the TSDF).
        unknown_space: frontier voxels (measured free space next to unmeasured space) are
            targets at the initial variance (see the module docstring).
        frontier_min_cluster_voxels: frontier clusters smaller than this are ignored.
        observed_rays_per_frame: pixels per frame integrated into the observed-space grid.
        grazing_weighting: an observation of a surface counts |cos| of its incidence angle
            (at least ``min_observation_weight``); False counts every view as 1.
        min_observation_weight: the least a single view counts with ``grazing_weighting``.
        planner_behind_surface_bound: the planner SDF at a voxel is at most ``s(p) + |p - c|``
            for every fused voxel ``p`` with negative SDF in its cell
            (:meth:`~naruto_gym.evaluation.TsdfFusionMapper.behind_surface_bounds`). A wall
            seen from one side fuses into a band of negative values 2-6 cm thick with unknown
            space behind it, which the planner's 10 cm samples straddle more often than not:
            the wall would vanish from the planner's map, and the agent would try to move
            through it. False: the SDF sampled at the planner voxels only.
    """

    voxel_size_m: float = 0.02
    truncation_m: float = 0.08
    max_depth_m: float = 5.0
    integrate_every: int = 1
    map_every: int = 5
    uncertainty_voxel_m: float = 0.1
    initial_variance: float = float(np.log1p(np.exp(3.0)) + 0.01)
    surface_band_m: float = 0.05
    planner_surface_m: float = 0.05
    device: str = "auto"
    unknown_space: bool = True
    frontier_min_cluster_voxels: int = 8
    observed_rays_per_frame: int = 2048
    grazing_weighting: bool = True
    min_observation_weight: float = 0.1
    planner_behind_surface_bound: bool = True

    def __post_init__(self) -> None:
        check_number("min_observation_weight", self.min_observation_weight, low=0.0, high=1.0)
        for name in (
            "voxel_size_m",
            "truncation_m",
            "max_depth_m",
            "uncertainty_voxel_m",
            "initial_variance",
            "surface_band_m",
            "planner_surface_m",
        ):
            check_number(name, getattr(self, name), low=0.0)
        check_integer("integrate_every", self.integrate_every, low=1)
        check_integer("map_every", self.map_every, low=1)
        check_integer("frontier_min_cluster_voxels", self.frontier_min_cluster_voxels, low=1)
        check_integer("observed_rays_per_frame", self.observed_rays_per_frame, low=1)
        for name in ("unknown_space", "grazing_weighting", "planner_behind_surface_bound"):
            check_bool(name, getattr(self, name))


class TsdfUncertaintyMapper:
    """TSDF fusion + count-derived uncertainty, with the neural mapper's interface.

    Args:
        bounds: (2, 3) world box of the scene.
        camera: intrinsics of the frames.
        config: settings.
    """

    def __init__(
        self, bounds: np.ndarray, camera: PinholeCamera, config: TsdfMapperConfig | None = None
    ) -> None:
        self.config = config or TsdfMapperConfig()
        self.bounds = check_bounds(bounds)
        self.camera = camera
        self._device = resolve_device(self.config.device)
        self.tsdf = TsdfFusionMapper(
            voxel_size_m=self.config.voxel_size_m,
            truncation_m=self.config.truncation_m,
            max_depth_m=self.config.max_depth_m,
            device="cuda"
            if self._device.type == "cuda" and open3d_module().core.cuda.is_available()
            else "cpu",
        )
        template = SdfVolume.from_function(
            lambda p: np.zeros(len(p)), self.bounds, self.config.uncertainty_voxel_m
        )
        self._grid_origin = template.origin
        self._grid_points = template.grid_points()
        self._flat_index = np.arange(self._grid_points.shape[0]).reshape(template.shape)
        self.counts = np.zeros(template.shape, dtype=np.float32)
        self.frames_integrated = 0
        self._sdf_view: SdfVolume | None = None
        self._bound_view: np.ndarray | None = None  # behind-surface bounds, planner voxels
        self.observed_space = ObservedSpace(
            self.bounds,
            ObservedSpaceConfig(
                voxel_size_m=self.config.uncertainty_voxel_m,
                max_range_m=self.config.max_depth_m,
                rays_per_frame=self.config.observed_rays_per_frame,
                min_cluster_voxels=self.config.frontier_min_cluster_voxels,
            ),
        )

    @property
    def device(self) -> torch.device:
        return self._device

    def integrate(
        self, rgb: np.ndarray, depth: np.ndarray, camera_to_world: np.ndarray, frame_index: int
    ) -> bool:
        """Fuse a frame (every ``integrate_every``-th); True every ``map_every`` frames."""
        rgb, depth, pose = check_frame(rgb, depth, camera_to_world)
        if frame_index % self.config.integrate_every == 0:
            self.tsdf.integrate(rgb, depth, pose, self.camera)
            self._count_observations(depth, pose)
            self.observed_space.integrate_depth(depth, pose, self.camera)
            self.frames_integrated += 1
        return frame_index % self.config.map_every == 0

    def _frustum_block(self, pose: np.ndarray) -> tuple[slice, slice, slice]:
        """Index ranges of the count grid within the box around the view frustum (to the
        mapping range): grid points outside it cannot be seen, so they are not projected."""
        camera, far = self.camera, self.config.max_depth_m
        corners = np.array(
            [[0.0, 0.0, 0.0]]
            + [
                [(u - camera.cx) / camera.fx * far, (v - camera.cy) / camera.fy * far, far]
                for u in (0.0, camera.width)
                for v in (0.0, camera.height)
            ]
        )
        world = corners @ pose[:3, :3].T + pose[:3, 3]
        low = np.floor((world.min(axis=0) - self._grid_origin) / self.config.uncertainty_voxel_m)
        high = np.ceil((world.max(axis=0) - self._grid_origin) / self.config.uncertainty_voxel_m)
        shape = np.asarray(self.counts.shape)
        low = np.clip(low.astype(np.int64), 0, shape)
        high = np.clip(high.astype(np.int64) + 1, 0, shape)
        return tuple(slice(int(a), int(b)) for a, b in zip(low, high, strict=True))

    def _count_observations(self, depth: np.ndarray, pose: np.ndarray) -> None:
        block = self._frustum_block(pose)
        flat_index = self._flat_index[block].reshape(-1)
        world_to_camera = np.linalg.inv(pose)
        camera_points = (
            self._grid_points[flat_index] @ world_to_camera[:3, :3].T + world_to_camera[:3, 3]
        )
        pixels, z = self.camera.project(camera_points)
        u = np.round(pixels[:, 0]).astype(np.int64)
        v = np.round(pixels[:, 1]).astype(np.int64)
        inside = (z > 0) & (u >= 0) & (u < self.camera.width) & (v >= 0) & (v < self.camera.height)
        index = np.flatnonzero(inside)
        measured = depth[v[index], u[index]]
        seen = (measured > 0) & (np.abs(z[index] - measured) <= self.config.surface_band_m)
        weight = 1.0
        if self.config.grazing_weighting:
            weight = np.maximum(
                incidence_cosine(depth, self.camera, u[index[seen]], v[index[seen]]),
                self.config.min_observation_weight,
            )
        self.counts.reshape(-1)[flat_index[index[seen]]] += weight  # points are distinct

    def integrate_panorama(self, panorama: np.ndarray, position: np.ndarray) -> None:
        """Add a depth panorama's rays to the observed space (free space all around)."""
        self.observed_space.integrate_panorama(panorama, position)

    def variance_grid(self) -> np.ndarray:
        """(nx, ny, nz) derived variance on the count grid."""
        return self.config.initial_variance / (1.0 + self.counts.astype(np.float64))

    def variance_volume(self) -> SdfVolume:
        """The derived variance on the count grid, placed in the world (every voxel, not
        only surface ones: see :meth:`planner_view` for the planner's volume)."""
        return SdfVolume(self.variance_grid(), self._grid_origin, self.config.uncertainty_voxel_m)

    def sdf(self, points: np.ndarray) -> np.ndarray:
        """(N,) fused SDF in metres; unobserved space reads as +truncation (see
        :meth:`TsdfFusionMapper.sdf`)."""
        return self.tsdf.sdf(points)

    def planner_view(self, voxel_size: float = 0.1) -> tuple[SdfVolume, SdfVolume]:
        """(SDF volume, uncertainty volume: derived variance on surface voxels, else 0)."""
        sampled, sdf_volume = self._planner_sdf(voxel_size)
        if math.isclose(voxel_size, self.config.uncertainty_voxel_m):
            values = self.variance_grid()  # the same grid: no interpolation needed
        else:
            values = (
                self.variance_volume()
                .sample(sdf_volume.grid_points(), outside_value=0.0)
                .reshape(sdf_volume.shape)
            )
        # Surface voxels by the sampled SDF: the bound reaches voxels behind a surface,
        # which no frame can see (they would stay targets at the initial variance).
        on_surface = (sampled.values >= 0.0) & (sampled.values <= self.config.planner_surface_m)
        uncertainty = SdfVolume(np.where(on_surface, values, 0.0), sdf_volume.origin, voxel_size)
        if self.config.unknown_space:
            uncertainty = add_unknown_space_uncertainty(
                uncertainty, self.observed_space, self.config.initial_variance
            )
        return sdf_volume, uncertainty

    query_volumes = planner_view

    def _planner_sdf(self, voxel_size: float) -> tuple[SdfVolume, SdfVolume]:
        """The SDF on the planner grid, re-evaluated only where fused blocks changed: as
        sampled, and bounded from behind measured surfaces (``planner_behind_surface_bound``;
        the same as sampled when it is off)."""
        cached = self._sdf_view
        bound = self.config.planner_behind_surface_bound
        if cached is None or not math.isclose(cached.voxel_size, voxel_size):
            self.tsdf.pop_touched_blocks()
            cached = self._sdf_view = SdfVolume.from_function(self.sdf, self.bounds, voxel_size)
            self._view_points = cached.grid_points()
            self._bound_view = (
                self.tsdf.behind_surface_bounds(self._view_points, 0.5 * voxel_size)
                if bound
                else None
            )
        else:
            blocks = self.tsdf.pop_touched_blocks()
            changed = self.tsdf.grid_near_blocks(
                cached.origin, cached.voxel_size, cached.shape, blocks
            ).reshape(-1)
            if changed.any():
                cached.values.reshape(-1)[changed] = self.sdf(self._view_points[changed])
            if bound:
                # The bound reads every fused voxel in a planner voxel's cell.
                near = self.tsdf.grid_cells_near_blocks(
                    cached.origin, cached.voxel_size, cached.shape, blocks, 0.5 * voxel_size
                ).reshape(-1)
                if near.any():
                    self._bound_view[near] = self.tsdf.behind_surface_bounds(
                        self._view_points[near], 0.5 * voxel_size
                    )
        sampled = SdfVolume(cached.values.copy(), cached.origin, cached.voxel_size)
        if not bound:
            return sampled, sampled
        bounded = np.minimum(cached.values, self._bound_view.reshape(cached.shape))
        return sampled, SdfVolume(bounded.astype(np.float32), cached.origin, cached.voxel_size)

    def extract_mesh(self, voxel_size: float = 0.02) -> trimesh.Trimesh:
        """Open3D's mesh at the TSDF resolution; a coarser marching-cubes preview otherwise."""
        if voxel_size <= self.config.voxel_size_m * 1.0001:
            return self.tsdf.extract_mesh()
        return mesh_from_sdf_function(self.sdf, self.bounds, voxel_size)

    def state_dict(self) -> dict[str, Any]:
        """The fused grid (Open3D's own file format, as bytes), counts and settings."""
        with tempfile.TemporaryDirectory() as folder:
            path = os.path.join(folder, "grid.npz")
            self.tsdf.save(path)
            with open(path, "rb") as handle:
                grid_bytes = handle.read()
        return {
            "config": asdict(self.config),
            "bounds": self.bounds.tolist(),
            "camera": self.camera.as_dict(),
            "grid": grid_bytes,
            "counts": self.counts.copy(),
            "observed_space": self.observed_space.state_dict(),
            "frames_integrated": self.frames_integrated,
            "tsdf_frames": self.tsdf.num_frames,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore a map saved by :meth:`state_dict`."""
        if np.asarray(state["counts"]).shape != self.counts.shape:
            raise ValueError("saved count grid does not match this mapper's bounds/voxel size")
        with tempfile.TemporaryDirectory() as folder:
            path = os.path.join(folder, "grid.npz")
            with open(path, "wb") as handle:
                handle.write(state["grid"])
            self.tsdf.load(path)
        self._sdf_view = None
        self.tsdf.num_frames = int(state["tsdf_frames"])
        self.counts = np.asarray(state["counts"], dtype=np.float32).copy()
        if "observed_space" in state:
            self.observed_space.load_state_dict(state["observed_space"])
        self.frames_integrated = int(state["frames_integrated"])


def incidence_cosine(
    depth: np.ndarray, camera: PinholeCamera, u: np.ndarray, v: np.ndarray
) -> np.ndarray:
    """(N,) |cos| of the angle between each pixel's viewing ray and the surface normal there.

    The normal comes from the depth image: the cross product of the back-projected
    neighbours to the right and below (left and above at the image border). Pixels whose
    neighbours have no depth, or lie across a depth jump of more than 10 %, read 1 (a view
    counted in full: no evidence of a grazing angle).
    """
    u = np.asarray(u, np.int64)
    v = np.asarray(v, np.int64)
    if len(u) == 0:
        return np.zeros(0)
    du = np.where(u + 1 < camera.width, 1, -1)
    dv = np.where(v + 1 < camera.height, 1, -1)

    def back_project(uu: np.ndarray, vv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        z = depth[vv, uu].astype(np.float64)
        x = (uu - camera.cx) / camera.fx * z
        y = (vv - camera.cy) / camera.fy * z
        return np.stack([x, y, z], axis=1), z

    centre, z0 = back_project(u, v)
    right, z1 = back_project(u + du, v)
    below, z2 = back_project(u, v + dv)
    normal = np.cross((right - centre) * du[:, None], (below - centre) * dv[:, None])
    length = np.linalg.norm(normal, axis=1)
    ray = centre / np.maximum(np.linalg.norm(centre, axis=1, keepdims=True), 1e-12)
    cosine = np.abs(np.einsum("ij,ij->i", normal, ray)) / np.maximum(length, 1e-12)
    smooth = (z1 > 0) & (z2 > 0) & (np.abs(z1 - z0) < 0.1 * z0) & (np.abs(z2 - z0) < 0.1 * z0)
    return np.where(smooth & (length > 0), cosine, 1.0)
