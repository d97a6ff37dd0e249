"""Fused Triton kernels of the neural field's input encodings (the mapper's fast CUDA path).

One mapping iteration evaluates the field at about 92,000 points (2148 rays x 43 samples).
On a GPU that is little arithmetic: the PyTorch path of :class:`HashGridEncoding` spends its
time launching the dozens of small kernels that build corner indices and weights, gather,
blend, permute and concatenate. The kernels here do the same function in one launch each:

* :func:`field_inputs`: the geometry decoder's whole input, OneBlob features then hash-grid
  features (``NeuralField``'s concatenation), written straight into one ``(N, 3 B + L F)``
  buffer;
* :func:`hash_grid_features`: the hash-grid features alone (the smoothness loss).

Both are differentiable with respect to the hash table (an ``autograd.Function`` whose
backward is one scatter kernel with atomic adds, the tiny-cuda-nn approach); like the PyTorch
path, no gradient goes to the positions (the mapper's poses are known).

The maths is :class:`HashGridEncoding`'s: per level, the cell corners ``floor(u r)`` and
``floor(u r) + 1``, trilinear weights from the fraction, table row ``x + S y + S^2 z`` on dense
levels and ``(x m0 ^ y m1 ^ z m2) mod T`` on hashed ones (multipliers from
:meth:`HashGridEncoding.kernel_constants`), plus the level's row offset. Results agree with
the PyTorch path to float32 rounding; the backward's atomic adds make the order of the sums,
and so the last bits of the gradient, vary between runs on a GPU.

Triton is optional (``pip install triton``; it comes with CUDA builds of torch on Linux).
This module imports it, so only code that has chosen the Triton backend
(:func:`naruto_agent.mapping.backends.resolve_backend`) imports this module. The kernels
compile on first use. On a CPU they run only in Triton's interpreter (``TRITON_INTERPRET=1``
set before triton is imported), which is how the tests check them without a GPU.
"""

from __future__ import annotations

import weakref
from typing import Any

import torch
import triton
import triton.language as tl

_BLOCK = 128
# Kernel layouts of the encodings in use, dropped with the encoding.
_LAYOUTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


@triton.jit
def _row(x, y, z, dense, mask, offset):
    """Table row of a corner from its per-axis products: summed on a dense level, hashed
    (XOR, masked to the table) on a hashed one, plus the level's first row."""
    return tl.where(dense, x + y + z, (x ^ y ^ z) & mask) + offset


@triton.jit
def _cell(unit_ptr, scales_ptr, mult_ptr, offs, valid, level, num_levels):
    """Per-axis products of the lower and upper cell corners (x0, x1, y0, y1, z0, z1) with
    the level's row multipliers, and the upper corners' trilinear weights (wx1, wy1, wz1)."""
    ux = tl.load(unit_ptr + offs * 3 + 0, mask=valid, other=0.0)
    uy = tl.load(unit_ptr + offs * 3 + 1, mask=valid, other=0.0)
    uz = tl.load(unit_ptr + offs * 3 + 2, mask=valid, other=0.0)
    scale = tl.load(scales_ptr + level)
    px = ux * scale
    py = uy * scale
    pz = uz * scale
    fx = tl.floor(px)
    fy = tl.floor(py)
    fz = tl.floor(pz)
    wx1 = px - fx
    wy1 = py - fy
    wz1 = pz - fz
    mx = tl.load(mult_ptr + level)
    my = tl.load(mult_ptr + num_levels + level)
    mz = tl.load(mult_ptr + 2 * num_levels + level)
    x0 = fx.to(tl.int64) * mx
    y0 = fy.to(tl.int64) * my
    z0 = fz.to(tl.int64) * mz
    return x0, x0 + mx, y0, y0 + my, z0, z0 + mz, wx1, wy1, wz1


@triton.jit
def _corners(unit_ptr, scales_ptr, mult_ptr, offs, valid, level, num_levels, num_dense,
             table_size):
    """The eight corner rows of each point's cell on ``level`` (r000 ... r111, bits x y z)
    and their trilinear weights in the same order."""
    x0, x1, y0, y1, z0, z1, wx1, wy1, wz1 = _cell(
        unit_ptr, scales_ptr, mult_ptr, offs, valid, level, num_levels
    )
    dense = level < num_dense
    mask = table_size - 1
    offset = level.to(tl.int64) * table_size
    wx0 = 1.0 - wx1
    wy0 = 1.0 - wy1
    wz0 = 1.0 - wz1
    w00 = wx0 * wy0
    w01 = wx0 * wy1
    w10 = wx1 * wy0
    w11 = wx1 * wy1
    return (
        _row(x0, y0, z0, dense, mask, offset), _row(x0, y0, z1, dense, mask, offset),
        _row(x0, y1, z0, dense, mask, offset), _row(x0, y1, z1, dense, mask, offset),
        _row(x1, y0, z0, dense, mask, offset), _row(x1, y0, z1, dense, mask, offset),
        _row(x1, y1, z0, dense, mask, offset), _row(x1, y1, z1, dense, mask, offset),
        w00 * wz0, w00 * wz1, w01 * wz0, w01 * wz1, w10 * wz0, w10 * wz1, w11 * wz0, w11 * wz1,
    )


