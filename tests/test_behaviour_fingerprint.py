"""``scripts/behaviour_fingerprint.py``'s comparison: depth frames within a tolerance, every
other entry exactly."""

from __future__ import annotations

import copy
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import naruto_gym  # noqa: F401
from tests.scripts import load_script

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "behaviour_fingerprint.py"


@pytest.fixture(scope="module")
def fingerprint():
    try:
        yield load_script(SCRIPT, "behaviour_fingerprint")
    finally:
        sys.modules.pop("behaviour_fingerprint", None)


def frame(offset: float = 0.0) -> np.ndarray:
    """A 12 x 16 depth frame with a band of no-hit pixels."""
    depth = np.linspace(1.0, 4.0, 12 * 16, dtype=np.float32).reshape(12, 16) + np.float32(offset)
    depth[:, :3] = 0.0
    return depth


def record(fingerprint, offset: float = 0.0, path_x: float = 1.0):
    episode = {
        "coverage": [0.1, 0.2],
        "path": [[path_x, 2.0, 1.5], [1.1, 2.0, 1.5]],
        "refusals": 0,
        "depth": [fingerprint.depth_summary(frame(offset)) for _ in range(2)],
        "depth_digest": fingerprint.digest(frame(offset)),
    }
    return {"episodes": {"random@room": episode}, "procedural": {"room:0": "abc"}}


def test_depth_summary_counts_hits_and_samples_a_grid(fingerprint):
    summary = fingerprint.depth_summary(frame())
    assert summary["valid"] == 12 * 13
    assert summary["min"] == pytest.approx(frame()[0, 3])
    assert summary["max"] == pytest.approx(4.0)
    assert len(summary["grid"]) == fingerprint.DEPTH_GRID_SIDE**2
    assert summary["grid"][0] == 0.0 and summary["grid"][-1] == pytest.approx(4.0)


def test_depths_within_the_tolerance_are_the_same(fingerprint):
    before = record(fingerprint)
    after = record(fingerprint, offset=2e-6)
    comparison = fingerprint.compare(before, after)
    assert comparison.same, comparison.differences
    assert comparison.exact_depth_differences == ["/episodes/random@room/depth_digest"]
    assert 1e-6 < comparison.max_depth_difference_m < 3e-6
    assert fingerprint.compare(before, copy.deepcopy(before)).max_depth_difference_m == 0.0


def test_a_changed_path_is_a_difference(fingerprint):
    comparison = fingerprint.compare(record(fingerprint), record(fingerprint, path_x=1.0001))
    assert not comparison.same
    assert comparison.differences == ["/episodes/random@room/path"]


def test_depths_beyond_the_tolerance_or_other_hits_are_differences(fingerprint):
    before = record(fingerprint)
    moved = fingerprint.compare(before, record(fingerprint, offset=1e-3))
    assert not moved.same and len(moved.differences) == 1
    assert moved.differences[0].startswith("/episodes/random@room/depth (2 of 2 frames")
    assert moved.exact_depth_differences == []  # reported as the depth difference only
    assert moved.max_depth_difference_m == pytest.approx(1e-3, rel=1e-3)
    fewer_hits = copy.deepcopy(before)
    fewer_hits["episodes"]["random@room"]["depth"][1]["valid"] -= 1
    (found,) = fingerprint.compare(before, fewer_hits).differences
    assert found.startswith("/episodes/random@room/depth (1 of 2 frames") and "first 1;" in found
    shorter = copy.deepcopy(before)
    shorter["episodes"]["random@room"]["depth"].pop()
    assert not fingerprint.compare(before, shorter).same
    missing = copy.deepcopy(before)
    del missing["procedural"]["room:0"]
    assert fingerprint.compare(before, missing).differences == ["/procedural/room:0"]


def test_rasterized_and_ray_cast_frames_agree_within_the_tolerance(fingerprint):
    """The tolerance covers what the two pinhole backends differ by: float rounding."""
    kwargs = {"image_scale": 0.125, "action_mode": "discrete"}
    cast = gym.make("NarutoRecon-v0", pinhole_backend="raycast", **kwargs)
    drawn = gym.make("NarutoRecon-v0", pinhole_backend="raster", **kwargs)
    assert drawn.unwrapped.renderer.frame_backend == "raster"
    frames = []
    for env in (cast, drawn):
        observation, _ = env.reset(seed=4)
        depths = [observation["depth"]]
        for action in [0, 6, 6, 0, 7]:
            depths.append(env.step(action)[0]["depth"])
        frames.append(depths)
        env.close()
    gap = max(float(np.abs(a - b).max()) for a, b in zip(*frames, strict=True))
    assert gap <= fingerprint.DEPTH_TOLERANCE_M
    summaries = [
        {"depth": [fingerprint.depth_summary(depth) for depth in depths]} for depths in frames
    ]
    assert fingerprint.compare(*summaries).same
