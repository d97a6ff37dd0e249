"""New procedural scenes: cost at reset, memory. Results: docs/benchmarks/throughput.md

What a new per-episode procedural scene costs at reset, and memory over a long run.

1. Cost of one new scene, per kind (room, apartment) and coverage sample count: generating the
   mesh, and building what the env needs of it (ray-casting structure, coverage samples, the
   observable surface, a start pose), median over ``seeds`` seeds. The reference in the same
   run: the observable-surface mask of the same samples from the same viewpoints by the
   per-viewpoint loop (``visible_from_any_per_viewpoint``, one ray per pending point and
   viewpoint, what the env used before) against the env's ``visible_from_any``; the masks
   must agree.
2. Resident memory over ``steps`` steps of a ``NarutoReconVectorEnv`` on
   ``"procedural:room"`` whose episodes last ``episode_steps`` steps, so every reset draws a
   new scene; memory is sampled every ``sample_every`` steps and plotted.

    flock /tmp/naruto_timing.lock python benchmarks/procedural_scenes.py
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from naruto_agent.cli_args import parse_dataclass_args
from naruto_gym.envs.naruto_recon_env import NarutoReconEnv
from naruto_gym.observability import visible_from_any, visible_from_any_per_viewpoint
from naruto_gym.scenes.procedural import make_random_scene
from naruto_gym.scenes.stream import SPLIT_SEEDS
from naruto_gym.sensors.pinhole import PinholeCamera
from naruto_gym.vector import NarutoReconVectorEnv

CAMERA = PinholeCamera(64, 64, 32, 32, 31.5, 31.5)


@dataclass
class Args:
    seeds: int = 5
    """scenes timed per kind and sample count"""
    total_steps: int = 10_000
    """steps of the memory run"""
    max_episode_steps: int = 50
    """episode length of the memory run (a new scene at every reset)"""
    coverage_samples: int = 20_000
    """coverage samples of the memory run (the env's default)"""
    sample_every: int = 250
    """steps between memory samples"""
    output_file: str = "benchmarks/results/procedural_scenes.json"
    """where the JSON (and the PNG beside it) go"""


def resident_mib() -> float:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def scene_costs(kind: str, samples: int, seeds: int) -> dict[str, Any]:
    generate, build, mask, reference_mask = [], [], [], []
    low = SPLIT_SEEDS["train"][0]
    for seed in range(low + 100, low + 100 + seeds):
        started = time.perf_counter()
        scene = make_random_scene(seed, kind)  # type: ignore[arg-type]
        generated = time.perf_counter()
        env = NarutoReconEnv(scene=scene, action_mode="discrete", camera=CAMERA,
                             panorama_shape=None, coverage_samples=samples)
        env.coverage  # noqa: B018 - builds the samples and the observable surface
        env.reset(seed=0)
        generate.append(generated - started)
        build.append(time.perf_counter() - generated)
        # The mask step alone, by both implementations, on the same samples and viewpoints.
        points = scene.sample_surface(samples, seed=0)
        viewpoints = env.observable_surface.viewpoints
        started = time.perf_counter()
        new = visible_from_any(env.raycaster, points, viewpoints)
        mask.append(time.perf_counter() - started)
        started = time.perf_counter()
        old = visible_from_any_per_viewpoint(env.raycaster, points, viewpoints)
        reference_mask.append(time.perf_counter() - started)
        if not np.array_equal(new, old):
            raise RuntimeError(f"observable masks differ on {kind} seed {seed}")
    total = np.add(generate, build)
    return {
        "kind": kind, "coverage_samples": samples,
        "generate_s": float(np.median(generate)), "build_s": float(np.median(build)),
        "total_s": float(np.median(total)), "max_total_s": float(np.max(total)),
        "mask_s": float(np.median(mask)),
        "reference_mask_s": float(np.median(reference_mask)),
        "mask_speedup": float(np.median(np.divide(reference_mask, mask))),
        # The build as it was with the per-viewpoint loop: this run's build, its mask swapped.
        "reference_total_s": float(np.median(total - np.array(mask) + reference_mask)),
        "load": [round(v, 2) for v in os.getloadavg()],
    }


def memory_run(args: Args) -> dict[str, Any]:
    from tqdm.auto import tqdm

    env = NarutoReconVectorEnv(
        1, scene="procedural:room", max_episode_steps=args.max_episode_steps,
        action_mode="discrete",
        camera=CAMERA, panorama_shape=None, coverage_samples=args.coverage_samples,
        pinhole_backend="auto",
    )
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    names, steps, memory = set(), [], []
    started = time.perf_counter()
    for step in tqdm(range(1, args.total_steps + 1), desc="steps, new scene every reset"):
        env.step(rng.integers(0, 10, 1))
        names.add(env.scene_runtimes[0].scene.name)
        if step % args.sample_every == 0:
            steps.append(step)
            memory.append(resident_mib())
    elapsed = time.perf_counter() - started
    return {
        "steps": steps, "resident_mib": memory, "scenes": len(names), "seconds": elapsed,
        "growth_after_first_quarter_mib": memory[-1] - memory[len(memory) // 4],
        "load": [round(v, 2) for v in os.getloadavg()],
    }


def main(args: Args) -> dict[str, Any]:
    results: dict[str, Any] = {"args": asdict(args), "load_start": os.getloadavg()}
    print(f"load average at start: {results['load_start']}")
    # One scene first, untimed: the compiled loops load once per process.
    scene_costs("room", 1000, 1)
    results["scene_costs"] = []
    for kind in ("room", "apartment"):
        for samples in (20_000, 5000):
            row = scene_costs(kind, samples, args.seeds)
            results["scene_costs"].append(row)
            print(f"new {kind:9s} scene, {samples:5d} coverage samples: generate "
                  f"{row['generate_s']:.3f} s + build {row['build_s']:.3f} s = "
                  f"{row['total_s']:.3f} s median, {row['max_total_s']:.3f} s max; "
                  f"observable mask {row['mask_s']:.3f} s vs {row['reference_mask_s']:.3f} s "
                  f"per viewpoint ({row['mask_speedup']:.1f}x), so {row['reference_total_s']:.3f} "
                  f"s with the per-viewpoint loop (load {row['load']})")
    run = memory_run(args)
    results["memory"] = run
    print(f"{args.total_steps} steps, {run['scenes']} scenes in {run['seconds']:.0f} s: resident "
          f"{run['resident_mib'][0]:.0f} -> {run['resident_mib'][-1]:.0f} MiB, growth after the "
          f"first quarter {run['growth_after_first_quarter_mib']:.1f} MiB (load {run['load']})")
    path = Path(args.output_file)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(results, indent=1))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(6, 3.5))
    axis.plot(run["steps"], run["resident_mib"])
    axis.set_xlabel("step (a new generated room every reset)")
    axis.set_ylabel("resident memory (MiB)")
    axis.set_ylim(bottom=0)
    axis.set_title(f"procedural:room, episodes of {args.max_episode_steps} steps")
    figure.tight_layout()
    figure.savefig(path.with_suffix(".png"), dpi=120)
    print(f"wrote {path} and {path.with_suffix('.png')}")
    return results


if __name__ == "__main__":
    main(parse_dataclass_args(Args))
