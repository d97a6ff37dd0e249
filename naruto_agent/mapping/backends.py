"""Which compute path the neural mapper runs: the PyTorch reference or the Triton kernels.

The PyTorch path (:mod:`naruto_agent.mapping.encoding`, :mod:`naruto_agent.mapping.field`)
is the reference and the CPU default. The Triton path
(:mod:`naruto_agent.mapping.triton_kernels`) computes the same function with fused kernels,
for CUDA, where a mapping iteration is bound by kernel launches rather than arithmetic.
Triton is optional, so nothing here imports it.
"""

from __future__ import annotations

import importlib.util
import os

import torch

#: Mapper compute backends (``NeuralMapperConfig.backend``).
BACKENDS = ("auto", "torch", "triton")


def triton_available() -> bool:
    """Whether the ``triton`` package can be imported (it is not a core dependency)."""
    return importlib.util.find_spec("triton") is not None


def interpreter_enabled() -> bool:
    """Whether Triton's CPU interpreter is switched on (``TRITON_INTERPRET=1``)."""
    return os.environ.get("TRITON_INTERPRET", "0").lower() in ("1", "true", "yes", "on")


#: Oldest CUDA compute capability the fast path is chosen for by "auto" (Triton's support).
MIN_COMPUTE_CAPABILITY = (7, 5)


def _gpu_supported(device: torch.device) -> bool:
    return (
        device.type == "cuda"
        and torch.cuda.is_available()
        and torch.cuda.get_device_capability(device) >= MIN_COMPUTE_CAPABILITY
    )


def resolve_backend(backend: str, device: torch.device | str) -> str:
    """The backend a mapper on ``device`` runs: "torch" or "triton".

    "auto" takes Triton on a CUDA GPU it supports (compute capability 7.5 or newer) when it
    is importable, and PyTorch otherwise (the reference and the CPU default). "triton" asks
    for the kernels explicitly: on CUDA, or on a CPU under Triton's interpreter (for tests;
    far slower than the PyTorch path there).

    Raises:
        ValueError: an unknown backend, or "triton" where it cannot run.
    """
    device = torch.device(device)
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if backend == "torch":
        return "torch"
    usable = triton_available() and (device.type == "cuda" or interpreter_enabled())
    if backend == "auto":
        return "triton" if usable and _gpu_supported(device) else "torch"
    if not triton_available():
        raise ValueError(
            "backend='triton' needs the triton package: pip install triton "
            "(or use backend='torch', the reference, or 'auto')"
        )
    if not usable:
        raise ValueError(
            f"backend='triton' runs on CUDA, but the mapper is on {device}; use a CUDA "
            "device, backend='torch', or set TRITON_INTERPRET=1 before importing triton "
            "to run the kernels in Triton's (slow) CPU interpreter"
        )
    return "triton"
