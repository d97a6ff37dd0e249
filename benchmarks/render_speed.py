"""Render speed of the pinhole RGB-D frame. Results: docs/benchmarks/rendering.md

The pinhole RGB-D frame by ray casting and by rasterizing, the panorama and a whole env.step,
side by side with a bare Open3D ``RaycastingScene.cast_rays`` of the same rays in the same run.

Goals:
* a ray-cast RGB-D frame costs at most 1.25x the bare depth cast;
* the 680 x 1200 RGB-D frame with ``pinhole_backend="raster"`` at least 6x
  faster than the bare cast of the same rays, on the Replica sample and on the apartment.

Every frame time is the median over ``repeats`` rounds of ``poses`` poses per scene. A second
table sweeps frame sizes (680 x 1200, 170 x 300, 64 x 64) and adds a mesh of about 760k
triangles (``two_rooms`` subdivided four times at run time), where the rasterizer's
per-triangle setup, not the pixels, dominates; it says which backend wins and which one
``pinhole_backend="auto"`` picks.

    flock /tmp/naruto_timing.lock python benchmarks/render_speed.py
    python benchmarks/render_speed.py --repeats 5 --no-paper-panorama --no-large-mesh
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import gymnasium as gym
import numpy as np
import open3d as o3d
import trimesh

import naruto_gym  # noqa: F401
from naruto_agent.cli_args import parse_dataclass_args
from naruto_gym.scenes import Scene, resolve_scene
from naruto_gym.sensors.panorama import EquirectangularCamera, render_panorama
from naruto_gym.sensors.pinhole import PinholeCamera, RgbdRenderer
from naruto_gym.sensors.raycaster import RayCaster

REPO = Path(__file__).resolve().parents[1]
REPLICA = REPO.parent / "shared" / "scenes" / "replica_office0"
FRAME_SIZES = {"680x1200": 1.0, "170x300": 0.25, "64x64": None}
GOAL_SPEEDUP = 6.0


@dataclass
class Args:
    repeats: int = 5
    """timed rounds; each round renders every pose once (4 poses x 5 = 20 frames)"""
    poses: int = 4
    """poses per scene (Replica: its trajectory; catalogue scenes: seeded resets)"""
    scenes: list[str] = field(
        default_factory=lambda: ["replica_like_room", "apartment", str(REPLICA / "mesh.ply")]
    )
    """catalogue names or mesh paths (default: the two catalogue rooms and the Replica
    office0 sample)"""
    paper_panorama: bool = True
    """also time the published 1024 x 2048 panorama"""
    large_mesh: bool = True
    """add two_rooms subdivided four times (760,832 triangles) to the frame-size sweep"""
    output_file: str = "benchmarks/results/render_speed.json"
    """the JSON report"""


def parse_args() -> Args:
    return parse_dataclass_args(Args, description="RGB-D / panorama / env.step speed")


def median_ms(function, poses: list[np.ndarray], repeats: int) -> float:
    """Median milliseconds of ``function(pose)`` over ``repeats`` rounds of all poses."""
    for pose in poses:
        function(pose)  # warm-up (JIT, caches, native scenes)
    times = []
    for _ in range(repeats):
        for pose in poses:
            started = time.perf_counter()
            function(pose)
            times.append(time.perf_counter() - started)
    return 1000.0 * float(np.median(times))


def scene_label(scene: str) -> str:
    return Path(scene).parent.name if scene.endswith((".ply", ".obj", ".glb")) else scene


def scene_poses(scene: str, count: int) -> list[np.ndarray]:
    """The first ``count`` of every 500th trajectory pose (Replica), else seeded env resets."""
    if Path(scene).parent == REPLICA:
        return list(np.loadtxt(REPLICA / "traj.txt").reshape(-1, 4, 4)[::500][:count])
    env = gym.make("NarutoRecon-v0", scene=scene, panorama_shape=None).unwrapped
    poses = []
    for seed in range(count):
        env.reset(seed=seed)
        poses.append(env.pose.copy())
    env.close()
    return poses


class BareCast:
    """Open3D's own ``cast_rays`` on prebuilt ray tensors of every pose, nothing else."""

    def __init__(self, scene: Scene, camera: PinholeCamera, poses: list[np.ndarray]) -> None:
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(
            o3d.core.Tensor(scene.vertices.astype(np.float32)),
            o3d.core.Tensor(scene.faces.astype(np.uint32)),
        )
        self.rays = {}
        for pose in poses:
            pose32 = pose.astype(np.float32)
            rays = np.empty((camera.width * camera.height, 6), np.float32)
            rays[:, :3] = pose32[:3, 3]
            rays[:, 3:] = camera.ray_directions @ pose32[:3, :3].T
            self.rays[id(pose)] = o3d.core.Tensor(rays)

    def __call__(self, pose: np.ndarray) -> None:
        self.scene.cast_rays(self.rays[id(pose)])


