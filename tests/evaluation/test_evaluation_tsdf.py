"""Reference TSDF mapper and policy-agnostic scoring on a rendered synthetic room."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from naruto_gym.evaluation import (
    EpisodeReconstruction,
    TsdfFusionMapper,
    evaluate_reconstruction,
    mean_absolute_distance_cm,
    point_to_mesh_distance,
    reconstruction_metrics,
    resolve_open3d_device,
    sample_mesh_surface,
)
from naruto_gym.geometry.transforms import look_at_rotation, make_pose
from naruto_gym.scenes.mesh_scene import load_scene, scene_from_trimesh
from naruto_gym.sensors.pinhole import PinholeCamera, RgbdRenderer

CAMERA = PinholeCamera().scaled(0.25)  # 300 x 170
SHARED_SCENES = Path(__file__).resolve().parents[2] / ".." / "shared" / "scenes"
RED = np.array([220, 30, 30])


def box_room():
    """A 4 x 4 x 2.5 m room (floor at z = 0) with a red wall at x = +2 and a small crate."""
    room = trimesh.creation.box(extents=[4.0, 4.0, 2.5])
    room.apply_translation([0.0, 0.0, 1.25])
    normals = room.face_normals
    colours = np.full((len(room.faces), 4), [150, 150, 150, 255], dtype=np.uint8)
    colours[normals[:, 0] > 0.5, :3] = RED
    colours[normals[:, 2] > 0.5, :3] = [60, 60, 200]
    room.visual.face_colors = colours
    crate = trimesh.creation.box(extents=[0.5, 0.5, 0.5])
    crate.apply_translation([-1.0, 1.0, 0.25])
    crate.visual.face_colors = [40, 160, 40, 255]
    return scene_from_trimesh(trimesh.Scene([room, crate]), name="box_room")


def room_poses() -> np.ndarray:
    """Twelve views from the room centre: 4 headings x (down, level, up)."""
    eye = np.array([0.1, -0.2, 1.3])
    poses = []
    for heading in np.deg2rad([0, 90, 180, 270]) + 0.3:
        for pitch in (-0.9, 0.0, 0.9):
            direction = np.array([np.cos(heading), np.sin(heading), np.tan(pitch)])
            poses.append(make_pose(look_at_rotation(eye, eye + direction), eye))
    return np.stack(poses)


@pytest.fixture(scope="module")
def room():
    return box_room()


@pytest.fixture(scope="module")
def fused(room):
    renderer = RgbdRenderer(room, CAMERA)
    mapper = TsdfFusionMapper(voxel_size_m=0.02, truncation_m=0.08, device="cpu")
    poses = room_poses()
    for pose in poses:
        rgb, depth = renderer.render(pose)
        mapper.integrate(rgb, depth, pose, CAMERA)
    return mapper, poses, renderer


def test_fusion_of_a_rendered_room_is_complete_and_accurate(fused, room):
    mapper, poses, _ = fused
    assert mapper.num_frames == len(poses)
    mesh = mapper.extract_mesh()
    assert len(mesh.faces) > 1000
    # Twelve far-apart views: cull with all of them (every 2nd would skip whole pitches).
    metrics = evaluate_reconstruction(
        mesh, room, poses=poses, camera=CAMERA, num_samples=50_000, cull_every=1
    )
    assert metrics.completion_ratio_pct > 90.0
    assert metrics.accuracy_cm < 2.5  # 50k samples over 80 m^2: ~2 cm of sampling floor
    assert metrics.precision_pct > 97.0
    assert metrics.faces_evaluated is not None and metrics.faces_culled is not None
    assert metrics.note == "no mad_cm: it needs the map's signed distance, pass sdf=..."
    assert metrics.mad_cm is None


def test_fused_colours_follow_the_scene(fused):
    mesh = fused[0].extract_mesh()
    colours = np.asarray(mesh.visual.vertex_colors)[:, :3].astype(float)
    # Vertices on the red wall (x = +2), away from its edges.
    on_red_wall = (mesh.vertices[:, 0] > 1.98) & (np.abs(mesh.vertices[:, 1]) < 1.5)
    on_red_wall &= (mesh.vertices[:, 2] > 0.3) & (mesh.vertices[:, 2] < 2.2)
    assert on_red_wall.sum() > 50
    np.testing.assert_allclose(np.median(colours[on_red_wall], axis=0), RED, atol=10)


def test_sdf_query_matches_the_geometry(fused, room):
    mapper = fused[0]
    # Points in front of / behind the red wall (x = 2), and the middle of the room.
    points = np.array([[1.95, 0.0, 1.2], [1.99, 0.3, 1.0], [2.03, 0.0, 1.2], [0.0, 0.0, 1.2]])
    sdf = mapper.sdf(points)
    np.testing.assert_allclose(sdf[:3], [0.05, 0.01, -0.03], atol=0.01)
    assert sdf[3] == pytest.approx(mapper.truncation_m)  # far from any surface: clamped
    assert mapper.sdf(np.array([[50.0, 50.0, 50.0]]))[0] == mapper.truncation_m  # unobserved
    gt_points = sample_mesh_surface(room.vertices, room.faces, 20_000, seed=0)
    # Large unseen parts (crate bottom) read as +truncation, so MAD stays above 0 but small.
    assert mean_absolute_distance_cm(mapper.sdf, gt_points) < 1.5


def test_point_cloud_and_reset(room):
    mapper = TsdfFusionMapper(device="cpu")
    assert len(mapper.extract_mesh().faces) == 0
    points, colours = mapper.extract_point_cloud()
    assert points.shape == (0, 3) and colours.shape == (0, 3)
    renderer = RgbdRenderer(room, CAMERA)
    pose = room_poses()[1]
    rgb, depth = renderer.render(pose)
    mapper.integrate(rgb, depth, pose, CAMERA)
    points, colours = mapper.extract_point_cloud()
    assert len(points) > 1000 and colours.dtype == np.uint8
    distance = point_to_mesh_distance(points, room.vertices, room.faces)
    assert np.median(distance) < 0.005 and distance.max() < 0.02
    mapper.reset()
    assert mapper.num_frames == 0 and len(mapper.extract_mesh().faces) == 0


def test_mapper_rejects_bad_settings_and_frames():
    with pytest.raises(ValueError, match="truncation"):
        TsdfFusionMapper(voxel_size_m=0.05, truncation_m=0.01)
    with pytest.raises(ValueError, match="unknown device|CUDA"):
        TsdfFusionMapper(device="tpu")
    assert str(resolve_open3d_device("cpu")) == "CPU:0"
    mapper = TsdfFusionMapper(device="cpu")
    with pytest.raises(ValueError, match="camera"):
        mapper.integrate(None, np.ones((10, 10), np.float32), np.eye(4), CAMERA)
    # A frame with no valid depth is accepted and changes nothing.
    mapper.integrate(None, np.zeros((CAMERA.height, CAMERA.width), np.float32), np.eye(4), CAMERA)
    assert mapper.num_frames == 0


def test_culling_removes_surfaces_invented_outside_the_views(fused, room):
    mapper, poses, renderer = fused
    mesh = mapper.extract_mesh()
    # A "hallucinated" box outside the room, which no view can see through the walls.
    ghost = trimesh.creation.box(extents=[1.0, 1.0, 1.0])
    ghost.apply_translation([4.0, 0.0, 1.0])
    polluted = trimesh.util.concatenate([mesh, ghost])
    culled = evaluate_reconstruction(
        polluted, room, poses=poses, camera=CAMERA, num_samples=50_000, renderer=renderer,
        cull_every=1,
    )
    whole = evaluate_reconstruction(polluted, room, cull=False, num_samples=50_000)
    assert culled.faces_culled >= len(ghost.faces)
    assert culled.accuracy_cm < 2.5 < 10.0 < whole.accuracy_cm
    assert "cull=False" in whole.note
    no_poses = evaluate_reconstruction(polluted, room, num_samples=10_000)
    assert "no poses" in no_poses.note and no_poses.faces_culled is None
    with pytest.raises(ValueError, match="culling removed every face"):
        evaluate_reconstruction(ghost, room, poses=poses, camera=CAMERA)
    with pytest.raises(ValueError, match="no triangles"):
        evaluate_reconstruction(trimesh.Trimesh(), room)


def test_episode_reconstruction_scores_any_trajectory(room):
    renderer = RgbdRenderer(room, CAMERA)
    episode = EpisodeReconstruction(CAMERA, device="cpu")
    empty = episode.evaluate(room)
    assert empty["completion_ratio_pct"] is None and "empty" in empty["note"]
    poses = room_poses()
    for pose in poses:
        rgb, depth = renderer.render(pose)
        episode.add_frame(rgb, depth, pose)
    result = episode.evaluate(room, num_samples=30_000, renderer=renderer, cull_every=1)
    assert result["num_frames"] == 12
    assert result["trajectory_length_m"] == 0.0  # all views from one spot
    assert result["completion_ratio_pct"] > 90.0
    assert result["accuracy_cm"] < 3.0
    # MAD of the fused SDF: small on what was seen, the truncation where nothing was
    assert 0.0 < result["mad_cm"] < 100.0 * episode.mapper.truncation_m
    assert empty["mad_cm"] is None
    episode.reset()
    assert episode.poses.shape == (0, 4, 4) and episode.evaluate(room)["num_frames"] == 0


@pytest.mark.skipif(not SHARED_SCENES.is_dir(), reason="../shared/scenes is not available")
def test_real_scene_against_itself_and_a_few_fused_frames():
    scene = load_scene(SHARED_SCENES / "replica_office0" / "mesh.ply")
    # 200k samples on this 101 m^2 mesh are ~2 cm apart: a 1.1 cm floor for a perfect mesh.
    itself = reconstruction_metrics(scene, scene)
    assert 0.8 < itself.accuracy_cm < 1.4 and itself.completion_ratio_pct > 99.9
    poses = np.loadtxt(SHARED_SCENES / "replica_office0" / "traj.txt").reshape(-1, 4, 4)
    camera = PinholeCamera().scaled(0.2)
    renderer = RgbdRenderer(scene, camera)
    episode = EpisodeReconstruction(camera, device="cpu")
    for pose in poses[::250]:
        episode.add_frame(*renderer.render(pose), pose)
    vertices = episode.mesh().vertices
    distance = point_to_mesh_distance(vertices, scene.vertices, scene.faces)
    assert np.median(distance) < 0.01
    result = episode.evaluate(scene, renderer=renderer, cull_every=1)
    assert result["accuracy_cm"] < 2.0
    assert 20.0 < result["completion_ratio_pct"] < 99.0  # 8 frames cannot see everything
