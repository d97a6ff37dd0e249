import pickle

import numpy as np
import pytest
import trimesh

from naruto_gym.sensors.raycaster import RayCaster


@pytest.fixture(params=["open3d", "embreex"])
def box_caster(request) -> RayCaster:
    box = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    return RayCaster(box.vertices, box.faces, backend=request.param)


def test_cast_hits_box_faces_at_known_distances(box_caster):
    origins = np.zeros((3, 3))
    directions = np.eye(3)
    hits = box_caster.cast(origins, directions)
    np.testing.assert_allclose(hits.distance, 1.0, atol=1e-5)
    assert np.all(hits.triangle_ids >= 0)


def test_cast_reports_misses(box_caster):
    hits = box_caster.cast(np.array([[0.0, 0.0, 5.0]]), np.array([[0.0, 0.0, 1.0]]))
    assert np.isinf(hits.distance[0])
    assert hits.triangle_ids[0] == -1


def test_both_backends_agree():
    mesh = trimesh.creation.icosphere(subdivisions=3)
    rng = np.random.default_rng(0)
    directions = rng.normal(size=(500, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    origins = rng.uniform(-0.3, 0.3, size=(500, 3))
    a = RayCaster(mesh.vertices, mesh.faces, "open3d").cast(origins, directions)
    b = RayCaster(mesh.vertices, mesh.faces, "embreex").cast(origins, directions)
    np.testing.assert_allclose(a.distance, b.distance, atol=1e-4)
    np.testing.assert_array_equal(a.triangle_ids, b.triangle_ids)


def test_any_hit_query_is_the_cast_hit_mask(box_caster):
    """hits_any_packed (an occlusion query with Open3D) answers as the first-hit cast does,
    from inside, outside and on the surface, along and across the faces."""
    rng = np.random.default_rng(3)
    origins = np.concatenate([
        rng.uniform(-3.0, 3.0, size=(2000, 3)),
        rng.uniform(-1.0, 1.0, size=(500, 3)) * np.array([1.0, 1.0, 0.0]) + [0, 0, 1.0],
    ])
    directions = rng.normal(size=(len(origins), 3))
    directions[::5] = [0.0, 0.0, -1.0]
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    rays = np.concatenate([origins, directions], axis=1).astype(np.float32)
    expected = box_caster.cast_packed(rays).hit_mask
    assert 0.2 < expected.mean() < 0.9
    np.testing.assert_array_equal(box_caster.hits_any_packed(rays), expected)


def test_free_fraction_stops_before_wall(box_caster):
    # From the centre towards the +x face at 1 m with a 0.1 m sphere: free up to 0.9 m.
    fraction = box_caster.free_fraction_of_segment(np.zeros(3), np.array([2.0, 0, 0]), 0.1)
    assert 0.43 <= fraction <= 0.45


def test_pickle_round_trip_rebuilds_native_scene(box_caster):
    clone = pickle.loads(pickle.dumps(box_caster))
    hits = clone.cast(np.zeros((1, 3)), np.array([[1.0, 0.0, 0.0]]))
    assert hits.distance[0] == pytest.approx(1.0, abs=1e-5)


def test_rejects_mesh_without_triangles():
    with pytest.raises(ValueError, match="faces"):
        RayCaster(np.zeros((3, 3)), np.zeros((0, 3), dtype=int))
