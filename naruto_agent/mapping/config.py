"""Settings of the neural mapper; every default is the published system's number.

Sources: NARUTO (Feng et al., CVPR 2024) and its mapping back end, Co-SLAM (Wang et al.,
CVPR 2023). Settings that exist only to make a CPU fast enough say so.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any, Literal

from naruto_agent.mapping.backends import BACKENDS
from naruto_gym.utils.checks import check_choice, check_integer, check_number

#: Active-sampling scores (see ``NeuralMapperConfig.active_score``).
ACTIVE_SCORES = ("rendered", "surface", "grid")


@dataclass
class NeuralMapperConfig:
    """Every number of the neural mapper.

    Encoding and decoders:
        one_blob_bins: OneBlob bins per axis (16).
        hash_levels, hash_features_per_level, hash_log2_table_size, hash_base_resolution:
            multi-resolution hash grid (16 levels x 2 features, 2^16 rows, base 16).
        hash_finest_voxel_m: finest level resolution = largest scene extent / this (0.02 m).
        hidden_dim, geometry_feature_dim: decoders are 2 layers x 32, bias-free; the geometry
            MLP outputs 1 SDF + 15 features.

    Rendering:
        truncation_m: SDF truncation tr (0.1 m); the SDF output is in units of tr.
        near_m, far_m: range of the uniform samples (0..5 m, the mapping depth range).
        num_uniform_samples: uniform samples per ray (32).
        num_surface_samples, surface_range_m: samples within +-range of the depth (11, 0.1 m).
        perturb: stratified jitter of the sample depths during training (True).
        cull_behind_depth_m: samples farther than this behind the measured depth are not
            evaluated (they carry no loss and, behind the first surface, no rendering weight).
            ``None`` evaluates all 43 samples as the published system does. A CPU speed-up.

    Losses (weights): rgb 5, depth 0.1, sdf 1000, free space 10, smoothness 1e-6,
        uncertainty (Gaussian NLL) 0.005. ``smoothness_points`` per axis of the random patch
        on which the feature smoothness is taken (voxel ``smoothness_voxel_m``).

    Optimisation and schedule:
        learning_rate: Adam for grid and decoders (0.01).
        first_frame_iterations: 200; iterations_per_step: 10; keyframe_every / map_every: 5.
        keyframe_pixel_fraction: share of a keyframe's pixels kept (5 %).
        rays_per_iteration: 2048 keyframe rays; current_frame_rays: >= 100 per iteration.

    Uncertainty grid:
        uncertainty_voxel_m 0.1, uncertainty_init 3.0, uncertainty_learning_rate 1.0,
        uncertainty_min_variance 0.01 (variance = softplus(raw) + 0.01).
        uncertainty_detach_geometry: if True the NLL term trains only the grid.

    Active ray sampling:
        active_sampling: on/off (for the ablation).
        active_oversample: pool size factor (4: 8192 keyframe + 400 current-frame rays).
        active_top_rays: rays kept for the highest uncertainty (500); the rest of the 2048
            (1548) are random keyframe rays, plus ``current_frame_rays`` current-frame rays.
        active_score: "rendered" renders sum w^2 sigma^2 of every pool ray with the whole
            sample set (the published scoring, default); two cheaper scorings for a CPU:
            "surface" renders it with the 11 samples around the measured depth only (the
            weights sit there), "grid" reads the uncertainty grid's sigma^2 at the measured
            surface point, with no field query (where the field renders the measured
            surface, the rendered variance is that sigma^2 times the ray's sum w^2).
            ``benchmarks/active_scoring_speed.py`` measures what each costs against a
            mapping iteration and how many of the published pick's rays it shares.

    Unexplored space (planner view):
        unknown_space: frontier voxels (measured free space next to space no frame has
            measured) are goal-search targets at the initial variance, as in the TSDF
            mapper (:mod:`naruto_agent.mapping.observed_space`). Fed by :meth:`integrate`'s
            full frames (and panoramas), not by ``integrate_pixels``.
        frontier_min_cluster_voxels: frontier clusters smaller than this are ignored (8).
        observed_rays_per_frame: pixels per frame integrated into the observed space (2048).

    Device and seed:
        device: "auto" (CUDA when present), "cpu", "cuda[:N]".
        backend: how the field's encodings are computed. "torch" is the PyTorch reference
            (the CPU default); "triton" runs fused Triton kernels that compute the same
            function in a few launches (:mod:`naruto_agent.mapping.triton_kernels`; CUDA,
            ``pip install triton``); "auto" (default) takes Triton on a CUDA GPU where it is
            installed, PyTorch everywhere else. A GPU speed-up.
        cuda_graphs: with the Triton path on a GPU, record each iteration once as a CUDA
            graph and replay it (:mod:`naruto_agent.mapping.cuda_graphs`): one launch
            instead of a few hundred; where capturing fails, a warning and the eager path.
            A GPU speed-up.
        seed: seeds the parameter initialisation and every ray draw.
        tune_cpu_allocator: on a CPU, let glibc keep freed tensor memory for reuse
            (:mod:`naruto_agent.mapping.cpu_allocator`; process-wide: an iteration no
            longer page-faults its temporaries in). A CPU speed-up.
    """

    one_blob_bins: int = 16
    hash_levels: int = 16
    hash_features_per_level: int = 2
    hash_log2_table_size: int = 16
    hash_base_resolution: int = 16
    hash_finest_voxel_m: float = 0.02
    hidden_dim: int = 32
    geometry_feature_dim: int = 15

    truncation_m: float = 0.1
    near_m: float = 0.0
    far_m: float = 5.0
    num_uniform_samples: int = 32
    num_surface_samples: int = 11
    surface_range_m: float = 0.1
    perturb: bool = True
    cull_behind_depth_m: float | None = 0.2

    rgb_weight: float = 5.0
    depth_weight: float = 0.1
    sdf_weight: float = 1000.0
    free_space_weight: float = 10.0
    smoothness_weight: float = 1e-6
    smoothness_points: int = 16
    smoothness_voxel_m: float = 0.1
    uncertainty_weight: float = 0.005

    learning_rate: float = 0.01
    first_frame_iterations: int = 200
    iterations_per_step: int = 10
    keyframe_every: int = 5
    map_every: int = 5
    keyframe_pixel_fraction: float = 0.05
    rays_per_iteration: int = 2048
    current_frame_rays: int = 100

    uncertainty_voxel_m: float = 0.1
    uncertainty_init: float = 3.0
    uncertainty_learning_rate: float = 1.0
    uncertainty_min_variance: float = 0.01
    uncertainty_detach_geometry: bool = False

    active_sampling: bool = True
    active_oversample: int = 4
    active_top_rays: int = 500
    active_score: Literal["rendered", "surface", "grid"] = "rendered"

    unknown_space: bool = True
    frontier_min_cluster_voxels: int = 8
    observed_rays_per_frame: int = 2048

    device: str = "auto"
    backend: Literal["auto", "torch", "triton"] = "auto"
    cuda_graphs: bool = True
    seed: int = 0
    tune_cpu_allocator: bool = True

    def __post_init__(self) -> None:
        positive = (
            "one_blob_bins",
            "hash_levels",
            "hash_features_per_level",
            "hash_base_resolution",
            "hidden_dim",
            "geometry_feature_dim",
            "num_uniform_samples",
            "num_surface_samples",
            "smoothness_points",
            "iterations_per_step",
            "keyframe_every",
            "map_every",
            "rays_per_iteration",
            "active_oversample",
            "hash_finest_voxel_m",
            "truncation_m",
            "surface_range_m",
            "learning_rate",
            "uncertainty_voxel_m",
            "uncertainty_learning_rate",
            "smoothness_voxel_m",
            "frontier_min_cluster_voxels",
            "observed_rays_per_frame",
        )
        for name in positive:
            check_number(name, getattr(self, name), low=0.0)
        check_number("keyframe_pixel_fraction", self.keyframe_pixel_fraction, low=0.0, high=1.0)
        check_number("near_m", self.near_m, low=0.0, low_open=False)
        check_number("far_m", self.far_m, low=self.near_m)
        check_integer("current_frame_rays", self.current_frame_rays, low=0)
        check_integer("first_frame_iterations", self.first_frame_iterations, low=0)
        check_integer("active_top_rays", self.active_top_rays, low=0, high=self.rays_per_iteration)
        check_choice("active_score", self.active_score, tuple(ACTIVE_SCORES))
        check_choice("backend", self.backend, tuple(BACKENDS))
        if self.cull_behind_depth_m is not None and self.cull_behind_depth_m < self.truncation_m:
            raise ValueError(
                "cull_behind_depth_m must be at least truncation_m (samples inside the "
                f"truncation band carry losses), got {self.cull_behind_depth_m}"
            )

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> NeuralMapperConfig:
        known = {f.name for f in fields(cls)}
        unknown = set(values) - known
        if unknown:
            raise ValueError(f"unknown NeuralMapperConfig settings: {sorted(unknown)}")
        return cls(**values)
