"""One prepared check of the neural mapper's fast GPU path, for a machine with one GPU.

Runs, each part as a subprocess under its own time limit (a part that fails or runs out of
time is reported and the next one runs), then prints a summary:

1. **tests**: the mapping tests that exercise CUDA: the Triton kernels compiled on the GPU
   against the PyTorch reference (values and gradients), the fixed-shape rendering, the
   backend selection;
2. **iteration**: one mapping iteration (2048 + 100 rays x 43 samples) with the PyTorch
   reference, the plain per-level hash grid and the fast path
   (``benchmarks/mapping_quality.py``'s speed test, no mapping run);
3. **episodes**: a shortened neural NARUTO episode on the Replica sample at full resolution
   (``benchmarks/naruto_episode.py``, rasterised frames), with the fast path and then with
   the reference path, each with its per-phase table and mesh metrics.

On one H100 or H200 with 16 cores the defaults should take five to seven minutes (an
estimate: the script has not run on a GPU yet; each part's limit caps it at about 10). The JSON
records and the logs go to ``--output-dir`` (``$OUT`` when set, so a lent machine returns them).

Usage::

    python benchmarks/gpu_check.py                       # everything, 250-step episodes
    python benchmarks/gpu_check.py --max-episode-steps 400 --parts iteration episodes
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from naruto_agent.cli_args import parse_dataclass_args

REPO_ROOT = Path(__file__).resolve().parents[1]
PARTS = ("tests", "iteration", "episodes")
TESTS = (
    "tests/agent/mapping/test_mapping_triton.py",
    "tests/agent/mapping/test_mapping_fixed_shape.py",
    "tests/agent/mapping/test_mapping_backends.py",
    "tests/agent/mapping/test_mapping_encoding.py",
    "tests/agent/mapping/test_mapping_cuda_graphs.py",
)


@dataclass
class Args:
    """Check settings."""

    parts: list[str] = field(default_factory=lambda: list(PARTS))
    """which parts to run: tests, iteration, episodes"""
    scene_dir: str = str(REPO_ROOT.parent / "shared" / "scenes" / "replica_office0")
    """folder with the Replica sample's mesh.ply and traj.txt"""
    max_episode_steps: int = 250
    """step budget of each episode"""
    speed_iterations: int = 20
    """timed mapping iterations per variant"""
    reference_episode: bool = True
    """also run the episode with the PyTorch reference path (backend torch)"""
    reference_steps: int = 0
    """step budget of the reference path's episode (0: ``max_episode_steps``)"""
    output_dir: str = (
        os.environ.get("OUT") or str(REPO_ROOT / "benchmarks" / "results" / "gpu_check")
    )
    """where the JSON records and logs go"""
    tests_limit_s: int = 150
    """time limit of the tests"""
    iteration_limit_s: int = 100
    """time limit of the iteration timing"""
    episode_limit_s: int = 140
    """time limit of each episode"""


