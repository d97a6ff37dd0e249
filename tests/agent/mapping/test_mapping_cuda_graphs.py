"""The fast path's mapping iteration replayed as a CUDA graph trains as the eager iteration
does. Needs a CUDA GPU and Triton; without them only the "off" status is checked."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from naruto_agent.mapping import NeuralMapper, NeuralMapperConfig
from naruto_agent.mapping.rendering import RayBatch

from .conftest import orbit_poses, tiny_mapper_config

CUDA = torch.cuda.is_available()
needs_cuda = pytest.mark.skipif(not CUDA, reason="needs a CUDA device")


def config(**overrides) -> NeuralMapperConfig:
    return tiny_mapper_config(
        **{"rays_per_iteration": 256, "current_frame_rays": 32, "active_top_rays": 64, **overrides}
    )


def fixed_rays(count: int, device: torch.device, seed: int) -> RayBatch:
    generator = torch.Generator().manual_seed(seed)
    directions = torch.rand(count, 3, generator=generator) - 0.5
    directions[:, 2] = 1.0
    depth = 0.5 + 2.0 * torch.rand(count, generator=generator)
    depth[:5] = 0.0
    return RayBatch(
        origins=torch.tensor([0.0, 0.0, 1.2]).expand(count, 3).contiguous().to(device),
        directions=directions.to(device),
        rgb=torch.rand(count, 3, generator=generator).to(device),
        depth=depth.to(device),
    )


def test_off_without_a_gpu_or_without_the_fast_path(room_bounds, small_camera):
    mapper = NeuralMapper(room_bounds, small_camera, config(device="cpu"))
    assert mapper.cuda_graph_status == "off"
    losses = mapper.train_iteration(fixed_rays(64, torch.device("cpu"), seed=0))
    assert set(losses) >= {"rgb", "depth", "sdf", "free_space", "total"}
    assert np.isfinite(list(losses.values())).all()


@needs_cuda
def test_replayed_iterations_equal_eager_ones_without_random_draws(room_bounds, small_camera):
    """No jitter and no smoothness patch: nothing random, so the graph must give the eager
    iteration's losses and parameters (up to the GPU's summation order)."""
    pytest.importorskip("triton")
    settings = dict(device="cuda", backend="triton", perturb=False, smoothness_weight=0.0)
    mappers = {
        graphs: NeuralMapper(room_bounds, small_camera, config(cuda_graphs=graphs, **settings))
        for graphs in (True, False)
    }
    assert mappers[False].cuda_graph_status == "off"
    batches = [fixed_rays(300, torch.device("cuda"), seed) for seed in range(6)]
    for index, batch in enumerate(batches):
        losses = {graphs: mapper.train_iteration(batch) for graphs, mapper in mappers.items()}
        for name, value in losses[False].items():
            assert losses[True][name] == pytest.approx(value, rel=1e-4, abs=1e-6), (index, name)
        if index == 0:
            assert mappers[True].cuda_graph_status == "waiting"  # a size is captured when it recurs
    assert mappers[True].cuda_graph_status == "replaying (sizes [300])"
    for (name, graph), (_, eager) in zip(
        mappers[True].field.named_parameters(), mappers[False].field.named_parameters(), strict=True
    ):
        torch.testing.assert_close(graph, eager, rtol=1e-4, atol=1e-6, msg=name)
    torch.testing.assert_close(
        mappers[True].uncertainty.raw, mappers[False].uncertainty.raw, rtol=1e-4, atol=1e-6
    )


@needs_cuda
def test_a_mapping_run_with_graphs_learns_the_room(room_bounds, small_camera, room_renderer):
    pytest.importorskip("triton")
    finals = {}
    for graphs in (True, False):
        mapper = NeuralMapper(
            room_bounds, small_camera, config(device="cuda", backend="triton", cuda_graphs=graphs)
        )
        for index, pose in enumerate(orbit_poses(12)):
            rgb, depth = room_renderer.render(pose)
            mapper.integrate(rgb, depth, pose, index)
        totals = [loss["total"] for loss in mapper.stats.losses]
        assert np.isfinite(totals).all()
        finals[graphs] = float(np.mean(totals[-4:]))
        if graphs:
            assert mapper.cuda_graph_status.startswith("replaying"), mapper.cuda_graph_status
    # Different random draws, same training: the late losses agree within a factor.
    assert 0.5 < finals[True] / finals[False] < 2.0
