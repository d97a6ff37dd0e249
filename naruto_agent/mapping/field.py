"""The neural field: OneBlob + hash-grid encoding and two bias-free MLP decoders (Co-SLAM)."""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from naruto_agent.mapping import cpu_kernels
from naruto_agent.mapping.config import NeuralMapperConfig
from naruto_agent.mapping.encoding import ONE_BLOB_CUTOFF, HashGridEncoding, OneBlobEncoding


def _mlp(in_dim: int, hidden_dim: int, out_dim: int) -> nn.Sequential:
    """Two bias-free layers (the published decoders)."""
    return nn.Sequential(
        nn.Linear(in_dim, hidden_dim, bias=False),
        nn.ReLU(inplace=True),
        nn.Linear(hidden_dim, out_dim, bias=False),
    )


class NeuralField(nn.Module):
    """SDF (in units of the truncation distance) and colour at world points.

    The geometry MLP reads OneBlob + hash-grid features and outputs one SDF value plus
    ``geometry_feature_dim`` features; the colour MLP reads OneBlob + those features and
    outputs RGB through a sigmoid.

    Args:
        bounds: (2, 3) world box the encodings cover; points outside are clamped to it.
        config: the mapper settings.
        hash_encoding_cls: the hash-grid implementation (the naive one, for benchmarks).
        backend: "torch" (the PyTorch encodings, the reference) or "triton" (the decoder's
            input from the fused kernels of :mod:`naruto_agent.mapping.triton_kernels`; the
            caller has checked that they can run, see
            :func:`naruto_agent.mapping.backends.resolve_backend`).
    """

    def __init__(
        self,
        bounds: np.ndarray,
        config: NeuralMapperConfig,
        hash_encoding_cls: type[HashGridEncoding] = HashGridEncoding,
        backend: str = "torch",
    ) -> None:
        super().__init__()
        if backend not in ("torch", "triton"):
            raise ValueError(
                f"NeuralField backend must be 'torch' or 'triton' (resolve 'auto' with "
                f"naruto_agent.mapping.backends.resolve_backend), got {backend!r}"
            )
        self.backend = backend
        bounds = np.asarray(bounds, dtype=np.float64)
        extent = bounds[1] - bounds[0]
        self.register_buffer("lower", torch.tensor(bounds[0], dtype=torch.float32))
        self.register_buffer("inverse_extent", torch.tensor(1.0 / extent, dtype=torch.float32))
        finest = max(float(extent.max()) / config.hash_finest_voxel_m, config.hash_base_resolution)
        self.one_blob = OneBlobEncoding(config.one_blob_bins)
        self.hash_grid = hash_encoding_cls(
            num_levels=config.hash_levels,
            features_per_level=config.hash_features_per_level,
            log2_table_size=config.hash_log2_table_size,
            base_resolution=config.hash_base_resolution,
            finest_resolution=finest,
        )
        self.geometry_feature_dim = config.geometry_feature_dim
        self.geometry_mlp = _mlp(
            self.one_blob.output_dim + self.hash_grid.output_dim,
            config.hidden_dim,
            1 + config.geometry_feature_dim,
        )
        self.colour_mlp = _mlp(
            self.one_blob.output_dim + config.geometry_feature_dim, config.hidden_dim, 3
        )

    def normalise(self, points: torch.Tensor) -> torch.Tensor:
        """World points -> [0, 1]^3 inside the bounds (clamped)."""
        return ((points - self.lower) * self.inverse_extent).clamp(0.0, 1.0)

    def decoder_input(self, unit: torch.Tensor) -> torch.Tensor:
        """(N, 3 bins + L F) geometry-decoder input of positions in [0, 1]: OneBlob features,
        then hash-grid features (one fused kernel on the Triton backend)."""
        if self.backend == "triton":
            from naruto_agent.mapping import triton_kernels

            return triton_kernels.field_inputs(
                self.hash_grid, unit, self.one_blob.num_bins, ONE_BLOB_CUTOFF
            )
        return torch.cat([self.one_blob(unit), self.hash_grid(unit)], dim=1)

    def fast_path_error(self, count: int = 257, seed: int = 0) -> str | None:
        """Why the Triton backend cannot be trusted on this device, or None when it can.

        Evaluates the decoder input (values and hash-table gradient) on ``count`` random
        points with the fused kernels and with the PyTorch encodings and compares them; this
        also compiles the kernels, which a first mapping iteration would do anyway. A failure
        to compile (an unsupported GPU, a broken toolchain) is reported, not raised.
        """
        generator = torch.Generator().manual_seed(seed)
        unit = torch.rand(count, 3, generator=generator).to(self.lower.device)
        weights = torch.rand(count, self.geometry_mlp[0].in_features, generator=generator)
        weights = weights.to(self.lower.device)
        table = self.hash_grid.table
        try:
            from naruto_agent.mapping import triton_kernels

            with torch.enable_grad():
                fast = triton_kernels.field_inputs(
                    self.hash_grid, unit, self.one_blob.num_bins, ONE_BLOB_CUTOFF
                )
                (fast_grad,) = torch.autograd.grad((fast * weights).sum(), table)
                reference = torch.cat([self.one_blob(unit), self.hash_grid(unit)], dim=1)
                (reference_grad,) = torch.autograd.grad((reference * weights).sum(), table)
        except Exception as error:  # noqa: BLE001 (any compile or launch failure)
            return f"the Triton kernels failed: {type(error).__name__}: {error}"
        fast, reference = fast.detach(), reference.detach()
        scale = float(reference.abs().max()) + 1e-6
        grad_scale = float(reference_grad.abs().max()) + 1e-6
        if not torch.allclose(fast, reference, rtol=1e-4, atol=1e-5 * scale):
            return "the Triton kernels' features differ from the PyTorch reference"
        if not torch.allclose(fast_grad, reference_grad, rtol=1e-3, atol=1e-4 * grad_scale):
            return "the Triton kernels' table gradient differs from the PyTorch reference"
        return None

    def forward(self, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(N, 3) world points -> (SDF (N,) in truncation units, RGB (N, 3) in [0, 1])."""
        unit = self.normalise(points)
        if self.backend == "triton":
            inputs = self.decoder_input(unit)
            # OneBlob depends on no parameter: detached, the colour decoder's backward skips
            # its columns (as it does for the separately computed OneBlob below).
            blob = inputs[:, : self.one_blob.output_dim].detach()
        else:
            blob = self.one_blob(unit)
            inputs = torch.cat([blob, self.hash_grid(unit)], dim=1)
        geometry = self.geometry_mlp(inputs)
        rgb = torch.sigmoid(self.colour_mlp(torch.cat([blob, geometry[:, 1:]], dim=1)))
        return geometry[:, 0], rgb

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        """(N,) SDF in truncation units (skips the colour decoder)."""
        unit = self.normalise(points)
        if (
            self.backend == "torch"
            and not torch.is_grad_enabled()
            and self.hash_grid.uses_cpu_kernel(unit)
        ):
            return self._sdf_compiled(unit)
        return self.geometry_mlp(self.decoder_input(unit))[:, 0]

    def _sdf_compiled(self, unit: torch.Tensor) -> torch.Tensor:
        """The SDF without gradients on a CPU: the decoder's input (OneBlob + hash grid) from
        one compiled loop (:func:`cpu_kernels.field_inputs`), and of the decoder's last layer
        only the SDF row."""
        scales, multipliers = self.hash_grid.kernel_constants()
        inputs = cpu_kernels.field_inputs(
            unit.detach().contiguous().numpy(),
            self.hash_grid.table.detach().numpy(),
            scales,
            multipliers,
            self.hash_grid.num_dense_levels,
            self.hash_grid.table_size,
            self.one_blob.num_bins,
            ONE_BLOB_CUTOFF,
        )
        first, _, last = self.geometry_mlp
        hidden = torch.relu(F.linear(torch.from_numpy(inputs), first.weight))
        return F.linear(hidden, last.weight[:1]).squeeze(1)

    def grid_features(self, points: torch.Tensor) -> torch.Tensor:
        """(N, levels * features) hash-grid features (for the smoothness loss)."""
        unit = self.normalise(points)
        if self.backend == "triton":
            from naruto_agent.mapping import triton_kernels

            return triton_kernels.hash_grid_features(self.hash_grid, unit)
        return self.hash_grid(unit)
