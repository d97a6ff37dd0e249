"""Input encodings of the neural field: OneBlob and a multi-resolution hash grid, pure PyTorch.

The published system uses tiny-cuda-nn's fused CUDA kernels. Here both encodings are plain
PyTorch, so they run on a CPU and on CUDA with nothing to compile.

:class:`HashGridEncoding` is the fast one. It has no Python loop over levels: the eight cell
corners of every level are indexed in one pass, gathered in one lookup per feature channel
and blended with their trilinear weights in one ``einsum``:

* one table for all levels (level ``l`` owns rows ``[l * T, (l + 1) * T)``);
* a corner's index is ``(x * m0) ^ (y * m1) ^ (z * m2)`` masked to the table size. For a
  hashed level ``(m0, m1, m2)`` are the usual primes (1, 2654435761, 805459861); for a coarse
  level whose vertices fit in the table, the multipliers are powers of two that pack the three
  coordinates into disjoint bits, which makes the same formula a collision-free dense index.
  So dense and hashed levels share one code path, and the per-axis products are computed
  once per axis and corner side, not once per corner;
* indices and weights are built corner-major (``[8, L, N]``, N contiguous, which PyTorch's
  element-wise kernels run fast, where a point-major layout with a size-8 inner dimension
  runs several times slower);
* the backward pass scatters with ``torch.bincount`` (one weighted histogram per feature
  channel), which on a CPU is several times faster than ``index_add_`` or the stock
  ``embedding_bag`` backward (that one sorts the indices). On CUDA ``index_add_`` is used.
* the table is feature-major, (F, L * T), so each feature is one 1-D ``index_select``.

No gradient flows to the positions: the mapper has known poses, so none is needed.

:class:`NaiveHashGridEncoding` is the same function written the obvious way (a Python loop
over levels, one gather per corner): the reference the benchmark measures the speed-up
against, and the check in the tests that the fast path computes the same numbers.
"""

from __future__ import annotations

import math

import torch
from torch import nn

# Spatial-hash primes of Instant-NGP (the first is 1 so that x varies fastest).
_HASH_PRIMES = (1, 2654435761, 805459861)
_CORNERS = [(i, j, k) for i in (0, 1) for j in (0, 1) for k in (0, 1)]
# OneBlob kernel values beyond this many standard deviations are 0 (they are below 1e-17).
_ONE_BLOB_CUTOFF = 9.0


def level_resolutions(
    num_levels: int, base_resolution: int, finest_resolution: float
) -> list[int]:
    """Grid resolution of each level: a geometric progression from base to finest."""
    if num_levels < 1:
        raise ValueError(f"num_levels must be at least 1, got {num_levels}")
    if base_resolution < 1 or finest_resolution < base_resolution:
        raise ValueError(
            f"need 1 <= base_resolution <= finest_resolution, got {base_resolution} and "
            f"{finest_resolution}"
        )
    if num_levels == 1:
        return [int(base_resolution)]
    scale = math.exp(math.log(finest_resolution / base_resolution) / (num_levels - 1))
    return [int(math.floor(base_resolution * scale**level + 1e-6)) for level in range(num_levels)]


def _level_multipliers(resolutions: list[int], log2_table_size: int) -> torch.Tensor:
    """(3, L) int64 per-axis multipliers: bit packing for dense levels, primes for hashed."""
    multipliers = torch.zeros(3, len(resolutions), dtype=torch.int64)
    for level, resolution in enumerate(resolutions):
        # Corner coordinates run over 0 .. resolution + 1 (the +1 corner of the last cell).
        bits = max(1, math.ceil(math.log2(resolution + 2)))
        if 3 * bits <= log2_table_size:
            multipliers[:, level] = torch.tensor([1, 1 << bits, 1 << (2 * bits)])
        else:
            multipliers[:, level] = torch.tensor(_HASH_PRIMES)
    return multipliers


