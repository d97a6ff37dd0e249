"""Cost of NARUTO's active ray scoring per mode. Results: docs/benchmarks/mapping.md

Times each scoring mode against the mapping iteration it serves, and counts how many of the
published scoring's picks each cheaper mode shares.

Maps the first frames of the Replica office0 sample (ground-truth poses, a keyframe every 5
frames, without active sampling, so the map does not depend on the mode), then scores the
same pool (8192 keyframe + 400 current-frame rays) with every mode of
``NeuralMapperConfig.active_score`` and times one training iteration (2048 + 100 rays) in
the same run:

* ``rendered`` (published): every sample of every pool ray, with the compiled no-gradient
  hash grid (``cpu_kernels``) and with the PyTorch path (the reference of the speed-up);
* ``surface``: the 11 samples around the measured depth;
* ``grid``: the uncertainty grid at the measured surface point (no field query).

Times are CPU seconds of this process (``time.process_time``), one torch thread by default:
on a shared machine they move far less with the other jobs than wall-clock time does. Each
figure is the median of ``--repeats`` runs, the modes interleaved.

Usage::

    python benchmarks/active_scoring_speed.py                 # 20 frames, 1 thread
    python benchmarks/active_scoring_speed.py --frames 100 --threads 2
"""

from __future__ import annotations

import copy
import dataclasses
import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from naruto_agent.cli_args import parse_dataclass_args
from naruto_agent.mapping import NeuralMapper, NeuralMapperConfig
from naruto_gym.scenes.mesh_scene import load_scene
from naruto_gym.sensors.pinhole import PinholeCamera, RgbdRenderer

REPO_ROOT = Path(__file__).resolve().parents[1]


@dataclass
class Args:
    """Benchmark settings."""

    scene_dir: str = str(REPO_ROOT.parent / "shared" / "scenes" / "replica_office0")
    """folder with mesh.ply and traj.txt"""
    frames: int = 20
    """frames mapped before scoring (one every 5 of the trajectory)"""
    threads: int = 1
    """torch threads (and compiled-loop threads)"""
    repeats: int = 5
    """timed runs per variant (median)"""
    seed: int = 0
    """seed of the mapper and of the pool"""
    output_file: str = str(REPO_ROOT / "benchmarks" / "results" / "active_scoring_speed.json")
    """where the JSON goes"""


def cpu_seconds(function, repeats: int) -> list[float]:  # noqa: ANN001
    """CPU seconds of this process for each of ``repeats`` calls (after one warm-up)."""
    function()
    durations = []
    for _ in range(repeats):
        start = time.process_time()
        function()
        durations.append(time.process_time() - start)
    return durations


def main(args: Args) -> dict:
    scene_dir = Path(args.scene_dir)
    if not (scene_dir / "mesh.ply").is_file():
        sys.exit(f"no mesh.ply in {scene_dir}; pass --scene-dir with the Replica sample")
    if args.frames < 2 or args.threads < 1 or args.repeats < 1:
        sys.exit("--frames must be at least 2, --threads and --repeats at least 1")
    torch.set_num_threads(args.threads)
    load_start = os.getloadavg()
    scene = load_scene(scene_dir / "mesh.ply", up_axis="z", name="replica_office0")
    poses = np.loadtxt(scene_dir / "traj.txt").reshape(-1, 4, 4)
    camera = PinholeCamera()
    renderer = RgbdRenderer(scene, camera, max_depth_m=5.0)
    bounds = scene.bounds + np.array([[-0.1], [0.1]])
    config = NeuralMapperConfig(
        device="cpu", seed=args.seed, first_frame_iterations=30, active_sampling=False
    )
    mapper = NeuralMapper(bounds, camera, config)
    indices = range(0, 5 * args.frames, 5)
    frames = [(index, *renderer.render(poses[index])) for index in indices]
    for index, rgb, depth in frames:
        mapper.integrate(rgb, depth, poses[index], index)
    index, rgb, depth = frames[-1]
    pixels = torch.randperm(depth.size, generator=torch.Generator().manual_seed(args.seed))
    pixels = pixels[: config.current_frame_rays * config.active_oversample]
    current = mapper.frame_rays(rgb, depth, poses[index], pixels.numpy())
    mapper.generator.manual_seed(args.seed)
    pool, _ = mapper.active_ray_pool(current)
    batch = pool.select(torch.arange(config.rays_per_iteration + config.current_frame_rays))
    state = copy.deepcopy(mapper.state_dict(include_keyframes=False))

    variants = {
        "rendered (compiled hash grid)": ("rendered", True),
        "rendered (PyTorch hash grid)": ("rendered", False),
        "surface (compiled hash grid)": ("surface", True),
        "grid": ("grid", True),
    }
    seconds: dict[str, list[float]] = {name: [] for name in (*variants, "training iteration")}
    picked: dict[str, set[int]] = {}
    for _ in range(args.repeats):
        for name, (score, compiled) in variants.items():
            mapper.config.active_score = score
            mapper.field.hash_grid.cpu_kernel = compiled
            seconds[name] += cpu_seconds(lambda: mapper.ray_uncertainty(pool), 1)
            scores = mapper.ray_uncertainty(pool)
            picked[score] = set(torch.topk(scores, config.active_top_rays).indices.tolist())
        mapper.field.hash_grid.cpu_kernel = True
        seconds["training iteration"] += cpu_seconds(lambda: mapper.train_iteration(batch), 1)
        mapper.load_state_dict(state)  # every timed iteration starts from the same map
    median = {name: float(np.median(values)) for name, values in seconds.items()}
    iteration = median["training iteration"]
    record = {
        "args": dataclasses.asdict(args),
        "cpu_seconds_median": median,
        "cpu_seconds_all": seconds,
        "relative_to_training_iteration": {
            name: value / iteration for name, value in median.items()
        },
        "compiled_speedup_rendered": median["rendered (PyTorch hash grid)"]
        / median["rendered (compiled hash grid)"],
        "top_rays_shared_with_rendered": {
            score: len(picked[score] & picked["rendered"]) / len(picked["rendered"])
            for score in ("surface", "grid")
        },
        "pool_rays": len(pool),
        "load_average_start": load_start,
        "load_average_end": os.getloadavg(),
    }
    Path(args.output_file).parent.mkdir(parents=True, exist_ok=True)
    Path(args.output_file).write_text(json.dumps(record, indent=2))
    print(
        f"\noffice0, {args.frames} frames mapped, pool of {len(pool)} rays, "
        f"{args.threads} thread(s), CPU time, median of {args.repeats}"
    )
    print("| variant | relative to one training iteration |")
    print("|---|---|")
    for name, value in record["relative_to_training_iteration"].items():
        print(f"| {name} | {value:.3f} |")
    print(
        f"compiled hash grid: {record['compiled_speedup_rendered']:.2f}x less CPU time for the "
        "published scoring"
    )
    for score, share in record["top_rays_shared_with_rendered"].items():
        print(f"top {config.active_top_rays} rays {score} shares with rendered: {share:.0%}")
    print(
        f"load average {load_start[0]:.1f} -> {record['load_average_end'][0]:.1f}; "
        f"written {args.output_file}"
    )
    return record


if __name__ == "__main__":
    main(parse_dataclass_args(Args, description=__doc__.split("\n")[0]))
