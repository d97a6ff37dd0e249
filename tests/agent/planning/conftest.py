"""Fixtures for the planner tests: the synthetic room of ``planning_scenes`` as SDF volumes."""

from __future__ import annotations

import pytest
import trimesh

from naruto_agent.planning import SdfVolume
from naruto_gym.sensors.raycaster import RayCaster
from tests.agent.planning.planning_scenes import room_mesh


@pytest.fixture(scope="session")
def room_trimesh() -> trimesh.Trimesh:
    return room_mesh()


@pytest.fixture(scope="session")
def room_caster(room_trimesh) -> RayCaster:
    return RayCaster(room_trimesh.vertices, room_trimesh.faces)


@pytest.fixture(scope="session")
def room_sdf(room_caster) -> SdfVolume:
    return SdfVolume.from_mesh(room_caster, voxel_size=0.1, padding=0.2)


@pytest.fixture(scope="session")
def closed_wall_sdf() -> SdfVolume:
    mesh = room_mesh(doorway=False, furniture=False)
    return SdfVolume.from_mesh(mesh.vertices, mesh.faces, voxel_size=0.1, padding=0.2)
