"""A Replica scan replayed and scored as every policy is. Results: docs/benchmarks/metrics.md

Replays a Replica scene's recorded camera trajectory (``traj.txt``, the human-style "passive"
scan of the published systems) in ``NarutoRecon-v0`` with pose actions and
``reconstruct=True``: each action is the next recorded pose, the env moves the camera there
(the recorded steps are far below the env's 0.1 m / 20 degree limits), renders the frame with
the scene's camera (``cam_params.json``) and fuses it at 2 cm; then scores the fused mesh with
the published protocol. On office0 the result is set beside the published passive figure.

The scene is a folder holding ``mesh.ply``, ``traj.txt`` and ``cam_params.json``: the office0
sample in ``../shared/scenes/replica_office0`` by default, or any of the eight scenes that
``scripts/prepare_replica.py`` lays out from the Replica release (see docs/replica.md).

Usage::

    python benchmarks/replica_passive.py                                 # the reported run
    python benchmarks/replica_passive.py --stride 10 --scale 0.5         # quick look
    python benchmarks/replica_passive.py --scene-dir data/replica/replica_room0

``--trajectory`` replays another pose file of the same layout (one flattened 4 x 4
camera-to-world matrix per line), e.g. the ``*_poses.txt`` that ``naruto_episode.py`` writes:
the reference map of an active episode, rebuilt and scored (MAD included) without running
its agent again.

Writes ``benchmarks/results/replica_passive.json`` (``replica_passive_<folder>.json`` for
another scene) and prints a Markdown table.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import gymnasium as gym
import numpy as np
from tqdm import tqdm

import naruto_gym  # noqa: F401  (registers the envs)
from naruto_agent.cli_args import parse_dataclass_args
from naruto_gym.evaluation import (
    EpisodeReconstruction,
    cull_mesh,
    reconstruction_metrics,
    sample_mesh_surface,
    trajectory_length,
    visible_vertex_mask,
)
from naruto_gym.geometry.transforms import quaternion_from_pose, rotation_angle_between
from naruto_gym.sensors.pinhole import PinholeCamera

REPO = Path(__file__).resolve().parents[1]
REPLICA = REPO.parent / "shared" / "scenes" / "replica_office0"
DEFAULT_OUT = "benchmarks/results/replica_passive.json"

# NARUTO (Feng et al., CVPR 2024) supplementary Tables 4 and 6: passive Co-SLAM without
# tracking along office0's trajectory, full-resolution mesh, 2000 frames.
PUBLISHED = {
    "completion_ratio_pct": 96.33,
    "accuracy_cm": 1.50,
    "completion_cm": 1.48,
    "trajectory_length_m": 18.20,
}


@dataclass
class Args:
    """Settings of the replay."""

    scene_dir: str = str(REPLICA)
    """scene folder with mesh.ply, traj.txt and cam_params.json (default: the office0 sample
    in ../shared/scenes; scripts/prepare_replica.py writes one per Replica scene)"""
    stride: int = 1
    """replay every stride-th pose (1: all of them, 2000 on Replica, the reported run)"""
    scale: float = 1.0
    """image resolution factor of the scene's camera (1: the published 680 x 1200)"""
    voxel_size_m: float = 0.02
    """voxel size of the TSDF fusion in metres (2 cm as the env's reference map)"""
    truncation_m: float = 0.08
    """truncation distance of the TSDF fusion in metres"""
    num_samples: int = 200_000
    """surface samples per mesh for the metrics (200,000 as published)"""
    seed: int = 0
    """seed of the env reset and of the surface samples"""
    trajectory: str = ""
    """pose file to replay, one flattened 4 x 4 camera-to-world matrix per line (default:
    the scene's traj.txt)"""
    pinhole_backend: str = "raycast"
    """the env's pinhole_backend: raycast, raster, or auto (the rasterizer where cheaper)"""
    output_file: str = ""
    """the JSON report (default: benchmarks/results/replica_passive.json for the office0
    sample, replica_passive_<folder>.json for another scene folder)"""
    mesh_out: str = ""
    """also save the fused mesh here (PLY), e.g. /tmp/office0_tsdf.ply"""


