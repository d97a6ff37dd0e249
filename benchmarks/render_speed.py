"""Render speed: the 680 x 1200 RGB-D frame, the panorama and a whole env.step, side by side
with a bare Open3D ``RaycastingScene.cast_rays`` of the same rays in the same run.

Goal (env issue): an RGB-D frame costs at most 1.25x the bare depth cast and at most 60 ms on
the 2-core CI machine (the published simulator: 24.4 ms on a V100).

    python benchmarks/render_speed.py
    python benchmarks/render_speed.py --repeats 30 --scenes replica_like_room apartment
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import gymnasium as gym
import numpy as np
import open3d as o3d

import naruto_gym  # noqa: F401
from naruto_gym.cli_args import parse_dataclass_args
from naruto_gym.sensors.panorama import EquirectangularCamera, render_panorama
from naruto_gym.sensors.raycaster import RayCaster

REPO = Path(__file__).resolve().parents[1]
REPLICA = REPO.parent / "shared" / "scenes" / "replica_office0" / "mesh.ply"


@dataclass
class Args:
    repeats: int = 20
    scenes: list[str] = field(default_factory=lambda: ["replica_like_room", str(REPLICA)])
    paper_panorama: bool = True  # also time the published 1024 x 2048 panorama
    out: str = "benchmarks/results/render_speed.json"


def parse_args() -> Args:
    return parse_dataclass_args(Args, description="RGB-D / panorama / env.step speed")


def median_ms(function, repeats: int) -> float:
    function()  # warm-up (JIT, caches)
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        function()
        times.append(time.perf_counter() - started)
    return 1000.0 * float(np.median(times))


def bench_scene(scene: str, args: Args) -> dict:
    env = gym.make("NarutoRecon-v0", scene=scene).unwrapped
    env.reset(seed=0)
    pose = env.pose.astype(np.float32)
    camera = env.camera
    rays = np.empty((camera.width * camera.height, 6), np.float32)
    rays[:, :3] = pose[:3, 3]
    rays[:, 3:] = camera.ray_directions @ pose[:3, :3].T
    # The reference: Open3D's own call on a prebuilt tensor, nothing else.
    bare = o3d.t.geometry.RaycastingScene()
    bare.add_triangles(
        o3d.core.Tensor(env.scene.vertices.astype(np.float32)),
        o3d.core.Tensor(env.scene.faces.astype(np.uint32)),
    )
    ray_tensor = o3d.core.Tensor(rays)
    embree = RayCaster(env.scene.vertices, env.scene.faces, "embreex")
    row = {
        "scene": Path(scene).parent.name if scene.endswith((".ply", ".obj", ".glb")) else scene,
        "triangles": int(len(env.scene.faces)),
        "rays": int(len(rays)),
        "bare_open3d_cast_ms": median_ms(lambda: bare.cast_rays(ray_tensor), args.repeats),
        "embreex_cast_ms": median_ms(lambda: embree.cast_packed(rays), args.repeats),
        "rgbd_frame_ms": median_ms(lambda: env.renderer.render(pose), args.repeats),
        "depth_only_ms": median_ms(lambda: env.renderer.render_depth(pose), args.repeats),
        "panorama_ms": median_ms(
            lambda: render_panorama(env.raycaster, env.panorama_camera, pose[:3, 3]), args.repeats
        ),
        "panorama_shape": [env.panorama_camera.height, env.panorama_camera.width],
    }
    if args.paper_panorama:
        paper = EquirectangularCamera(1024, 2048)
        row["paper_panorama_1024x2048_ms"] = median_ms(
            lambda: render_panorama(env.raycaster, paper, pose[:3, 3]), max(args.repeats // 4, 3)
        )

    def step() -> None:
        env.step(env.action_space.sample())

    env.action_space.seed(0)
    row["env_step_ms"] = median_ms(step, args.repeats)
    row["rgbd_vs_bare_ratio"] = row["rgbd_frame_ms"] / row["bare_open3d_cast_ms"]
    row["rgbd_mrays_per_s"] = row["rays"] / row["rgbd_frame_ms"] / 1000.0
    env.close()
    return row


def main() -> None:
    args = parse_args()
    rows = [bench_scene(scene, args) for scene in args.scenes if _exists(scene)]
    print("| scene | tris | bare O3D cast | embreex cast | RGB-D frame | ratio | Mrays/s "
          "| panorama | 1024x2048 pano | env.step |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['scene']} | {r['triangles']} | {r['bare_open3d_cast_ms']:.1f} ms "
            f"| {r['embreex_cast_ms']:.1f} ms | {r['rgbd_frame_ms']:.1f} ms "
            f"| {r['rgbd_vs_bare_ratio']:.2f}x | {r['rgbd_mrays_per_s']:.1f} "
            f"| {r['panorama_ms']:.2f} ms ({r['panorama_shape'][0]}x{r['panorama_shape'][1]}) "
            f"| {r.get('paper_panorama_1024x2048_ms', float('nan')):.1f} ms "
            f"| {r['env_step_ms']:.1f} ms |"
        )
    print("goal: RGB-D <= 1.25x bare cast and <= 60 ms; published simulator 24.4 ms on a V100")
    out = REPO / args.out
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"args": asdict(args), "rows": rows}, indent=2))


def _exists(scene: str) -> bool:
    if scene.endswith((".ply", ".obj", ".glb")) and not Path(scene).is_file():
        print(f"skipping {scene}: not found")
        return False
    return True


if __name__ == "__main__":
    main()
