"""Reconstruction metrics of the active-mapping literature, as pure functions.

Definitions (as in NARUTO, Feng et al., CVPR 2024, and the works it compares with):

* **Accuracy** (cm): mean distance from each *reconstruction* sample to its nearest
  *ground-truth* sample. Low when nothing spurious was reconstructed.
* **Completion** (cm): mean distance from each *ground-truth* sample to its nearest
  *reconstruction* sample. Low when the whole scene was reconstructed.
* **Completion ratio** (%): share of ground-truth samples closer than the threshold (5 cm) to
  the reconstruction; it is the recall at that threshold.
* **Precision** (%): share of reconstruction samples closer than the threshold to the ground
  truth, and **F-score** (%): the harmonic mean of precision and completion ratio.

The released NARUTO evaluation passes the two meshes in swapped order, which exchanges
accuracy with completion; this module uses the definitions above, and
:func:`release_reading` gives the release's reading of the same scores: its "accuracy" is
the completion above, its "completion" the accuracy, and its "completion ratio" the share
of *reconstruction* samples within 5 cm of the ground truth, the precision above.

Surfaces are compared through area-uniform point samples (200,000 per mesh by default,
seeded), nearest neighbours through a KD-tree (``scipy.spatial.cKDTree``, all cores).

**Sample density.** A distance to the nearest *sample* of a surface is never much below the
samples' spacing: with density rho (samples per m^2) a point lying exactly on the surface is
more than 5 cm from every sample with probability exp(-rho pi 0.05^2). 200,000 samples on the
Replica office (101 m^2, about 2,000 per m^2) make that negligible, but on a 1,400 m^2
apartment (140 per m^2) a third of a perfect reconstruction would count as missing. The
surface a distance is measured *to* (the reference) is therefore sampled with at least
``reference_samples_per_m2`` (2,000, the published density on Replica) and never fewer than
``num_samples``; the points measured *from* (the queries) stay ``num_samples`` of those. On
meshes up to 100 m^2 nothing changes: both are the same ``num_samples`` points, as published.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from naruto_gym.scenes.mesh_scene import Scene, sample_mesh_surface

DEFAULT_NUM_SAMPLES = 200_000
DEFAULT_THRESHOLD_M = 0.05
# Reference samples per m^2 of surface: the published 200,000 on the Replica office (101 m^2).
DEFAULT_REFERENCE_SAMPLES_PER_M2 = 2_000.0
# Memory bound on the reference samples of one mesh (a 2,500 m^2 surface at the density above).
MAX_REFERENCE_SAMPLES = 5_000_000

# Anything the metrics can turn into surface points: an (N, 3) array of points, a
# trimesh.Trimesh or PointCloud, a naruto_gym Scene, or a (vertices, faces) pair.
SurfaceLike = np.ndarray | trimesh.Trimesh | trimesh.PointCloud | Scene | tuple


@dataclass(frozen=True)
class ReconstructionMetrics:
    """Scores of one reconstruction against the ground truth.

    Attributes:
        accuracy_cm: mean reconstruction -> ground-truth nearest distance, cm.
        completion_cm: mean ground-truth -> reconstruction nearest distance, cm.
        completion_ratio_pct: % of ground-truth samples within ``threshold_m`` of the
            reconstruction.
        precision_pct: % of reconstruction samples within ``threshold_m`` of the ground truth.
        fscore_pct: harmonic mean of precision and completion ratio, %.
        threshold_m: the distance threshold used for the three percentages, metres.
        num_recon_samples: number of reconstruction points measured from (accuracy).
        num_gt_samples: number of ground-truth points measured from (completion).
        num_recon_reference_samples: reconstruction points measured to (completion).
        num_gt_reference_samples: ground-truth points measured to (accuracy).
        faces_evaluated: faces of the reconstruction after culling (None for point inputs).
        faces_culled: faces removed by culling (None when no culling ran).
        note: free-text remark (e.g. why culling was skipped).
        observable_share_pct: % of ground-truth samples that some free viewpoint can see
            (None when no observability mask was given).
        observable_completion_ratio_pct: completion ratio over the observable samples only.
        observable_completion_cm: completion over the observable samples only.
        mad_cm: mean |SDF| of the reconstruction's SDF at the ground-truth samples, cm
            (None when no SDF was given; see :func:`mean_absolute_distance_cm`).
        observable_mad_cm: the same over the observable samples only.
    """

    accuracy_cm: float
    completion_cm: float
    completion_ratio_pct: float
    precision_pct: float
    fscore_pct: float
    threshold_m: float
    num_recon_samples: int
    num_gt_samples: int
    num_recon_reference_samples: int | None = None
    num_gt_reference_samples: int | None = None
    faces_evaluated: int | None = None
    faces_culled: int | None = None
    note: str = ""
    observable_share_pct: float | None = None
    observable_completion_ratio_pct: float | None = None
    observable_completion_cm: float | None = None
    mad_cm: float | None = None
    observable_mad_cm: float | None = None

    def as_dict(self) -> dict[str, Any]:
        """Plain ``dict`` (JSON-serialisable) of every field."""
        return asdict(self)


# -- input handling --------------------------------------------------------------------
def _check_points(points: np.ndarray, what: str) -> np.ndarray:
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"{what} must be an (N, 3) array of points, got shape {points.shape}")
    if len(points) == 0:
        raise ValueError(
            f"{what} is empty (0 points): the reconstruction or ground truth has no surface; "
            "check that the mapper integrated frames before scoring"
        )
    if not np.isfinite(points).all():
        raise ValueError(f"{what} contains NaN or infinite coordinates; remove them first")
    return points


def _mesh_arrays(surface: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """(vertices, faces) of a mesh-like input, or None when it is a point set."""
    if isinstance(surface, trimesh.Trimesh):
        return np.asarray(surface.vertices), np.asarray(surface.faces)
    if isinstance(surface, tuple) and len(surface) == 2:
        return np.asarray(surface[0]), np.asarray(surface[1])
    if isinstance(surface, Scene):
        return np.asarray(surface.vertices), np.asarray(surface.faces)
    return None


def surface_points(
    surface: SurfaceLike, count: int = DEFAULT_NUM_SAMPLES, seed: int = 0, what: str = "surface"
) -> np.ndarray:
    """Points that stand for a surface: samples of a mesh, or the given points unchanged.

    Args:
        surface: (N, 3) points, ``trimesh.Trimesh``, ``trimesh.PointCloud``, a ``Scene`` or a
            ``(vertices, faces)`` pair.
        count: number of area-uniform samples drawn from a mesh.
        seed: seed of the sampling.
        what: name used in error messages.

    Returns:
        (M, 3) float64 points.
    """
    arrays = _mesh_arrays(surface)
    if arrays is not None:
        return sample_mesh_surface(arrays[0], arrays[1], count, seed, what=what)
    if isinstance(surface, trimesh.PointCloud):
        return _check_points(surface.vertices, what)
    return _check_points(surface, what)


def mesh_area(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Total triangle area of a mesh, m^2."""
    triangles = np.asarray(vertices, np.float64)[np.asarray(faces, np.int64)]
    cross = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    return float(0.5 * np.linalg.norm(cross, axis=1).sum())


