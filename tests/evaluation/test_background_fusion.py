"""Background fusion of the reference reconstruction: same map, errors raised in the caller."""

from __future__ import annotations

import threading

import numpy as np
import pytest
import trimesh

from naruto_gym.evaluation import EpisodeReconstruction
from naruto_gym.evaluation.background_fusion import BackgroundFusion
from naruto_gym.geometry.transforms import look_at_rotation, make_pose
from naruto_gym.scenes.mesh_scene import scene_from_trimesh
from naruto_gym.sensors.pinhole import PinholeCamera, RgbdRenderer

CAMERA = PinholeCamera(width=80, height=60, fx=50.0, fy=50.0, cx=39.5, cy=29.5)


def test_items_run_in_order_on_one_other_thread():
    seen, threads = [], set()

    def fuse(item):
        seen.append(item)
        threads.add(threading.get_ident())

    fusion = BackgroundFusion(fuse, max_pending=2)
    for item in range(20):
        fusion.submit(item)
        assert fusion.pending <= 2
    fusion.wait()
    assert seen == list(range(20)) and fusion.pending == 0
    assert threads and threading.get_ident() not in threads
    assert fusion.busy_seconds > 0.0
    fusion.close()
    fusion.submit(20)  # usable after close: a new thread
    fusion.close()
    assert seen[-1] == 20


def test_a_failure_is_raised_in_the_caller_and_the_queue_stays_usable():
    gate = threading.Event()
    seen = []

    def fuse(item):
        gate.wait(5.0)
        if item == 1:
            raise RuntimeError("fusion failed on item 1")
        seen.append(item)

    fusion = BackgroundFusion(fuse, max_pending=8)
    for item in range(4):
        fusion.submit(item)
    gate.set()
    with pytest.raises(RuntimeError, match="item 1"):
        fusion.wait()
    assert fusion.pending == 0
    fusion.submit(10)
    fusion.wait()
    assert seen[0] == 0 and seen[-1] == 10 and 1 not in seen
    with pytest.raises(ValueError, match="max_pending"):
        BackgroundFusion(fuse, max_pending=0)


def _frames():
    """A 4 x 3 x 2.5 m room and ten views around its centre, looking slightly down."""
    box = trimesh.creation.box(extents=[4.0, 3.0, 2.5])
    box.apply_translation([0.0, 0.0, 1.25])
    box.invert()  # faces inward, as a room's walls
    room = scene_from_trimesh(box)
    renderer = RgbdRenderer(room, CAMERA)
    eye = np.array([0.2, -0.1, 1.2])
    poses = []
    for heading in np.linspace(0.0, 2.0 * np.pi, 10, endpoint=False):
        direction = np.array([np.cos(heading), np.sin(heading), -0.2])
        poses.append(make_pose(look_at_rotation(eye, eye + direction), eye))
    return room, renderer, poses


def test_background_fusion_gives_the_same_map():
    room, renderer, poses = _frames()
    probes = np.random.default_rng(0).uniform([-2.0, -1.5, 0.0], [2.0, 1.5, 2.5], (5000, 3))
    maps = {}
    for background in (False, True):
        episode = EpisodeReconstruction(CAMERA, device="cpu", fuse_in_background=background)
        assert episode.fuses_in_background is background
        for pose in poses:
            rgb, depth = renderer.render(pose)
            episode.add_frame(rgb, depth, pose)
            depth[:] = 0.0  # the caller reuses its buffers at once: the frame was copied
            rgb[:] = 0
        assert episode.mapper.num_frames == len(poses)  # waits for the queue
        assert episode.fusion_seconds > 0.0
        # Open3D's parallel hashing orders the faces differently from run to run: compare
        # the map's values and the mesh's vertex set, not the face order.
        vertices = np.round(episode.mesh().vertices, 6)
        maps[background] = (episode.mapper.sdf(probes), vertices[np.lexsort(vertices.T)])
        assert episode.evaluate(room, num_samples=5_000)["completion_ratio_pct"] > 40.0
        episode.close()
    np.testing.assert_array_equal(maps[True][0], maps[False][0])
    np.testing.assert_array_equal(maps[True][1], maps[False][1])


def test_a_bad_frame_raises_at_once_with_background_fusion():
    episode = EpisodeReconstruction(CAMERA, device="cpu", fuse_in_background=True)
    with pytest.raises(ValueError, match="pass the camera the frame was rendered with"):
        episode.add_frame(None, np.ones((10, 10), np.float32), np.eye(4))
    with pytest.raises(ValueError, match="finite 4x4"):
        episode.add_frame(None, np.ones((60, 80), np.float32), np.full((4, 4), np.nan))
    assert episode.poses.shape == (0, 4, 4)
    episode.add_frame(None, np.ones((60, 80), np.float32), np.eye(4))
    assert episode.mapper.num_frames == 1
