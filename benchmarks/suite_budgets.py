"""Coverage curves and episode costs of the scene suite's size classes: what its budgets rest on.

For a few test scenes per size class, runs every policy for a number of steps with the
harness's default settings (``naruto-benchmark``: image scale 0.25, the reference TSDF map,
4 checkpoints, 200 000 final samples) one episode at a time in this process, and reports per
class and policy the coverage reached at fractions of the run, the gain over its last quarter
(a curve still rising at the end has not saturated), and the CPU seconds of an episode
(process time of all threads, so a busy machine inflates it less than wall time). From those
it estimates the CPU minutes of the full test split at the suite's budgets. Results:
docs/scenes.md (the suite section). Example::

    PYTHONPATH=. python benchmarks/suite_budgets.py --classes small --seeds 1000000 \\
        --policies random frontier --max-episode-steps 600 --output-file /tmp/suite_budgets.json
"""

from __future__ import annotations

import json
import resource
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from naruto_agent.benchmark.runner import run_episode
from naruto_agent.benchmark.spec import build_specs
from naruto_agent.cli_args import dataclass_parser
from naruto_gym.scenes import suite


@dataclass
class Args:
    """Arguments of the measurement (each field is a ``--flag``)."""

    classes: list[str] = field(default_factory=lambda: list(suite.SIZE_CLASSES))
    """size classes to measure"""
    seeds: list[int] = field(default_factory=lambda: [1_000_000])
    """scene seeds of each class (suite test seeds by default)"""
    policies: list[str] = field(default_factory=lambda: ["passive", "random", "frontier",
                                                         "naruto"])
    """policies to run"""
    max_episode_steps: int = 0
    """steps per episode; 0: 1.5 x the class's suite budget, to see past it"""
    episode_seed: int = 0
    """episode seed"""
    image_scale: float = 0.25
    """camera resolution factor (the harness's default)"""
    eval_points: int = 4
    """completion checkpoints per episode (the harness's default)"""
    reconstruct: bool = True
    """fuse and score the reference TSDF map as the harness does (off: coverage curves and
    the policy's and env's own cost only)"""
    output_file: str = "suite_budgets.json"
    """JSON file of the results (updated after every episode)"""


def cpu_seconds() -> float:
    """User + system CPU seconds of this process and its threads so far."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def summarise(record: dict[str, Any], budget: int) -> dict[str, Any]:
    """Coverage at fractions of the budget, gain over its last quarter, episode costs."""
    curve = np.asarray(record["coverage_curve"], np.float64)
    at = {f"{fraction:g}": round(100 * float(curve[min(len(curve) - 1, int(fraction * budget))]),
                                 2) for fraction in (0.25, 0.5, 0.75, 1.0, 1.5)}
    end = min(len(curve) - 1, budget)
    gain = 100 * float(curve[end] - curve[int(0.75 * end)])
    completion = [(p["step"], round(p["completion_ratio_pct"], 2))
                  for p in record["completion_curve"]]
    return {"coverage_pct_at_budget_fraction": at, "last_quarter_gain_pp": round(gain, 2),
            "completion_curve": completion, "steps_run": record["steps_run"],
            "path_length_m": round(record["path_length_m"], 2),
            "evaluation_s": round(record["evaluation_s"], 1)}


def main(argv: list[str] | None = None) -> int:
    """Run the measurement; returns 0."""
    parser = dataclass_parser(Args, description="Coverage curves and costs of the suite.",
                              prog="suite_budgets.py")
    args = Args(**vars(parser.parse_args(argv)))
    out = Path(args.output_file)
    results: list[dict[str, Any]] = json.loads(out.read_text()) if out.is_file() else []
    done = {(r["scene"], r["policy"], r["steps"], r["reconstruct"]) for r in results}
    for size_class in args.classes:
        budget = suite.budget(size_class)
        steps = args.max_episode_steps or int(1.5 * budget)
        for seed in args.seeds:
            scene = suite.scene_name(size_class, seed)
            for spec in build_specs([scene], args.policies, [args.episode_seed], steps,
                                    image_scale=args.image_scale, eval_points=args.eval_points,
                                    reconstruct=args.reconstruct):
                if (scene, spec.policy, steps, args.reconstruct) in done:
                    continue
                cpu, wall = cpu_seconds(), time.perf_counter()
                record = run_episode(spec)
                row = {"scene": scene, "size_class": size_class, "policy": spec.policy,
                       "steps": steps, "budget": budget, "reconstruct": args.reconstruct,
                       "time_per_step_ms": record["time_per_step_ms"],
                       "cpu_s": round(cpu_seconds() - cpu, 1),
                       "wall_s": round(time.perf_counter() - wall, 1),
                       "coverage_curve": record["coverage_curve"][::10],
                       **summarise(record, budget)}
                results.append(row)
                out.write_text(json.dumps(results, indent=1))
                print(json.dumps({k: v for k, v in row.items() if k != "coverage_curve"}),
                      flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
