"""The ground truth a scene is scored against (culled, full, named by ground_truth.json), the
release's reading of the scores, and scores that do not depend on a mesh's listing order."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from naruto_gym.evaluation import (
    evaluate_reconstruction,
    find_ground_truth,
    load_ground_truth,
    reconstruction_metrics,
    release_reading,
)
from naruto_gym.evaluation.ground_truth import PROTOCOL_CULLED, PROTOCOL_FULL
from naruto_gym.evaluation.metrics import canonical_mesh
from naruto_gym.scenes import resolve_scene


def _room_folder(tmp_path, culled=True):
    """A scene folder as prepare_replica.py lays it out: mesh.ply, and mesh_culled.ply (the
    room without its ceiling, the surface the recorded scan never saw)."""
    scene = resolve_scene("replica_like_room")
    mesh = trimesh.Trimesh(scene.vertices, scene.faces, process=False)
    mesh.export(tmp_path / "mesh.ply")
    if culled:
        top = scene.vertices[:, 2].max()
        keep = scene.vertices[scene.faces][:, :, 2].min(axis=1) < top - 0.05
        trimesh.Trimesh(scene.vertices, scene.faces[keep], process=False).export(
            tmp_path / "mesh_culled.ply"
        )
    return tmp_path / "mesh.ply", scene


def test_the_culled_mesh_beside_a_scene_is_its_ground_truth(tmp_path):
    path, scene = _room_folder(tmp_path)
    truth = find_ground_truth(path)
    assert truth.protocol == PROTOCOL_CULLED
    assert truth.label == "culled ground truth (mesh_culled.ply)"
    culled = load_ground_truth(truth, scene)
    assert 0 < len(culled.faces) < len(scene.faces)
    np.testing.assert_allclose(culled.bounds[0], scene.bounds[0], atol=1e-6)
    # Asked for the full mesh, or with no culled mesh: the scene itself.
    full = find_ground_truth(path, choice="full")
    assert full.protocol == PROTOCOL_FULL and full.path is None
    assert load_ground_truth(full, scene) is scene
    assert find_ground_truth(None).label == "full mesh"
    assert find_ground_truth("replica_like_room").path is None


def test_scores_against_the_culled_ground_truth_differ_from_the_full_mesh(tmp_path):
    path, scene = _room_folder(tmp_path)
    culled = load_ground_truth(find_ground_truth(path), scene)
    # A reconstruction of everything but the ceiling: complete against the culled ground truth.
    recon = (culled.vertices, culled.faces)
    against_culled = reconstruction_metrics(recon, culled, num_samples=20_000)
    against_full = reconstruction_metrics(recon, scene, num_samples=20_000)
    assert against_culled.completion_ratio_pct > 99.0
    assert against_full.completion_ratio_pct < against_culled.completion_ratio_pct - 5.0


def test_a_ground_truth_file_names_another_mesh_and_its_up_axis(tmp_path):
    path, scene = _room_folder(tmp_path, culled=False)
    y_up = scene.vertices[:, [0, 2, 1]] * [1.0, 1.0, -1.0]  # z-up (x, y, z) -> y-up (x, z, -y)
    trimesh.Trimesh(y_up, scene.faces, process=False).export(tmp_path / "house.obj")
    (tmp_path / "ground_truth.json").write_text(json.dumps({"mesh": "house.obj", "up_axis": "y"}))
    truth = find_ground_truth(path)
    assert truth.protocol == PROTOCOL_FULL and truth.label == "full mesh (house.obj)"
    loaded = load_ground_truth(truth, scene)
    np.testing.assert_allclose(loaded.bounds, scene.bounds, atol=1e-5)
    (tmp_path / "ground_truth.json").write_text(json.dumps({"mesh": "gone.obj", "up_axis": "y"}))
    with pytest.raises(ValueError, match="does not exist"):
        find_ground_truth(path)
    (tmp_path / "ground_truth.json").write_text("{}")
    with pytest.raises(ValueError, match="must hold"):
        find_ground_truth(path)
    with pytest.raises(ValueError, match="unknown ground truth"):
        find_ground_truth(path, choice="culled")


def test_release_reading_swaps_accuracy_with_completion_and_reads_precision():
    scene = resolve_scene("replica_like_room")
    centres = scene.vertices[scene.faces].mean(axis=1)
    half = scene.faces[centres[:, 0] < np.median(centres[:, 0])]
    metrics = reconstruction_metrics((scene.vertices, half), scene, num_samples=5000).as_dict()
    release = release_reading(metrics)
    assert release == {
        "release_accuracy_cm": metrics["completion_cm"],
        "release_completion_cm": metrics["accuracy_cm"],
        "release_completion_ratio_pct": metrics["precision_pct"],
    }
    # Half the room reconstructed: precise (the release's "completion ratio") but incomplete.
    assert release["release_completion_ratio_pct"] > 99.0
    assert metrics["completion_ratio_pct"] < 80.0
    assert release_reading({})["release_accuracy_cm"] is None


def test_the_score_of_a_mesh_does_not_depend_on_its_listing_order():
    scene = resolve_scene("replica_like_room")
    vertices, faces = scene.vertices, scene.faces[: len(scene.faces) * 2 // 3]
    rng = np.random.default_rng(0)
    new_order = rng.permutation(len(vertices))
    shuffled_vertices = vertices[new_order]
    shuffled_faces = np.argsort(new_order)[faces][rng.permutation(len(faces))]
    shuffled_faces = np.roll(shuffled_faces, 1, axis=1)  # same winding, another start
    a, b = (
        evaluate_reconstruction(mesh, scene, num_samples=3000).as_dict()
        for mesh in ((vertices, faces), (shuffled_vertices, shuffled_faces))
    )
    assert a == b
    canonical = canonical_mesh(shuffled_vertices, shuffled_faces)
    np.testing.assert_array_equal(canonical[1], canonical_mesh(vertices, faces)[1])
