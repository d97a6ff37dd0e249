"""Which compute path the neural mapper takes, and the errors when one cannot run."""

from __future__ import annotations

import pytest
import torch

from naruto_agent.mapping import NeuralMapper, NeuralMapperConfig, resolve_backend
from naruto_agent.mapping.backends import triton_available


def test_torch_and_auto_on_a_cpu_take_the_reference() -> None:
    assert resolve_backend("torch", torch.device("cpu")) == "torch"
    assert resolve_backend("auto", "cpu") == "torch"


def test_unknown_backends_are_refused() -> None:
    with pytest.raises(ValueError, match="backend must be one of"):
        resolve_backend("cuda", "cpu")
    with pytest.raises(ValueError, match="backend must be one of"):
        NeuralMapperConfig(backend="fast")


def test_triton_on_a_cpu_without_the_interpreter_says_what_to_do(monkeypatch) -> None:
    monkeypatch.setenv("TRITON_INTERPRET", "0")
    with pytest.raises(ValueError, match="backend='torch'"):
        resolve_backend("triton", "cpu")


def test_the_cpu_mapper_defaults_to_the_reference(room_bounds, small_camera) -> None:
    mapper = NeuralMapper(room_bounds, small_camera, NeuralMapperConfig(device="cpu"))
    assert mapper.backend == "torch"
    assert mapper.field.backend == "torch"


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_auto_on_cuda_takes_triton_where_installed() -> None:
    expected = "triton" if triton_available() else "torch"
    if torch.cuda.get_device_capability() < (7, 5):
        expected = "torch"
    assert resolve_backend("auto", "cuda") == expected