def reference_sample_count(area_m2: float, num_samples: int, samples_per_m2: float | None) -> int:
    """Samples a mesh of ``area_m2`` gets as the reference of nearest distances: at least
    ``num_samples``, at least ``samples_per_m2`` per m^2 (None: no density bound), at most
    :data:`MAX_REFERENCE_SAMPLES`."""
    if not samples_per_m2:
        return num_samples
    dense = int(np.ceil(area_m2 * samples_per_m2))
    return max(num_samples, min(dense, MAX_REFERENCE_SAMPLES))


def _reference_and_queries(
    surface: SurfaceLike, num_samples: int, samples_per_m2: float | None, seed: int, what: str
) -> tuple[np.ndarray, np.ndarray]:
    """(reference points, query points) of a surface: ``num_samples`` query samples, and the
    same points as the reference unless the density asks for more (then a denser draw)."""
    points = surface_points(surface, num_samples, seed, what)  # validates the input
    arrays = _mesh_arrays(surface)
    if arrays is None:
        return points, points
    count = reference_sample_count(mesh_area(*arrays), num_samples, samples_per_m2)
    if count == num_samples:
        return points, points
    return sample_mesh_surface(arrays[0], arrays[1], count, seed + 1, what=what), points


def canonical_mesh(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The same surface with its vertices and triangles in an order fixed by their geometry.

    Seeded samples of a mesh depend on the order of its triangles, and a mapper's mesh
    extraction may list them in another order on every call (threads); in this order the
    scores of a surface do not depend on how it was listed. Vertices are sorted by their
    coordinates (equal ones merged), each triangle starts at its lowest vertex (its winding
    kept), and triangles are sorted by their vertices.

    Returns:
        (vertices (V', 3) float64, faces (F, 3) int64), F the same as given.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if len(faces) == 0:
        return vertices, faces.reshape(0, 3)
    unique, inverse = np.unique(vertices, axis=0, return_inverse=True)
    faces = inverse.reshape(-1)[faces]
    start = np.argmin(faces, axis=1)
    faces = np.take_along_axis(faces, (start[:, None] + np.arange(3)) % 3, axis=1)
    order = np.lexsort((faces[:, 2], faces[:, 1], faces[:, 0]))
    return unique, faces[order]


# -- metrics ---------------------------------------------------------------------------
def nearest_distances(queries: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Distance from each query point to its nearest reference point, (N,) float64 metres."""
    queries = _check_points(queries, "query points")
    reference = _check_points(reference, "reference points")
    # A sliding-midpoint (unbalanced) tree builds about twice as fast and queries as fast on
    # surface samples, measured on the Replica mesh.
    distances, _ = cKDTree(reference, balanced_tree=False).query(queries, k=1, workers=-1)
    return distances


def reconstruction_metrics(
    reconstruction: SurfaceLike,
    ground_truth: SurfaceLike,
    threshold_m: float = DEFAULT_THRESHOLD_M,
    num_samples: int = DEFAULT_NUM_SAMPLES,
    seed: int = 0,
    observable_mask: Callable[[np.ndarray], np.ndarray] | None = None,
    reference_samples_per_m2: float | None = DEFAULT_REFERENCE_SAMPLES_PER_M2,
    sdf: Callable[[np.ndarray], np.ndarray] | None = None,
) -> ReconstructionMetrics:
    """Accuracy, completion, completion ratio, precision and F-score of a reconstruction.

    Meshes are sampled with ``num_samples`` area-uniform points each, and more where they
    are the reference of a nearest distance on a large surface (see the module docstring);
    point arrays are used as given. The two meshes get different seeds derived from
    ``seed``, so a mesh scored against itself shows the sampling floor (a few mm) rather than
    an artificial zero.

    Args:
        reconstruction: the reconstructed surface (mesh or (N, 3) points).
        ground_truth: the true surface (mesh, ``Scene`` or (M, 3) points).
        threshold_m: distance under which a sample counts as matched, metres (default 5 cm).
        num_samples: samples per mesh.
        seed: seed of the sampling.
        observable_mask: maps ground-truth samples to a boolean "some free viewpoint can see
            it" mask (e.g. ``ObservableSurface.mask``); completion and its ratio are then also
            reported over the observable samples only.
        reference_samples_per_m2: least density of a mesh's samples where it is the
            reference (2,000 per m^2); None for ``num_samples`` on every mesh, as the
            published evaluation.
        sdf: the reconstruction's signed distance function ((N, 3) metres -> (N,) metres);
            MAD is then reported at the same ground-truth samples as completion.

    Returns:
        The :class:`ReconstructionMetrics`.

    Raises:
        ValueError: empty, degenerate or non-finite input, or a non-positive threshold.
    """
    if not threshold_m > 0.0:
        raise ValueError(f"threshold_m must be positive (metres), got {threshold_m}")
    recon_seed, gt_seed = (
        int(s.generate_state(1)[0]) for s in np.random.SeedSequence(seed).spawn(2)
    )
    recon_reference, recon_points = _reference_and_queries(
        reconstruction, num_samples, reference_samples_per_m2, recon_seed, "reconstruction"
    )
    gt_reference, gt_points = _reference_and_queries(
        ground_truth, num_samples, reference_samples_per_m2, gt_seed, "ground truth"
    )
    accuracy = nearest_distances(recon_points, gt_reference)
    completion = nearest_distances(gt_points, recon_reference)
    precision = float(np.mean(accuracy < threshold_m))
    recall = float(np.mean(completion < threshold_m))
    fscore = 0.0 if precision + recall == 0.0 else 2.0 * precision * recall / (precision + recall)
    optional: dict[str, float] = {}  # the scores that need a mask or an SDF
    mask = None if observable_mask is None else np.asarray(observable_mask(gt_points), dtype=bool)
    if mask is not None:
        optional["observable_share_pct"] = float(mask.mean() * 100.0)
        if mask.any():
            optional["observable_completion_ratio_pct"] = float(
                np.mean(completion[mask] < threshold_m) * 100.0
            )
            optional["observable_completion_cm"] = float(completion[mask].mean() * 100.0)
    if sdf is not None:
        optional.update(_mad_fields(sdf, gt_points, mask))
    arrays = _mesh_arrays(reconstruction)
    return ReconstructionMetrics(
        **optional,
        accuracy_cm=float(accuracy.mean() * 100.0),
        completion_cm=float(completion.mean() * 100.0),
        completion_ratio_pct=recall * 100.0,
        precision_pct=precision * 100.0,
        fscore_pct=fscore * 100.0,
        threshold_m=float(threshold_m),
        num_recon_samples=len(recon_points),
        num_gt_samples=len(gt_points),
        num_recon_reference_samples=len(recon_reference),
        num_gt_reference_samples=len(gt_reference),
        faces_evaluated=None if arrays is None else len(arrays[1]),
    )


def point_to_mesh_distance(
    points: np.ndarray, vertices: np.ndarray, faces: np.ndarray
) -> np.ndarray:
    """Exact unsigned distance from each point to a triangle mesh, (N,) float64 metres.

    Uses Embree's closest-point query (Open3D ``RaycastingScene.compute_distance``).
    """
    from naruto_gym.sensors.raycaster import RayCaster

    points = _check_points(points, "points")
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces)
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise ValueError(f"the mesh has no triangles (faces shape {faces.shape})")
    return RayCaster(vertices, faces).unsigned_distance(points).astype(np.float64)


def _mad_fields(
    sdf: Callable[[np.ndarray], np.ndarray], gt_points: np.ndarray, mask: np.ndarray | None
) -> dict[str, float]:
    """MAD over every ground-truth sample and, with a mask, over the observable ones."""
    absolute = _sdf_values(sdf, gt_points)
    fields = {"mad_cm": float(absolute.mean() * 100.0)}
    if mask is not None and mask.any():
        fields["observable_mad_cm"] = float(absolute[mask].mean() * 100.0)
    return fields


def _sdf_values(sdf: Callable[[np.ndarray], np.ndarray], points: np.ndarray) -> np.ndarray:
    """|SDF| at the points, checked for one finite value per point."""
    values = np.asarray(sdf(points), dtype=np.float64).reshape(-1)
    if values.shape != (len(points),):
        raise ValueError(
            f"the SDF callable must return one value per point ({len(points)}), got {values.shape}"
        )
    if not np.isfinite(values).all():
        raise ValueError(
            "the SDF callable returned NaN or infinite values; clamp unobserved space "
            "(e.g. to the truncation distance) before computing MAD"
        )
    return np.abs(values)


def mean_absolute_distance_cm(
    sdf_or_mesh: Callable[[np.ndarray], np.ndarray] | SurfaceLike,
    gt_points: np.ndarray,
) -> float:
    """MAD: mean |SDF| of a reconstruction at ground-truth surface samples, in cm.

    Args:
        sdf_or_mesh: either a callable mapping (N, 3) world points (metres) to (N,) signed
            distances in metres (a mapper's SDF), or a mesh (``trimesh.Trimesh``, ``Scene``,
            ``(vertices, faces)``), for which the exact point-to-mesh distance is used.
        gt_points: (N, 3) samples of the ground-truth surface (e.g. 200,000 from
            :func:`sample_mesh_surface`).

    Returns:
        The mean absolute distance in centimetres.

    Raises:
        ValueError: empty points, a callable returning the wrong shape, or NaN values.
    """
    gt_points = _check_points(gt_points, "ground-truth points")
    if callable(sdf_or_mesh):
        values = _sdf_values(sdf_or_mesh, gt_points)
    else:
        arrays = _mesh_arrays(sdf_or_mesh)
        if arrays is None:
            raise ValueError(
                "sdf_or_mesh must be a callable SDF or a mesh (trimesh.Trimesh, Scene or "
                f"(vertices, faces)), got {type(sdf_or_mesh).__name__}"
            )
        values = point_to_mesh_distance(gt_points, *arrays)
    return float(np.mean(np.abs(values)) * 100.0)


RELEASE_READING: dict[str, str] = {
    "release_accuracy_cm": "completion_cm",
    "release_completion_cm": "accuracy_cm",
    "release_completion_ratio_pct": "precision_pct",
}
"""The published release's names of the scores, each mapped to the score it computes under
this module's definitions (the release passes the meshes in swapped order)."""


def release_reading(metrics: Mapping[str, Any]) -> dict[str, float | None]:
    """The published release's reading of scores made by this module.

    Args:
        metrics: a :class:`ReconstructionMetrics` ``as_dict()`` (or any mapping with
            ``accuracy_cm``, ``completion_cm`` and ``precision_pct``; a missing one reads as
            None).

    Returns:
        ``release_accuracy_cm`` (our completion), ``release_completion_cm`` (our accuracy) and
        ``release_completion_ratio_pct`` (our precision): the figures the release would print
        for the same reconstruction and ground truth, to set beside published tables.
    """
    return {
        name: None if metrics.get(ours) is None else float(metrics[ours])
        for name, ours in RELEASE_READING.items()
    }


def trajectory_length(poses: np.ndarray) -> float:
    """Length of a camera path: the sum of distances between consecutive positions, metres.

    Args:
        poses: (N, 4, 4) camera-to-world matrices or (N, 3) positions. Fewer than two poses
            give 0.

    Raises:
        ValueError: wrong shape or non-finite values.
    """
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim == 3 and poses.shape[1:] == (4, 4):
        positions = poses[:, :3, 3]
    elif poses.ndim == 2 and poses.shape[1] == 3:
        positions = poses
    else:
        raise ValueError(
            f"poses must be (N, 4, 4) camera-to-world matrices or (N, 3) positions, "
            f"got shape {poses.shape}"
        )
    if not np.isfinite(positions).all():
        raise ValueError("poses contain NaN or infinite values")
    if len(positions) < 2:
        return 0.0
    return float(np.linalg.norm(np.diff(positions, axis=0), axis=1).sum())