@triton.jit
def hash_forward(
    unit_ptr,
    table_ptr,
    scales_ptr,
    mult_ptr,
    out_ptr,
    count,
    table_cols,
    out_stride,
    out_column,
    num_levels,
    num_dense,
    table_size,
    FEATURES: tl.constexpr,
    BLOCK: tl.constexpr,
):
    level = tl.program_id(1)
    offs = tl.program_id(0).to(tl.int64) * BLOCK + tl.arange(0, BLOCK)
    valid = offs < count
    (r000, r001, r010, r011, r100, r101, r110, r111,
     w000, w001, w010, w011, w100, w101, w110, w111) = _corners(
        unit_ptr, scales_ptr, mult_ptr, offs, valid, level, num_levels, num_dense, table_size
    )
    for f in tl.static_range(FEATURES):
        base = table_ptr + f * table_cols
        value = (
            w000 * tl.load(base + r000, mask=valid, other=0.0)
            + w001 * tl.load(base + r001, mask=valid, other=0.0)
            + w010 * tl.load(base + r010, mask=valid, other=0.0)
            + w011 * tl.load(base + r011, mask=valid, other=0.0)
            + w100 * tl.load(base + r100, mask=valid, other=0.0)
            + w101 * tl.load(base + r101, mask=valid, other=0.0)
            + w110 * tl.load(base + r110, mask=valid, other=0.0)
            + w111 * tl.load(base + r111, mask=valid, other=0.0)
        )
        column = out_column + level * FEATURES + f
        tl.store(out_ptr + offs * out_stride + column, value, mask=valid)


@triton.jit
def hash_backward(
    unit_ptr,
    grad_ptr,
    scales_ptr,
    mult_ptr,
    grad_table_ptr,
    count,
    table_cols,
    grad_stride,
    grad_column,
    num_levels,
    num_dense,
    table_size,
    FEATURES: tl.constexpr,
    BLOCK: tl.constexpr,
):
    level = tl.program_id(1)
    offs = tl.program_id(0).to(tl.int64) * BLOCK + tl.arange(0, BLOCK)
    valid = offs < count
    (r000, r001, r010, r011, r100, r101, r110, r111,
     w000, w001, w010, w011, w100, w101, w110, w111) = _corners(
        unit_ptr, scales_ptr, mult_ptr, offs, valid, level, num_levels, num_dense, table_size
    )
    for f in tl.static_range(FEATURES):
        column = grad_column + level * FEATURES + f
        g = tl.load(grad_ptr + offs * grad_stride + column, mask=valid, other=0.0)
        base = grad_table_ptr + f * table_cols
        tl.atomic_add(base + r000, w000 * g, mask=valid)
        tl.atomic_add(base + r001, w001 * g, mask=valid)
        tl.atomic_add(base + r010, w010 * g, mask=valid)
        tl.atomic_add(base + r011, w011 * g, mask=valid)
        tl.atomic_add(base + r100, w100 * g, mask=valid)
        tl.atomic_add(base + r101, w101 * g, mask=valid)
        tl.atomic_add(base + r110, w110 * g, mask=valid)
        tl.atomic_add(base + r111, w111 * g, mask=valid)


@triton.jit
def one_blob(
    unit_ptr,
    out_ptr,
    count,
    out_stride,
    cutoff_squared,
    bins,
    BINS: tl.constexpr,
    BLOCK: tl.constexpr,
):
    offs = tl.program_id(0).to(tl.int64) * BLOCK + tl.arange(0, BLOCK)
    valid = offs < count
    b = tl.arange(0, BINS)
    in_range = b < bins
    centres = (b.to(tl.float32) + 0.5) / bins
    store_mask = valid[:, None] & in_range[None, :]
    for axis in tl.static_range(3):
        u = tl.load(unit_ptr + offs * 3 + axis, mask=valid, other=0.0)
        offset = (u[:, None] - centres[None, :]) * bins
        squared = offset * offset
        value = tl.where(squared > cutoff_squared, 0.0, tl.exp(-0.5 * squared))
        pointer = out_ptr + offs[:, None] * out_stride + axis * bins + b[None, :]
        tl.store(pointer, value, mask=store_mask)


