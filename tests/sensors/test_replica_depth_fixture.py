"""The env's depth must reproduce the real Replica depth frames (the correctness fixture)."""

import json

import gymnasium as gym
import numpy as np
import pytest
from PIL import Image

import naruto_gym  # noqa: F401


@pytest.mark.parametrize("frame_index", [0, 1, 2, 3])
def test_depth_reproduces_real_frames(replica_dir, frame_index):
    params = json.loads((replica_dir / "cam_params.json").read_text())["camera"]
    poses = np.loadtxt(replica_dir / "traj.txt").reshape(-1, 4, 4)
    env = gym.make(
        "NarutoRecon-v0", scene=str(replica_dir / "mesh.ply"), panorama_shape=None
    )
    observation, _ = env.reset(options={"pose": poses[frame_index]})
    real = np.asarray(
        Image.open(replica_dir / "frames" / f"depth{frame_index:06d}.png"), dtype=np.float32
    ) / params["scale"]
    depth = observation["depth"]
    assert depth.shape == real.shape == (params["h"], params["w"])
    both = (depth > 0) & (real > 0)
    assert both.mean() >= 0.99
    assert np.median(np.abs(depth[both] - real[both])) <= 0.003
    env.close()
