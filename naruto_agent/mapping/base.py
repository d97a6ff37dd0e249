"""What every mapper offers the agent, and the device setting they share.

A mapper turns posed RGB-D frames into a map. The agent needs four things from it: a
planner's view (an SDF volume and an uncertainty volume on a coarse grid), a mesh to score,
an SDF to query at arbitrary points (MAD), and a way to save and restore it.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np
import torch
import trimesh

from naruto_agent.mapping.sdf_volume import SdfVolume


def resolve_device(device: str | torch.device = "auto") -> torch.device:
    """The torch device of a setting: ``"auto"`` (CUDA when present, else CPU), ``"cpu"``,
    ``"cuda"`` or ``"cuda:N"``.

    Raises:
        ValueError: CUDA was asked for but is not available, or the name is unknown.
    """
    if isinstance(device, torch.device):
        name = str(device)
    else:
        name = str(device).strip().lower()
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        resolved = torch.device(name)
    except RuntimeError as error:
        raise ValueError(f"unknown device {device!r}; use 'auto', 'cpu' or 'cuda[:N]'") from error
    if resolved.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(
            f"device {device!r} asks for CUDA but torch sees no GPU; use device='auto' or 'cpu'"
        )
    if resolved.type not in ("cpu", "cuda"):
        raise ValueError(f"unsupported device {device!r}; use 'auto', 'cpu' or 'cuda[:N]'")
    return resolved


def check_bounds(bounds: np.ndarray) -> np.ndarray:
    """Validate a (2, 3) [min, max] box in metres and return it as float64."""
    bounds = np.asarray(bounds, dtype=np.float64)
    if bounds.shape != (2, 3) or not np.all(np.isfinite(bounds)):
        raise ValueError(f"bounds must be a finite (2, 3) [min, max] box in metres, got {bounds}")
    if np.any(bounds[1] <= bounds[0]):
        raise ValueError(f"bounds max must exceed min on every axis, got {bounds.tolist()}")
    return bounds


def check_frame(
    rgb: np.ndarray, depth: np.ndarray, camera_to_world: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Validate one RGB-D frame and its pose; returns (rgb uint8, depth float32, pose float64)."""
    depth = np.asarray(depth, dtype=np.float32)
    if depth.ndim != 2:
        raise ValueError(f"depth must be an (H, W) z-depth image in metres, got {depth.shape}")
    rgb = np.asarray(rgb)
    if rgb.shape != (*depth.shape, 3):
        raise ValueError(f"rgb must be (H, W, 3) matching depth {depth.shape}, got {rgb.shape}")
    if rgb.dtype != np.uint8:
        raise ValueError(f"rgb must be uint8 (0..255), got {rgb.dtype}")
    pose = np.asarray(camera_to_world, dtype=np.float64)
    if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
        raise ValueError(f"camera_to_world must be a finite 4x4 matrix, got shape {pose.shape}")
    return rgb, depth, pose


@runtime_checkable
class Mapper(Protocol):
    """The interface shared by :class:`~naruto_agent.mapping.NeuralMapper` and
    :class:`~naruto_agent.mapping.TsdfUncertaintyMapper`."""

    @property
    def device(self) -> torch.device:
        """Where the map lives."""
        ...

    def integrate(
        self, rgb: np.ndarray, depth: np.ndarray, camera_to_world: np.ndarray, frame_index: int
    ) -> bool:
        """Take one frame; the mapper applies its own keyframe / mapping schedule.

        Returns True when the map changed (a mapping step ran), so the planner knows when to
        query it again.
        """
        ...

    def planner_view(self, voxel_size: float = 0.1) -> tuple[SdfVolume, SdfVolume]:
        """(SDF volume in metres, uncertainty volume: 0 except on surface voxels)."""
        ...

    def extract_mesh(self, voxel_size: float = 0.02) -> trimesh.Trimesh:
        """Marching-cubes mesh with vertex colours."""
        ...

    def sdf(self, points: np.ndarray) -> np.ndarray:
        """(N,) signed distance in metres at (N, 3) world points (positive in free space)."""
        ...

    def state_dict(self) -> dict[str, Any]:
        """Everything needed to restore the map."""
        ...

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore a map saved by :meth:`state_dict`."""
        ...
