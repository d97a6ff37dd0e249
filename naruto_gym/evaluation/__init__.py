"""Reconstruction scoring: metrics (and the release's reading of them), mesh culling, the ground
truth a scene is scored against, a reference TSDF mapper (fusing on a background thread),
one-call scoring."""

from naruto_gym.evaluation.culling import (
    CullingCache,
    CullingSettings,
    cull_mesh,
    visible_vertex_mask,
)
from naruto_gym.evaluation.ground_truth import GroundTruth, find_ground_truth, load_ground_truth
from naruto_gym.evaluation.metrics import (
    ReconstructionMetrics,
    mean_absolute_distance_cm,
    mesh_area,
    nearest_distances,
    point_to_mesh_distance,
    reconstruction_metrics,
    reference_sample_count,
    release_reading,
    trajectory_length,
)
from naruto_gym.evaluation.scoring import EpisodeReconstruction, evaluate_reconstruction
from naruto_gym.evaluation.tsdf_mapper import TsdfFusionMapper, resolve_open3d_device
from naruto_gym.scenes.mesh_scene import sample_mesh_surface

__all__ = [
    "CullingCache",
    "CullingSettings",
    "EpisodeReconstruction",
    "GroundTruth",
    "ReconstructionMetrics",
    "TsdfFusionMapper",
    "cull_mesh",
    "evaluate_reconstruction",
    "find_ground_truth",
    "load_ground_truth",
    "mean_absolute_distance_cm",
    "mesh_area",
    "nearest_distances",
    "point_to_mesh_distance",
    "reconstruction_metrics",
    "reference_sample_count",
    "release_reading",
    "resolve_open3d_device",
    "sample_mesh_surface",
    "trajectory_length",
    "visible_vertex_mask",
]
