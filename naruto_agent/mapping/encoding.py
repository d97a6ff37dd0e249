"""Input encodings of the neural field: OneBlob and a multi-resolution hash grid, pure PyTorch.

The published system uses tiny-cuda-nn's fused CUDA kernels. Here both encodings are plain
PyTorch, so they run on a CPU and on CUDA with nothing to compile.

:class:`HashGridEncoding` is the fast one. One table holds all levels (level ``l`` owns rows
``[l * T, (l + 1) * T)``), feature-major ``(F, L * T)``. Levels come in two kinds:

* **dense** coarse levels, whose ``(resolution + 2)^3`` vertices fit in ``T`` rows: each
  vertex has its own row (``x + S y + S^2 z`` with one side ``S`` for all dense levels), so
  the level is a small ``S^3`` volume. All dense levels are interpolated together by one
  batched ``torch.grid_sampler`` call, whose fused trilinear kernel (and its backward) beats
  gathering the eight corners one by one;
* **hashed** finer levels: a corner's row is ``(x * m0) ^ (y * m1) ^ (z * m2)`` masked to the
  table size, with the usual primes (1, 2654435761, 805459861). These have no Python loop
  over levels: the eight cell corners of every hashed level are indexed in one pass
  (corner-major ``[8, L, N]``, N contiguous, which PyTorch's element-wise kernels run fast),
  gathered with one 1-D ``index_select`` per feature and blended corner by corner.
  Only the multipliers' low bits matter after the mask, so the products run in int32.
  The backward pass scatters with ``torch.bincount`` (one weighted histogram per feature),
  which on a CPU is faster than ``index_add_`` or the stock ``embedding_bag`` backward (that
  one sorts the indices); on CUDA ``index_add_`` is used.

No gradient flows to the positions: the mapper has known poses, so none is needed.

:class:`NaiveHashGridEncoding` is the same function written the obvious way (a Python loop
over levels, one gather per corner): the reference the benchmark measures the speed-up
against, and the check in the tests that the fast path computes the same numbers.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

from naruto_agent.mapping import cpu_kernels
from naruto_gym.utils.checks import check_integer, check_number

# Spatial-hash primes of Instant-NGP (the first is 1 so that x varies fastest).
_HASH_PRIMES = (1, 2654435761, 805459861)
_CORNERS = [(i, j, k) for i in (0, 1) for j in (0, 1) for k in (0, 1)]
# OneBlob kernel values beyond this many standard deviations are 0 (they are below 1e-17).
ONE_BLOB_CUTOFF = 9.0


def level_resolutions(num_levels: int, base_resolution: int, finest_resolution: float) -> list[int]:
    """Grid resolution of each level: a geometric progression from base to finest."""
    check_integer("num_levels", num_levels, low=1)
    check_number("base_resolution", base_resolution, low=1.0, low_open=False)
    check_number("finest_resolution", finest_resolution, low=base_resolution, low_open=False)
    if num_levels == 1:
        return [int(base_resolution)]
    scale = math.exp(math.log(finest_resolution / base_resolution) / (num_levels - 1))
    return [int(math.floor(base_resolution * scale**level + 1e-6)) for level in range(num_levels)]


def dense_level_layout(resolutions: list[int], log2_table_size: int) -> tuple[int, int]:
    """(number of dense levels, side S of their volumes).

    A level is dense when its ``(resolution + 2)^3`` vertices (corner coordinates run up to
    resolution + 1) fit in the level's ``2^log2_table_size`` rows. Resolutions grow, so the
    dense levels are the first ones; they all use the side of the finest of them.
    """
    table_size = 1 << log2_table_size
    sides = [resolution + 2 for resolution in resolutions if (resolution + 2) ** 3 <= table_size]
    return len(sides), max(sides, default=0)


def _level_multipliers(resolutions: list[int], log2_table_size: int) -> torch.Tensor:
    """(3, L) int64 per-axis multipliers: (1, S, S^2) for dense levels, primes for hashed."""
    num_dense, side = dense_level_layout(resolutions, log2_table_size)
    multipliers = torch.zeros(3, len(resolutions), dtype=torch.int64)
    multipliers[:, :num_dense] = torch.tensor([1, side, side * side])[:, None]
    multipliers[:, num_dense:] = torch.tensor(_HASH_PRIMES)[:, None]
    return multipliers


class OneBlobEncoding(nn.Module):
    """OneBlob encoding: each coordinate in [0, 1] becomes ``num_bins`` Gaussian kernel values.

    Args:
        num_bins: bins per axis (16 in the published system).
    """

    def __init__(self, num_bins: int = 16) -> None:
        super().__init__()
        check_integer("num_bins", num_bins, low=1)
        self.num_bins = int(num_bins)
        self.register_buffer(
            "centres", (torch.arange(num_bins, dtype=torch.float32) + 0.5) / num_bins
        )
        self.sigma = 1.0 / num_bins

    @property
    def output_dim(self) -> int:
        return 3 * self.num_bins

    def forward(self, unit_positions: torch.Tensor) -> torch.Tensor:
        """(N, 3) positions in [0, 1] -> (N, 3 * num_bins) features."""
        offset = (unit_positions[:, :, None] - self.centres) * (1.0 / self.sigma)
        squared = offset * offset
        # Far tails are set to exactly 0: exp() of them would be float32 denormals, and a
        # matrix product with denormal inputs runs far slower on x86 CPUs.
        values = torch.exp(-0.5 * squared).masked_fill_(squared > ONE_BLOB_CUTOFF**2, 0.0)
        return values.reshape(unit_positions.shape[0], -1)


class _HashGridFunction(torch.autograd.Function):
    """Features ``(F, L, N)`` of all levels; the gradient goes to the table only.

    Dense levels: one batched ``torch.grid_sampler`` over their ``S^3`` volumes. Hashed levels:
    ``out[f, b] = sum_c weights[c, b] * table[f, indices[c, b]]`` over the eight corners.
    """

    @staticmethod
    def forward(ctx, table, unit_positions, encoding):  # noqa: ANN001, ANN205
        features, num_levels = table.shape[0], encoding.num_levels
        count = unit_positions.shape[0]
        num_dense = encoding.num_dense_levels
        out = table.new_empty((features, num_levels, count))
        ctx.table_rows = table.shape[1]
        ctx.encoding = encoding
        saved: list[torch.Tensor] = []
        if num_dense < num_levels:
            indices, weights = encoding.corner_indices_and_weights(unit_positions)
            flat = indices.reshape(-1)
            hashed = out[:, num_dense:].view(features, -1)
            for f in range(features):
                corners = table[f].index_select(0, flat).view_as(weights)
                # Accumulating corner by corner is faster than an einsum (a strided bmm) here.
                torch.mul(corners[0], weights[0], out=hashed[f])
                for c in range(1, corners.shape[0]):
                    hashed[f].addcmul_(corners[c], weights[c])
            saved += [indices, weights]
        if num_dense:
            volumes = encoding.dense_volumes(table)
            grid = encoding.dense_sampling_grid(unit_positions)
            sampled = torch.grid_sampler(volumes, grid, 0, 0, True)  # bilinear, zeros, corners
            out[:, :num_dense] = sampled.view(num_dense, features, count).transpose(0, 1)
            saved += [volumes, grid]
        ctx.save_for_backward(*saved)
        return out

    @staticmethod
    def backward(ctx, grad_output):  # noqa: ANN001, ANN205
        encoding = ctx.encoding
        num_dense, num_levels = encoding.num_dense_levels, encoding.num_levels
        features, _, count = grad_output.shape
        saved = list(ctx.saved_tensors)
        if num_dense < num_levels:
            indices, weights = saved[:2]
            saved = saved[2:]
            flat = indices.reshape(-1)
            grad_hashed = grad_output[:, num_dense:].reshape(features, -1)
            values = [(weights * grad_hashed[f][None, :]).reshape(-1) for f in range(features)]
            if grad_output.is_cuda:
                grad_table = grad_output.new_zeros((features, ctx.table_rows))
                for f, value in enumerate(values):
                    grad_table[f].index_add_(0, flat.long(), value)
            else:
                # A weighted histogram per feature: on a CPU faster than index_add_. Serial,
                # not in Python threads, which would fight the idle-spinning OpenMP workers
                # for the cores.
                grad_table = torch.stack(
                    [
                        torch.bincount(flat, weights=value, minlength=ctx.table_rows).to(
                            grad_output.dtype
                        )
                        for value in values
                    ]
                )
        else:
            grad_table = grad_output.new_zeros((features, ctx.table_rows))
        if num_dense:
            volumes, grid = saved
            grad_dense = (
                grad_output[:, :num_dense].transpose(0, 1).reshape(num_dense, features, 1, 1, count)
            )
            grad_volumes, _ = torch.ops.aten.grid_sampler_3d_backward(
                grad_dense, volumes, grid, 0, 0, True, [True, False]
            )
            side_cubed = volumes.shape[-1] ** 3
            dense_rows = grad_table.view(features, num_levels, -1)[:, :num_dense, :side_cubed]
            dense_rows += grad_volumes.view(num_dense, features, side_cubed).transpose(0, 1)
        return grad_table, None, None


class HashGridEncoding(nn.Module):
    """Multi-resolution hash-grid encoding (Instant-NGP style) with dense coarse levels.

    Args:
        num_levels: number of levels (16).
        features_per_level: features stored per table row (2).
        log2_table_size: log2 of the rows per level (16, i.e. 2^16 entries).
        base_resolution: resolution of the coarsest level (16).
        finest_resolution: resolution of the finest level (largest scene extent / 0.02 m).
        init_scale: table entries start uniform in [-init_scale, init_scale].
    """

    def __init__(
        self,
        num_levels: int = 16,
        features_per_level: int = 2,
        log2_table_size: int = 16,
        base_resolution: int = 16,
        finest_resolution: float = 256.0,
        init_scale: float = 1e-4,
    ) -> None:
        super().__init__()
        check_integer("log2_table_size", log2_table_size, low=1, high=26)
        self.num_levels = int(num_levels)
        self.features_per_level = int(features_per_level)
        self.log2_table_size = int(log2_table_size)
        self.table_size = 1 << self.log2_table_size
        self.resolutions = level_resolutions(num_levels, base_resolution, finest_resolution)
        self.num_dense_levels, self.dense_side = dense_level_layout(
            self.resolutions, self.log2_table_size
        )
        # Feature-major (F, L * T): each feature channel is gathered as one 1-D lookup.
        self.table = nn.Parameter(
            (torch.rand(self.features_per_level, self.num_levels * self.table_size) * 2.0 - 1.0)
            * init_scale
        )
        # The layout below follows from the settings, so it is not part of the state dict.
        resolutions = torch.tensor(self.resolutions, dtype=torch.float32)
        multipliers = _level_multipliers(self.resolutions, self.log2_table_size)
        self.register_buffer("multipliers", multipliers[:, :, None], persistent=False)
        self.register_buffer(
            "level_offsets",
            (torch.arange(self.num_levels, dtype=torch.int64) * self.table_size)[:, None],
            persistent=False,
        )
        # Hashed levels: the hash needs only the multipliers' low bits,
        # (c * m) mod T == (c * (m mod T)) mod T, so with reduced multipliers the products of
        # corner coordinates (< 2^coordinate_bits) fit in int32 whenever
        # log2(T) + coordinate_bits <= 31. int32 halves the traffic of every index array.
        hashed = slice(self.num_dense_levels, None)
        coordinate_bits = math.ceil(math.log2(max(self.resolutions) + 2))
        fits_int32 = (
            self.log2_table_size + coordinate_bits <= 31
            and self.num_levels * self.table_size < 2**31
        )
        self._index_dtype = torch.int32 if fits_int32 else torch.int64
        self.register_buffer(
            "hashed_scales", resolutions[hashed].view(1, -1, 1).clone(), persistent=False
        )
        self.register_buffer(
            "hashed_multipliers",
            (multipliers[:, hashed, None] & (self.table_size - 1)).to(self._index_dtype),
            persistent=False,
        )
        self.register_buffer(
            "hashed_offsets",
            self.level_offsets[hashed].to(self._index_dtype).clone(),
            persistent=False,
        )
        # Dense levels: grid_sampler's align_corners coordinate of vertex index i is
        # 2 i / (S - 1) - 1, and a point's vertex index is unit * resolution.
        self.register_buffer(
            "dense_grid_scales",
            (resolutions[: self.num_dense_levels] * 2.0 / max(self.dense_side - 1, 1)).view(
                -1, 1, 1, 1, 1
            ),
            persistent=False,
        )

        # No-gradient queries on a CPU take a compiled loop (:mod:`cpu_kernels`); False keeps
        # them on the PyTorch path (the reference the tests compare against).
        self.cpu_kernel = True
        self._kernel_constants: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def output_dim(self) -> int:
        return self.num_levels * self.features_per_level

    def vertex_rows(self, level: int, vertices: torch.Tensor) -> torch.Tensor:
        """Table rows of integer grid vertices ``(M, 3)`` of one level (the reference layout)."""
        multipliers = self.multipliers[:, level, 0].to(vertices.device)
        scaled = vertices.long() * multipliers
        if level < self.num_dense_levels:
            local = scaled.sum(dim=1)
        else:
            local = (scaled[:, 0] ^ scaled[:, 1] ^ scaled[:, 2]) & (self.table_size - 1)
        return local + level * self.table_size

    def dense_volumes(self, table: torch.Tensor) -> torch.Tensor:
        """The dense levels' rows as ``(levels, F, S, S, S)`` volumes, z slowest."""
        side, count = self.dense_side, self.num_dense_levels
        rows = table.view(self.features_per_level, self.num_levels, -1)[:, :count, : side**3]
        return rows.transpose(0, 1).reshape(count, self.features_per_level, side, side, side)

    def dense_sampling_grid(self, unit_positions: torch.Tensor) -> torch.Tensor:
        """``(levels, 1, 1, N, 3)`` grid_sampler coordinates of points in every dense level."""
        return unit_positions[None, None, None] * self.dense_grid_scales - 1.0

    def corner_indices_and_weights(
        self, unit_positions: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Table rows and trilinear weights of every corner of the hashed levels: two
        ``(8, hashed_levels * N)`` tensors."""
        scaled = unit_positions.t().contiguous()[:, None, :] * self.hashed_scales  # (3, L, N)
        floor = torch.floor(scaled)
        fraction = scaled - floor
        corner = floor.to(self._index_dtype)
        mask = self.table_size - 1
        low = (corner * self.hashed_multipliers) & mask
        high = ((corner + 1) * self.hashed_multipliers) & mask
        # The level offset is added on the x term only: XOR with bits above the mask is a sum.
        low[0] += self.hashed_offsets
        high[0] += self.hashed_offsets
        sides = (low, high)
        weights_per_side = (1.0 - fraction, fraction)
        # Pair x and y first (4 combinations), then z: 12 element-wise ops instead of 16,
        # each writing straight into its contiguous corner slice (no stack/cat copy).
        xy_index = {(i, j): sides[i][0] ^ sides[j][1] for i in (0, 1) for j in (0, 1)}
        xy_weight = {
            (i, j): weights_per_side[i][0] * weights_per_side[j][1] for i in (0, 1) for j in (0, 1)
        }
        indices = torch.empty(
            (8, *fraction.shape[1:]), dtype=self._index_dtype, device=fraction.device
        )
        weights = torch.empty(
            (8, *fraction.shape[1:]), dtype=fraction.dtype, device=fraction.device
        )
        for c, (i, j, k) in enumerate(_CORNERS):
            torch.bitwise_xor(xy_index[i, j], sides[k][2], out=indices[c])
            torch.mul(xy_weight[i, j], weights_per_side[k][2], out=weights[c])
        return indices.view(8, -1), weights.view(8, -1)

    def uses_cpu_kernel(self, unit_positions: torch.Tensor) -> bool:
        """Whether a call on ``unit_positions`` takes the compiled no-gradient loop
        (:mod:`cpu_kernels`): on a CPU, float32, published layout, no gradient wanted, and
        ``cpu_kernel`` on. A caller that fuses more work into that loop asks this first."""
        return (
            self.cpu_kernel
            and cpu_kernels.supports(self.features_per_level)
            and not unit_positions.is_cuda
            and not self.table.is_cuda
            and self.table.dtype == torch.float32
            and not (torch.is_grad_enabled() and self.table.requires_grad)
        )

    def kernel_constants(self) -> tuple[np.ndarray, np.ndarray]:
        """(L,) float32 level resolutions and (3, L) int64 row multipliers (hash primes
        reduced modulo the table size on hashed levels) for :mod:`cpu_kernels`."""
        if self._kernel_constants is None:
            multipliers = self.multipliers[:, :, 0].cpu().numpy().copy()
            multipliers[:, self.num_dense_levels :] &= self.table_size - 1
            self._kernel_constants = (
                np.asarray(self.resolutions, dtype=np.float32),
                np.ascontiguousarray(multipliers, dtype=np.int64),
            )
        return self._kernel_constants

    def _cpu_kernel_features(self, unit_positions: torch.Tensor) -> torch.Tensor:
        scales, multipliers = self.kernel_constants()
        features = cpu_kernels.hash_grid_features(
            unit_positions.detach().contiguous().numpy(),
            self.table.detach().numpy(),
            scales,
            multipliers,
            self.num_dense_levels,
            self.table_size,
        )
        return torch.from_numpy(features)

    def forward(self, unit_positions: torch.Tensor) -> torch.Tensor:
        """(N, 3) positions in [0, 1] -> (N, num_levels * features_per_level) features."""
        count = unit_positions.shape[0]
        unit_positions = unit_positions.clamp(0.0, 1.0).to(self.table.dtype)
        if self.uses_cpu_kernel(unit_positions):
            return self._cpu_kernel_features(unit_positions)
        features = _HashGridFunction.apply(self.table, unit_positions, self)
        # (F, L, N) -> (N, L * F), level-major like tiny-cuda-nn's output.
        return features.permute(2, 1, 0).reshape(count, self.output_dim)


class NaiveHashGridEncoding(HashGridEncoding):
    """The same encoding written plainly: a loop over levels, one gather per corner.

    Kept as the speed reference of the benchmark and as the correctness reference of the
    tests; it has the same parameters and state as :class:`HashGridEncoding`.
    """

    def forward(self, unit_positions: torch.Tensor) -> torch.Tensor:
        unit_positions = unit_positions.clamp(0.0, 1.0)
        outputs = []
        for level, resolution in enumerate(self.resolutions):
            scaled = unit_positions * resolution
            floor = torch.floor(scaled)
            fraction = scaled - floor
            corner = floor.long()
            level_features = 0.0
            for i, j, k in _CORNERS:
                offset = torch.tensor([i, j, k], device=corner.device)
                rows = self.table[:, self.vertex_rows(level, corner + offset)].t()
                weight = (
                    (fraction[:, 0] if i else 1.0 - fraction[:, 0])
                    * (fraction[:, 1] if j else 1.0 - fraction[:, 1])
                    * (fraction[:, 2] if k else 1.0 - fraction[:, 2])
                )
                level_features = level_features + weight[:, None] * rows
            outputs.append(level_features)
        return torch.cat(outputs, dim=1)