class OneBlobEncoding(nn.Module):
    """OneBlob encoding: each coordinate in [0, 1] becomes ``num_bins`` Gaussian kernel values.

    Args:
        num_bins: bins per axis (16 in the published system).
    """

    def __init__(self, num_bins: int = 16) -> None:
        super().__init__()
        if num_bins < 1:
            raise ValueError(f"num_bins must be at least 1, got {num_bins}")
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
        # matrix product with denormal inputs runs up to 10x slower on x86 CPUs.
        values = torch.exp(-0.5 * squared).masked_fill_(squared > _ONE_BLOB_CUTOFF**2, 0.0)
        return values.reshape(unit_positions.shape[0], -1)


class _CornerGather(torch.autograd.Function):
    """out[f, b] = sum_c weights[c, b] * table[f, indices[c, b]]; gradient to the table only.

    Corner-major layout (``indices`` and ``weights`` are (8, B)) so that nothing has to be
    transposed; the table is feature-major (F, rows) so each feature is a 1-D gather.
    """

    @staticmethod
    def forward(ctx, table, indices, weights):  # noqa: ANN001, ANN205
        ctx.save_for_backward(indices, weights)
        ctx.table_rows = table.shape[1]
        flat = indices.reshape(-1)
        out = torch.empty((table.shape[0], weights.shape[1]), dtype=table.dtype,
                          device=table.device)
        for f in range(table.shape[0]):
            corners = table[f].index_select(0, flat).view_as(weights)
            # Accumulating corner by corner is about 2x faster than an einsum (a strided bmm).
            torch.mul(corners[0], weights[0], out=out[f])
            for c in range(1, corners.shape[0]):
                out[f].addcmul_(corners[c], weights[c])
        return out

    @staticmethod
    def backward(ctx, grad_output):  # noqa: ANN001, ANN205
        indices, weights = ctx.saved_tensors
        flat = indices.reshape(-1)
        values = [
            (weights * grad_output[f][None, :]).reshape(-1) for f in range(grad_output.shape[0])
        ]
        if grad_output.is_cuda:
            grad_table = torch.zeros((len(values), ctx.table_rows), device=grad_output.device,
                                     dtype=grad_output.dtype)
            for f, value in enumerate(values):
                grad_table[f].index_add_(0, flat.long(), value)
            return grad_table, None, None
        # A weighted histogram per feature: on a CPU several times faster than index_add_.
        # (Running the features' histograms in Python threads was tried: slower, because the
        # threads fight the idle-spinning OpenMP workers for the cores.)
        rows = [torch.bincount(flat, weights=value, minlength=ctx.table_rows) for value in values]
        return torch.stack([row.to(grad_output.dtype) for row in rows]), None, None


