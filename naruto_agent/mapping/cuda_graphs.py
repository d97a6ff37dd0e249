"""The fast path's mapping iteration captured as a CUDA graph and replayed.

An iteration of the fused-kernel path (``backend="triton"``) launches a few hundred small
kernels, and on a fast GPU their launches, not their arithmetic, set its time. The
fixed-shape path makes every tensor's shape follow from the number of rays alone and never
waits for the device, so the whole iteration (rendering, losses, backward pass and both
optimiser steps) can be recorded once per batch size and replayed as one launch: the rays
are copied into the graph's input tensors and the loss values come back in one transfer.

Inside the graph the random draws (sample jitter, the smoothness patch) come from the
default CUDA generator, which graphs advance at every replay; the mapper seeds it. A batch
size is captured the second time it comes (the first frame's batches are sized apart), at
most ``max_graphs`` of them; any other batch, and every batch after a capture failed (with
a warning), runs eagerly.
"""

from __future__ import annotations

import warnings
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import torch

from naruto_agent.mapping.rendering import RayBatch

#: An iteration: ``step(rays, update)`` renders ``rays``, back-propagates the losses and,
#: with ``update``, steps the optimisers; returns the loss names and their values stacked on
#: the device. Gradients are cleared by the caller.
IterationStep = Callable[[RayBatch, bool], tuple[list[str], torch.Tensor]]


@dataclass
class _Captured:
    inputs: RayBatch
    graph: torch.cuda.CUDAGraph
    names: list[str]
    values: torch.Tensor


class CapturedIterations:
    """Replays ``step`` as CUDA graphs, one per recurring batch size.

    Args:
        step: the iteration (see :data:`IterationStep`).
        optimisers: every optimiser ``step`` steps; created with ``capturable=True``.
        max_graphs: batch sizes captured at most.
    """

    def __init__(
        self, step: IterationStep, optimisers: Sequence[torch.optim.Optimizer], max_graphs: int = 2
    ) -> None:
        self._step = step
        self._optimisers = list(optimisers)
        self.max_graphs = int(max_graphs)
        self._graphs: dict[int, _Captured] = {}
        self._seen: Counter[int] = Counter()
        self.failure: str | None = None
        """Why capturing failed (every iteration then runs eagerly), or None."""

    @property
    def captured_sizes(self) -> list[int]:
        """The batch sizes that have a graph."""
        return sorted(self._graphs)

    def clear(self) -> None:
        """Forget the graphs (the parameters or optimiser states were replaced)."""
        self._graphs.clear()
        self._seen.clear()

    def run(self, rays: RayBatch) -> tuple[list[str], torch.Tensor] | None:
        """One iteration on ``rays`` by replaying its graph (capturing it first where due);
        None where this batch runs eagerly."""
        if self.failure is not None:
            return None
        count = len(rays)
        captured = self._graphs.get(count)
        if captured is None:
            self._seen[count] += 1
            if self._seen[count] < 2 or len(self._graphs) >= self.max_graphs:
                return None
            try:
                captured = self._capture(rays)
            except Exception as error:  # noqa: BLE001 - reported, then the eager path runs
                self.failure = f"{type(error).__name__}: {error}"
                warnings.warn(
                    f"the mapping iteration could not be captured as a CUDA graph "
                    f"({self.failure}); it runs eagerly (set cuda_graphs=False to skip the "
                    "attempt)",
                    stacklevel=3,
                )
                return None
            self._graphs[count] = captured
        for target, source in zip(_tensors(captured.inputs), _tensors(rays), strict=True):
            target.copy_(source)
        captured.graph.replay()
        return captured.names, captured.values

    def _capture(self, rays: RayBatch) -> _Captured:
        inputs = RayBatch(*(tensor.clone() for tensor in _tensors(rays)))
        device = inputs.depth.device
        # One pass without an update on a side stream: lazy initialisation (library handles,
        # autograd's buffers) must not happen during the capture.
        side = torch.cuda.Stream(device)
        side.wait_stream(torch.cuda.current_stream(device))
        with torch.cuda.stream(side):
            self._clear_gradients()
            self._step(inputs, False)
        torch.cuda.current_stream(device).wait_stream(side)
        # The backward pass in the graph then writes gradients of its own memory.
        self._clear_gradients()
        graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(graph):
            names, values = self._step(inputs, True)
        return _Captured(inputs, graph, names, values)

    def _clear_gradients(self) -> None:
        for optimiser in self._optimisers:
            optimiser.zero_grad(set_to_none=True)


def _tensors(rays: RayBatch) -> tuple[torch.Tensor, ...]:
    return rays.origins, rays.directions, rays.rgb, rays.depth