def run_part(name: str, command: list[str], limit_s: int, out_dir: Path) -> dict:
    """Run one part, stream its output into a log, return its status and duration."""
    log = out_dir / f"{name}.log"
    print(f"\n=== {name}: {' '.join(command)} (limit {limit_s} s)", flush=True)
    start = time.perf_counter()
    # The repository first, then whatever the caller's PYTHONPATH holds (carried packages).
    paths = [str(REPO_ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(paths)}
    env.pop("TRITON_INTERPRET", None)  # the compiled kernels, not the interpreter
    with log.open("w") as handle:
        # Its own process group, so that a part out of time is stopped with its children.
        process = subprocess.Popen(
            command, cwd=REPO_ROOT, env=env, stdout=handle, stderr=subprocess.STDOUT,
            start_new_session=True,
        )  # fmt: skip
        try:
            code = process.wait(timeout=limit_s)
            status = "ok" if code == 0 else f"failed (exit {code})"
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
            status = f"out of time ({limit_s} s)"
    seconds = time.perf_counter() - start
    tail = log.read_text(errors="replace").splitlines()[-25:]
    print("\n".join(tail), flush=True)
    print(f"=== {name}: {status} in {seconds:.0f} s", flush=True)
    return {"status": status, "seconds": seconds, "log": str(log)}


def environment() -> dict:
    """What the figures were taken on."""
    import open3d
    import torch

    info = {
        "torch": torch.__version__,
        "cuda": torch.version.cuda,
        "gpu": torch.cuda.get_device_name() if torch.cuda.is_available() else None,
        "cpu_cores": os.cpu_count(),
        "open3d": open3d.__version__,
        "open3d_cuda": bool(open3d.core.cuda.is_available()),
    }
    try:
        import triton

        info["triton"] = triton.__version__
    except ImportError:
        info["triton"] = None
    return info


def episode_command(args: Args, backend: str, out_dir: Path) -> list[str]:
    steps = args.max_episode_steps
    if backend == "torch" and args.reference_steps:
        steps = args.reference_steps
    return [
        sys.executable, "benchmarks/naruto_episode.py",
        "--scene", str(Path(args.scene_dir) / "mesh.ply"),
        "--mapper-kind", "neural", "--device", "cuda", "--backend", backend,
        "--image-scale", "1.0", "--max-episode-steps", str(steps),
        "--env-kwargs", '{"pinhole_backend": "raster"}',
        "--target-snapshots", "0", "--checkpoint-every", "100",
        "--output-dir", str(out_dir), "--tag", f"gpu_check_{backend}",
    ]  # fmt: skip


def summary(out_dir: Path, args: Args) -> list[str]:
    """Lines of the summary from the parts' JSON records (those that finished)."""
    lines: list[str] = []
    speed_path = out_dir / "mapping_iteration.json"
    if speed_path.is_file():
        speed = json.loads(speed_path.read_text()).get("iteration_speed_s", {})
        lines.append("| mapping iteration (2048 + 100 rays) | ms |")
        lines.append("|---|---|")
        lines += [f"| {name} | {seconds * 1e3:.2f} |" for name, seconds in speed.items()]
    records = {}
    for backend in ("triton", "torch"):
        path = out_dir / f"naruto_episode_gpu_check_{backend}.json"
        if path.is_file():
            records[backend] = json.loads(path.read_text())
    if records:
        names = sorted({n for r in records.values() for n in r.get("phases_ms_per_step", {})})
        lines.append("")
        steps = " / ".join(str(r.get("steps_run")) for r in records.values())
        lines.append(f"| phase (ms per step, {steps} steps) | " + " | ".join(records) + " |")
        lines.append("|---|" + "---|" * len(records))
        for name in names:
            values = [f"{r['phases_ms_per_step'].get(name, 0.0):.1f}" for r in records.values()]
            lines.append(f"| {name} | " + " | ".join(values) + " |")
        walls = [
            f"{1e3 * r['episode_s'] / max(r['steps_run'], 1):.1f}" for r in records.values()
        ]
        lines.append("| **episode wall time** | " + " | ".join(walls) + " |")
        for backend, record in records.items():
            for label, key in (("reference TSDF", "reference_tsdf_metrics"),
                               ("own mesh", "agent_mesh_metrics")):  # fmt: skip
                metrics = record.get(key, {})
                lines.append(
                    f"{backend} {label}: completion ratio "
                    f"{metrics.get('completion_ratio_pct', float('nan')):.2f} %, accuracy "
                    f"{metrics.get('accuracy_cm', float('nan')):.2f} cm, completion "
                    f"{metrics.get('completion_cm', float('nan')):.2f} cm, MAD "
                    f"{metrics.get('mad_cm') or float('nan'):.2f} cm"
                )
    return lines


def main() -> None:
    args = parse_dataclass_args(Args, description=__doc__.split("\n")[0])
    unknown = set(args.parts) - set(PARTS)
    if unknown:
        sys.exit(f"unknown parts {sorted(unknown)}; choose from {PARTS}")
    out_dir = Path(args.output_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    info = environment()
    print(json.dumps(info), flush=True)
    if info["gpu"] is None:
        print("warning: no CUDA device; the fast path is not exercised", flush=True)
    if "episodes" in args.parts or "iteration" in args.parts:
        if not (Path(args.scene_dir) / "mesh.ply").is_file():
            sys.exit(f"no mesh.ply in {args.scene_dir}; pass --scene-dir with the Replica sample")
    status = {"environment": info}
    started = time.perf_counter()
    if "tests" in args.parts:
        command = [sys.executable, "-m", "pytest", "-q", "-rs", *TESTS]
        status["tests"] = run_part("tests", command, args.tests_limit_s, out_dir)
    if "iteration" in args.parts:
        command = [
            sys.executable, "benchmarks/mapping_quality.py", "--scene-dir", args.scene_dir,
            "--num-frames", "1", "--variants", "--device", "cuda",
            "--speed-iterations", str(args.speed_iterations),
            "--output-file", str(out_dir / "mapping_iteration.json"),
        ]  # fmt: skip
        status["iteration"] = run_part("iteration", command, args.iteration_limit_s, out_dir)
    if "episodes" in args.parts:
        backends = ["triton", "torch"] if args.reference_episode else ["triton"]
        for backend in backends:
            status[f"episode_{backend}"] = run_part(
                f"episode_{backend}",
                episode_command(args, backend, out_dir),
                args.episode_limit_s,
                out_dir,
            )
    status["seconds"] = time.perf_counter() - started
    (out_dir / "gpu_check.json").write_text(json.dumps(status, indent=2))
    print("\n=== summary")
    for name, part in status.items():
        if isinstance(part, dict) and "status" in part:
            print(f"{name}: {part['status']} in {part['seconds']:.0f} s")
    print("\n".join(summary(out_dir, args)))
    print(f"\nrecords and logs in {out_dir}")


if __name__ == "__main__":
    main()
