"""Speed of the reconstruction metrics and of culling. Results: docs/benchmarks/metrics.md

Times accuracy / completion / ratio / F-score of a 200k-sample pair beside a bare
``scipy.spatial.cKDTree`` build + query of the same points in the same run.

Goal: the metrics of a 200,000 vs 200,000 sample pair in under 2 s on the
2-core CI machine. Also times surface sampling, the whole mesh-to-mesh call and culling of a
reconstruction by a trajectory, which an episode's scoring pays too.

Culling is timed against the straightforward per-pose loop
(``visible_vertex_mask_reference``) on the same reconstruction and poses, with the masks
checked equal: by default the Replica sample's 2000-pose trajectory and a TSDF map of it; with
``--cull-scene NAME`` a frontier episode recorded on a catalogue scene (``--cull-steps``
steps, 170 x 300 frames as in the benchmark harness; recorded once into ``outputs/culling/``),
whose checkpoint maps are also culled in turn with and without a ``CullingCache``.

    python benchmarks/metrics_speed.py
    python benchmarks/metrics_speed.py --samples 200000 --repeats 5
    python benchmarks/metrics_speed.py --culling-only --cull-scene apartment --cull-steps 2000
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from naruto_agent.cli_args import parse_dataclass_args
from naruto_gym.evaluation import (
    CullingCache,
    TsdfFusionMapper,
    reconstruction_metrics,
    sample_mesh_surface,
    visible_vertex_mask,
)
from naruto_gym.evaluation.culling import visible_vertex_mask_reference
from naruto_gym.scenes.mesh_scene import load_scene
from naruto_gym.sensors.pinhole import PinholeCamera, RgbdRenderer

REPO = Path(__file__).resolve().parents[1]
REPLICA = REPO.parent / "shared" / "scenes" / "replica_office0"
GOAL_S = 2.0


@dataclass
class Args:
    samples: int = 200_000
    """surface samples per mesh (200,000 as published)"""
    repeats: int = 5
    """timed repetitions of each measurement"""
    cull_poses: int = 2000
    """Replica trajectory poses for the culling timing (every 2nd is used)"""
    cull_scene: str = ""
    """catalogue scene of a recorded frontier episode to cull instead of the Replica sample"""
    cull_steps: int = 2000
    """steps of that episode"""
    culling_only: bool = False
    """time only the culling (written to benchmarks/results/culling_speed_<scene>.json)"""
    output_file: str = "benchmarks/results/metrics_speed.json"
    """the JSON report"""


def parse_args() -> Args:
    return parse_dataclass_args(Args, description=__doc__.splitlines()[0])


def median_s(function: Callable[[], object], repeats: int) -> float:
    function()  # warm-up (thread pools, page faults)
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        function()
        times.append(time.perf_counter() - started)
    return float(np.median(times))


def replica_reconstruction(scene, poses: np.ndarray, camera: PinholeCamera):
    """A realistic reconstruction to score: TSDF fusion of every 20th frame of the real
    trajectory (nearly complete, as at the end of an episode; a partial one is slower to
    score, as ground-truth points far from it search longer)."""
    renderer = RgbdRenderer(scene, camera)
    mapper = TsdfFusionMapper(device="cpu")
    for pose in poses[::20]:
        mapper.integrate(*renderer.render(pose), pose, camera)
    return mapper.extract_mesh()


def record_episode(scene_name: str, steps: int, seed: int = 0) -> dict[str, np.ndarray]:
    """A frontier episode with the harness's settings: its poses and the reference TSDF map at
    the harness's checkpoints (``mesh_<step>`` vertices and faces), recorded once."""
    from naruto_agent.benchmark.runner import make_env
    from naruto_agent.benchmark.spec import EpisodeSpec
    from naruto_agent.episode_loop import EvalPoints, FrameFusion, run_episode_loop
    from naruto_agent.policies import make_policy
    from naruto_gym.evaluation import EpisodeReconstruction

    path = REPO / "outputs" / "culling" / f"{scene_name}_frontier_{steps}_seed{seed}.npz"
    if path.exists():
        return dict(np.load(path))
    spec = EpisodeSpec(scene=scene_name, policy="frontier", seed=seed, steps=steps)
    policy = make_policy(spec.policy)
    env = make_env(spec, policy.preferred_action_mode)
    reconstruction = EpisodeReconstruction(env.unwrapped.camera, device="cpu")
    record: dict[str, np.ndarray] = {}

    def keep_mesh(step: int, last: bool) -> None:
        mesh = reconstruction.mesh()
        record[f"vertices_{step}"] = np.asarray(mesh.vertices)
        record[f"faces_{step}"] = np.asarray(mesh.faces)

    hooks = [FrameFusion(reconstruction), EvalPoints(steps, spec.eval_points, keep_mesh, True)]
    run_episode_loop(env, policy, steps, seed, hooks)
    record["poses"] = reconstruction.poses
    record["camera"] = np.array(list(env.unwrapped.camera.as_dict().values()))
    env.close()
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, **record)
    return record


