"""The Triton fast path computes what the PyTorch reference computes: values and gradients.

On a machine without CUDA the kernels run in Triton's CPU interpreter: ``TRITON_INTERPRET``
must be set before triton is first imported, so this module sets it at collection time
(nothing earlier in a CPU-only test run imports triton). With CUDA the compiled kernels are
checked on the GPU instead. Without triton installed the module is skipped.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

if not torch.cuda.is_available():
    if "triton" in sys.modules and os.environ.get("TRITON_INTERPRET") != "1":
        pytest.skip(
            "triton was imported before TRITON_INTERPRET=1 was set; run this module alone",
            allow_module_level=True,
        )
    os.environ["TRITON_INTERPRET"] = "1"
pytest.importorskip("triton")

from naruto_agent.mapping import (  # noqa: E402
    HashGridEncoding,
    NeuralMapper,
    NeuralMapperConfig,
    OneBlobEncoding,
    neural_mapper,
    triton_kernels,
)
from naruto_agent.mapping.encoding import ONE_BLOB_CUTOFF  # noqa: E402
from naruto_agent.mapping.field import NeuralField  # noqa: E402
from naruto_agent.mapping.rendering import (  # noqa: E402
    fast_compositing_error,
    truncated_weights,
)

from .conftest import orbit_poses, tiny_mapper_config  # noqa: E402

DEVICE = torch.device("cuda" if torch.cuda.is_available() else "cpu")
# Feature values: the interpreter repeats the reference's float32 arithmetic; on a GPU the
# compiled kernel fuses multiply-adds and sums the eight corners in its own order, which
# moves values by a few 1e-6 (up to 6.8e-6 seen on an H200 for features of order 1).
VALUE_ATOL = 1e-5 if DEVICE.type == "cuda" else 2e-6
# The table gradient sums many points' contributions per row with atomic adds, whose order a
# GPU does not fix: rows differ by a few 1e-5.
TABLE_GRAD_ATOL = 1e-4 if DEVICE.type == "cuda" else 2e-5
# Over a few iterations those differences grow through Adam's steps to about a percent of a
# loss; the interpreter on a CPU adds in a fixed order.
LOSS_RTOL = 3e-2 if DEVICE.type == "cuda" else 1e-3

# (levels, log2 table size, base resolution, finest resolution, features per level):
# dense and hashed levels mixed, all dense, all hashed, one and four features per level.
LAYOUTS = [
    (6, 12, 4, 90.0, 2),
    (3, 20, 4, 30.0, 2),
    (5, 6, 8, 200.0, 2),
    (4, 10, 2, 50.0, 1),
    (3, 14, 16, 128.0, 4),
]


def edge_points(count: int, resolution: int) -> torch.Tensor:
    """Random points plus the box's corners, faces, exact grid vertices and points outside
    the box (clamped by the encoding)."""
    generator = torch.Generator().manual_seed(count)
    points = torch.rand(count, 3, generator=generator)
    special = torch.tensor(
        [
            [0.0, 0.0, 0.0],
            [1.0, 1.0, 1.0],
            [1.0, 0.0, 0.5],
            [0.0, 1.0, 1.0],
            [1.0 - 1e-7, 0.5, 0.0],
            [3.0 / resolution, 5.0 / resolution, 1.0 / resolution],
            [-0.25, 0.5, 1.5],
            [2.0, -1.0, 0.5],
        ]
    )
    points[: min(count, len(special))] = special[: min(count, len(special))]
    return points


def make_grid(layout: tuple) -> HashGridEncoding:
    levels, log2_size, base, finest, features = layout
    torch.manual_seed(levels * 7 + log2_size)
    return HashGridEncoding(
        num_levels=levels,
        features_per_level=features,
        log2_table_size=log2_size,
        base_resolution=base,
        finest_resolution=finest,
        init_scale=0.5,
    ).to(DEVICE)


@pytest.mark.parametrize("layout", LAYOUTS)
@pytest.mark.parametrize("count", [1, 129, 700])
def test_field_inputs_match_the_reference_values_and_table_gradient(layout, count) -> None:
    grid = make_grid(layout)
    blob = OneBlobEncoding(16).to(DEVICE)
    points = edge_points(count, grid.resolutions[-1]).to(DEVICE)
    grid.cpu_kernel = False  # the PyTorch path, not the compiled CPU loop

    fast = triton_kernels.field_inputs(grid, points, 16, ONE_BLOB_CUTOFF)
    reference = torch.cat([blob(points.clamp(0.0, 1.0)), grid(points)], dim=1)
    assert fast.shape == reference.shape == (count, 48 + grid.output_dim)
    torch.testing.assert_close(fast, reference, rtol=1e-5, atol=VALUE_ATOL)

    upstream = torch.randn(reference.shape, generator=torch.Generator().manual_seed(3))
    upstream = upstream.to(DEVICE)
    fast.backward(upstream)
    fast_grad = grid.table.grad.clone()
    grid.table.grad = None
    reference.backward(upstream)
    torch.testing.assert_close(fast_grad, grid.table.grad, rtol=1e-4, atol=TABLE_GRAD_ATOL)


@pytest.mark.parametrize("layout", LAYOUTS[:3])
def test_hash_grid_features_match_the_encoding(layout) -> None:
    grid = make_grid(layout)
    points = edge_points(300, grid.resolutions[-1]).to(DEVICE)
    fast = triton_kernels.hash_grid_features(grid, points)
    reference = grid(points)
    torch.testing.assert_close(fast, reference, rtol=1e-5, atol=VALUE_ATOL)
    (fast.square().sum()).backward()
    fast_grad = grid.table.grad.clone()
    grid.table.grad = None
    (reference.square().sum()).backward()
    torch.testing.assert_close(fast_grad, grid.table.grad, rtol=1e-4, atol=TABLE_GRAD_ATOL)


def test_no_points_give_an_empty_buffer_and_a_zero_gradient() -> None:
    grid = make_grid(LAYOUTS[0])
    out = triton_kernels.field_inputs(grid, torch.zeros(0, 3, device=DEVICE), 16, ONE_BLOB_CUTOFF)
    assert out.shape == (0, 48 + grid.output_dim)
    out.sum().backward()
    assert torch.count_nonzero(grid.table.grad) == 0


def test_a_non_float32_table_is_refused() -> None:
    grid = make_grid(LAYOUTS[0]).double()
    with pytest.raises(ValueError, match="float32"):
        triton_kernels.hash_grid_features(grid, torch.rand(4, 3, device=DEVICE))


def small_config(**overrides) -> NeuralMapperConfig:
    return tiny_mapper_config(**{"device": DEVICE.type, **overrides})


def test_field_forward_sdf_and_every_parameter_gradient_match(room_bounds) -> None:
    config = small_config()
    torch.manual_seed(0)
    reference = NeuralField(room_bounds, config).to(DEVICE)
    fast = NeuralField(room_bounds, config, backend="triton").to(DEVICE)
    fast.load_state_dict(reference.state_dict())
    reference.hash_grid.cpu_kernel = False
    generator = torch.Generator().manual_seed(5)
    lower = torch.tensor(room_bounds[0], dtype=torch.float32)
    extent = torch.tensor(room_bounds[1] - room_bounds[0], dtype=torch.float32)
    points = (lower + extent * torch.rand(400, 3, generator=generator)).to(DEVICE)
    for field in (reference, fast):
        sdf, rgb = field(points)
        loss = sdf.square().sum() + rgb.sum() + field.grid_features(points[:50]).square().sum()
        loss.backward()
    torch.testing.assert_close(fast(points)[0], reference(points)[0], rtol=1e-4, atol=1e-5)
    torch.testing.assert_close(fast(points)[1], reference(points)[1], rtol=1e-4, atol=1e-5)
    with torch.no_grad():
        torch.testing.assert_close(fast.sdf(points), reference.sdf(points), rtol=1e-4, atol=1e-5)
    for (name, a), (_, b) in zip(
        fast.named_parameters(), reference.named_parameters(), strict=True
    ):
        torch.testing.assert_close(a.grad, b.grad, rtol=1e-3, atol=1e-5, msg=name)


@pytest.mark.slow  # a few mapping iterations in Triton's interpreter
def test_mapper_on_the_triton_backend_maps_like_the_reference(
    room_renderer, small_camera, room_bounds
) -> None:
    """Same frames, same draws: the losses of every iteration agree (float32 rounding and
    the backward's summation order are the only differences)."""
    losses = {}
    for backend in ("torch", "triton"):
        mapper = NeuralMapper(room_bounds, small_camera, small_config(backend=backend))
        assert mapper.backend == backend
        mapper.field.hash_grid.cpu_kernel = False
        for index, pose in enumerate(orbit_poses(6)):
            rgb, depth = room_renderer.render(pose)
            mapper.integrate(rgb, depth, pose, index)
        losses[backend] = [loss["total"] for loss in mapper.stats.losses]
    assert len(losses["torch"]) == 4
    torch.testing.assert_close(
        torch.tensor(losses["triton"]), torch.tensor(losses["torch"]), rtol=LOSS_RTOL, atol=1e-5
    )


def test_the_self_check_passes_and_a_failing_kernel_falls_back_or_raises(
    monkeypatch, room_bounds, small_camera
) -> None:
    field = NeuralField(room_bounds, small_config(), backend="triton").to(DEVICE)
    assert field.fast_path_error() is None
    assert fast_compositing_error(DEVICE) is None

    def broken_composite(*args, **kwargs):
        raise RuntimeError("no kernel")

    with monkeypatch.context() as patch:
        patch.setattr(triton_kernels, "composite", broken_composite)
        assert "no kernel" in fast_compositing_error(DEVICE)

    def broken(*args, **kwargs):
        raise RuntimeError("no compiler")

    monkeypatch.setattr(triton_kernels, "field_inputs", broken)
    assert "no compiler" in field.fast_path_error()
    with pytest.raises(RuntimeError, match="backend='torch'"):
        NeuralMapper(room_bounds, small_camera, small_config(backend="triton"))
    # "auto" where Triton would be chosen (a GPU): a warning, and the reference path.
    monkeypatch.setattr(neural_mapper, "resolve_backend", lambda backend, device: "triton")
    with pytest.warns(UserWarning, match="PyTorch path"):
        mapper = NeuralMapper(room_bounds, small_camera, small_config(backend="auto"))
    assert mapper.backend == mapper.field.backend == "torch"


_COMPILE_FOR_GPUS = """
import itertools, sys
import triton
from triton.backends.compiler import GPUTarget
from triton.compiler import ASTSource
from naruto_agent.mapping import triton_kernels as tk

pointers = ("*fp32", "*fp32", "*fp32", "*i64", "*fp32")
hash_signature = pointers + ("i32",) * 7
blob_signature = ("*fp32", "*fp32", "i32", "i32", "fp32", "i32")
kernels = [(tk.hash_forward, hash_signature, (2, 128)),
           (tk.hash_backward, hash_signature, (2, 128)),
           (tk.one_blob, blob_signature, (16, 128))]
kernels += [(tk.hash_forward, hash_signature, (f, 128)) for f in (1, 4)]
composite_forward = ("*fp32",) * 5 + ("i32", "i32", "fp32")
composite_backward = ("*fp32",) * 8 + ("i32", "i32", "fp32")
kernels += [(tk.composite_forward, composite_forward, (True, True, 64, 16)),
            (tk.composite_forward, composite_forward, (False, True, 64, 16)),
            (tk.composite_backward, composite_backward, (True, True, True, 64, 16)),
            (tk.composite_backward, composite_backward, (True, True, False, 64, 16))]
for capability, (fn, types, constants) in itertools.product((75, 80, 90), kernels):
    names = fn.arg_names
    signature = dict(zip(names, types + ("constexpr",) * len(constants)))
    constexprs = {(len(types) + i,): value for i, value in enumerate(constants)}
    compiled = triton.compile(ASTSource(fn, signature, constexprs),
                              target=GPUTarget("cuda", capability, 32))
    assert "cubin" in compiled.asm, (fn.__name__, capability)
print("compiled")
"""


@pytest.mark.skipif(sys.platform != "linux", reason="Triton's CUDA compiler ships for Linux")
def test_the_kernels_compile_for_cuda_gpus_without_one() -> None:
    """The real compiler (not the interpreter) turns every kernel into a cubin for Turing,
    Ampere and Hopper GPUs: a machine with no GPU checks what the interpreter cannot (types,
    supported operations, the compile step of the first GPU run)."""
    env = {k: v for k, v in os.environ.items() if k != "TRITON_INTERPRET"}
    env["TRITON_DEFAULT_FP_FUSION"] = "1"
    result = subprocess.run(
        [sys.executable, "-c", _COMPILE_FOR_GPUS],
        env={
            **env,
            "PYTHONPATH": os.pathsep.join(
                filter(None, [str(Path(__file__).resolve().parents[3]), env.get("PYTHONPATH")])
            ),
        },
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert result.returncode == 0 and "compiled" in result.stdout, result.stderr[-3000:]


def composite_reference(sdf, z, rgb, sigma2, truncation, sigma_to_weights):
    weights = truncated_weights(sdf, z, truncation)
    w = weights if sigma_to_weights else weights.detach()
    return (
        (weights * z).sum(dim=1),
        (weights[:, :, None] * rgb).sum(dim=1),
        (w * w * sigma2).sum(dim=1),
    )


@pytest.mark.parametrize("count", [1, 37])
@pytest.mark.parametrize("sigma_to_weights", [True, False])
def test_fused_compositing_matches_the_reference_weights_and_gradients(
    count, sigma_to_weights
) -> None:
    generator = torch.Generator().manual_seed(count)
    samples = 43
    z = torch.sort(5.0 * torch.rand(count, samples, generator=generator), dim=1).values
    surface = 0.5 + 4.0 * torch.rand(count, 1, generator=generator)
    sdf = ((surface - z) / 0.1).clamp(-1.0, 1.0) * 0.3
    sdf = sdf + 0.05 * torch.randn(count, samples, generator=generator)
    if count > 1:
        sdf[0] = 0.2  # no sign change: every sample kept
        sdf[1, 30:] = -1.0  # culled samples behind the surface
    rgb = torch.rand(count, samples, 3, generator=generator)
    sigma2 = 0.01 + torch.rand(count, samples, generator=generator)
    upstream = [torch.randn(count, generator=generator), torch.randn(count, 3, generator=generator),
                torch.randn(count, generator=generator)]  # fmt: skip
    results = []
    for fused in (True, False):
        inputs = [t.clone().to(DEVICE).requires_grad_() for t in (sdf, rgb, sigma2)]
        zz = z.to(DEVICE)
        if fused:
            depth, colour, variance = triton_kernels.composite(
                inputs[0], zz, inputs[1], inputs[2], 0.1, sigma_to_weights
            )
        else:
            depth, colour, variance = composite_reference(
                inputs[0], zz, inputs[1], inputs[2], 0.1, sigma_to_weights
            )
        outputs = (depth, colour, variance)
        loss = sum((o * g.to(DEVICE)).sum() for o, g in zip(outputs, upstream, strict=True))
        loss.backward()
        results.append([depth, colour, variance, *(t.grad for t in inputs)])
    names = ("depth", "rgb", "variance", "grad sdf", "grad rgb", "grad sigma2")
    for name, fast, reference in zip(names, *results, strict=True):
        torch.testing.assert_close(fast, reference, rtol=1e-4, atol=1e-5, msg=name)


def test_fused_compositing_without_colour_or_variance() -> None:
    generator = torch.Generator().manual_seed(9)
    sdf = (torch.rand(5, 43, generator=generator) - 0.5).to(DEVICE)
    z = torch.sort(torch.rand(5, 43, generator=generator), dim=1).values.to(DEVICE)
    depth, rgb, variance = triton_kernels.composite(sdf, z, None, None, 0.1)
    assert rgb is None and variance is None
    torch.testing.assert_close(depth, (truncated_weights(sdf, z, 0.1) * z).sum(dim=1))
    empty = triton_kernels.composite(sdf[:0], z[:0], None, None, 0.1)[0]
    assert empty.shape == (0,)
