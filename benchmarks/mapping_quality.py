"""Mapping quality and speed on the Replica trajectory. Results: docs/benchmarks/mapping.md

Maps the sample scene from its 2000 ground-truth poses with:

* ``neural``: the neural mapper without active ray sampling (Co-SLAM with known poses);
* ``neural_active``: the same with NARUTO's uncertainty-driven active ray sampling;
* ``tsdf``: the fast alternative (TSDF fusion + count-derived uncertainty),

then scores the 2 cm meshes (culled by the trajectory's views, as in the literature) with
accuracy, completion and completion ratio, and reports the time per mapping iteration and in
total. Before that it times one mapping iteration (2048 + 100 rays) with the batched hash
grid and with a plain per-level hash grid (the reference for the speed-up ratio), both in
this run.

Frames come from the same renderer the env uses (:class:`RgbdRenderer`'s ray caster and
colour lookup). The neural mapper reads only the pixels it needs (keyframes: 5 %; mapping
frames: the current-frame rays of the 10 iterations), so only those pixels are ray-cast
(:meth:`NeuralMapper.required_pixels`): the result is identical to rendering whole frames
and picking the same pixels, but costs a fraction of the time. The TSDF mapper fuses whole
frames, so it renders them.

Usage::

    python benchmarks/mapping_quality.py                    # everything (long)
    python benchmarks/mapping_quality.py --num-frames 500 --variants neural tsdf
"""

from __future__ import annotations

import dataclasses
import json
import platform
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from naruto_agent.cli_args import parse_dataclass_args
from naruto_agent.mapping import (
    NaiveHashGridEncoding,
    NeuralMapper,
    NeuralMapperConfig,
    TsdfMapperConfig,
    TsdfUncertaintyMapper,
    resolve_backend,
    resolve_device,
)
from naruto_gym.evaluation import evaluate_reconstruction
from naruto_gym.scenes.mesh_scene import Scene, load_scene
from naruto_gym.sensors.pinhole import PinholeCamera, RgbdRenderer

REPO_ROOT = Path(__file__).resolve().parents[1]
PUBLISHED_COMPLETION_RATIO = 96.33  # passive Co-SLAM, office0, full mesh (NARUTO supp. T4)


@dataclass
class Args:
    """Benchmark settings."""

    scene_dir: str = str(REPO_ROOT.parent / "shared" / "scenes" / "replica_office0")
    """folder with mesh.ply and traj.txt"""
    num_frames: int = 2000
    """frames of the trajectory to map (the whole sequence has 2000)"""
    trajectory: str = ""
    """poses to map instead of the scene's traj.txt (same format: a flattened 4x4
    camera-to-world matrix per line), e.g. an agent's episode written by naruto_episode.py"""
    variants: list[str] = field(default_factory=lambda: ["neural", "neural_active", "tsdf"])
    """which mappers to run: neural, neural_active, tsdf"""
    speed_iterations: int = 10
    """timed iterations per hash-grid implementation in the speed test (0 skips it)"""
    device: str = "auto"
    """torch device of the neural mapper"""
    backend: str = "auto"
    """compute path of the neural mapper's runs: auto (Triton on CUDA where installed),
    torch (the reference) or triton; the speed test times both paths where Triton runs"""
    active_score: str = "surface"
    """how neural_active scores its ray pool: "surface" (the 11 samples around the measured
    depth), "grid" (the uncertainty grid at the measured point, no field query), "rendered"
    (every sample, the published scoring)"""
    mesh_voxel_m: float = 0.02
    """marching-cubes voxel of the final meshes"""
    eval_samples: int = 200_000
    """surface samples per mesh for the metrics"""
    bounds_padding_m: float = 0.1
    """margin added around the mesh bounds for the map's box"""
    seed: int = 0
    """seed of the mapper and of the evaluation sampling"""
    output_file: str = str(REPO_ROOT / "benchmarks" / "results" / "mapping_quality.json")
    """where the JSON results go"""


def parse_args() -> Args:
    return parse_dataclass_args(Args, description=__doc__.split("\n")[0])


def load_trajectory(path: Path) -> np.ndarray:
    return np.loadtxt(path, dtype=np.float64).reshape(-1, 4, 4)