_KERNELS = {"hash_forward": hash_forward, "hash_backward": hash_backward}


class _Layout:
    """What the kernels need to know of a hash grid (from the encoding's public state)."""

    def __init__(self, encoding: Any) -> None:
        scales, multipliers = encoding.kernel_constants()
        device = encoding.table.device
        self.scales = torch.as_tensor(scales, dtype=torch.float32).to(device).contiguous()
        self.multipliers = torch.as_tensor(multipliers).to(device).contiguous()
        self.num_levels = int(encoding.num_levels)
        self.num_dense = int(encoding.num_dense_levels)
        self.table_size = int(encoding.table_size)
        self.features = int(encoding.features_per_level)


def _layout(encoding: Any) -> _Layout:
    """The encoding's kernel layout on its table's device (cached per encoding)."""
    cached = _LAYOUTS.get(encoding)
    if cached is None or cached.scales.device != encoding.table.device:
        cached = _LAYOUTS[encoding] = _Layout(encoding)
    return cached


def _launch_hash(
    name: str,
    layout: _Layout,
    unit: torch.Tensor,
    table: torch.Tensor,
    data: torch.Tensor,
    target: torch.Tensor,
    column: int,
) -> None:
    count = unit.shape[0]
    if count == 0:
        return
    grid = (triton.cdiv(count, _BLOCK), layout.num_levels)
    first, second = (table, target) if name == "hash_forward" else (data, target)
    _KERNELS[name][grid](
        unit,
        first,
        layout.scales,
        layout.multipliers,
        second,
        count,
        table.shape[1],
        data.stride(0) if name == "hash_backward" else target.stride(0),
        column,
        layout.num_levels,
        layout.num_dense,
        layout.table_size,
        FEATURES=layout.features,
        BLOCK=_BLOCK,
    )


class _HashFeatures(torch.autograd.Function):
    """Encoding buffer with hash features from ``column`` on; the gradient goes to the table."""

    @staticmethod
    def forward(ctx, table, unit, layout, prefix_bins, cutoff):  # noqa: ANN001, ANN205
        count = unit.shape[0]
        prefix = 3 * prefix_bins
        width = prefix + layout.num_levels * layout.features
        out = torch.empty((count, width), dtype=table.dtype, device=table.device)
        if prefix_bins and count:
            one_blob[(triton.cdiv(count, _BLOCK),)](
                unit,
                out,
                count,
                out.stride(0),
                float(cutoff) ** 2,
                prefix_bins,
                BINS=triton.next_power_of_2(prefix_bins),
                BLOCK=_BLOCK,
            )
        _launch_hash("hash_forward", layout, unit, table, out, out, prefix)
        ctx.save_for_backward(unit)
        ctx.layout, ctx.prefix, ctx.table_shape = layout, prefix, table.shape
        return out

    @staticmethod
    def backward(ctx, grad_output):  # noqa: ANN001, ANN205
        (unit,) = ctx.saved_tensors
        grad_table = grad_output.new_zeros(ctx.table_shape)
        grad_output = grad_output.contiguous()
        _launch_hash(
            "hash_backward", ctx.layout, unit, grad_table, grad_output, grad_table, ctx.prefix
        )
        return grad_table, None, None, None, None


def _prepare(encoding: Any, unit: torch.Tensor) -> torch.Tensor:
    if encoding.table.dtype != torch.float32 or not encoding.table.is_contiguous():
        raise ValueError("the Triton kernels need a contiguous float32 hash table")
    return unit.clamp(0.0, 1.0).to(torch.float32).contiguous()


def hash_grid_features(encoding: Any, unit: torch.Tensor) -> torch.Tensor:
    """(N, L F) hash-grid features of (N, 3) positions in [0, 1] (clamped), level-major,
    differentiable with respect to ``encoding.table`` (a :class:`HashGridEncoding`)."""
    unit = _prepare(encoding, unit)
    return _HashFeatures.apply(encoding.table, unit, _layout(encoding), 0, 0.0)


def field_inputs(encoding: Any, unit: torch.Tensor, bins: int, cutoff: float) -> torch.Tensor:
    """(N, 3 bins + L F) geometry-decoder input: OneBlob features (``bins`` per axis, 0
    beyond ``cutoff`` bins) then the hash-grid features, as one buffer; differentiable with
    respect to ``encoding.table``."""
    unit = _prepare(encoding, unit)
    return _HashFeatures.apply(encoding.table, unit, _layout(encoding), int(bins), cutoff)