class HashGridEncoding(nn.Module):
    """Multi-resolution hash-grid encoding (Instant-NGP style), batched over all levels.

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
        if not 1 <= log2_table_size <= 26:
            raise ValueError(f"log2_table_size must be in 1..26, got {log2_table_size}")
        self.num_levels = int(num_levels)
        self.features_per_level = int(features_per_level)
        self.log2_table_size = int(log2_table_size)
        self.table_size = 1 << self.log2_table_size
        self.resolutions = level_resolutions(num_levels, base_resolution, finest_resolution)
        # Feature-major (F, L * T): each feature channel is gathered as one 1-D lookup.
        self.table = nn.Parameter(
            (torch.rand(self.features_per_level, self.num_levels * self.table_size) * 2.0 - 1.0)
            * init_scale
        )
        self.register_buffer(
            "scales", torch.tensor(self.resolutions, dtype=torch.float32).view(1, -1, 1)
        )
        self.register_buffer(
            "multipliers", _level_multipliers(self.resolutions, self.log2_table_size)[:, :, None]
        )
        self.register_buffer(
            "level_offsets",
            (torch.arange(self.num_levels, dtype=torch.int64) * self.table_size)[:, None],
        )
        # The hash needs only the multipliers' low bits, (c * m) mod T == (c * (m mod T)) mod T,
        # so with reduced multipliers the products of corner coordinates (< 2^coordinate_bits)
        # fit in int32 whenever log2(T) + coordinate_bits <= 31. int32 halves the memory
        # traffic of every index array; the summed table must fit too.
        coordinate_bits = math.ceil(math.log2(max(self.resolutions) + 2))
        fits_int32 = (
            self.log2_table_size + coordinate_bits <= 31
            and self.num_levels * self.table_size < 2**31
        )
        self._index_dtype = torch.int32 if fits_int32 else torch.int64
        self.register_buffer(
            "reduced_multipliers",
            (self.multipliers & (self.table_size - 1)).to(self._index_dtype),
            persistent=False,
        )
        self.register_buffer(
            "index_level_offsets", self.level_offsets.to(self._index_dtype), persistent=False
        )

    @property
    def output_dim(self) -> int:
        return self.num_levels * self.features_per_level

    def corner_indices_and_weights(
        self, unit_positions: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Table rows and trilinear weights of every corner: two (8, L * N) tensors."""
        scaled = unit_positions.t().contiguous()[:, None, :] * self.scales  # (3, L, N)
        floor = torch.floor(scaled)
        fraction = scaled - floor
        corner = floor.to(self._index_dtype)
        mask = self.table_size - 1
        low = (corner * self.reduced_multipliers) & mask
        high = ((corner + 1) * self.reduced_multipliers) & mask
        # The level offset is added on the x term only: XOR with bits above the mask is a sum.
        low[0] += self.index_level_offsets
        high[0] += self.index_level_offsets
        sides = (low, high)
        weights_per_side = (1.0 - fraction, fraction)
        # Pair x and y first (4 combinations), then z: 12 element-wise ops instead of 16,
        # each writing straight into its contiguous corner slice (no stack/cat copy).
        xy_index = {(i, j): sides[i][0] ^ sides[j][1] for i in (0, 1) for j in (0, 1)}
        xy_weight = {
            (i, j): weights_per_side[i][0] * weights_per_side[j][1] for i in (0, 1) for j in (0, 1)
        }
        indices = torch.empty((8, *fraction.shape[1:]), dtype=self._index_dtype,
                              device=fraction.device)
        weights = torch.empty((8, *fraction.shape[1:]), dtype=fraction.dtype,
                              device=fraction.device)
        for c, (i, j, k) in enumerate(_CORNERS):
            torch.bitwise_xor(xy_index[i, j], sides[k][2], out=indices[c])
            torch.mul(xy_weight[i, j], weights_per_side[k][2], out=weights[c])
        return indices.view(8, -1), weights.view(8, -1)

    def forward(self, unit_positions: torch.Tensor) -> torch.Tensor:
        """(N, 3) positions in [0, 1] -> (N, num_levels * features_per_level) features."""
        count = unit_positions.shape[0]
        unit_positions = unit_positions.clamp(0.0, 1.0)
        indices, weights = self.corner_indices_and_weights(unit_positions)
        features = _CornerGather.apply(self.table, indices, weights.to(self.table.dtype))
        # (F, L, N) -> (N, L * F), level-major like tiny-cuda-nn's output.
        return (
            features.view(self.features_per_level, self.num_levels, count)
            .permute(2, 1, 0)
            .reshape(count, self.output_dim)
        )


class NaiveHashGridEncoding(HashGridEncoding):
    """The same encoding written plainly: a loop over levels, one gather per corner.

    Kept as the speed reference of the benchmark and as the correctness reference of the
    tests; it has the same parameters and state as :class:`HashGridEncoding`.
    """

    def forward(self, unit_positions: torch.Tensor) -> torch.Tensor:
        unit_positions = unit_positions.clamp(0.0, 1.0)
        mask = self.table_size - 1
        outputs = []
        for level, resolution in enumerate(self.resolutions):
            scaled = unit_positions * resolution
            floor = torch.floor(scaled)
            fraction = scaled - floor
            corner = floor.long()
            multipliers = self.multipliers[:, level, 0]
            level_features = 0.0
            for i, j, k in _CORNERS:
                offset = torch.tensor([i, j, k], device=corner.device)
                hashed = (corner + offset) * multipliers
                index = (hashed[:, 0] ^ hashed[:, 1] ^ hashed[:, 2]) & mask
                weight = (
                    (fraction[:, 0] if i else 1.0 - fraction[:, 0])
                    * (fraction[:, 1] if j else 1.0 - fraction[:, 1])
                    * (fraction[:, 2] if k else 1.0 - fraction[:, 2])
                )
                rows = self.table[:, index + level * self.table_size].t()
                level_features = level_features + weight[:, None] * rows
            outputs.append(level_features)
        return torch.cat(outputs, dim=1)
