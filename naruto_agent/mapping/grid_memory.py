"""How much memory a dense voxel grid over a scene's bounds would take, checked before it is
allocated, so that a scene too large for a map's voxel size gets an error saying what to do
instead of a ``MemoryError`` (or the machine's swap) at the first step."""

from __future__ import annotations

import os
from collections.abc import Sequence


def physical_memory_bytes() -> int | None:
    """This machine's physical memory in bytes (None where the platform does not say)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


def check_grid_memory(
    shape: Sequence[int], bytes_per_voxel: float, voxel_size_m: float, what: str
) -> None:
    """Raise ``ValueError`` when a dense grid of ``shape`` voxels, ``bytes_per_voxel`` each,
    would need more than half this machine's physical memory.

    Args:
        shape: voxels along each axis.
        bytes_per_voxel: the memory one voxel takes, summed over the grid's arrays.
        voxel_size_m: the voxel size (for the message).
        what: the map's name (for the message).
    """
    voxels = 1
    for count in shape:
        voxels *= int(count)
    needed = voxels * float(bytes_per_voxel)
    available = physical_memory_bytes()
    if available is not None and needed > available / 2:
        raise ValueError(
            f"{what}: a {' x '.join(str(int(c)) for c in shape)} grid of {voxel_size_m:g} m "
            f"voxels over the scene's bounds needs {needed / 2**30:.1f} GiB, more than half "
            f"this machine's {available / 2**30:.1f} GiB; the scene is too large for this "
            "voxel size: crop the mesh to the part to explore, or give the map a larger voxel"
        )
