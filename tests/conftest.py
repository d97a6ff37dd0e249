"""Shared fixtures: the research-only sample scenes beside the repo (skipped when absent)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from naruto_gym.utils.threads import available_cpus  # imports no torch


def _share_the_cores_between_workers() -> None:
    """pytest-xdist runs one worker per core, and every worker's compiled loops and torch
    default to every core: N workers would start N pools of N threads each. A worker (and the
    interpreters its tests start) gets its share instead, unless the caller set a count. Set
    here, before any test module imports torch, which reads ``OMP_NUM_THREADS`` once."""
    workers = os.environ.get("PYTEST_XDIST_WORKER_COUNT", "").strip()
    if not workers.isdigit() or int(workers) < 2:
        return
    share = str(max(1, available_cpus() // int(workers)))
    os.environ.setdefault("NARUTO_GYM_THREADS", share)
    os.environ.setdefault("OMP_NUM_THREADS", share)


_share_the_cores_between_workers()

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