def parse_args(argv: list[str] | None = None) -> Args:
    description = " ".join(__doc__.split("\n\n")[1:3]).replace("\n", " ")
    return parse_dataclass_args(Args, argv, description=description)


def scene_camera(scene_dir: Path, scale: float) -> dict:
    """The env's camera keywords for the scene's ``cam_params.json``: ``image_scale`` alone
    when it is the env's default camera (the published one), else a ``camera``."""
    params = scene_dir / "cam_params.json"
    if not params.is_file():
        return {"image_scale": scale}
    values = json.loads(params.read_text())["camera"]
    camera = PinholeCamera(int(values["w"]), int(values["h"]), float(values["fx"]),
                           float(values["fy"]), float(values["cx"]), float(values["cy"]))
    if camera == PinholeCamera():
        return {"image_scale": scale}
    return {"camera": camera.scaled(scale)}


def pose_action(pose: np.ndarray) -> np.ndarray:
    """The env's pose action (x, y, z, qx, qy, qz, qw) for a camera-to-world matrix."""
    return np.concatenate([pose[:3, 3], quaternion_from_pose(pose)]).astype(np.float32)


def main(argv: list[str] | None = None) -> dict:
    args = parse_args(argv)
    scene_dir = Path(args.scene_dir)
    if not (scene_dir / "mesh.ply").is_file():
        raise SystemExit(
            f"{scene_dir / 'mesh.ply'} not found: pass --scene-dir with a scene folder (the "
            "office0 sample is ../shared/scenes/replica_office0; scripts/prepare_replica.py "
            "makes one per Replica scene, see docs/replica.md)"
        )
    trajectory = Path(args.trajectory) if args.trajectory else scene_dir / "traj.txt"
    if not trajectory.is_file():
        raise SystemExit(f"{trajectory} not found: pass a pose file (16 numbers per line)")
    office0 = scene_dir.name.endswith("office0")
    poses = np.loadtxt(trajectory).reshape(-1, 4, 4)[:: args.stride]
    # A strided replay takes longer steps: widen the step limits so the poses are reached.
    limits = {} if args.stride == 1 else {"max_translation_m": 1.0, "max_rotation_deg": 180.0}
    env = gym.make(
        "NarutoRecon-v0",
        scene=str(scene_dir / "mesh.ply"),
        action_mode="pose",
        **scene_camera(scene_dir, args.scale),
        panorama_shape=None,  # not needed for a replay; saves a render per step
        reconstruct=True,
        pinhole_backend=args.pinhole_backend,
        **limits,
    )
    unwrapped = env.unwrapped
    # The env fuses at 2 cm / 8 cm; other settings swap in an equally built reconstruction.
    unwrapped.reconstruction = EpisodeReconstruction(
        unwrapped.camera, voxel_size_m=args.voxel_size_m, truncation_m=args.truncation_m
    )

    started = time.perf_counter()
    _, info = env.reset(seed=args.seed, options={"pose": poses[0]})
    off_target = 0
    for pose in tqdm(poses[1:], desc="replay", unit="frame"):
        _, _, terminated, truncated, info = env.step(pose_action(pose))
        reached = unwrapped.poses[-1]
        moved_ok = np.linalg.norm(reached[:3, 3] - pose[:3, 3]) < 1e-4
        turned_ok = rotation_angle_between(reached[:3, :3], pose[:3, :3]) < 1e-4
        off_target += int(not (moved_ok and turned_ok))
        if terminated or truncated:
            break
    replay_s = time.perf_counter() - started

    started = time.perf_counter()
    metrics = unwrapped.reconstruction_metrics(num_samples=args.num_samples, seed=args.seed)
    evaluate_s = time.perf_counter() - started
    recon = unwrapped.reconstruction.mesh()
    scene = unwrapped.scene
    uncropped = reconstruction_metrics(
        recon, scene, num_samples=args.num_samples, seed=args.seed
    ).as_dict()
    # The floor of the protocol: the ground truth scored against itself (sampling density).
    floor = reconstruction_metrics(scene, scene, num_samples=args.num_samples, seed=args.seed)
    gt_points = sample_mesh_surface(scene.vertices, scene.faces, args.num_samples, args.seed)
    mad_cm = metrics["mad_cm"]  # the fused SDF at the completion's ground-truth samples
    # How much of the ground truth could this trajectory see at all (frustum + occlusion, the
    # culling rule applied to ground-truth samples), and the completion on that part alone.
    replayed = unwrapped.poses
    observable = visible_vertex_mask(gt_points, replayed, unwrapped.camera, unwrapped.renderer)
    culled = cull_mesh(recon.vertices, recon.faces, replayed, unwrapped.camera, unwrapped.renderer)
    on_observable = reconstruction_metrics(
        culled, gt_points[observable], num_samples=args.num_samples, seed=args.seed
    )
    if args.mesh_out:
        recon.export(args.mesh_out)

    report = {
        "args": asdict(args),
        "scene": scene_dir.name,
        "trajectory_file": trajectory.name,
        "frames": int(unwrapped.reconstruction.mapper.num_frames),
        "image": f"{unwrapped.camera.height} x {unwrapped.camera.width}",
        "poses_not_reached": off_target,
        "trajectory_length_m": trajectory_length(unwrapped.poses),
        "env_path_length_m": float(info["path_length_m"]),
        "env_coverage_pct": 100.0 * float(info["coverage"]),
        "metrics_culled": metrics,
        "metrics_not_culled": uncropped,
        "mad_cm": mad_cm,
        "observable_gt_pct": 100.0 * float(observable.mean()),
        "completion_on_observable_gt": {
            "completion_cm": on_observable.completion_cm,
            "completion_ratio_pct": on_observable.completion_ratio_pct,
        },
        "gt_against_itself": floor.as_dict(),
        "published_passive_coslam": PUBLISHED if office0 else None,
        "recon_faces": len(recon.faces),
        "replay_s": replay_s,
        "evaluate_s": evaluate_s,
    }
    default_out = (DEFAULT_OUT if scene_dir.resolve() == REPLICA.resolve()
                   else f"benchmarks/results/replica_passive_{scene_dir.name}.json")
    out = Path(args.output_file or default_out)
    out = out if out.is_absolute() else REPO / out
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=2))

    m = metrics
    print(f"\nframes fused {report['frames']} at {report['image']}, poses not reached {off_target}")
    print(f"replay {replay_s:.0f} s, culling + metrics {evaluate_s:.1f} s")
    print(
        f"\n| Replica {scene_dir.name}, {report['trajectory_file']} ({report['frames']} frames) "
        "| mapper "
        "| Acc. (cm) | Comp. (cm) | Comp. ratio (%) | Traj. (m) |"
    )
    print("|---|---|---|---|---|---|")
    print(
        f"| naruto-gym env replay ({len(scene.faces):,}-triangle mesh, culled) | TSDF fusion, "
        f"{100 * args.voxel_size_m:.0f} cm | {m['accuracy_cm']:.2f} | {m['completion_cm']:.2f} | "
        f"{m['completion_ratio_pct']:.2f} | {report['trajectory_length_m']:.2f} |"
    )
    if office0:
        print(
            f"| NARUTO paper, passive (full-resolution mesh) | Co-SLAM, no tracking | "
            f"{PUBLISHED['accuracy_cm']:.2f} | {PUBLISHED['completion_cm']:.2f} | "
            f"{PUBLISHED['completion_ratio_pct']:.2f} | {PUBLISHED['trajectory_length_m']:.2f} |"
        )
    print(
        f"\nprecision {m['precision_pct']:.2f} %, F-score {m['fscore_pct']:.2f} %, "
        f"MAD {mad_cm:.2f} cm; not culled: acc {uncropped['accuracy_cm']:.2f} cm, "
        f"ratio {uncropped['completion_ratio_pct']:.2f} %; ground truth against itself: "
        f"acc {floor.accuracy_cm:.2f} cm, comp {floor.completion_cm:.2f} cm "
        f"({args.num_samples:,} samples)"
    )
    print(
        f"observable ground truth (seen by any used pose): {report['observable_gt_pct']:.1f} %; "
        f"completion ratio on it {on_observable.completion_ratio_pct:.2f} %, "
        f"completion {on_observable.completion_cm:.2f} cm"
    )
    print(f"saved {out}")
    env.close()
    return report


if __name__ == "__main__":
    main()
