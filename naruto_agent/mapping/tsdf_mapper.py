"""The fast alternative: TSDF fusion plus an uncertainty grid derived from observation counts.

Same interface as :class:`~naruto_agent.mapping.NeuralMapper`, for users who want speed over
fidelity, and as an ablation. The geometry is the project's reference
:class:`~naruto_gym.evaluation.TsdfFusionMapper` (Open3D); on top of it this module keeps a
coarse count grid (the planner's 0.1 m voxels) of how many frames saw each voxel near the
measured surface. The derived variance of a voxel is ``initial_variance / (1 + n)``: the
neural mapper's initial variance (softplus(3.0) + 0.01) for a surface never seen, halving
with the second view, and so on, which is the shape the NLL-trained grid takes too (a surface
seen often is certain).
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import open3d as o3d
import torch
import trimesh

from naruto_agent.mapping.base import check_bounds, check_frame, resolve_device
from naruto_agent.mapping.meshing import mesh_from_sdf_function
from naruto_agent.planning.sdf_volume import SdfVolume
from naruto_gym.evaluation.tsdf_mapper import TsdfFusionMapper
from naruto_gym.sensors.pinhole import PinholeCamera


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

    def __post_init__(self) -> None:
        for name in ("voxel_size_m", "truncation_m", "max_depth_m", "uncertainty_voxel_m",
                     "initial_variance", "surface_band_m", "planner_surface_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")
        if self.integrate_every < 1 or self.map_every < 1:
            raise ValueError("integrate_every and map_every must be at least 1")


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
            device="cuda" if self._device.type == "cuda" and o3d.core.cuda.is_available()
            else "cpu",
        )
        template = SdfVolume.from_function(
            lambda p: np.zeros(len(p)), self.bounds, self.config.uncertainty_voxel_m
        )
        self._grid_origin = template.origin
        self._grid_points = template.grid_points()
        self.counts = np.zeros(template.shape, dtype=np.int32)
        self.frames_integrated = 0

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
            self.frames_integrated += 1
        return frame_index % self.config.map_every == 0

    def _count_observations(self, depth: np.ndarray, pose: np.ndarray) -> None:
        world_to_camera = np.linalg.inv(pose)
        camera_points = self._grid_points @ world_to_camera[:3, :3].T + world_to_camera[:3, 3]
        pixels, z = self.camera.project(camera_points)
        u = np.round(pixels[:, 0]).astype(np.int64)
        v = np.round(pixels[:, 1]).astype(np.int64)
        inside = (z > 0) & (u >= 0) & (u < self.camera.width) & (v >= 0) & (v < self.camera.height)
        index = np.flatnonzero(inside)
        measured = depth[v[index], u[index]]
        seen = (measured > 0) & (np.abs(z[index] - measured) <= self.config.surface_band_m)
        self.counts.reshape(-1)[index[seen]] += 1

    def variance_grid(self) -> np.ndarray:
        """(nx, ny, nz) derived variance on the count grid."""
        return self.config.initial_variance / (1.0 + self.counts.astype(np.float64))

    def sdf(self, points: np.ndarray) -> np.ndarray:
        """(N,) fused SDF in metres; unobserved space reads as +truncation (see
        :meth:`TsdfFusionMapper.sdf`)."""
        return self.tsdf.sdf(points)

    def planner_view(self, voxel_size: float = 0.1) -> tuple[SdfVolume, SdfVolume]:
        """(SDF volume, uncertainty volume: derived variance on surface voxels, else 0)."""
        sdf_volume = SdfVolume.from_function(self.sdf, self.bounds, voxel_size)
        variance = SdfVolume(self.variance_grid(), self._grid_origin,
                             self.config.uncertainty_voxel_m)
        values = variance.sample(sdf_volume.grid_points(), outside_value=0.0).reshape(
            sdf_volume.shape
        )
        on_surface = (sdf_volume.values >= 0.0) & (
            sdf_volume.values <= self.config.planner_surface_m
        )
        return sdf_volume, SdfVolume(np.where(on_surface, values, 0.0), sdf_volume.origin,
                                     voxel_size)

    query_volumes = planner_view

    def extract_mesh(self, voxel_size: float = 0.02) -> trimesh.Trimesh:
        """Open3D's mesh at the TSDF resolution; a coarser marching-cubes preview otherwise."""
        if voxel_size <= self.config.voxel_size_m * 1.0001:
            return self.tsdf.extract_mesh()
        return mesh_from_sdf_function(self.sdf, self.bounds, voxel_size)

    def state_dict(self) -> dict[str, Any]:
        """The fused grid (Open3D's own file format, as bytes), counts and settings."""
        with tempfile.TemporaryDirectory() as folder:
            path = os.path.join(folder, "grid.npz")
            self.tsdf._grid.save(path)
            with open(path, "rb") as handle:
                grid_bytes = handle.read()
        return {
            "config": asdict(self.config),
            "bounds": self.bounds.tolist(),
            "camera": self.camera.as_dict(),
            "grid": grid_bytes,
            "counts": self.counts.copy(),
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
            self.tsdf._grid = o3d.t.geometry.VoxelBlockGrid.load(path).to(self.tsdf.device)
        self.tsdf._sdf_index = None
        self.tsdf.num_frames = int(state["tsdf_frames"])
        self.counts = np.asarray(state["counts"], dtype=np.int32).copy()
        self.frames_integrated = int(state["frames_integrated"])
