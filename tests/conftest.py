"""Shared fixtures: the research-only sample scenes beside the repo (skipped when absent)."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_SCENES = REPO_ROOT.parent / "shared" / "scenes"
REPLICA_DIR = SHARED_SCENES / "replica_office0"

# (path relative to SHARED_SCENES, up axis) of every sample mesh.
SAMPLE_MESHES = {
    "replica_office0": ("replica_office0/mesh.ply", "z"),
    "scenenet_room89": ("scenenet_room89/mesh.obj", "y"),
    "habitat_simple_room": ("habitat_simple_room/simple_room.glb", "z"),
}


def require_shared_scenes() -> Path:
    if not SHARED_SCENES.is_dir():
        pytest.skip("../shared/scenes is absent (research-only sample meshes)")
    return SHARED_SCENES


@pytest.fixture
def shared_scenes() -> Path:
    return require_shared_scenes()


@pytest.fixture
def replica_dir() -> Path:
    require_shared_scenes()
    if not REPLICA_DIR.is_dir():
        pytest.skip("../shared/scenes/replica_office0 is absent")
    return REPLICA_DIR