def render_pixels(
    renderer: RgbdRenderer, pose: np.ndarray, pixels: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """RGB (K, 3) uint8 and z-depth (K,) of chosen pixels: exactly what a full render gives
    at those pixels (same rays, same range cut, same colour lookup)."""
    pose32 = np.asarray(pose, dtype=np.float32)
    directions = renderer.camera.ray_directions[pixels] @ pose32[:3, :3].T
    hits = renderer.raycaster.cast(pose32[:3, 3], directions)
    depth = hits.distance.copy()
    depth[~(depth <= renderer.max_depth_m)] = 0.0
    triangle_ids = np.where(depth > 0, hits.triangle_ids, -1)
    rgb = renderer.scene.colour_at(triangle_ids, hits.barycentric_uv)
    return rgb, depth


def time_iteration(
    scene: Scene, renderer: RgbdRenderer, poses: np.ndarray, bounds: np.ndarray, args: Args
) -> dict[str, float]:
    """Seconds per mapping iteration of 2048 + 100 rays: batched vs plain hash grid (both
    PyTorch), and the fast path (Triton kernels, fixed shapes) where it runs (CUDA)."""
    camera = renderer.camera
    rgb, depth = renderer.render(poses[0])
    results: dict[str, float] = {}
    variants = {
        "batched hash grid (published 43 samples)": (None, None, "torch", False),
        "batched hash grid (samples > 0.2 m behind depth skipped)": (0.2, None, "torch", False),
        "plain per-level hash grid (published 43 samples)": (
            None, NaiveHashGridEncoding, "torch", False
        ),
    }
    if fast_path_runs(args.device):
        variants["fast path, Triton, eager (published 43 samples)"] = (
            None, None, "triton", False
        )
        variants["fast path, Triton, CUDA graph (published 43 samples)"] = (
            None, None, "triton", True
        )
        variants["fast path, Triton, CUDA graph (samples > 0.2 m behind depth masked)"] = (
            0.2, None, "triton", True
        )
    for name, (cull, encoding, backend, graphs) in variants.items():
        config = NeuralMapperConfig(
            device=args.device,
            backend=backend,
            cuda_graphs=graphs,
            seed=args.seed,
            first_frame_iterations=0,
            cull_behind_depth_m=cull,
            active_sampling=False,
        )
        kwargs = {"hash_encoding_cls": encoding} if encoding is not None else {}
        mapper = NeuralMapper(bounds, camera, config, **kwargs)
        rays = mapper.frame_rays(rgb, depth, poses[0])
        generator = torch.Generator().manual_seed(args.seed)
        durations = []
        for _ in range(args.speed_iterations + 2):
            index = torch.randint(0, len(rays), (2048 + 100,), generator=generator)
            batch = rays.select(index.to(mapper.device))
            start = time.perf_counter()
            mapper.train_iteration(batch)
            if mapper.device.type == "cuda":
                torch.cuda.synchronize()
            durations.append(time.perf_counter() - start)
        results[name] = float(np.median(durations[2:]))  # the first two warm up (and capture)
        status = f" (CUDA graph: {mapper.cuda_graph_status})" if graphs else ""
        print(f"  {name}: {results[name] * 1e3:.1f} ms per iteration{status}", flush=True)
    return results


def fast_path_runs(device: str) -> bool:
    """Whether the Triton fast path runs compiled on this device (not the interpreter)."""
    torch_device = resolve_device(device)
    if torch_device.type != "cuda":
        return False
    try:
        return resolve_backend("triton", torch_device) == "triton"
    except ValueError:
        return False


def time_active_scoring(
    renderer: RgbdRenderer, poses: np.ndarray, bounds: np.ndarray, args: Args
) -> dict[str, float]:
    """Seconds to pick one iteration's rays by uncertainty (pool of 8192 keyframe + 400
    current rays), per scoring mode, and how many of the 500 rays each mode picks the
    published ("rendered") scoring picks too. All modes score the same pool of the same map
    (mapped from the first 50 frames, a keyframe every 5, without active sampling)."""
    camera = renderer.camera
    results: dict[str, float] = {}
    picked: dict[str, set[int]] = {}
    frames = [(index, *renderer.render(poses[index])) for index in range(0, min(50, len(poses)), 5)]
    config = NeuralMapperConfig(
        device=args.device,
        backend=args.backend,
        seed=args.seed,
        first_frame_iterations=20,
        active_sampling=False,
    )
    mapper = NeuralMapper(bounds, camera, config)
    for index, rgb, depth in frames:
        mapper.integrate(rgb, depth, poses[index], index)
    rgb, depth = frames[-1][1], frames[-1][2]
    pixels = torch.randperm(depth.size, generator=torch.Generator().manual_seed(args.seed))
    pixels = pixels[: config.current_frame_rays * config.active_oversample]
    current = mapper.frame_rays(rgb, depth, poses[frames[-1][0]], pixels.numpy())
    for score in ("rendered", "surface", "grid"):
        mapper.config.active_score = score
        durations = []
        for _ in range(args.speed_iterations + 2):
            mapper.generator.manual_seed(args.seed)
            start = time.perf_counter()
            pool, _ = mapper.active_ray_pool(current)
            scores = mapper.ray_uncertainty(pool)
            if mapper.device.type == "cuda":
                torch.cuda.synchronize()
            durations.append(time.perf_counter() - start)
        picked[score] = set(torch.topk(scores, config.active_top_rays).indices.tolist())
        name = f"active ray scoring, {score} (8192-ray pool)"
        results[name] = float(np.median(durations[2:]))
        print(f"  {name}: {results[name] * 1e3:.1f} ms per iteration", flush=True)
    for score in ("surface", "grid"):
        shared = len(picked["rendered"] & picked[score]) / max(len(picked["rendered"]), 1)
        print(f"  top-500 rays {score} shares with rendered: {shared:.0%}", flush=True)
        results[f"active top rays shared by rendered and {score} scoring"] = shared
    return results


def run_neural(
    scene: Scene,
    renderer: RgbdRenderer,
    poses: np.ndarray,
    bounds: np.ndarray,
    args: Args,
    active: bool,
) -> tuple[NeuralMapper, dict[str, float]]:
    config = NeuralMapperConfig(
        device=args.device,
        backend=args.backend,
        seed=args.seed,
        active_sampling=active,
        active_score=args.active_score,
    )
    mapper = NeuralMapper(bounds, renderer.camera, config)
    render_seconds = 0.0
    start = time.perf_counter()
    cpu_start = time.process_time()  # CPU time of the process: compare runs at other loads
    for index in tqdm(range(len(poses)), desc="neural" + (" active" if active else "")):
        pixels = mapper.required_pixels(index)
        if len(pixels) == 0:
            continue
        t0 = time.perf_counter()
        rgb, depth = render_pixels(renderer, poses[index], pixels)
        render_seconds += time.perf_counter() - t0
        mapper.integrate_pixels(pixels, rgb, depth, poses[index], index)
    total = time.perf_counter() - start
    return mapper, {
        "total_s": total,
        "cpu_s": time.process_time() - cpu_start,
        "render_s": render_seconds,
        "mapping_s": total - render_seconds,
        "iterations": mapper.stats.iterations,
        "ms_per_iteration": mapper.stats.seconds_per_iteration * 1e3,
        "backend": mapper.backend,
        "keyframes": mapper.keyframes.num_keyframes,
    }


def run_tsdf(
    renderer: RgbdRenderer, poses: np.ndarray, bounds: np.ndarray, args: Args
) -> tuple[TsdfUncertaintyMapper, dict[str, float]]:
    mapper = TsdfUncertaintyMapper(bounds, renderer.camera, TsdfMapperConfig(device=args.device))
    render_seconds = 0.0
    start = time.perf_counter()
    for index in tqdm(range(len(poses)), desc="tsdf"):
        t0 = time.perf_counter()
        rgb, depth = renderer.render(poses[index])
        render_seconds += time.perf_counter() - t0
        mapper.integrate(rgb, depth, poses[index], index)
    total = time.perf_counter() - start
    return mapper, {
        "total_s": total,
        "render_s": render_seconds,
        "mapping_s": total - render_seconds,
        "ms_per_frame": (total - render_seconds) / len(poses) * 1e3,
    }


def main() -> None:
    args = parse_args()
    scene_dir = Path(args.scene_dir)
    if not (scene_dir / "mesh.ply").is_file():
        sys.exit(f"no mesh.ply in {scene_dir}; pass --scene-dir with the Replica sample")
    torch.set_num_threads(max(torch.get_num_threads(), 1))
    scene = load_scene(scene_dir / "mesh.ply", up_axis="z", name="replica_office0")
    if args.num_frames < 1:
        sys.exit(f"--num-frames must be at least 1, got {args.num_frames}")
    trajectory = Path(args.trajectory) if args.trajectory else scene_dir / "traj.txt"
    if not trajectory.is_file():
        sys.exit(f"trajectory {trajectory} not found; pass --trajectory with a poses file")
    poses = load_trajectory(trajectory)[: args.num_frames]
    camera = PinholeCamera()
    renderer = RgbdRenderer(scene, camera, max_depth_m=5.0)
    bounds = scene.bounds + np.array([[-1.0], [1.0]]) * args.bounds_padding_m
    torch_device = resolve_device(args.device)
    backend = resolve_backend(args.backend, torch_device)
    print(
        f"device: {torch_device}, backend: {backend}, torch threads: {torch.get_num_threads()}, "
        f"frames: {len(poses)}",
        flush=True,
    )

    results: dict[str, object] = {
        "args": dataclasses.asdict(args),
        "device": str(torch_device),
        "backend": backend,
        "gpu": torch.cuda.get_device_name(torch_device) if torch_device.type == "cuda" else None,
        "torch": torch.__version__,
        "machine": platform.processor() or platform.machine(),
        "cpu_threads": torch.get_num_threads(),
        "variants": {},
    }
    if args.speed_iterations > 0:
        print("speed of one mapping iteration (2048 + 100 rays):", flush=True)
        speed = time_iteration(scene, renderer, poses, bounds, args)
        plain = speed["plain per-level hash grid (published 43 samples)"]
        results["iteration_speed_s"] = speed
        results["speedup_vs_plain"] = {k: plain / v for k, v in speed.items()}
        results["active_scoring"] = time_active_scoring(renderer, poses, bounds, args)

    for variant in args.variants:
        if variant in ("neural", "neural_active"):
            mapper, timing = run_neural(
                scene, renderer, poses, bounds, args, active=variant == "neural_active"
            )
        elif variant == "tsdf":
            mapper, timing = run_tsdf(renderer, poses, bounds, args)
        else:
            sys.exit(f"unknown variant {variant!r}; use neural, neural_active, tsdf")
        start = time.perf_counter()
        mesh = mapper.extract_mesh(args.mesh_voxel_m)
        mesh_seconds = time.perf_counter() - start
        metrics = evaluate_reconstruction(
            mesh,
            scene,
            poses=poses,
            camera=camera,
            num_samples=args.eval_samples,
            seed=args.seed,
            renderer=renderer,
        )
        entry = {**timing, "mesh_s": mesh_seconds, "faces": len(mesh.faces), **metrics.as_dict()}
        results["variants"][variant] = entry
        print(f"{variant}: {json.dumps(entry, default=str)}", flush=True)
        out_dir = Path(args.output_file).parent
        out_dir.mkdir(parents=True, exist_ok=True)
        Path(args.output_file).write_text(json.dumps(results, indent=2, default=str))

    print_table(results)
    Path(args.output_file).write_text(json.dumps(results, indent=2, default=str))
    print(f"results written to {args.output_file}")


def print_table(results: dict) -> None:
    print()
    print(
        "| mapper | accuracy (cm) | completion (cm) | completion ratio (%) "
        "| ms / iteration | total (s) |"
    )
    print("|---|---|---|---|---|---|")
    for name, entry in results["variants"].items():
        per = entry.get("ms_per_iteration", entry.get("ms_per_frame"))
        unit = "" if "ms_per_iteration" in entry else " (per frame)"
        print(
            f"| {name} | {entry['accuracy_cm']:.2f} | {entry['completion_cm']:.2f} | "
            f"{entry['completion_ratio_pct']:.2f} | {per:.0f}{unit} | {entry['total_s']:.0f} |"
        )
    print(
        f"| published passive Co-SLAM (full mesh) | 1.50 | 1.48 | "
        f"{PUBLISHED_COMPLETION_RATIO:.2f} | ~30 (V100) | |"
    )
    if "iteration_speed_s" in results:
        print()
        print("| hash grid | ms per iteration (2048 + 100 rays) | speed-up vs plain |")
        print("|---|---|---|")
        for name, seconds in results["iteration_speed_s"].items():
            print(f"| {name} | {seconds * 1e3:.1f} | {results['speedup_vs_plain'][name]:.2f}x |")
    if results.get("active_scoring"):
        print()
        for name, value in results["active_scoring"].items():
            shown = f"{value:.0%}" if "shared" in name else f"{value * 1e3:.0f} ms"
            print(f"{name}: {shown}")


if __name__ == "__main__":
    main()
