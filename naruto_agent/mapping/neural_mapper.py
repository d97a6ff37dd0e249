"""NARUTO's mapper: a Co-SLAM neural field with known poses, an uncertainty grid, and active
ray sampling, in pure PyTorch (CPU or CUDA).

Schedule (published): the first frame gets ``first_frame_iterations`` (200) iterations of
``rays_per_iteration`` (2048) rays drawn from it; afterwards every ``map_every`` (5) frames a
mapping step of ``iterations_per_step`` (10) iterations runs, each with 2048 rays drawn from
all keyframes plus ``current_frame_rays`` (>= 100) from the current frame; every
``keyframe_every`` (5) frames the frame becomes a keyframe that keeps 5 % of its pixels.

Because a frame contributes only those pixels, the mapper can tell beforehand which ones it
will read (:meth:`NeuralMapper.required_pixels`): a caller that renders frames (a simulator)
can ray-cast just those pixels and pass them to :meth:`NeuralMapper.integrate_pixels`. That
is exactly equivalent to rendering the whole frame and calling :meth:`NeuralMapper.integrate`,
which picks the same pixels (same draws) from the full images.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
import trimesh

from naruto_agent.mapping.backends import resolve_backend
from naruto_agent.mapping.base import check_bounds, check_frame, resolve_device
from naruto_agent.mapping.config import NeuralMapperConfig
from naruto_agent.mapping.cpu_allocator import keep_freed_memory_for_reuse
from naruto_agent.mapping.cuda_graphs import CapturedIterations
from naruto_agent.mapping.encoding import HashGridEncoding
from naruto_agent.mapping.field import NeuralField
from naruto_agent.mapping.keyframes import KeyframeRays
from naruto_agent.mapping.meshing import mesh_from_sdf_function
from naruto_agent.mapping.observed_space import (
    ObservedSpace,
    ObservedSpaceConfig,
    add_unknown_space_uncertainty,
)
from naruto_agent.mapping.rendering import (
    RayBatch,
    fast_compositing_error,
    mapping_losses,
    measured_point_variance,
    render_rays,
    smoothness_loss,
    surface_variance,
    weighted_total,
)
from naruto_agent.mapping.sdf_volume import SdfVolume
from naruto_agent.mapping.uncertainty_grid import UncertaintyGrid
from naruto_gym.sensors.pinhole import PinholeCamera

_QUERY_CHUNK = 65_536
# On a GPU a query takes more points at once: fewer launches and host round trips (the
# planner view's ~10^5-10^6 voxels in one or a few passes), memory is no concern.
_GPU_QUERY_CHUNK = 1 << 20
# Rays rendered at once when the PyTorch path scores the active-sampling pool.
_SCORING_CHUNK = 4096


@dataclass
class _FramePlan:
    """Which pixels of one frame the mapper reads, drawn before the frame is seen."""

    frame_index: int
    first_frame: bool
    keyframe_pixels: np.ndarray
    iteration_pixels: list[np.ndarray] = field(default_factory=list)

    def all_pixels(self) -> np.ndarray:
        parts = [self.keyframe_pixels, *self.iteration_pixels]
        return np.unique(np.concatenate(parts)) if parts else np.zeros(0, np.int64)


@dataclass
class MappingStats:
    """Counters of the work done, for benchmarks.

    ``iteration_seconds`` is the whole of every mapping iteration, the active ray selection
    included; ``scoring_seconds`` is the part of it spent drawing and scoring the active pool
    and picking the rays. ``observed_space_seconds`` is the integration of frames and
    panoramas into the measure of explored space (outside the iterations).
    """

    iterations: int = 0
    mapping_steps: int = 0
    iteration_seconds: float = 0.0
    scoring_seconds: float = 0.0
    observed_space_seconds: float = 0.0
    losses: list[dict[str, float]] = field(default_factory=list)

    @property
    def seconds_per_iteration(self) -> float:
        return self.iteration_seconds / max(self.iterations, 1)


class NeuralMapper:
    """Neural implicit map with NARUTO's uncertainty grid and active ray sampling.

    Args:
        bounds: (2, 3) [min, max] world box of the scene, metres (the encodings, the
            uncertainty grid and all queries cover it).
        camera: intrinsics of the frames that will be integrated.
        config: settings (published defaults); ``config.device`` picks the device.
        hash_encoding_cls: hash-grid implementation (the naive reference, for benchmarks).

    Example:
        >>> mapper = NeuralMapper(scene.bounds, PinholeCamera())  # doctest: +SKIP
        >>> for i, pose in enumerate(poses):  # doctest: +SKIP
        ...     rgb, depth = renderer.render(pose)
        ...     mapper.integrate(rgb, depth, pose, i)
        >>> sdf_volume, uncertainty_volume = mapper.planner_view()  # doctest: +SKIP
    """

    def __init__(
        self,
        bounds: np.ndarray,
        camera: PinholeCamera,
        config: NeuralMapperConfig | None = None,
        hash_encoding_cls: type[HashGridEncoding] = HashGridEncoding,
    ) -> None:
        self.config = config or NeuralMapperConfig()
        self.bounds = check_bounds(bounds)
        self.camera = camera
        self._device = resolve_device(self.config.device)
        if self._device.type == "cpu" and self.config.tune_cpu_allocator:
            keep_freed_memory_for_reuse()
        torch.manual_seed(self.config.seed)
        # The field owns the backend in use (resolved here once); ``backend`` reads it.
        self.field = NeuralField(
            self.bounds,
            self.config,
            hash_encoding_cls,
            backend=resolve_backend(self.config.backend, self._device),
        ).to(self._device)
        if self.field.backend == "triton":
            self._check_fast_path()
        self.uncertainty = UncertaintyGrid(
            self.bounds,
            self.config.uncertainty_voxel_m,
            self.config.uncertainty_init,
            self.config.uncertainty_min_variance,
        ).to(self._device)
        graphs = (
            self.config.cuda_graphs
            and self._device.type == "cuda"
            and self.field.backend == "triton"
        )
        self.optimiser = self._adam(
            self.field.parameters(), self.config.learning_rate, capturable=graphs
        )
        self.uncertainty_optimiser = self._adam(
            self.uncertainty.parameters(), self.config.uncertainty_learning_rate, capturable=graphs
        )
        self._captured = (
            CapturedIterations(self._iteration, [self.optimiser, self.uncertainty_optimiser])
            if graphs
            else None
        )
        self.keyframes = KeyframeRays(self._device)
        self.generator = torch.Generator(device=self._device).manual_seed(self.config.seed)
        self.rng = np.random.default_rng(self.config.seed)
        self._bounds_tensor = torch.tensor(self.bounds, dtype=torch.float32, device=self._device)
        self._directions = torch.from_numpy(camera.ray_directions).to(self._device)
        self._plan: _FramePlan | None = None
        self.frames_integrated = 0
        self.observed_space = ObservedSpace(
            self.bounds,
            ObservedSpaceConfig(
                voxel_size_m=self.config.uncertainty_voxel_m,
                max_range_m=self.config.far_m,
                rays_per_frame=self.config.observed_rays_per_frame,
                min_cluster_voxels=self.config.frontier_min_cluster_voxels,
            ),
        )
        self.stats = MappingStats()

    def _check_fast_path(self) -> None:
        """Compile the Triton kernels and compare them with the reference once: "auto" falls
        back to the PyTorch path with a warning when they fail, "triton" raises."""
        error = self.field.fast_path_error() or fast_compositing_error(
            self._device, self.config.truncation_m
        )
        if error is None:
            return
        if self.config.backend == "triton":
            raise RuntimeError(f"{error}; use backend='torch' (the reference) on this machine")
        warnings.warn(f"{error}; the neural mapper uses the PyTorch path", stacklevel=3)
        self.field.backend = "torch"

    def _adam(self, parameters, lr: float, capturable: bool = False) -> torch.optim.Optimizer:  # noqa: ANN001
        # Co-SLAM's betas; the fused kernel when this torch has it for the device;
        # ``capturable`` keeps its step count on the device, as a CUDA graph needs.
        parameters = list(parameters)
        extra = {"capturable": True} if capturable else {}
        try:
            return torch.optim.Adam(parameters, lr=lr, betas=(0.9, 0.99), fused=True, **extra)
        except (RuntimeError, TypeError, ValueError):
            return torch.optim.Adam(parameters, lr=lr, betas=(0.9, 0.99), **extra)

    @property
    def device(self) -> torch.device:
        return self._device

    @property
    def _query_chunk(self) -> int:
        return _GPU_QUERY_CHUNK if self._device.type == "cuda" else _QUERY_CHUNK

    @property
    def backend(self) -> str:
        """The compute path in use: "torch" (the reference) or "triton" (fused kernels),
        resolved from ``config.backend`` and the device (the field holds it)."""
        return self.field.backend

    @property
    def active_sampling(self) -> bool:
        return self.config.active_sampling

    # -- schedule -------------------------------------------------------------------------
    def _plan_frame(self, frame_index: int) -> _FramePlan:
        cfg = self.config
        pixel_count = self.camera.width * self.camera.height
        first = self.frames_integrated == 0
        is_keyframe = first or frame_index % cfg.keyframe_every == 0
        keyframe_pixels = np.zeros(0, dtype=np.int64)
        if is_keyframe:
            keep = max(1, int(round(cfg.keyframe_pixel_fraction * pixel_count)))
            keyframe_pixels = np.sort(self.rng.choice(pixel_count, keep, replace=False))
        plan = _FramePlan(frame_index, first, keyframe_pixels)
        if first:
            for _ in range(cfg.first_frame_iterations):
                plan.iteration_pixels.append(
                    self.rng.integers(0, pixel_count, cfg.rays_per_iteration)
                )
        elif frame_index % cfg.map_every == 0:
            per_iteration = cfg.current_frame_rays * (
                cfg.active_oversample if cfg.active_sampling else 1
            )
            for _ in range(cfg.iterations_per_step):
                plan.iteration_pixels.append(self.rng.integers(0, pixel_count, per_iteration))
        return plan

    def required_pixels(self, frame_index: int) -> np.ndarray:
        """Sorted flat pixel indices (row-major, ``v * width + u``) this frame will be read at.

        Empty when the frame is neither a keyframe nor a mapping frame. Calling it twice for
        the same frame returns the same pixels.
        """
        if self._plan is None or self._plan.frame_index != frame_index:
            self._plan = self._plan_frame(frame_index)
        return self._plan.all_pixels()

    # -- integration ----------------------------------------------------------------------
    def integrate(
        self, rgb: np.ndarray, depth: np.ndarray, camera_to_world: np.ndarray, frame_index: int
    ) -> bool:
        """Take one full frame. Returns True when a mapping step ran (the map changed)."""
        rgb, depth, pose = check_frame(rgb, depth, camera_to_world)
        if depth.shape != (self.camera.height, self.camera.width):
            raise ValueError(
                f"frame is {depth.shape} but the mapper's camera is "
                f"{self.camera.height} x {self.camera.width}; pass the camera the frames use"
            )
        if self.config.unknown_space:
            start = time.perf_counter()
            self.observed_space.integrate_depth(depth, pose, self.camera)
            self.stats.observed_space_seconds += time.perf_counter() - start
        pixels = self.required_pixels(frame_index)
        return self.integrate_pixels(
            pixels, rgb.reshape(-1, 3)[pixels], depth.reshape(-1)[pixels], pose, frame_index
        )

    def integrate_pixels(
        self,
        pixels: np.ndarray,
        rgb: np.ndarray,
        depth: np.ndarray,
        camera_to_world: np.ndarray,
        frame_index: int,
    ) -> bool:
        """Take the pixels of a frame that :meth:`required_pixels` named.

        Args:
            pixels: (K,) flat pixel indices, at least those of :meth:`required_pixels`.
            rgb: (K, 3) uint8 colours of those pixels.
            depth: (K,) z-depth in metres (0 = missing).
            camera_to_world: 4x4 pose.
            frame_index: frame number (drives the schedule).

        Returns:
            True when a mapping step ran.
        """
        plan = self._plan
        if plan is None or plan.frame_index != frame_index:
            plan = self._plan = self._plan_frame(frame_index)
        pixels = np.asarray(pixels, dtype=np.int64)
        rgb = np.asarray(rgb, dtype=np.uint8).reshape(-1, 3)
        depth = np.asarray(depth, dtype=np.float32).reshape(-1)
        if not (len(pixels) == len(rgb) == len(depth)):
            raise ValueError("pixels, rgb and depth must have the same length")
        needed = plan.all_pixels()
        order = np.argsort(pixels)
        sorted_pixels = pixels[order]
        slot = np.searchsorted(sorted_pixels, needed)
        slot = np.minimum(slot, max(len(sorted_pixels) - 1, 0))
        if len(needed) and (len(pixels) == 0 or np.any(sorted_pixels[slot] != needed)):
            raise ValueError(
                "integrate_pixels was not given every pixel of required_pixels(frame_index); "
                "ray-cast exactly those pixels (or call integrate with the full frame)"
            )
        pose = torch.tensor(np.asarray(camera_to_world), dtype=torch.float32, device=self._device)

        def rays_of(wanted: np.ndarray) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
            index = order[np.searchsorted(sorted_pixels, wanted)]
            directions = self._directions[torch.from_numpy(wanted).to(self._device)]
            colours = torch.from_numpy(rgb[index]).to(self._device)
            depths = torch.from_numpy(depth[index]).to(self._device)
            return directions, colours, depths

        self._plan = None
        self.frames_integrated += 1
        mapped = False
        if plan.iteration_pixels:
            current = [_world_rays(pose, *rays_of(p)) for p in plan.iteration_pixels]
            self._mapping_step(current, first_frame=plan.first_frame)
            mapped = True
        if len(plan.keyframe_pixels):
            directions, colours, depths = rays_of(plan.keyframe_pixels)
            self.keyframes.add(pose, directions, colours, depths)
        return mapped

    def frame_rays(
        self,
        rgb: np.ndarray,
        depth: np.ndarray,
        camera_to_world: np.ndarray,
        pixels: np.ndarray | None = None,
    ) -> RayBatch:
        """World rays of a frame's pixels, on the mapper's device, as a mapping iteration
        reads them (for benchmarks and tests that feed :meth:`active_ray_pool` or
        :meth:`train_iteration` themselves).

        Args:
            rgb: (H, W, 3) or (H * W, 3) uint8 colours of the whole frame.
            depth: (H, W) or (H * W,) z-depth in metres (0 = missing).
            camera_to_world: 4x4 pose.
            pixels: flat pixel indices (``v * width + u``) to take, in this order; None
                takes every pixel.
        """
        pose = torch.tensor(np.asarray(camera_to_world), dtype=torch.float32, device=self._device)
        rgb = np.asarray(rgb, dtype=np.uint8).reshape(-1, 3)
        depth = np.asarray(depth, dtype=np.float32).reshape(-1)
        directions = self._directions
        if pixels is not None:
            pixels = np.asarray(pixels, dtype=np.int64)
            directions = directions[torch.from_numpy(pixels).to(self._device)]
            rgb, depth = rgb[pixels], depth[pixels]
        return _world_rays(
            pose,
            directions,
            torch.from_numpy(rgb).to(self._device),
            torch.from_numpy(depth).to(self._device),
        )

    # -- optimisation ---------------------------------------------------------------------
    def _select_rays(self, current: RayBatch) -> RayBatch:
        """The rays of one iteration: keyframe rays + current-frame rays (active or random)."""
        cfg = self.config
        if not cfg.active_sampling:
            return RayBatch.concatenate(
                [self.keyframes.sample(cfg.rays_per_iteration, self.generator), current]
            )
        start = time.perf_counter()
        pool, num_keyframe_rays = self.active_ray_pool(current)
        scores = self.ray_uncertainty(pool)
        selected = pool.select(
            select_active_rays(
                scores,
                num_keyframe_rays=num_keyframe_rays,
                top=cfg.active_top_rays,
                random_keyframe=cfg.rays_per_iteration - cfg.active_top_rays,
                current=cfg.current_frame_rays,
                generator=self.generator,
            )
        )
        if self._device.type == "cuda":
            torch.cuda.synchronize(self._device)
        self.stats.scoring_seconds += time.perf_counter() - start
        return selected

    def active_ray_pool(self, current: RayBatch) -> tuple[RayBatch, int]:
        """The oversampled pool active sampling scores: ``active_oversample`` x
        ``rays_per_iteration`` keyframe rays, then the current-frame rays. Returns the pool and
        how many of its rays (the first ones) come from keyframes."""
        cfg = self.config
        keyframe_rays = self.keyframes.sample(
            cfg.rays_per_iteration * cfg.active_oversample, self.generator
        )
        return RayBatch.concatenate([keyframe_rays, current]), len(keyframe_rays)

    @torch.no_grad()
    def ray_uncertainty(self, rays: RayBatch) -> torch.Tensor:
        """(N,) active-sampling score of rays: the rendered variance sum w^2 sigma^2
        (``active_score`` "rendered", published), the same over the samples around the
        measured depth ("surface"), or the grid's variance at the measured surface point
        ("grid"; see :class:`NeuralMapperConfig`)."""
        if self.config.active_score == "surface":
            return surface_variance(self.field, self.uncertainty, rays, self.config)
        if self.config.active_score == "grid":
            return measured_point_variance(self.uncertainty, rays)
        # The fast path scores the whole pool at once (its memory is no concern on a GPU).
        fixed = self.field.backend == "triton"
        chunk = len(rays) if fixed else _SCORING_CHUNK
        scores = []
        for begin in range(0, len(rays), max(chunk, 1)):
            part = rays.select(slice(begin, begin + chunk))
            scores.append(
                render_rays(
                    self.field,
                    part,
                    self.config,
                    self.uncertainty,
                    with_colour=False,
                    fixed_shape=fixed,
                ).variance
            )
        return torch.cat(scores)

    def _mapping_step(self, current_per_iteration: list[RayBatch], first_frame: bool) -> None:
        self.stats.mapping_steps += 1
        for current in current_per_iteration:
            start = time.perf_counter()
            rays = current if first_frame else self._select_rays(current)
            losses = self.train_iteration(rays)
            if self._device.type == "cuda":
                torch.cuda.synchronize(self._device)
            self.stats.iteration_seconds += time.perf_counter() - start
            self.stats.iterations += 1
            self.stats.losses.append(losses)

    def train_iteration(self, rays: RayBatch) -> dict[str, float]:
        """One optimisation step on a batch of rays; returns the loss values."""
        replayed = self._captured.run(rays) if self._captured is not None else None
        if replayed is not None:
            names, values = replayed
        else:
            self.optimiser.zero_grad(set_to_none=True)
            self.uncertainty_optimiser.zero_grad(set_to_none=True)
            names, values = self._iteration(rays, True, self.generator)
        # One transfer for all the values (each float() of a device tensor waits on it).
        return dict(zip(names, values.tolist(), strict=True))

    def _iteration(
        self, rays: RayBatch, update: bool, generator: torch.Generator | None = None
    ) -> tuple[list[str], torch.Tensor]:
        """Render ``rays``, back-propagate the losses and (with ``update``) step both
        optimisers; the loss names and values (stacked, on the device, total last).
        ``generator=None`` draws from the default generator (what a CUDA graph replays)."""
        cfg = self.config
        fixed = self.field.backend == "triton"
        output = render_rays(
            self.field,
            rays,
            cfg,
            self.uncertainty,
            generator,
            perturb=cfg.perturb,
            fixed_shape=fixed,
        )
        losses = mapping_losses(output, rays, cfg, fixed_shape=fixed)
        if cfg.smoothness_weight > 0:
            losses["smoothness"] = smoothness_loss(self.field, self._bounds_tensor, cfg, generator)
        total = weighted_total(losses, cfg)
        total.backward()
        if update:
            self.optimiser.step()
            self.uncertainty_optimiser.step()
        return [*losses, "total"], torch.stack([*losses.values(), total]).detach()

    @property
    def cuda_graph_status(self) -> str:
        """Whether iterations replay as CUDA graphs: "off" (not asked for, or not the fast
        path on a GPU), "waiting" (no batch size captured yet), "replaying (sizes ...)", or
        "failed: <why>" (they run eagerly)."""
        if self._captured is None:
            return "off"
        if self._captured.failure is not None:
            return f"failed: {self._captured.failure}"
        sizes = self._captured.captured_sizes
        return f"replaying (sizes {sizes})" if sizes else "waiting"

    # -- queries --------------------------------------------------------------------------
    @torch.no_grad()
    def sdf(self, points: np.ndarray) -> np.ndarray:
        """(N,) signed distance in metres at (N, 3) world points (positive in free space)."""
        points = np.asarray(points, dtype=np.float32).reshape(-1, 3)
        out = np.empty(len(points), dtype=np.float64)
        step = self._query_chunk
        for begin in range(0, len(points), step):
            chunk = torch.from_numpy(points[begin : begin + step]).to(self._device)
            values = self.field.sdf(chunk) * self.config.truncation_m
            out[begin : begin + len(chunk)] = values.cpu().numpy()
        return out

    @torch.no_grad()
    def colour(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) uint8 colour of the field at world points."""
        points = np.asarray(points, dtype=np.float32).reshape(-1, 3)
        out = np.empty((len(points), 3), dtype=np.uint8)
        step = self._query_chunk
        for begin in range(0, len(points), step):
            chunk = torch.from_numpy(points[begin : begin + step]).to(self._device)
            _, rgb = self.field(chunk)
            out[begin : begin + len(chunk)] = (
                (rgb * 255.0 + 0.5).clamp(0, 255).to(torch.uint8).cpu().numpy()
            )
        return out

    @torch.no_grad()
    def variance(self, points: np.ndarray) -> np.ndarray:
        """(N,) uncertainty-grid variance sigma^2 at world points."""
        points = torch.as_tensor(np.asarray(points, np.float32).reshape(-1, 3), device=self._device)
        return self.uncertainty.variance(points).cpu().numpy().astype(np.float64)

    def planner_view(self, voxel_size: float = 0.1) -> tuple[SdfVolume, SdfVolume]:
        """The planner's map: (SDF volume, uncertainty volume) on a grid over the bounds.

        The SDF is in metres. The uncertainty volume holds the grid's variance sigma^2 on
        surface voxels (SDF between 0 and half a truncation), the initial variance on the
        frontier of unexplored space (``unknown_space``), and 0 everywhere else.
        """
        sdf_volume = SdfVolume.from_function(self.sdf, self.bounds, voxel_size)
        variance = self._variance_on(sdf_volume)
        on_surface = (sdf_volume.values >= 0.0) & (
            sdf_volume.values <= 0.5 * self.config.truncation_m
        )
        uncertainty_volume = SdfVolume(
            np.where(on_surface, variance, 0.0), sdf_volume.origin, voxel_size
        )
        if self.config.unknown_space:
            uncertainty_volume = add_unknown_space_uncertainty(
                uncertainty_volume, self.observed_space, self.initial_variance
            )
        return sdf_volume, uncertainty_volume

    @torch.no_grad()
    def _variance_on(self, volume: SdfVolume) -> np.ndarray:
        """The grid's variance at every voxel of a volume; read straight off the grid (no
        interpolation) when the volume's voxels are the grid's own."""
        grid = self.uncertainty
        if (
            volume.shape == grid.shape
            and np.allclose(volume.origin, grid.origin_numpy, atol=1e-6)
            and abs(volume.voxel_size - grid.voxel_size) < 1e-9
        ):
            return grid.variance_grid().cpu().numpy().astype(np.float64)
        return self.variance(volume.grid_points()).reshape(volume.shape)

    @property
    def initial_variance(self) -> float:
        """The variance of a voxel nothing has measured: softplus(init) + min variance."""
        return float(
            np.logaddexp(0.0, self.config.uncertainty_init) + self.config.uncertainty_min_variance
        )

    def integrate_panorama(self, panorama: np.ndarray, position: np.ndarray) -> None:
        """Add a depth panorama's rays to the observed space (free space all around)."""
        if self.config.unknown_space:
            start = time.perf_counter()
            self.observed_space.integrate_panorama(panorama, position)
            self.stats.observed_space_seconds += time.perf_counter() - start

    query_volumes = planner_view

    def extract_mesh(self, voxel_size: float = 0.02) -> trimesh.Trimesh:
        """Marching-cubes mesh of the SDF (2 cm final; coarser for previews), coloured."""
        return mesh_from_sdf_function(self.sdf, self.bounds, voxel_size, self.colour)

    # -- persistence ----------------------------------------------------------------------
    def state_dict(self, include_keyframes: bool = True) -> dict[str, Any]:
        """The map (field, uncertainty grid, optimisers, counters; keyframe rays optional)."""
        state: dict[str, Any] = {
            "config": self.config.to_dict(),
            "bounds": self.bounds.tolist(),
            "camera": self.camera.as_dict(),
            "field": {k: v.cpu() for k, v in self.field.state_dict().items()},
            "uncertainty": {k: v.cpu() for k, v in self.uncertainty.state_dict().items()},
            "optimiser": self.optimiser.state_dict(),
            "uncertainty_optimiser": self.uncertainty_optimiser.state_dict(),
            "frames_integrated": self.frames_integrated,
            "observed_space": self.observed_space.state_dict(),
        }
        if include_keyframes:
            state["keyframes"] = self.keyframes.state_dict()
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore a map saved by :meth:`state_dict` (same bounds and grid settings)."""
        if not np.allclose(np.asarray(state["bounds"]), self.bounds):
            raise ValueError(
                f"saved map covers bounds {state['bounds']}, this mapper {self.bounds.tolist()}; "
                "build the mapper with the saved bounds"
            )
        self.field.load_state_dict(state["field"])
        self.uncertainty.load_state_dict(state["uncertainty"])
        self.optimiser.load_state_dict(state["optimiser"])
        self.uncertainty_optimiser.load_state_dict(state["uncertainty_optimiser"])
        self.frames_integrated = int(state["frames_integrated"])
        if "observed_space" in state:
            self.observed_space.load_state_dict(state["observed_space"])
        if "keyframes" in state:
            self.keyframes.load_state_dict(state["keyframes"])
        self._plan = None
        if self._captured is not None:
            # The graphs hold the replaced optimiser states; a saved state may come from an
            # optimiser that was not capturable.
            for optimiser in (self.optimiser, self.uncertainty_optimiser):
                for group in optimiser.param_groups:
                    group["capturable"] = True
            self._captured.clear()

    @classmethod
    def from_state_dict(cls, state: dict[str, Any], device: str = "auto") -> NeuralMapper:
        """Build a mapper from a saved state (on ``device``)."""
        config = NeuralMapperConfig.from_dict({**state["config"], "device": device})
        mapper = cls(np.asarray(state["bounds"]), PinholeCamera(**state["camera"]), config)
        mapper.load_state_dict(state)
        return mapper


def _world_rays(
    pose: torch.Tensor, directions: torch.Tensor, rgb: torch.Tensor, depth: torch.Tensor
) -> RayBatch:
    """Rays of camera-frame ``directions`` (z = 1) seen from ``pose`` (4x4 camera-to-world),
    with uint8 colours and z-depths."""
    return RayBatch(
        origins=pose[:3, 3].expand(len(depth), 3),
        directions=directions @ pose[:3, :3].T,
        rgb=rgb.float() / 255.0,
        depth=depth,
    )


def select_active_rays(
    scores: torch.Tensor,
    num_keyframe_rays: int,
    top: int,
    random_keyframe: int,
    current: int,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Indices of NARUTO's active ray selection from a scored pool.

    The pool holds ``num_keyframe_rays`` keyframe rays first, then current-frame rays. Kept:
    the ``top`` rays of highest score in the whole pool (the MOST uncertain, as in the paper;
    the released code takes the least), plus ``random_keyframe`` random keyframe rays and
    ``current`` random current-frame rays among those not already kept.

    Returns:
        (top + random_keyframe + current,) int64 indices into the pool (fewer if the pool
        is too small).
    """
    total = scores.shape[0]
    device = scores.device
    top = min(top, total)
    chosen = torch.topk(scores, top).indices
    taken = torch.zeros(total, dtype=torch.bool, device=device)
    taken[chosen] = True
    parts = [chosen]
    for begin, end, count in (
        (0, num_keyframe_rays, random_keyframe),
        (num_keyframe_rays, total, current),
    ):
        free = (~taken[begin:end]).nonzero().squeeze(1) + begin
        if count > 0 and len(free):
            order = torch.randperm(len(free), device=device, generator=generator)
            parts.append(free[order[:count]])
    return torch.cat(parts)