def bench_scene(scene: str, args: Args) -> dict:
    """The full-resolution row of one scene: every renderer and a whole env step."""
    poses = scene_poses(scene, args.poses)
    env = gym.make("NarutoRecon-v0", scene=scene).unwrapped
    env.reset(seed=0)
    raster = RgbdRenderer(env.scene, env.camera, env.settings.max_depth_m, env.raycaster, "raster")
    embree = RayCaster(env.scene.vertices, env.scene.faces, "embreex")
    bare = BareCast(env.scene, env.camera, poses)
    reference = env.renderer

    def embreex_cast(pose: np.ndarray) -> None:
        rays = bare.rays[id(pose)].numpy()
        embree.cast_packed(rays)

    def panorama(pose: np.ndarray) -> None:
        render_panorama(env.raycaster, env.panorama_camera, pose[:3, 3])

    row = {
        "scene": scene_label(scene),
        "triangles": int(len(env.scene.faces)),
        "rays": int(env.camera.width * env.camera.height),
        "poses": len(poses),
        "bare_open3d_cast_ms": median_ms(bare, poses, args.repeats),
        "embreex_cast_ms": median_ms(embreex_cast, poses, args.repeats),
        "rgbd_frame_ms": median_ms(reference.render, poses, args.repeats),
        "depth_only_ms": median_ms(reference.render_depth, poses, args.repeats),
        "raster_rgbd_frame_ms": median_ms(raster.render, poses, args.repeats),
        "raster_depth_only_ms": median_ms(raster.render_depth, poses, args.repeats),
        "panorama_ms": median_ms(panorama, poses, args.repeats),
        "panorama_shape": [env.panorama_camera.height, env.panorama_camera.width],
    }
    if args.paper_panorama:
        paper = EquirectangularCamera(1024, 2048)
        row["paper_panorama_1024x2048_ms"] = median_ms(
            lambda pose: render_panorama(env.raycaster, paper, pose[:3, 3]),
            poses[:1],
            max(args.repeats // 4, 3),
        )
    steps = args.repeats * args.poses
    row["env_step_ms"] = env_step_ms(env, steps)
    env.close()
    raster_env = gym.make("NarutoRecon-v0", scene=scene, pinhole_backend="raster").unwrapped
    raster_env.reset(seed=0)
    row["raster_env_step_ms"] = env_step_ms(raster_env, steps)
    raster_env.close()
    row["rgbd_vs_bare_ratio"] = row["rgbd_frame_ms"] / row["bare_open3d_cast_ms"]
    row["rgbd_mrays_per_s"] = row["rays"] / row["rgbd_frame_ms"] / 1000.0
    row["raster_speedup_vs_bare"] = row["bare_open3d_cast_ms"] / row["raster_rgbd_frame_ms"]
    row["raster_speedup_vs_raycast_rgbd"] = row["rgbd_frame_ms"] / row["raster_rgbd_frame_ms"]
    row["load_average"] = list(os.getloadavg())
    return row


def env_step_ms(env, steps: int) -> float:
    env.action_space.seed(0)
    return median_ms(lambda _: env.step(env.action_space.sample()), [None], steps)


def subdivided(scene: Scene, times: int) -> Scene:
    """``scene`` with every triangle split into 4, ``times`` times; each child keeps its
    parent's mean corner colour."""
    vertices, faces = scene.vertices, scene.faces
    parents = np.arange(len(faces))
    for _ in range(times):
        vertices, faces, children = trimesh.remesh.subdivide(vertices, faces, return_index=True)
        parent_of = np.empty(len(faces), np.int64)
        for parent, new_faces in children.items():
            parent_of[new_faces] = parent
        parents = parents[parent_of]
    colours = scene.corner_colours.mean(axis=1).astype(np.uint8)[parents]
    return Scene(
        vertices, faces, np.repeat(colours[:, None, :], 3, axis=1), f"{scene.name}_x{4**times}"
    )


def frame_camera(size: str) -> PinholeCamera:
    scale = FRAME_SIZES[size]
    if scale is None:  # 64 x 64 with the same horizontal field of view as 1200 pixels at 600
        return PinholeCamera(width=64, height=64, fx=32.0, fy=32.0, cx=31.5, cy=31.5)
    return PinholeCamera().scaled(scale)


def bench_frame_sizes(
    name: str, scene: Scene, poses: list[np.ndarray], args: Args, full_frame: dict | None = None
) -> list:
    """Bare cast, ray-cast and rasterized RGB-D frames of one mesh at every frame size
    (``full_frame``: the scene's row of :func:`bench_scene`, reused for 680 x 1200)."""
    rows = []
    raycaster = RayCaster(scene.vertices, scene.faces)
    for size in FRAME_SIZES:
        camera = frame_camera(size)
        reference = RgbdRenderer(scene, camera, 10.0, raycaster)
        raster = RgbdRenderer(scene, camera, 10.0, raycaster, backend="raster")
        auto = RgbdRenderer(scene, camera, 10.0, raycaster, backend="auto")
        row = {
            "scene": name,
            "triangles": int(len(scene.faces)),
            "frame": size,
            "pixels": camera.width * camera.height,
            "triangles_per_pixel": len(scene.faces) / (camera.width * camera.height),
            "auto_picks": auto.frame_backend,
        }
        if size == "680x1200" and full_frame is not None:
            row["bare_open3d_cast_ms"] = full_frame["bare_open3d_cast_ms"]
            row["raycast_rgbd_ms"] = full_frame["rgbd_frame_ms"]
            row["raster_rgbd_ms"] = full_frame["raster_rgbd_frame_ms"]
        else:
            repeats = args.repeats if size == "680x1200" else 3 * args.repeats
            row["bare_open3d_cast_ms"] = median_ms(BareCast(scene, camera, poses), poses, repeats)
            row["raycast_rgbd_ms"] = median_ms(reference.render, poses, repeats)
            row["raster_rgbd_ms"] = median_ms(raster.render, poses, repeats)
        row["faster"] = "raster" if row["raster_rgbd_ms"] < row["raycast_rgbd_ms"] else "raycast"
        row["raster_speedup_vs_bare"] = row["bare_open3d_cast_ms"] / row["raster_rgbd_ms"]
        row["raster_speedup_vs_raycast_rgbd"] = row["raycast_rgbd_ms"] / row["raster_rgbd_ms"]
        row["load_average"] = list(os.getloadavg())
        rows.append(row)
        print(
            f"  {name} {size}: bare {row['bare_open3d_cast_ms']:.2f} ms, ray-cast RGB-D "
            f"{row['raycast_rgbd_ms']:.2f} ms, raster RGB-D {row['raster_rgbd_ms']:.2f} ms "
            f"(load {row['load_average'][0]:.2f})",
            flush=True,
        )
    return rows


FIRST_CALL_SCRIPT = """
import time
import numpy as np
from naruto_gym.sensors.raster import PinholeRasterizer
started = time.perf_counter()
PinholeRasterizer(np.eye(3), np.array([[0, 1, 2]]), 8, 8, 4.0, 4.0, 3.5, 3.5).render(np.eye(4))
print(time.perf_counter() - started)
"""


def first_call_seconds(cache_dir: str | None) -> float:
    """Seconds of the first rasterized frame in a fresh process: numba compiling the kernels
    (an empty cache) or loading them from its cache."""
    environment = dict(os.environ)
    if cache_dir is not None:
        environment["NUMBA_CACHE_DIR"] = cache_dir
    result = subprocess.run(
        [sys.executable, "-c", FIRST_CALL_SCRIPT], env=environment, capture_output=True,
        text=True, check=True,
    )
    return float(result.stdout.strip().splitlines()[-1])


def main() -> None:
    args = parse_args()
    load_before = list(os.getloadavg())
    with tempfile.TemporaryDirectory() as empty_cache:
        first_call = {
            "compile_s": first_call_seconds(empty_cache),
            "cached_s": first_call_seconds(None),
        }
    print(
        f"first rasterized frame in a fresh process: {first_call['compile_s']:.2f} s compiling, "
        f"{first_call['cached_s']:.2f} s from numba's cache"
    )
    scenes = [scene for scene in args.scenes if _exists(scene)]
    rows = []
    for scene in scenes:
        rows.append(bench_scene(scene, args))
        print(f"  {rows[-1]['scene']} done (load {rows[-1]['load_average'][0]:.2f})", flush=True)
    sweep = []
    for scene, row in zip(scenes, rows, strict=True):
        poses = scene_poses(scene, args.poses)
        sweep += bench_frame_sizes(row["scene"], resolve_scene(scene), poses, args, row)
    if args.large_mesh:
        large = subdivided(resolve_scene("two_rooms"), 4)
        sweep += bench_frame_sizes(large.name, large, scene_poses("two_rooms", args.poses), args)
    load_after = list(os.getloadavg())
    print_tables(rows, sweep)
    print(f"load average before {load_before}, after {load_after}")
    out = REPO / args.output_file
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(
        json.dumps(
            {
                "args": asdict(args),
                "load_average_before": load_before,
                "load_average_after": load_after,
                "first_rasterized_frame": first_call,
                "rows": rows,
                "frame_sizes": sweep,
            },
            indent=2,
        )
    )


def print_tables(rows: list[dict], sweep: list[dict]) -> None:
    print(
        "| scene | tris | bare O3D cast | embreex cast | ray-cast RGB-D | ratio | raster RGB-D "
        "| raster depth | bare / raster | panorama | 1024x2048 pano | env.step | env.step raster |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['scene']} | {r['triangles']} | {r['bare_open3d_cast_ms']:.1f} ms "
            f"| {r['embreex_cast_ms']:.1f} ms | {r['rgbd_frame_ms']:.1f} ms "
            f"| {r['rgbd_vs_bare_ratio']:.2f}x | {r['raster_rgbd_frame_ms']:.1f} ms "
            f"| {r['raster_depth_only_ms']:.1f} ms | {r['raster_speedup_vs_bare']:.1f}x "
            f"| {r['panorama_ms']:.2f} ms "
            f"| {r.get('paper_panorama_1024x2048_ms', float('nan')):.1f} ms "
            f"| {r['env_step_ms']:.1f} ms | {r['raster_env_step_ms']:.1f} ms |"
        )
    print("goal (env issue): ray-cast RGB-D <= 1.25x bare cast")
    for r in rows:
        if r["scene"] in ("apartment", "replica_office0"):
            verdict = "met" if r["raster_speedup_vs_bare"] >= GOAL_SPEEDUP else "NOT met"
            print(
                f"goal (rasterizer issue) on {r['scene']}: raster RGB-D >= {GOAL_SPEEDUP:.0f}x "
                f"faster than the bare cast: {r['raster_speedup_vs_bare']:.2f}x, {verdict}"
            )
    print()
    print(
        "| mesh | tris | frame | tris / pixel | bare O3D cast | ray-cast RGB-D | raster RGB-D "
        "| raster speed-up vs ray-cast RGB-D | faster | auto picks |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in sweep:
        print(
            f"| {r['scene']} | {r['triangles']} | {r['frame']} | {r['triangles_per_pixel']:.2f} "
            f"| {r['bare_open3d_cast_ms']:.2f} ms | {r['raycast_rgbd_ms']:.2f} ms "
            f"| {r['raster_rgbd_ms']:.2f} ms | {r['raster_speedup_vs_raycast_rgbd']:.2f}x "
            f"| {r['faster']} | {r['auto_picks']} |"
        )


def _exists(scene: str) -> bool:
    if scene.endswith((".ply", ".obj", ".glb")) and not Path(scene).is_file():
        print(f"skipping {scene}: not found")
        return False
    return True


if __name__ == "__main__":
    main()
