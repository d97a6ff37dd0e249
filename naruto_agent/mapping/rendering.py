"""SDF-based volume rendering of rays through the neural field, and the mapping losses.

A ray is ``origin + z * direction`` with the direction's camera-frame z equal to 1, so the
ray parameter ``z`` is z-depth (as in the depth images). Per ray: ``num_uniform_samples``
depths in [near, far] plus ``num_surface_samples`` within +-``surface_range_m`` of the
measured depth (or more uniform ones where the depth is missing). Weights are
``sigmoid(s / tr) * sigmoid(-s / tr)`` of the SDF ``s`` (truncation units), cut one truncation
behind the first sign change of the SDF along the ray, then normalised (Co-SLAM). The
rendered variance is ``sum_i w_i^2 sigma_i^2`` (NARUTO).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from naruto_agent.mapping.config import NeuralMapperConfig
from naruto_agent.mapping.field import NeuralField
from naruto_agent.mapping.uncertainty_grid import UncertaintyGrid, gaussian_nll

# SDF given to samples that are not evaluated (far behind the measured surface): "inside".
_CULLED_SDF = -1.0


@dataclass
class RayBatch:
    """N rays with their measurements.

    Attributes:
        origins: (N, 3) world positions of the camera centres.
        directions: (N, 3) world directions whose camera-frame z is 1.
        rgb: (N, 3) measured colour in [0, 1].
        depth: (N,) measured z-depth in metres, 0 where missing.
    """

    origins: torch.Tensor
    directions: torch.Tensor
    rgb: torch.Tensor
    depth: torch.Tensor

    def __len__(self) -> int:
        return int(self.depth.shape[0])

    def select(self, index: torch.Tensor) -> RayBatch:
        return RayBatch(
            self.origins[index], self.directions[index], self.rgb[index], self.depth[index]
        )

    @staticmethod
    def concatenate(batches: list[RayBatch]) -> RayBatch:
        return RayBatch(
            torch.cat([b.origins for b in batches]),
            torch.cat([b.directions for b in batches]),
            torch.cat([b.rgb for b in batches]),
            torch.cat([b.depth for b in batches]),
        )


@dataclass
class RenderOutput:
    """Rendered quantities and the per-sample values the losses need."""

    rgb: torch.Tensor  # (N, 3)
    depth: torch.Tensor  # (N,)
    variance: torch.Tensor | None  # (N,) sum w^2 sigma^2, None without a grid
    sdf: torch.Tensor  # (N, S) truncation units
    z: torch.Tensor  # (N, S)
    evaluated: torch.Tensor  # (N, S) bool


def sample_depths(
    depth: torch.Tensor,
    config: NeuralMapperConfig,
    generator: torch.Generator | None,
    perturb: bool,
) -> torch.Tensor:
    """(N, S) sorted sample depths: uniform in [near, far] + around the measured depth."""
    count = depth.shape[0]
    device = depth.device
    steps = torch.linspace(0.0, 1.0, config.num_uniform_samples, device=device)
    uniform = (config.near_m + (config.far_m - config.near_m) * steps).expand(count, -1)
    offsets = torch.linspace(
        -config.surface_range_m, config.surface_range_m, config.num_surface_samples, device=device
    )
    spread = torch.linspace(config.near_m, config.far_m, config.num_surface_samples, device=device)
    valid = (depth > 0)[:, None]
    surface = torch.where(valid, depth[:, None] + offsets, spread)
    z, _ = torch.sort(torch.cat([uniform, surface], dim=1), dim=1)
    if perturb:
        mids = 0.5 * (z[:, 1:] + z[:, :-1])
        upper = torch.cat([mids, z[:, -1:]], dim=1)
        lower = torch.cat([z[:, :1], mids], dim=1)
        jitter = torch.rand(z.shape, device=device, generator=generator)
        z = lower + (upper - lower) * jitter
    return z.clamp(min=1e-4)


def truncated_weights(sdf: torch.Tensor, z: torch.Tensor, truncation_m: float) -> torch.Tensor:
    """Normalised rendering weights from the SDF (truncation units) along each ray.

    ``w = sigmoid(s / tr) * sigmoid(-s / tr)``, zeroed from one truncation behind the first
    sign change on. Rays whose SDF never changes sign keep all their samples.
    """
    scaled = sdf / truncation_m
    weights = torch.sigmoid(scaled) * torch.sigmoid(-scaled)
    crossing = (sdf[:, 1:] * sdf[:, :-1]) < 0.0
    has_crossing = crossing.any(dim=1, keepdim=True)
    first = torch.argmax(crossing.to(torch.uint8), dim=1, keepdim=True)
    first_surface = torch.gather(z, 1, first)
    keep = (z < first_surface + truncation_m) | ~has_crossing
    weights = weights * keep
    return weights / (weights.sum(dim=1, keepdim=True) + 1e-8)


def _scatter(values: torch.Tensor, flat: torch.Tensor, shape: tuple[int, int], fill: float):
    full = torch.full(
        (shape[0] * shape[1], *values.shape[1:]), fill, device=values.device, dtype=values.dtype
    )
    return full.index_put((flat,), values).view(*shape, *values.shape[1:])


def render_rays(
    field: NeuralField,
    rays: RayBatch,
    config: NeuralMapperConfig,
    uncertainty: UncertaintyGrid | None = None,
    generator: torch.Generator | None = None,
    perturb: bool = False,
    with_colour: bool = True,
    fixed_shape: bool = False,
) -> RenderOutput:
    """Render colour, depth and (with a grid) variance of a batch of rays.

    ``fixed_shape`` evaluates the field at every sample, culled ones included, and masks
    the culled ones afterwards (SDF -1, colour and variance 0: what the compact path gives
    them, with zero gradient): the same result, but every tensor's shape follows from the
    batch size alone, so nothing waits for the device to count the kept samples (the fast
    GPU path; on a CPU the compact evaluation is cheaper).
    """
    z = sample_depths(rays.depth, config, generator, perturb)
    count, samples = z.shape
    evaluated = torch.ones_like(z, dtype=torch.bool)
    if config.cull_behind_depth_m is not None:
        valid = (rays.depth > 0)[:, None]
        evaluated = ~(valid & (z > rays.depth[:, None] + config.cull_behind_depth_m))
    if fixed_shape:
        points = (rays.origins[:, None, :] + rays.directions[:, None, :] * z[:, :, None]).reshape(
            -1, 3
        )
        if with_colour:
            sdf_values, rgb_values = field(points)
            rgb_samples = torch.where(
                evaluated[:, :, None], rgb_values.view(count, samples, 3), 0.0
            )
        else:
            sdf_values, rgb_samples = field.sdf(points), None
        sdf = torch.where(evaluated, sdf_values.view(count, samples), _CULLED_SDF)
    else:
        flat = evaluated.reshape(-1).nonzero().squeeze(1)
        ray_of_sample = torch.div(flat, samples, rounding_mode="floor")
        points = (
            rays.origins[ray_of_sample] + rays.directions[ray_of_sample] * z.reshape(-1)[flat, None]
        )
        if with_colour:
            sdf_values, rgb_values = field(points)
            rgb_samples = _scatter(rgb_values, flat, (count, samples), 0.0)
        else:
            sdf_values, rgb_samples = field.sdf(points), None
        sdf = _scatter(sdf_values, flat, (count, samples), _CULLED_SDF)
    sigma2 = None
    if uncertainty is not None:
        if fixed_shape:
            sigma2 = torch.where(evaluated, uncertainty.variance(points).view(count, samples), 0.0)
        else:
            sigma2 = _scatter(uncertainty.variance(points), flat, (count, samples), 0.0)
    if fixed_shape and field.backend == "triton":
        # The weights, their sums and their gradients in one kernel per direction.
        from naruto_agent.mapping import triton_kernels

        depth, rgb, variance = triton_kernels.composite(
            sdf,
            z,
            rgb_samples,
            sigma2,
            config.truncation_m,
            sigma_to_weights=not config.uncertainty_detach_geometry,
        )
        return RenderOutput(rgb, depth, variance, sdf, z, evaluated)
    weights = truncated_weights(sdf, z, config.truncation_m)
    rgb = (weights[:, :, None] * rgb_samples).sum(dim=1) if rgb_samples is not None else None
    depth = (weights * z).sum(dim=1)
    variance = None
    if sigma2 is not None:
        w = weights.detach() if config.uncertainty_detach_geometry else weights
        variance = (w * w * sigma2).sum(dim=1)
    return RenderOutput(rgb, depth, variance, sdf, z, evaluated)


def fast_compositing_error(device: torch.device, truncation_m: float = 0.1) -> str | None:
    """Why the Triton compositing kernel cannot be trusted on ``device``, or None when it can.

    Renders a few random rays (values and gradients) with the kernel and with
    :func:`truncated_weights` and compares them; this also compiles the kernel. A failure to
    compile or launch is reported, not raised.
    """
    generator = torch.Generator().manual_seed(0)
    z = torch.sort(5.0 * torch.rand(8, 43, generator=generator), dim=1).values.to(device)
    sdf = (0.4 * torch.rand(8, 43, generator=generator) - 0.2).to(device)
    rgb = torch.rand(8, 43, 3, generator=generator).to(device)
    sigma2 = (0.01 + torch.rand(8, 43, generator=generator)).to(device)
    results = []
    try:
        from naruto_agent.mapping import triton_kernels

        for fused in (True, False):
            inputs = [t.clone().requires_grad_() for t in (sdf, rgb, sigma2)]
            with torch.enable_grad():
                if fused:
                    depth, colour, variance = triton_kernels.composite(
                        inputs[0], z, inputs[1], inputs[2], truncation_m
                    )
                else:
                    weights = truncated_weights(inputs[0], z, truncation_m)
                    depth = (weights * z).sum(dim=1)
                    colour = (weights[:, :, None] * inputs[1]).sum(dim=1)
                    variance = (weights * weights * inputs[2]).sum(dim=1)
                total = depth.sum() + colour.sum() + variance.sum()
                grads = torch.autograd.grad(total, inputs)
            results.append([t.detach() for t in (depth, colour, variance, *grads)])
    except Exception as error:  # noqa: BLE001 (any compile or launch failure)
        return f"the Triton compositing kernel failed: {type(error).__name__}: {error}"
    for fast, reference in zip(*results, strict=True):
        if not torch.allclose(fast, reference, rtol=1e-3, atol=1e-5):
            return "the Triton compositing kernel differs from the PyTorch reference"
    return None


def surface_variance(
    field: NeuralField,
    uncertainty: UncertaintyGrid,
    rays: RayBatch,
    config: NeuralMapperConfig,
) -> torch.Tensor:
    """Rendered variance using only the samples around each measured depth (cheap scoring).

    Rays without a depth fall back to the full rendering.
    """
    valid = rays.depth > 0
    result = torch.empty_like(rays.depth)
    if (~valid).any():
        result[~valid] = render_rays(
            field, rays.select(~valid), config, uncertainty, with_colour=False
        ).variance
    if valid.any():
        sub = rays.select(valid)
        offsets = torch.linspace(
            -config.surface_range_m,
            config.surface_range_m,
            config.num_surface_samples,
            device=sub.depth.device,
        )
        z = sub.depth[:, None] + offsets
        points = (sub.origins[:, None, :] + sub.directions[:, None, :] * z[:, :, None]).reshape(
            -1, 3
        )
        sdf = field.sdf(points).view(z.shape)
        weights = truncated_weights(sdf, z, config.truncation_m)
        sigma2 = uncertainty.variance(points).view(z.shape)
        result[valid] = (weights * weights * sigma2).sum(dim=1)
    return result


def measured_point_variance(uncertainty: UncertaintyGrid, rays: RayBatch) -> torch.Tensor:
    """(N,) the grid's variance sigma^2 at each ray's measured surface point (no field query).

    The cheapest active-sampling score: where the field renders the measured surface, the
    rendered variance is about ``sigma^2`` there times the ray's ``sum w^2``. Rays without a
    depth score 0 (they are still drawn among the random rays).
    """
    valid = rays.depth > 0
    points = rays.origins + rays.directions * rays.depth[:, None]
    return torch.where(valid, uncertainty.variance(points), torch.zeros_like(rays.depth))


def smoothness_loss(
    field: NeuralField,
    bounds: torch.Tensor,
    config: NeuralMapperConfig,
    generator: torch.Generator | None,
) -> torch.Tensor:
    """Squared finite differences of the grid features on a random patch (Co-SLAM)."""
    points_per_axis = config.smoothness_points
    voxel = config.smoothness_voxel_m
    device = bounds.device
    span = voxel * (points_per_axis - 1)
    room = (bounds[1] - bounds[0] - span).clamp(min=0.0)
    corner = bounds[0] + room * torch.rand(3, device=device, generator=generator)
    axis = torch.arange(points_per_axis, device=device, dtype=torch.float32) * voxel
    grid = torch.stack(torch.meshgrid(axis, axis, axis, indexing="ij"), dim=-1) + corner
    features = field.grid_features(grid.reshape(-1, 3)).view(
        points_per_axis, points_per_axis, points_per_axis, -1
    )
    total = (
        (features[1:] - features[:-1]).square().sum()
        + (features[:, 1:] - features[:, :-1]).square().sum()
        + (features[:, :, 1:] - features[:, :, :-1]).square().sum()
    )
    return total / points_per_axis**3


def mapping_losses(
    output: RenderOutput, rays: RayBatch, config: NeuralMapperConfig, fixed_shape: bool = False
) -> dict[str, torch.Tensor]:
    """The unweighted Co-SLAM losses and NARUTO's NLL (when a variance was rendered).

    Each loss is a mean over the rays or samples it applies to, 0 when there are none.
    ``fixed_shape`` computes the same means as masked sums over all rays and samples,
    without boolean indexing or host-side tests (the fast GPU path: no device sync).
    """
    if fixed_shape:
        return _masked_mapping_losses(output, rays, config)
    valid = rays.depth > 0
    zero = output.depth.new_zeros(())
    losses: dict[str, torch.Tensor] = {}
    if valid.any():
        losses["rgb"] = (output.rgb[valid] - rays.rgb[valid]).square().mean()
        losses["depth"] = (output.depth[valid] - rays.depth[valid]).square().mean()
    else:
        losses["rgb"] = losses["depth"] = zero
    target = rays.depth[:, None]
    tr = config.truncation_m
    has_depth = valid[:, None] & output.evaluated
    front = has_depth & (output.z < target - tr)
    band = has_depth & ~front & (output.z <= target + tr)
    losses["free_space"] = (output.sdf[front] - 1.0).square().mean() if front.any() else zero
    losses["sdf"] = (
        (output.z[band] + output.sdf[band] * tr - target.expand_as(output.z)[band]).square().mean()
        if band.any()
        else zero
    )
    if output.variance is not None:
        if valid.any():
            depth_hat = output.depth[valid]
            if config.uncertainty_detach_geometry:
                depth_hat = depth_hat.detach()
            losses["uncertainty"] = gaussian_nll(
                depth_hat, rays.depth[valid], output.variance[valid]
            )
        else:
            losses["uncertainty"] = zero
    return losses


def _masked_mean(values: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean of ``values`` where ``mask`` (0 where it is nowhere true), with no device sync.

    ``torch.where`` rather than a product, so a non-finite value outside the mask (a
    variance of a ray with no depth, say) cannot leak in, in the value or the gradient.
    """
    total = torch.where(mask, values, 0.0).sum()
    return total / mask.sum().clamp(min=1)