@triton.jit
def _ray_weights(sdf_ptr, z_ptr, rays, samples, count, truncation, SAMPLES: tl.constexpr):
    """Per sample of a block of rays: the normalised weights, the unnormalised ones' sum,
    the keep mask and sigmoid(sdf / tr) (see :func:`rendering.truncated_weights`)."""
    index = tl.arange(0, SAMPLES)
    inside = (rays[:, None] < count) & (index[None, :] < samples)
    offsets = rays[:, None] * samples + index[None, :]
    sdf = tl.load(sdf_ptr + offsets, mask=inside, other=0.0)
    z = tl.load(z_ptr + offsets, mask=inside, other=0.0)
    following = inside & (index[None, :] + 1 < samples)
    sdf_next = tl.load(sdf_ptr + offsets + 1, mask=following, other=0.0)
    crossing = following & (sdf * sdf_next < 0.0)
    first = tl.min(tl.where(crossing, index[None, :], SAMPLES), axis=1)
    has_crossing = first < SAMPLES
    first_surface = tl.sum(tl.where(index[None, :] == first[:, None], z, 0.0), axis=1)
    keep = inside & ((z < first_surface[:, None] + truncation) | ~has_crossing[:, None])
    positive = tl.sigmoid(sdf / truncation)
    raw = tl.where(keep, positive * tl.sigmoid(-sdf / truncation), 0.0)
    total = tl.sum(raw, axis=1) + 1e-8
    return raw / total[:, None], total, keep, positive, offsets, inside, z


@triton.jit
def composite_forward(
    sdf_ptr,
    z_ptr,
    rgb_ptr,
    sigma2_ptr,
    out_ptr,
    count,
    samples,
    truncation,
    HAS_RGB: tl.constexpr,
    HAS_SIGMA: tl.constexpr,
    SAMPLES: tl.constexpr,
    RAYS: tl.constexpr,
):
    """Per ray: depth, colour and variance from the weights (out: (N, 5) = depth, r, g, b,
    variance)."""
    rays = tl.program_id(0).to(tl.int64) * RAYS + tl.arange(0, RAYS)
    weights, _, _, _, offsets, inside, z = _ray_weights(
        sdf_ptr, z_ptr, rays, samples, count, truncation, SAMPLES
    )
    valid = rays < count
    tl.store(out_ptr + rays * 5, tl.sum(weights * z, axis=1), mask=valid)
    if HAS_RGB:
        for channel in tl.static_range(3):
            colour = tl.load(rgb_ptr + offsets * 3 + channel, mask=inside, other=0.0)
            tl.store(out_ptr + rays * 5 + 1 + channel, tl.sum(weights * colour, axis=1), mask=valid)
    if HAS_SIGMA:
        sigma2 = tl.load(sigma2_ptr + offsets, mask=inside, other=0.0)
        tl.store(out_ptr + rays * 5 + 4, tl.sum(weights * weights * sigma2, axis=1), mask=valid)


@triton.jit
def composite_backward(
    sdf_ptr,
    z_ptr,
    rgb_ptr,
    sigma2_ptr,
    grad_out_ptr,
    grad_sdf_ptr,
    grad_rgb_ptr,
    grad_sigma2_ptr,
    count,
    samples,
    truncation,
    HAS_RGB: tl.constexpr,
    HAS_SIGMA: tl.constexpr,
    SIGMA_TO_WEIGHTS: tl.constexpr,
    SAMPLES: tl.constexpr,
    RAYS: tl.constexpr,
):
    """Gradients of the per-sample SDF, colours and variances from those of the per-ray
    outputs (the weights' chain rule through the normalisation and the sigmoids; the keep
    mask has none)."""
    rays = tl.program_id(0).to(tl.int64) * RAYS + tl.arange(0, RAYS)
    weights, total, keep, positive, offsets, inside, z = _ray_weights(
        sdf_ptr, z_ptr, rays, samples, count, truncation, SAMPLES
    )
    valid = rays < count
    grad_depth = tl.load(grad_out_ptr + rays * 5, mask=valid, other=0.0)
    grad_weights = grad_depth[:, None] * z
    if HAS_RGB:
        for channel in tl.static_range(3):
            grad_colour = tl.load(grad_out_ptr + rays * 5 + 1 + channel, mask=valid, other=0.0)
            colour = tl.load(rgb_ptr + offsets * 3 + channel, mask=inside, other=0.0)
            grad_weights += grad_colour[:, None] * colour
            tl.store(grad_rgb_ptr + offsets * 3 + channel, grad_colour[:, None] * weights,
                     mask=inside)  # fmt: skip
    if HAS_SIGMA:
        grad_variance = tl.load(grad_out_ptr + rays * 5 + 4, mask=valid, other=0.0)
        sigma2 = tl.load(sigma2_ptr + offsets, mask=inside, other=0.0)
        tl.store(grad_sigma2_ptr + offsets, grad_variance[:, None] * weights * weights,
                 mask=inside)  # fmt: skip
        if SIGMA_TO_WEIGHTS:
            grad_weights += 2.0 * grad_variance[:, None] * weights * sigma2
    mean = tl.sum(weights * grad_weights, axis=1)
    grad_raw = (grad_weights - mean[:, None]) / total[:, None]
    slope = positive * (1.0 - positive) * (1.0 - 2.0 * positive)
    grad_sdf = tl.where(keep, grad_raw * slope, 0.0) / truncation
    tl.store(grad_sdf_ptr + offsets, grad_sdf, mask=inside)


