"""What every mapper offers the agent (:class:`Mapper`), and the checks mappers share.

A mapper turns posed RGB-D frames into a map. The NARUTO agent reads from it: the measure of
explored space (``observed_space``), a planner's view (an SDF volume and an uncertainty volume
on a coarse grid), an SDF to query at arbitrary points (MAD) and a mesh to score.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
import torch
import trimesh

from naruto_agent.mapping.observed_space import ObservedSpace
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


#: The methods the NARUTO agent calls on its mapper (:class:`Mapper`).
MAPPER_METHODS = ("integrate", "integrate_panorama", "planner_view", "sdf", "extract_mesh")
MAPPER_MEMBERS = ("observed_space", *MAPPER_METHODS)
"""Every member the NARUTO agent reads from its mapper (:class:`Mapper`): the observed space
and :data:`MAPPER_METHODS`."""


@runtime_checkable
class Mapper(Protocol):
    """Everything the NARUTO agent reads from its mapper (``docs/mappers.md``).

    :class:`~naruto_agent.mapping.TsdfUncertaintyMapper` and
    :class:`~naruto_agent.mapping.NeuralMapper` are mappers; a mapper of one's own is named by
    ``NarutoPolicy(mapper_kind="package.module:ClassName")`` (see
    :mod:`naruto_agent.mapping.registry`). World frame: metres, z up; poses camera-to-world
    with OpenCV camera axes; SDFs positive in free space. ``isinstance(x, Mapper)`` checks
    that the members exist; :func:`missing_members` also checks what ``observed_space`` is.
    The project's mappers also offer ``device``, ``state_dict()`` and ``load_state_dict()``,
    which the agent does not read.

    Attributes:
        observed_space: the unknown / free / occupied grid of every frame's rays, with its
            frontier (:class:`~naruto_agent.mapping.observed_space.ObservedSpace`): the agent
            reads its observed fraction (progress), free voxels (candidate goals), frontier
            and measured top (the scan's extent). The mapper feeds it: ``integrate_depth``
            with each frame, ``integrate_panorama`` with each panorama.
    """

    observed_space: ObservedSpace

    def integrate(
        self, rgb: np.ndarray, depth: np.ndarray, camera_to_world: np.ndarray, frame_index: int
    ) -> bool:
        """Take one frame; the mapper applies its own keyframe / mapping schedule.

        Args:
            rgb: (H, W, 3) uint8 colour image.
            depth: (H, W) float32 z-depth in metres, 0 where there is no hit.
            camera_to_world: 4x4 pose, OpenCV camera axes (x right, y down, z forward).
            frame_index: the frame's index in the episode (0 for the first).

        Returns:
            True when the map changed (a mapping step ran): the agent reads
            :meth:`planner_view` again only after such a step.
        """
        ...

    def integrate_panorama(self, panorama: np.ndarray, position: np.ndarray) -> None:
        """Take a depth panorama (equirectangular, radial distance in metres, 0 where there
        is no hit) taken at world ``position``; the project's mappers add its rays to
        :attr:`observed_space` (``observed_space.integrate_panorama``)."""
        ...

    def planner_view(self, voxel_size: float = 0.1) -> tuple[SdfVolume, SdfVolume]:
        """The planner's map on one grid of ``voxel_size`` voxels over the scene's bounds.

        Returns:
            (SDF volume in metres, positive in free space; uncertainty volume on the same
            grid: a variance, 0 except on surface voxels and the frontier, highest where the
            map knows least). Both share shape, origin and voxel size.
        """
        ...

    def sdf(self, points: np.ndarray) -> np.ndarray:
        """(N,) signed distance in metres at (N, 3) world points (positive in free space);
        read by the scoring (MAD) and by ``Policy.reconstruction()``."""
        ...

    def extract_mesh(self, voxel_size: float = 0.02) -> trimesh.Trimesh:
        """The map's surface as a world-frame mesh in metres (vertex colours if any), for the
        scores and the pictures; ``voxel_size`` is the resolution asked for (2 cm: the
        final mesh; coarser for previews)."""
        ...


def missing_members(mapper: object) -> list[str]:
    """What ``mapper`` lacks of :class:`Mapper`, each with what it should be (empty: none).

    Methods must be callable; ``observed_space`` must be an
    :class:`~naruto_agent.mapping.observed_space.ObservedSpace`.
    """
    missing = [f"{name}()" for name in MAPPER_METHODS if not callable(getattr(mapper, name, None))]
    observed = getattr(mapper, "observed_space", None)
    if not isinstance(observed, ObservedSpace):
        what = "missing" if observed is None else f"a {type(observed).__name__}"
        missing.insert(0, f"observed_space (an ObservedSpace; got {what})")
    return missing


def missing_methods(cls: type) -> list[str]:
    """The methods of :data:`MAPPER_METHODS` that class ``cls`` does not define (its
    ``observed_space`` may be set in ``__init__``, so only an instance can show it; a class
    that forwards members with ``__getattr__`` shows none until it has an instance)."""
    if hasattr(cls, "__getattr__"):
        return []
    return [f"{name}()" for name in MAPPER_METHODS if not callable(getattr(cls, name, None))]
