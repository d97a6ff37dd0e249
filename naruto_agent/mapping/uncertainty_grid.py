"""NARUTO's uncertainty grid: a dense 0.1 m grid of learnable log-variances.

Each cell holds a raw value (initialised to 3.0); the variance at a point is
``softplus(trilinear(raw)) + 0.01``. A ray's rendered variance is ``sum_i w_i^2 sigma_i^2``
over its samples, and the grid learns from a Gaussian negative log-likelihood of the rendered
depth (weight 0.005), with its own Adam optimiser (learning rate 1.0).

Axis order is (x, y, z): ``raw[i, j, k]`` sits at ``origin + voxel_size * (i, j, k)``. (The
released NARUTO code swaps x and z when it samples the grid; this one does not.)
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn


class UncertaintyGrid(nn.Module):
    """A dense trilinear grid of raw uncertainty values over a world box.

    Args:
        bounds: (2, 3) [min, max] world box, metres.
        voxel_size: cell size (0.1 m).
        init_value: initial raw value of every cell (3.0).
        min_variance: variance floor added after the softplus (0.01).
    """

    def __init__(
        self,
        bounds: np.ndarray,
        voxel_size: float = 0.1,
        init_value: float = 3.0,
        min_variance: float = 0.01,
    ) -> None:
        super().__init__()
        bounds = np.asarray(bounds, dtype=np.float64)
        if not voxel_size > 0:
            raise ValueError(f"voxel_size must be positive, got {voxel_size}")
        counts = np.maximum(np.ceil((bounds[1] - bounds[0]) / voxel_size - 1e-9).astype(int) + 1, 2)
        self.shape = tuple(int(c) for c in counts)
        self.voxel_size = float(voxel_size)
        self.min_variance = float(min_variance)
        self.register_buffer("origin", torch.tensor(bounds[0], dtype=torch.float32))
        self.register_buffer("upper_index", torch.tensor(counts - 1, dtype=torch.float32))
        self.register_buffer(
            "strides",
            torch.tensor([self.shape[1] * self.shape[2], self.shape[2], 1], dtype=torch.int64),
        )
        # Per-axis factor from world offsets to grid_sampler coordinates (+1).
        self.register_buffer(
            "coordinate_scale",
            torch.tensor(2.0 / ((counts - 1) * voxel_size), dtype=torch.float32),
            persistent=False,
        )
        self.raw = nn.Parameter(torch.full(self.shape, float(init_value), dtype=torch.float32))

    @property
    def origin_numpy(self) -> np.ndarray:
        return self.origin.detach().cpu().numpy().astype(np.float64)

    def raw_at(self, points: torch.Tensor) -> torch.Tensor:
        """(N,) trilinear raw value at (N, 3) world points (clamped to the grid).

        One fused ``grid_sampler`` call (trilinear, border padding = clamping, corners
        aligned with the voxel centres), forward and backward, instead of eight gathers.
        """
        # grid_sampler's coordinate of voxel index i is 2 i / (n - 1) - 1; its last grid
        # axis indexes the input's last dimension, so (x, y, z) goes in as (z, y, x).
        coords = (points - self.origin) * self.coordinate_scale - 1.0
        grid = coords.flip(-1).reshape(1, 1, 1, -1, 3).to(self.raw.dtype)
        sampled = torch.grid_sampler(self.raw[None, None], grid, 0, 1, True)
        return sampled.reshape(-1)

    def raw_at_reference(self, points: torch.Tensor) -> torch.Tensor:
        """:meth:`raw_at` written out over the eight corners (the tests' reference)."""
        index = ((points - self.origin) / self.voxel_size).clamp(min=0.0)
        index = torch.minimum(index, self.upper_index)
        cell = torch.minimum(torch.floor(index), self.upper_index - 1.0)
        fraction = index - cell
        base = (cell.long() * self.strides).sum(dim=1)
        flat = self.raw.reshape(-1)
        sx, sy, sz = (int(s) for s in self.strides)
        fx, fy, fz = fraction.unbind(dim=1)
        gx, gy, gz = 1.0 - fx, 1.0 - fy, 1.0 - fz
        c00 = flat[base] * gz + flat[base + sz] * fz
        c01 = flat[base + sy] * gz + flat[base + sy + sz] * fz
        c10 = flat[base + sx] * gz + flat[base + sx + sz] * fz
        c11 = flat[base + sx + sy] * gz + flat[base + sx + sy + sz] * fz
        return (c00 * gy + c01 * fy) * gx + (c10 * gy + c11 * fy) * fx

    def variance(self, points: torch.Tensor) -> torch.Tensor:
        """(N,) sigma^2 = softplus(raw) + min_variance at world points."""
        return F.softplus(self.raw_at(points)) + self.min_variance

    def variance_grid(self) -> torch.Tensor:
        """(nx, ny, nz) sigma^2 at the grid's own voxel centres."""
        return F.softplus(self.raw) + self.min_variance


def gaussian_nll(
    rendered_depth: torch.Tensor, target_depth: torch.Tensor, variance: torch.Tensor
) -> torch.Tensor:
    """mean((d_hat - d)^2 / (2 U)) + 0.5 mean(log U) over the given rays."""
    return ((rendered_depth - target_depth) ** 2 / (2.0 * variance)).mean() + 0.5 * torch.log(
        variance
    ).mean()