def culling_report(args: Args) -> dict:
    """The fast culling against the per-pose loop on one reconstruction (same run, same
    masks), and for a recorded episode its checkpoints culled with and without a cache."""
    camera = PinholeCamera().scaled(0.25)  # the harness's 170 x 300 frames
    checkpoints: list[tuple[int, np.ndarray]] = []
    if args.cull_scene:
        from naruto_gym.scenes import load_catalogue_scene

        scene = load_catalogue_scene(args.cull_scene)
        record = record_episode(args.cull_scene, args.cull_steps)
        width, height, fx, fy, cx, cy = record["camera"]
        camera = PinholeCamera(int(width), int(height), fx, fy, cx, cy)
        steps = sorted(int(key.split("_")[1]) for key in record if key.startswith("vertices_"))
        checkpoints = [(step, record[f"vertices_{step}"]) for step in steps]
        poses, vertices = record["poses"], checkpoints[-1][1]
        label = f"{args.cull_scene}_frontier_{args.cull_steps}"
    else:
        scene = load_scene(REPLICA / "mesh.ply")
        poses = np.loadtxt(REPLICA / "traj.txt").reshape(-1, 4, 4)[: args.cull_poses]
        vertices = np.asarray(replica_reconstruction(scene, poses, camera).vertices)
        label = f"replica_office0_{len(poses)}"
    renderer = RgbdRenderer(scene, camera)
    load_at_start = os.getloadavg()[0]
    mask = visible_vertex_mask(vertices, poses, camera, renderer)  # also compiles the kernels
    fast_s = median_s(lambda: visible_vertex_mask(vertices, poses, camera, renderer), 2)
    started = time.perf_counter()
    reference = visible_vertex_mask_reference(vertices, poses, camera, renderer)
    reference_s = time.perf_counter() - started
    report = {
        "load_average_1min_at_start": load_at_start,
        "load_average_1min_at_end": os.getloadavg()[0],
        "trajectory": label,
        "poses": len(poses),
        "used_poses": len(poses[::2]),
        "vertices": len(vertices),
        "visible_vertices": int(mask.sum()),
        "cull_s": fast_s,
        "cull_reference_loop_s": reference_s,
        "cull_reference_over_fast": reference_s / fast_s,
        "cull_masks_equal": bool(np.array_equal(mask, reference)),
    }
    print(
        f"culling {len(vertices):,} vertices by {len(poses)} poses of {label} (every 2nd): "
        f"{fast_s:.2f} s, per-pose loop {reference_s:.1f} s "
        f"({report['cull_reference_over_fast']:.0f}x), masks equal: {report['cull_masks_equal']}"
    )
    if checkpoints:
        cache = CullingCache()
        plain_s = cached_s = 0.0
        for step, step_vertices in checkpoints:
            step_poses = poses[: step + 1]
            started = time.perf_counter()
            plain = visible_vertex_mask(step_vertices, step_poses, camera, renderer)
            plain_s += time.perf_counter() - started
            started = time.perf_counter()
            cached = visible_vertex_mask(step_vertices, step_poses, camera, renderer, cache=cache)
            cached_s += time.perf_counter() - started
            if not np.array_equal(plain, cached):
                raise RuntimeError(f"the cached culling differs at step {step}")
        report.update(
            load_average_1min_after_checkpoints=os.getloadavg()[0],
            checkpoints=[step for step, _ in checkpoints],
            cull_checkpoints_s=plain_s,
            cull_checkpoints_cached_s=cached_s,
            cull_checkpoints_plain_over_cached=plain_s / cached_s,
        )
        print(
            f"culling the {len(checkpoints)} checkpoint maps in turn: {plain_s:.2f} s, with a "
            f"CullingCache {cached_s:.2f} s ({plain_s / cached_s:.2f}x), masks equal"
        )
    return report