_RAYS = 16


class _Composite(torch.autograd.Function):
    """(N, 5) per-ray depth, RGB and variance from per-sample SDF, depths, colours and
    variances; gradients to the SDF, the colours and the variances."""

    @staticmethod
    def forward(ctx, sdf, z, rgb, sigma2, truncation, sigma_to_weights):  # noqa: ANN001, ANN205
        count, samples = sdf.shape
        out = sdf.new_zeros((count, 5))
        dummy = sdf.new_empty(0)
        has_rgb, has_sigma = rgb is not None, sigma2 is not None
        arguments = (
            sdf, z, rgb if has_rgb else dummy, sigma2 if has_sigma else dummy,
        )  # fmt: skip
        if count:
            composite_forward[(triton.cdiv(count, _RAYS),)](
                *arguments, out, count, samples, float(truncation),
                HAS_RGB=has_rgb, HAS_SIGMA=has_sigma,
                SAMPLES=triton.next_power_of_2(samples), RAYS=_RAYS,
            )  # fmt: skip
        ctx.save_for_backward(*arguments)
        ctx.flags = (has_rgb, has_sigma, bool(sigma_to_weights), float(truncation))
        return out

    @staticmethod
    def backward(ctx, grad_out):  # noqa: ANN001, ANN205
        sdf, z, rgb, sigma2 = ctx.saved_tensors
        has_rgb, has_sigma, sigma_to_weights, truncation = ctx.flags
        count, samples = sdf.shape
        grad_sdf = torch.zeros_like(sdf)
        grad_rgb = torch.zeros_like(rgb)
        grad_sigma2 = torch.zeros_like(sigma2)
        if count:
            composite_backward[(triton.cdiv(count, _RAYS),)](
                sdf, z, rgb, sigma2, grad_out.contiguous(), grad_sdf, grad_rgb, grad_sigma2,
                count, samples, truncation,
                HAS_RGB=has_rgb, HAS_SIGMA=has_sigma, SIGMA_TO_WEIGHTS=sigma_to_weights,
                SAMPLES=triton.next_power_of_2(samples), RAYS=_RAYS,
            )  # fmt: skip
        return (
            grad_sdf,
            None,
            grad_rgb if has_rgb else None,
            grad_sigma2 if has_sigma else None,
            None,
            None,
        )


def composite(
    sdf: torch.Tensor,
    z: torch.Tensor,
    rgb: torch.Tensor | None,
    sigma2: torch.Tensor | None,
    truncation: float,
    sigma_to_weights: bool = True,
) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor | None]:
    """Volume rendering of rays in one kernel: (depth (N,), RGB (N, 3) or None, variance
    (N,) or None) from the SDF (N, S) of the samples at depths ``z`` (N, S), their colours
    (N, S, 3) and variances (N, S).

    The weights are :func:`naruto_agent.mapping.rendering.truncated_weights`'s; the variance
    is ``sum w^2 sigma^2``. ``sigma_to_weights`` False treats the weights as constants in the
    variance's gradient (``uncertainty_detach_geometry``). Differentiable with respect to the
    SDF, the colours and the variances (not ``z``).
    """
    sdf = sdf.contiguous().float()
    z = z.detach().contiguous().float()
    rgb = rgb.contiguous().float() if rgb is not None else None
    sigma2 = sigma2.contiguous().float() if sigma2 is not None else None
    out = _Composite.apply(sdf, z, rgb, sigma2, truncation, sigma_to_weights)
    return (
        out[:, 0],
        out[:, 1:4] if rgb is not None else None,
        out[:, 4] if sigma2 is not None else None,
    )
