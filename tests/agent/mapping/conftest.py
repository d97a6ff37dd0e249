"""A small coloured box room (4 x 3 x 2.5 m) with a block inside, and frames of it."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from naruto_agent.mapping import NeuralMapperConfig
from naruto_gym.geometry.transforms import look_at_rotation, make_pose
from naruto_gym.scenes.mesh_scene import Scene, scene_from_trimesh
from naruto_gym.sensors.pinhole import PinholeCamera, RgbdRenderer


def box_room() -> Scene:
    """Room walls facing inwards, a block standing on the floor, stripes of colour."""
    room = trimesh.creation.box(extents=(4.0, 3.0, 2.5))
    room.apply_translation((0.0, 0.0, 1.25))
    room.invert()  # normals point into the room
    block = trimesh.creation.box(extents=(0.8, 0.6, 0.9))
    block.apply_translation((1.0, 0.5, 0.45))
    mesh = trimesh.util.concatenate([room, block])
    mesh = mesh.subdivide().subdivide()
    centres = mesh.triangles_center
    colours = np.stack(
        [
            128 + 100 * np.sin(3.0 * centres[:, 0]),
            128 + 100 * np.cos(2.0 * centres[:, 1]),
            128 + 100 * np.sin(2.5 * centres[:, 2]),
        ],
        axis=1,
    ).astype(np.uint8)
    mesh.visual.face_colors = np.concatenate([colours, np.full((len(colours), 1), 255)], 1)
    return scene_from_trimesh(mesh, name="box_room")


def orbit_poses(count: int, radius: float = 0.6, height: float = 1.3) -> np.ndarray:
    """Poses on a small circle in the room, looking outwards at the walls."""
    poses = []
    for angle in np.linspace(0.0, 2.0 * np.pi, count, endpoint=False):
        eye = np.array([radius * np.cos(angle), radius * np.sin(angle), height])
        target = eye + np.array([np.cos(angle), np.sin(angle), -0.25])
        poses.append(make_pose(look_at_rotation(eye, target), eye))
    return np.stack(poses)


@pytest.fixture(scope="session")
def room() -> Scene:
    return box_room()


@pytest.fixture(scope="session")
def small_camera() -> PinholeCamera:
    return PinholeCamera().scaled(0.1)


@pytest.fixture(scope="session")
def room_renderer(room: Scene, small_camera: PinholeCamera) -> RgbdRenderer:
    return RgbdRenderer(room, small_camera)


@pytest.fixture(scope="session")
def room_bounds(room: Scene) -> np.ndarray:
    return room.bounds + np.array([[-0.1], [0.1]])


def tiny_mapper_config(**overrides) -> NeuralMapperConfig:
    """A neural mapper small enough for a few iterations in a test (a coarse 6-level hash
    grid, 24 + 6 rays an iteration, two iterations a step); ``overrides`` replace fields."""
    settings = dict(
        hash_levels=6,
        hash_log2_table_size=11,
        hash_finest_voxel_m=0.1,
        first_frame_iterations=2,
        iterations_per_step=2,
        rays_per_iteration=24,
        current_frame_rays=6,
        active_top_rays=8,
        active_oversample=2,
        keyframe_pixel_fraction=0.05,
        smoothness_points=4,
        device="cpu",
        seed=0,
    )
    settings.update(overrides)
    return NeuralMapperConfig(**settings)
