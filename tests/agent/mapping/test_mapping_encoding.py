"""The fast hash grid computes what the plain one computes; OneBlob and device handling."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from naruto_agent.mapping import (
    HashGridEncoding,
    NaiveHashGridEncoding,
    OneBlobEncoding,
    resolve_device,
)
from naruto_agent.mapping.encoding import level_resolutions


def test_fast_hash_grid_matches_naive_forward_and_backward() -> None:
    torch.manual_seed(0)
    fast = HashGridEncoding(
        num_levels=6, log2_table_size=12, base_resolution=4, finest_resolution=90.0, init_scale=0.5
    )
    naive = NaiveHashGridEncoding(
        num_levels=6, log2_table_size=12, base_resolution=4, finest_resolution=90.0
    )
    naive.load_state_dict(fast.state_dict())
    assert 0 < fast.num_dense_levels < fast.num_levels  # both paths are exercised
    points = torch.rand(500, 3)
    points[:5] = torch.tensor(
        [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [1.0, 0.0, 0.5], [0.999, 0.5, 0.0], [0.25, 0.75, 1.0]]
    )
    out_fast, out_naive = fast(points), naive(points)
    assert out_fast.shape == (500, 12)
    torch.testing.assert_close(out_fast, out_naive, rtol=1e-5, atol=1e-6)
    upstream = torch.randn_like(out_fast)
    out_fast.backward(upstream)
    out_naive.backward(upstream)
    torch.testing.assert_close(fast.table.grad, naive.table.grad, rtol=1e-4, atol=1e-5)


def test_dense_levels_have_no_collisions_and_every_level_stays_in_its_rows() -> None:
    grid = HashGridEncoding(
        num_levels=4, log2_table_size=12, base_resolution=8, finest_resolution=64.0
    )
    assert grid.num_dense_levels == 1 and grid.dense_side == 10  # (8 + 2)^3 <= 4096 < 15^3
    for level, resolution in enumerate(grid.resolutions):
        axis = torch.arange(resolution + 2)
        vertices = torch.stack(torch.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
        rows = grid.vertex_rows(level, vertices)
        assert rows.min() >= level * grid.table_size
        assert rows.max() < (level + 1) * grid.table_size
        if level < grid.num_dense_levels:
            assert len(torch.unique(rows)) == len(vertices)


def test_fast_hash_grid_handles_all_dense_and_all_hashed_layouts() -> None:
    torch.manual_seed(1)
    points = torch.rand(300, 3)
    for log2_table_size, expected_dense in ((20, 3), (6, 0)):
        fast = HashGridEncoding(
            num_levels=3,
            log2_table_size=log2_table_size,
            base_resolution=4,
            finest_resolution=20.0,
            init_scale=0.5,
        )
        naive = NaiveHashGridEncoding(
            num_levels=3, log2_table_size=log2_table_size, base_resolution=4, finest_resolution=20.0
        )
        naive.load_state_dict(fast.state_dict())
        assert fast.num_dense_levels == expected_dense
        out_fast, out_naive = fast(points), naive(points)
        torch.testing.assert_close(out_fast, out_naive, rtol=1e-5, atol=1e-6)
        upstream = torch.randn_like(out_fast)
        out_fast.backward(upstream)
        out_naive.backward(upstream)
        torch.testing.assert_close(fast.table.grad, naive.table.grad, rtol=1e-4, atol=1e-5)


def test_trilinear_weights_sum_to_one() -> None:
    grid = HashGridEncoding(num_levels=3, log2_table_size=10, finest_resolution=40.0)
    _, weights = grid.corner_indices_and_weights(torch.rand(100, 3))
    hashed_levels = grid.num_levels - grid.num_dense_levels
    torch.testing.assert_close(weights.sum(0), torch.ones(100 * hashed_levels))


def test_level_resolutions_span_base_to_finest() -> None:
    res = level_resolutions(16, 16, 250.5)
    assert res[0] == 16 and res[-1] == 250 and res == sorted(res)
    with pytest.raises(ValueError, match="num_levels"):
        level_resolutions(0, 16, 100)


def test_one_blob_peaks_at_the_bin_of_the_coordinate() -> None:
    blob = OneBlobEncoding(16)
    features = blob(torch.tensor([[0.03, 0.5, 0.97]])).view(3, 16)
    assert features.argmax(dim=1).tolist() == [0, 7, 15] or features.argmax(dim=1).tolist() == [
        0,
        8,
        15,
    ]


def test_resolve_device() -> None:
    expected = "cuda" if torch.cuda.is_available() else "cpu"
    assert resolve_device("auto").type == expected
    assert resolve_device("cpu").type == "cpu"
    with pytest.raises(ValueError, match="device"):
        resolve_device("tpu")
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="CUDA"):
            resolve_device("cuda")


def test_one_blob_tails_are_zero_not_denormal() -> None:
    # Denormal inputs slow the decoders' matrix products several times on x86 CPUs.
    features = OneBlobEncoding(16)(torch.rand(2000, 3))
    denormal = (features > 0) & (features < torch.finfo(torch.float32).tiny)
    assert not denormal.any()
    assert (features == 0).any() and features.max() > 0.9


@pytest.mark.parametrize("log2_table_size", [12, 20, 6])
def test_compiled_no_gradient_path_matches_the_torch_path(log2_table_size) -> None:
    torch.manual_seed(2)
    grid = HashGridEncoding(
        num_levels=6,
        features_per_level=2,
        log2_table_size=log2_table_size,
        base_resolution=4,
        finest_resolution=90.0,
        init_scale=0.5,
    )
    # Many points, so the points are split over threads; corners and edges included.
    points = torch.rand(40_000, 3)
    points[:4] = torch.tensor([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [1.0, 0.0, 0.5], [-0.2, 1.3, 0.5]])
    with torch.no_grad():
        assert grid.uses_cpu_kernel(points)
        compiled = grid(points)
        grid.cpu_kernel = False
        assert not grid.uses_cpu_kernel(points)
        reference = grid(points)
    # The dense levels' grid_sampler maps coordinates through [-1, 1] and back: float32
    # rounding of about 1e-5 of the table's scale (0.5 here).
    torch.testing.assert_close(compiled, reference, rtol=1e-4, atol=5e-5)
    # With gradients the autograd path runs (the compiled loop has no backward).
    grid.cpu_kernel = True
    assert not grid.uses_cpu_kernel(points)
    grid(points[:10]).sum().backward()
    assert grid.table.grad is not None and grid.table.grad.abs().sum() > 0
    # Layouts the loop does not cover take the torch path.
    wide = HashGridEncoding(num_levels=3, features_per_level=3, log2_table_size=8)
    with torch.no_grad():
        assert not wide.uses_cpu_kernel(points)
        assert wide(points[:10]).shape == (10, 9)


def test_compiled_field_sdf_matches_the_torch_path() -> None:
    from naruto_agent.mapping import NeuralMapperConfig
    from naruto_agent.mapping.field import NeuralField

    torch.manual_seed(3)
    bounds = torch.tensor([[-2.0, -1.5, 0.0], [2.0, 1.5, 2.5]]).numpy()
    field = NeuralField(bounds, NeuralMapperConfig(hash_levels=8, hash_log2_table_size=12))
    with torch.no_grad():
        field.hash_grid.table.uniform_(-0.5, 0.5)
    # Inside the box, on its faces and outside it (clamped).
    points = torch.rand(20_000, 3) * 5.0 - torch.tensor([2.5, 2.0, 0.5])
    with torch.no_grad():
        compiled = field.sdf(points)
        field.hash_grid.cpu_kernel = False
        reference = field.sdf(points)
        field.hash_grid.cpu_kernel = True
        unit = field.normalise(points)
        assert field.hash_grid.uses_cpu_kernel(unit)
    torch.testing.assert_close(compiled, reference, rtol=1e-4, atol=1e-5)
    # With gradients enabled the SDF takes the autograd path and can be trained.
    field.sdf(points[:50]).sum().backward()
    assert field.hash_grid.table.grad is not None


def test_compiled_one_blob_matches_the_encoding() -> None:
    from naruto_agent.mapping import cpu_kernels
    from naruto_agent.mapping.encoding import ONE_BLOB_CUTOFF

    unit = torch.rand(5000, 3)
    unit[:3] = torch.tensor([[0.0, 1.0, 0.5], [1e-7, 0.9999999, 0.03125], [0.5, 0.5, 0.5]])
    for bins in (4, 16):
        grid = HashGridEncoding(
            num_levels=2, log2_table_size=8, base_resolution=4, finest_resolution=8.0
        )
        scales, multipliers = grid.kernel_constants()
        inputs = cpu_kernels.field_inputs(
            unit.numpy(),
            grid.table.detach().numpy(),
            scales,
            multipliers,
            grid.num_dense_levels,
            grid.table_size,
            bins,
            ONE_BLOB_CUTOFF,
        )
        expected = OneBlobEncoding(bins)(unit)
        torch.testing.assert_close(
            torch.from_numpy(inputs[:, : 3 * bins]), expected, rtol=1e-5, atol=1e-6
        )
        assert np.all(inputs[:, : 3 * bins][expected.numpy() == 0.0] == 0.0)
