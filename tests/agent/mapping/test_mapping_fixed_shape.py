"""The fast path's fixed-shape rendering and masked losses equal the compact reference:
values and gradients, also for batches without depth or without samples in a loss."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from naruto_agent.mapping import NeuralMapperConfig, UncertaintyGrid
from naruto_agent.mapping.field import NeuralField
from naruto_agent.mapping.rendering import RayBatch, mapping_losses, render_rays


def config() -> NeuralMapperConfig:
    return NeuralMapperConfig(
        hash_levels=6, hash_log2_table_size=11, hash_finest_voxel_m=0.1, device="cpu"
    )


def rays(count: int, valid_share: float, seed: int) -> RayBatch:
    generator = torch.Generator().manual_seed(seed)
    directions = torch.rand(count, 3, generator=generator) - 0.5
    directions[:, 2] = 1.0
    depth = 0.5 + 2.0 * torch.rand(count, generator=generator)
    depth[torch.rand(count, generator=generator) >= valid_share] = 0.0
    return RayBatch(
        origins=torch.tensor([0.0, 0.0, 1.2]).expand(count, 3),
        directions=directions,
        rgb=torch.rand(count, 3, generator=generator),
        depth=depth,
    )


def run(fixed: bool, batch: RayBatch, bounds: np.ndarray, cull: float | None):
    cfg = config()
    cfg.cull_behind_depth_m = cull
    torch.manual_seed(0)
    field = NeuralField(bounds, cfg)
    grid = UncertaintyGrid(bounds, 0.1)
    with torch.no_grad():
        grid.raw.normal_(generator=torch.Generator().manual_seed(1))
    generator = torch.Generator().manual_seed(2)
    output = render_rays(field, batch, cfg, grid, generator, perturb=True, fixed_shape=fixed)
    losses = mapping_losses(output, batch, cfg, fixed_shape=fixed)
    total = sum(losses.values())
    if total.requires_grad:  # the compact losses of rays without depth are constants
        total.backward()
    grads = {name: p.grad for name, p in [*field.named_parameters(), ("raw", grid.raw)]}
    return output, losses, grads


@pytest.mark.parametrize(("valid_share", "cull"), [(0.7, 0.2), (1.0, None), (0.0, 0.2), (0.5, 0.1)])
def test_fixed_shape_rendering_and_losses_equal_the_compact_ones(
    valid_share, cull, room_bounds
) -> None:
    batch = rays(64, valid_share, seed=3)
    compact, compact_losses, compact_grads = run(False, batch, room_bounds, cull)
    fixed, fixed_losses, fixed_grads = run(True, batch, room_bounds, cull)
    for name in ("rgb", "depth", "variance", "sdf", "z"):
        torch.testing.assert_close(
            getattr(fixed, name), getattr(compact, name), rtol=1e-5, atol=1e-6, msg=name
        )
    assert fixed_losses.keys() == compact_losses.keys()
    for name, value in compact_losses.items():
        torch.testing.assert_close(fixed_losses[name], value, rtol=1e-5, atol=1e-7, msg=name)
    for name, grad in compact_grads.items():
        if grad is None:  # no ray with depth: the fixed path's gradient is 0
            assert valid_share == 0.0
            assert not torch.count_nonzero(fixed_grads[name]), name
            continue
        torch.testing.assert_close(fixed_grads[name], grad, rtol=1e-4, atol=1e-7, msg=name)


def test_no_depth_gives_zero_losses_on_both_paths(room_bounds) -> None:
    batch = rays(16, 0.0, seed=4)
    _, compact_losses, _ = run(False, batch, room_bounds, 0.2)
    _, fixed_losses, _ = run(True, batch, room_bounds, 0.2)
    for name in ("rgb", "depth", "free_space", "sdf", "uncertainty"):
        assert float(compact_losses[name].detach()) == float(fixed_losses[name].detach()) == 0.0