def main() -> None:
    args = parse_args()
    if not REPLICA.is_dir() and not (args.culling_only and args.cull_scene):
        raise SystemExit(f"{REPLICA} not found: this benchmark needs ../shared/scenes")
    if args.culling_only:
        report = {"args": asdict(args), **culling_report(args)}
        out = REPO / "benchmarks" / "results" / f"culling_speed_{args.cull_scene or 'replica'}.json"
        out.write_text(json.dumps(report, indent=2))
        print(f"saved {out.relative_to(REPO)}")
        return
    scene = load_scene(REPLICA / "mesh.ply")
    poses = np.loadtxt(REPLICA / "traj.txt").reshape(-1, 4, 4)
    recon = replica_reconstruction(scene, poses, PinholeCamera().scaled(0.25))

    recon_points = sample_mesh_surface(recon.vertices, recon.faces, args.samples, seed=1)
    gt_points = sample_mesh_surface(scene.vertices, scene.faces, args.samples, seed=2)

    def bare_kdtree() -> None:
        # The irreducible work: two trees, two nearest-neighbour queries.
        cKDTree(gt_points).query(recon_points, workers=-1)
        cKDTree(recon_points).query(gt_points, workers=-1)
        # (default scipy settings; the metrics use an unbalanced tree)

    results = {
        "bare_kdtree_pair_s": median_s(bare_kdtree, args.repeats),
        "metrics_on_points_s": median_s(
            lambda: reconstruction_metrics(recon_points, gt_points), args.repeats
        ),
        "sampling_200k_s": median_s(
            lambda: sample_mesh_surface(scene.vertices, scene.faces, args.samples), args.repeats
        ),
        "metrics_mesh_to_mesh_s": median_s(
            lambda: reconstruction_metrics(recon, scene, num_samples=args.samples), args.repeats
        ),
    }
    ratio = results["metrics_on_points_s"] / results["bare_kdtree_pair_s"]
    report = {
        "args": asdict(args),
        "recon_faces": len(recon.faces),
        "gt_faces": len(scene.faces),
        **results,
        "metrics_over_bare_kdtree": ratio,
        "goal_s": GOAL_S,
        "meets_goal": results["metrics_mesh_to_mesh_s"] < GOAL_S,
    }
    print(f"samples per surface        : {args.samples:,}")
    print(f"bare cKDTree pair          : {results['bare_kdtree_pair_s']:.3f} s (reference)")
    print(f"metrics on points          : {results['metrics_on_points_s']:.3f} s ({ratio:.2f}x)")
    print(f"surface sampling (one mesh): {results['sampling_200k_s']:.3f} s")
    print(
        f"metrics mesh to mesh       : {results['metrics_mesh_to_mesh_s']:.3f} s "
        f"(goal < {GOAL_S} s: {'met' if report['meets_goal'] else 'MISSED'})"
    )
    report.update(culling_report(args))
    out = REPO / args.output_file
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=2))
    print(f"saved {out.relative_to(REPO)}")


if __name__ == "__main__":
    main()