def _masked_mapping_losses(
    output: RenderOutput, rays: RayBatch, config: NeuralMapperConfig
) -> dict[str, torch.Tensor]:
    valid = rays.depth > 0
    losses: dict[str, torch.Tensor] = {}
    rgb_error = (output.rgb - rays.rgb).square().sum(dim=1)
    # The reference averages over the valid rays' three channels.
    losses["rgb"] = _masked_mean(rgb_error, valid) / 3.0
    losses["depth"] = _masked_mean((output.depth - rays.depth).square(), valid)
    target = rays.depth[:, None]
    tr = config.truncation_m
    has_depth = valid[:, None] & output.evaluated
    front = has_depth & (output.z < target - tr)
    band = has_depth & ~front & (output.z <= target + tr)
    losses["free_space"] = _masked_mean((output.sdf - 1.0).square(), front)
    losses["sdf"] = _masked_mean((output.z + output.sdf * tr - target).square(), band)
    if output.variance is not None:
        depth_hat = output.depth
        if config.uncertainty_detach_geometry:
            depth_hat = depth_hat.detach()
        variance = torch.where(valid, output.variance, 1.0)
        losses["uncertainty"] = _masked_mean(
            (depth_hat - rays.depth).square() / (2.0 * variance), valid
        ) + 0.5 * _masked_mean(torch.log(variance), valid)
    return losses


def weighted_total(losses: dict[str, torch.Tensor], config: NeuralMapperConfig) -> torch.Tensor:
    """Sum of the losses with the published weights."""
    weights = {
        "rgb": config.rgb_weight,
        "depth": config.depth_weight,
        "sdf": config.sdf_weight,
        "free_space": config.free_space_weight,
        "smoothness": config.smoothness_weight,
        "uncertainty": config.uncertainty_weight,
    }
    return sum(weights[name] * value for name, value in losses.items())
