"""Analytic checks of the reconstruction metrics (accuracy, completion, ratio, F-score, MAD)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from naruto_gym.evaluation import (
    mean_absolute_distance_cm,
    mesh_area,
    point_to_mesh_distance,
    reconstruction_metrics,
    reference_sample_count,
    sample_mesh_surface,
    trajectory_length,
)

NUM_SAMPLES = 100_000


def square(size: float = 1.0, offset=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """A horizontal size x size square (two triangles) with its corner at ``offset``."""
    vertices = np.array(
        [[0.0, 0.0, 0.0], [size, 0.0, 0.0], [size, size, 0.0], [0.0, size, 0.0]]
    ) + np.asarray(offset)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    return vertices, faces


def union(*meshes: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    vertices, faces, offset = [], [], 0
    for v, f in meshes:
        vertices.append(v)
        faces.append(f + offset)
        offset += len(v)
    return np.concatenate(vertices), np.concatenate(faces)


def test_plane_shifted_by_one_centimetre_gives_one_centimetre_both_ways():
    metrics = reconstruction_metrics(
        square(offset=(0, 0, 0.01)), square(), num_samples=NUM_SAMPLES, seed=3
    )
    # Sample spacing (~3 mm) adds a little on top of the 1 cm offset.
    assert metrics.accuracy_cm == pytest.approx(1.0, abs=0.05)
    assert metrics.completion_cm == pytest.approx(1.0, abs=0.05)
    assert metrics.accuracy_cm >= 1.0 and metrics.completion_cm >= 1.0
    assert metrics.completion_ratio_pct == 100.0
    assert metrics.precision_pct == 100.0
    assert metrics.num_recon_samples == NUM_SAMPLES == metrics.num_gt_samples


def test_threshold_is_configurable():
    shifted, truth = square(offset=(0, 0, 0.01)), square()
    strict = reconstruction_metrics(shifted, truth, threshold_m=0.005, num_samples=20_000)
    assert strict.completion_ratio_pct == 0.0 and strict.fscore_pct == 0.0
    assert strict.threshold_m == 0.005
    with pytest.raises(ValueError, match="threshold"):
        reconstruction_metrics(shifted, truth, threshold_m=0.0)


def test_half_missing_scene_halves_completion_ratio_and_keeps_accuracy():
    # Two equal squares 2 m apart: nothing of the second is within 5 cm of the first.
    left, right = square(), square(offset=(3.0, 0.0, 0.0))
    full = reconstruction_metrics(union(left, right), union(left, right), num_samples=NUM_SAMPLES)
    half = reconstruction_metrics(left, union(left, right), num_samples=NUM_SAMPLES)
    assert half.completion_ratio_pct == pytest.approx(50.0, abs=1.0)
    assert half.accuracy_cm == pytest.approx(full.accuracy_cm, abs=0.05)
    assert half.accuracy_cm < 0.5
    # The missing half is 2-3 m away, so completion (gt -> recon) is large: directions right.
    assert half.completion_cm > 100.0
    assert half.precision_pct == 100.0
    assert full.completion_ratio_pct == 100.0


def test_spurious_surface_lowers_precision_and_fscore_not_completion():
    truth = square()
    recon = union(square(), square(offset=(3.0, 0.0, 0.0)))
    metrics = reconstruction_metrics(recon, truth, num_samples=NUM_SAMPLES)
    assert metrics.completion_ratio_pct == 100.0
    assert metrics.precision_pct == pytest.approx(50.0, abs=1.0)
    p, r = metrics.precision_pct, metrics.completion_ratio_pct
    assert metrics.fscore_pct == pytest.approx(2 * p * r / (p + r))
    assert metrics.fscore_pct == pytest.approx(200.0 / 3.0, abs=1.0)
    assert metrics.accuracy_cm > 100.0  # half the reconstruction is 2-3 m from the truth


def test_point_arrays_trimesh_and_scene_inputs_agree():
    from naruto_gym.scenes.mesh_scene import scene_from_trimesh

    vertices, faces = square()
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    scene = scene_from_trimesh(mesh, name="square")
    points = sample_mesh_surface(vertices, faces, 20_000, seed=1)
    from_mesh = reconstruction_metrics(mesh, scene, num_samples=20_000)
    from_points = reconstruction_metrics(points + [0, 0, 0.02], scene, num_samples=20_000)
    assert from_mesh.accuracy_cm < 0.5
    assert from_points.accuracy_cm == pytest.approx(2.0, abs=0.1)
    assert from_points.faces_evaluated is None and from_mesh.faces_evaluated == 2


def test_same_seed_same_result_and_mesh_against_itself_shows_sampling_floor():
    mesh = square()
    first = reconstruction_metrics(mesh, mesh, num_samples=20_000, seed=7)
    again = reconstruction_metrics(mesh, mesh, num_samples=20_000, seed=7)
    other = reconstruction_metrics(mesh, mesh, num_samples=20_000, seed=8)
    assert first == again
    assert first != other
    assert 0.0 < first.accuracy_cm < 0.5


@pytest.mark.parametrize(
    "recon, message",
    [
        (np.zeros((0, 3)), "empty"),
        ((np.zeros((0, 3)), np.zeros((0, 3), dtype=int)), "no triangles"),
        ((np.zeros((3, 3)), np.array([[0, 1, 2]])), "degenerate"),
        (np.array([[0.0, 0.0, np.nan]]), "NaN"),
        (np.zeros((5, 2)), r"\(N, 3\)"),
        ((np.zeros((3, 3)), np.array([[0, 1, 5]])), "out of range"),
    ],
)
def test_empty_or_degenerate_input_raises_instead_of_nan(recon, message):
    with pytest.raises(ValueError, match=message):
        reconstruction_metrics(recon, square(), num_samples=1000)
    with pytest.raises(ValueError, match=message):
        reconstruction_metrics(square(), recon, num_samples=1000)


def test_sampling_is_area_uniform_and_on_the_surface():
    # Two triangles whose areas are 1:3.
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 0, 0], [8, 0, 0], [5, 1, 0.0]])
    faces = np.array([[0, 1, 2], [3, 4, 5]])
    points = sample_mesh_surface(vertices, faces, 40_000, seed=0)
    assert points.shape == (40_000, 3)
    assert np.all(points[:, 2] == 0.0)
    assert np.mean(points[:, 0] >= 5.0) == pytest.approx(0.75, abs=0.01)
    first = points[points[:, 0] < 5.0]
    assert np.all(first[:, 0] + first[:, 1] <= 1.0 + 1e-12) and np.all(first >= -1e-12)
    np.testing.assert_array_equal(points, sample_mesh_surface(vertices, faces, 40_000, seed=0))
    with pytest.raises(ValueError, match="positive"):
        sample_mesh_surface(vertices, faces, 0)


def test_mad_of_an_analytic_plane_sdf():
    gt_points = sample_mesh_surface(*square(), 10_000, seed=2)

    def plane_sdf(points: np.ndarray) -> np.ndarray:
        return points[:, 2] - 0.02  # the map's surface sits 2 cm above the truth

    assert mean_absolute_distance_cm(plane_sdf, gt_points) == pytest.approx(2.0, abs=1e-9)
    assert mean_absolute_distance_cm(lambda p: -plane_sdf(p), gt_points) == pytest.approx(2.0)
    with pytest.raises(ValueError, match="NaN"):
        mean_absolute_distance_cm(lambda p: np.full(len(p), np.nan), gt_points)
    with pytest.raises(ValueError, match="one value per point"):
        mean_absolute_distance_cm(lambda p: np.zeros(3), gt_points)
    with pytest.raises(ValueError, match="empty"):
        mean_absolute_distance_cm(plane_sdf, np.zeros((0, 3)))


def test_metrics_report_mad_of_an_sdf_at_their_ground_truth_samples():
    truth = union(square(), square(offset=(2.0, 0.0, 0.0)))

    def sdf(points: np.ndarray) -> np.ndarray:
        # 1 cm off over the first square, 5 cm off over the second
        return points[:, 2] - np.where(points[:, 0] < 1.5, 0.01, 0.05)

    def first_square_only(points: np.ndarray) -> np.ndarray:
        return points[:, 0] < 1.5

    metrics = reconstruction_metrics(
        truth, truth, num_samples=20_000, seed=1, sdf=sdf, observable_mask=first_square_only
    )
    assert metrics.mad_cm == pytest.approx(3.0, abs=0.1)  # equal areas: the mean of 1 and 5
    assert metrics.observable_mad_cm == pytest.approx(1.0, abs=1e-9)
    assert reconstruction_metrics(truth, truth, num_samples=1000).mad_cm is None
    with pytest.raises(ValueError, match="NaN"):
        reconstruction_metrics(truth, truth, num_samples=1000, sdf=lambda p: p[:, 0] * np.nan)


def test_mad_and_point_to_mesh_distance_of_a_plain_mesh():
    gt_points = sample_mesh_surface(*square(), 10_000, seed=2)
    # Exact distance: the shifted plane is 3 cm away, and a plane larger than the truth so
    # that no point sees an edge.
    shifted = square(size=3.0, offset=(-1.0, -1.0, 0.03))
    assert mean_absolute_distance_cm(shifted, gt_points) == pytest.approx(3.0, abs=1e-4)
    distance = point_to_mesh_distance(np.array([[0.5, 0.5, 1.0], [2.0, 0.5, 0.0]]), *square())
    np.testing.assert_allclose(distance, [1.0, 1.0], atol=1e-6)
    with pytest.raises(ValueError, match="callable SDF or a mesh"):
        mean_absolute_distance_cm(np.zeros((3, 3)), gt_points)


def test_trajectory_length_of_a_known_path():
    positions = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 0.0]])
    poses = np.tile(np.eye(4), (len(positions), 1, 1))
    poses[:, :3, 3] = positions
    assert trajectory_length(positions) == pytest.approx(4.0)
    assert trajectory_length(poses) == pytest.approx(4.0)
    assert trajectory_length(positions[:1]) == 0.0
    assert trajectory_length(np.array([[0, 0, 0], [3, 4, 0.0]])) == pytest.approx(5.0)
    with pytest.raises(ValueError, match="shape"):
        trajectory_length(np.zeros((4, 3, 3)))
    with pytest.raises(ValueError, match="NaN"):
        trajectory_length(np.array([[0, 0, 0], [np.nan, 0, 0]]))


def test_large_surfaces_are_sampled_densely_enough_to_see_a_perfect_reconstruction():
    """On a 1,600 m^2 floor 200,000 samples are 125 per m^2: a perfect reconstruction would
    miss more than a third at 5 cm from sample spacing alone. The reference side is sampled
    at 2,000 per m^2, so it scores as perfect; a Replica-sized surface keeps the published
    200,000 samples on both sides."""
    truth = square(40.0)
    floor = trimesh.Trimesh(*truth, process=False).subdivide()  # the same surface, re-meshed
    sparse = reconstruction_metrics(floor, truth, reference_samples_per_m2=None)
    assert 50.0 < sparse.completion_ratio_pct < 75.0 and sparse.precision_pct < 75.0
    dense = reconstruction_metrics(floor, truth)
    assert dense.completion_ratio_pct > 99.5 and dense.precision_pct > 99.5
    assert dense.accuracy_cm < 1.5 and dense.completion_cm < 1.5
    assert dense.num_gt_samples == 200_000 == dense.num_recon_samples
    assert dense.num_gt_reference_samples == 3_200_000 == dense.num_recon_reference_samples
    assert mesh_area(*truth) == pytest.approx(1600.0)
    room = square(10.0)  # 100 m^2, as the Replica office: exactly the published evaluation
    assert reference_sample_count(100.0, 200_000, 2000.0) == 200_000
    same = reconstruction_metrics(trimesh.Trimesh(*room).subdivide(), room)
    published = reconstruction_metrics(
        trimesh.Trimesh(*room).subdivide(), room, reference_samples_per_m2=None
    )
    assert same.as_dict() == published.as_dict()
