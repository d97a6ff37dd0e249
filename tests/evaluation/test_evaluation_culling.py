"""Mesh culling: faces seen from the trajectory stay, faces never seen go."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from naruto_gym.evaluation import (
    CullingCache,
    CullingSettings,
    cull_mesh,
    visible_vertex_mask,
)
from naruto_gym.evaluation.culling import visible_vertex_mask_reference
from naruto_gym.geometry.transforms import look_at_rotation, make_pose
from naruto_gym.scenes.mesh_scene import scene_from_trimesh
from naruto_gym.sensors.pinhole import PinholeCamera, RgbdRenderer

CAMERA = PinholeCamera().scaled(0.1)  # 120 x 68: enough for these tests, fast


def wall_scene():
    """Ground truth: one 4 m x 3 m wall in the plane y = 2, facing the camera at the origin."""
    wall = trimesh.Trimesh(
        [[-2, 2, -1.5], [2, 2, -1.5], [2, 2, 1.5], [-2, 2, 1.5]], [[0, 1, 2], [0, 2, 3]]
    )
    return scene_from_trimesh(wall, name="wall")


def small_quad(y: float, x: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """A 10 cm quad in the plane at ``y``, centred at (x, y, 0)."""
    h = 0.05
    vertices = np.array([[x - h, y, -h], [x + h, y, -h], [x + h, y, h], [x - h, y, h]])
    return vertices, np.array([[0, 1, 2], [0, 2, 3]])


def union(*meshes):
    vertices, faces, offset = [], [], 0
    for v, f in meshes:
        vertices.append(v)
        faces.append(f + offset)
        offset += len(v)
    return np.concatenate(vertices), np.concatenate(faces)


def pose_looking_at(eye, target) -> np.ndarray:
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    return make_pose(look_at_rotation(eye, target), eye)


FORWARD_POSE = pose_looking_at([0, 0, 0], [0, 1, 0])


def test_keeps_seen_faces_and_drops_hidden_or_behind_faces():
    scene = wall_scene()
    on_wall = small_quad(1.99)
    hidden_behind_wall = small_quad(2.5)
    just_behind_within_margin = small_quad(2.02, x=0.5)
    behind_camera = small_quad(-1.0)
    vertices, faces = union(on_wall, hidden_behind_wall, just_behind_within_margin, behind_camera)
    kept_vertices, kept_faces = cull_mesh(vertices, faces, FORWARD_POSE[None], CAMERA, scene)
    assert len(kept_faces) == 4
    kept_points = kept_vertices[kept_faces].reshape(-1, 3)
    assert set(np.round(kept_points[:, 1], 2)) == {1.99, 2.02}
    # Faces are re-indexed into the compacted vertex array.
    assert kept_faces.max() == len(kept_vertices) - 1
    mask = visible_vertex_mask(vertices, FORWARD_POSE[None], CAMERA, scene)
    assert mask.tolist() == [True] * 4 + [False] * 4 + [True] * 4 + [False] * 4


def test_margin_is_respected():
    scene = wall_scene()
    vertices, faces = small_quad(2.05)
    assert len(cull_mesh(vertices, faces, FORWARD_POSE[None], CAMERA, scene)[1]) == 0
    assert (
        len(cull_mesh(vertices, faces, FORWARD_POSE[None], CAMERA, scene, depth_margin_m=0.06)[1])
        == 2
    )


def test_face_outside_the_frustum_is_dropped_and_one_visible_vertex_keeps_a_face():
    scene = wall_scene()
    # Far to the side: the 90 degree horizontal field of view at 1.9 m spans |x| < 1.9.
    outside = small_quad(1.9, x=1.95 + 0.2)
    # A long triangle with one vertex in view and two outside: kept whole.
    straddling = (
        np.array([[0.0, 1.9, 0.0], [5.0, 1.9, 0.0], [5.0, 1.9, 0.5]]),
        np.array([[0, 1, 2]]),
    )
    vertices, faces = union(outside, straddling)
    kept_vertices, kept_faces = cull_mesh(vertices, faces, FORWARD_POSE[None], CAMERA, scene)
    assert len(kept_faces) == 1
    np.testing.assert_allclose(kept_vertices[kept_faces[0]], straddling[0])


def test_every_nth_pose_is_used():
    scene = wall_scene()
    vertices, faces = small_quad(1.99)
    away = pose_looking_at([0, 0, 0], [0, -1, 0])
    poses = np.stack([away, FORWARD_POSE, away])
    assert len(cull_mesh(vertices, faces, poses, CAMERA, scene, every=1)[1]) == 2
    # every=2 uses poses 0 and 2, both looking away.
    assert len(cull_mesh(vertices, faces, poses, CAMERA, scene, every=2)[1]) == 0


def test_vertex_rays_and_depth_images_agree_and_renderer_is_accepted():
    scene = wall_scene()
    rng = np.random.default_rng(0)
    # Random small triangles in front of, on, and behind the wall, all inside the frustum.
    centres = np.column_stack(
        [rng.uniform(-0.8, 0.8, 300), rng.uniform(1.0, 3.0, 300), rng.uniform(-0.4, 0.4, 300)]
    )
    vertices = (centres[:, None, :] + rng.normal(0, 0.01, (300, 3, 3))).reshape(-1, 3)
    faces = np.arange(len(vertices)).reshape(-1, 3)
    rays = visible_vertex_mask(vertices, FORWARD_POSE[None], CAMERA, scene)
    full = visible_vertex_mask(vertices, FORWARD_POSE[None], CAMERA, scene, depth_scale=1.0)
    renderer = RgbdRenderer(scene, CAMERA)
    half = visible_vertex_mask(vertices, FORWARD_POSE[None], CAMERA, renderer, depth_scale=0.5)
    expected = vertices[:, 1] <= 2.03
    for mask in (rays, full, half):
        np.testing.assert_array_equal(mask, expected)
    assert 0 < len(cull_mesh(vertices, faces, FORWARD_POSE[None], CAMERA, scene)[1]) < 300


def test_bad_inputs_raise_clear_errors():
    scene = wall_scene()
    vertices, faces = small_quad(1.99)
    with pytest.raises(ValueError, match="camera-to-world"):
        cull_mesh(vertices, faces, np.zeros((0, 4, 4)), CAMERA, scene)
    with pytest.raises(ValueError, match="every"):
        cull_mesh(vertices, faces, FORWARD_POSE[None], CAMERA, scene, every=0)
    with pytest.raises(ValueError, match="Scene"):
        cull_mesh(vertices, faces, FORWARD_POSE[None], CAMERA, "scene.ply")
    with pytest.raises(ValueError, match="out of range"):
        cull_mesh(vertices, faces + 10, FORWARD_POSE[None], CAMERA, scene)


# -- the fast culling against the straightforward per-pose loop ------------------------------
def cluttered_room(seed: int):
    """Ground truth: a 6 x 5 x 3 m room (walls facing in) with random boxes and thin posts,
    some narrower than a pixel of the coarse guide images; reconstruction vertices scattered
    on and around its surfaces (some hidden inside boxes, some behind walls)."""
    rng = np.random.default_rng(seed)
    room = trimesh.creation.box(extents=(6.0, 5.0, 3.0))
    room.invert()
    parts = [room]
    for _ in range(12):
        size = rng.uniform([0.02, 0.02, 0.3], [1.0, 1.0, 2.5])
        box = trimesh.creation.box(extents=size)
        box.apply_translation([rng.uniform(-2.5, 2.5), rng.uniform(-2.0, 2.0), size[2] / 2 - 1.5])
        parts.append(box)
    scene = scene_from_trimesh(trimesh.util.concatenate(parts), name=f"clutter{seed}")
    on_surface = scene.sample_surface(6000, seed=seed) + rng.normal(0.0, 0.03, (6000, 3))
    anywhere = rng.uniform([-3.5, -3.0, -2.0], [3.5, 3.0, 2.0], (1500, 3))
    vertices = np.concatenate([on_surface, anywhere])
    return scene, vertices, rng


def random_poses(rng: np.random.Generator, count: int) -> np.ndarray:
    eyes = rng.uniform([-2.8, -2.3, -0.5], [2.8, 2.3, 1.0], (count, 3))
    targets = eyes + rng.normal(0.0, 1.0, (count, 3)) * [1.0, 1.0, 0.3]
    return np.stack(
        [pose_looking_at(eye, target) for eye, target in zip(eyes, targets, strict=True)]
    )


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fast_culling_equals_the_per_pose_loop(seed):
    scene, vertices, rng = cluttered_room(seed)
    poses = random_poses(rng, 40)
    renderer = RgbdRenderer(scene, CAMERA)
    for every, margin in ((1, 0.03), (3, 0.0), (2, 0.15)):
        expected = visible_vertex_mask_reference(vertices, poses, CAMERA, renderer, every, margin)
        # Neither all nor nothing: the comparison has occluded and visible vertices to get right.
        assert 0.2 < expected.mean() < 0.9
        mask = visible_vertex_mask(vertices, poses, CAMERA, renderer, every, margin)
        np.testing.assert_array_equal(mask, expected)


def test_fast_culling_equals_the_loop_with_tiny_casts_and_rounds():
    # Many chunks per round and one pair per vertex per round: every bookkeeping path runs.
    settings = CullingSettings(
        max_rays_per_cast=257, max_likely_per_round=1, max_unlikely_per_round=3, block_size_m=0.2
    )
    scene, vertices, rng = cluttered_room(3)
    poses = random_poses(rng, 25)
    expected = visible_vertex_mask_reference(vertices, poses, CAMERA, scene, every=1)
    mask = visible_vertex_mask(vertices, poses, CAMERA, scene, 1, settings=settings)
    np.testing.assert_array_equal(mask, expected)
    # Other guide images and pose orders change how many rays are cast, not the verdicts.
    for other in (
        CullingSettings(guide_width_px=7, guide_slack_m=0.0, guide_slack_share=0.0),
        CullingSettings(order_poses_by_distance=False, block_size_m=3.0),
    ):
        mask = visible_vertex_mask(vertices, poses, CAMERA, scene, 1, settings=other)
        np.testing.assert_array_equal(mask, expected)
    with pytest.raises(ValueError, match="max_rays_per_cast"):
        CullingSettings(max_rays_per_cast=0)


def test_fast_depth_image_culling_equals_the_loop():
    scene, vertices, rng = cluttered_room(4)
    poses = random_poses(rng, 12)
    renderer = RgbdRenderer(scene, CAMERA)
    for scale in (1.0, 0.5):
        expected = visible_vertex_mask_reference(
            vertices, poses, CAMERA, renderer, every=2, depth_scale=scale
        )
        mask = visible_vertex_mask(vertices, poses, CAMERA, renderer, every=2, depth_scale=scale)
        np.testing.assert_array_equal(mask, expected)


def test_nothing_in_any_frustum():
    scene, vertices, _ = cluttered_room(5)
    looking_down_from_outside = pose_looking_at([0.0, 0.0, 30.0], [0.0, 0.0, 40.0])
    poses = np.stack([looking_down_from_outside] * 3)
    assert not visible_vertex_mask(vertices, poses, CAMERA, scene).any()
    assert not visible_vertex_mask(vertices, poses, CAMERA, scene, depth_scale=0.5).any()
    assert not visible_vertex_mask_reference(vertices, poses, CAMERA, scene).any()
    assert visible_vertex_mask(np.zeros((0, 3)), poses, CAMERA, scene).shape == (0,)
    with pytest.raises(ValueError, match="NaN"):
        visible_vertex_mask(np.full((2, 3), np.nan), poses, CAMERA, scene)


def test_cache_carries_verdicts_along_a_growing_trajectory():
    scene, vertices, rng = cluttered_room(6)
    poses = random_poses(rng, 30)
    renderer = RgbdRenderer(scene, CAMERA)
    cache = CullingCache()
    for count, jitter_share in ((10, 0.0), (20, 0.3), (30, 0.5)):
        # A later mesh keeps some vertices bit for bit, moves others and adds new ones.
        moved = rng.random(len(vertices)) < jitter_share
        vertices = vertices.copy()
        vertices[moved] += rng.normal(0.0, 0.01, (int(moved.sum()), 3))
        vertices = np.concatenate([vertices, rng.uniform(-2.5, 2.5, (200, 3))])
        expected = visible_vertex_mask_reference(vertices, poses[:count], CAMERA, renderer)
        mask = visible_vertex_mask(vertices, poses[:count], CAMERA, renderer, cache=cache)
        np.testing.assert_array_equal(mask, expected)
    # Other settings, other poses (not an extension): the cache must not leak verdicts.
    for other_poses in (poses, random_poses(rng, 30)):
        expected = visible_vertex_mask_reference(vertices, other_poses, CAMERA, renderer, 2, 0.0)
        mask = visible_vertex_mask(vertices, other_poses, CAMERA, renderer, 2, 0.0, cache=cache)
        np.testing.assert_array_equal(mask, expected)
    for count in (8, 16):
        expected = visible_vertex_mask_reference(
            vertices, poses[:count], CAMERA, renderer, depth_scale=0.5
        )
        mask = visible_vertex_mask(
            vertices, poses[:count], CAMERA, renderer, depth_scale=0.5, cache=cache
        )
        np.testing.assert_array_equal(mask, expected)
    cache.clear()
    mask = visible_vertex_mask(vertices, poses, CAMERA, renderer, cache=cache)
    np.testing.assert_array_equal(
        mask, visible_vertex_mask_reference(vertices, poses, CAMERA, renderer)
    )
