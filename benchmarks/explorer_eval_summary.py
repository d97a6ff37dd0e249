"""Coverage summary of a ``naruto-benchmark --no-reconstruct`` run of the explorer against
other policies. Results: docs/benchmarks/explorer.md

Reads the episode records of ``input_dir`` (the benchmark's ``--output-dir``) and writes
``output_dir/output_name``: per policy and scene, the mean final coverage and the area
under the coverage curve (the mean coverage over the episode's steps, as
``benchmarks/explorer_scripted_check.py`` computes it) over the seeds, refused moves per 100
steps, and the paired difference of the areas of ``--policy`` and every other policy over the
(scene, seed) pairs both ran, with the leaderboard's 95 % bootstrap interval (scenes
resampled, then seeds inside each scene). ``--scene-prefix`` keeps one size class.

    python benchmarks/explorer_eval_summary.py --input-dir runs/explorer_eval \\
        --output-dir benchmarks/results/explorer_candidates
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from naruto_agent.benchmark.efficiency import mean_over_steps
from naruto_agent.benchmark.statistics import paired_comparison
from naruto_agent.cli_args import parse_dataclass_args


@dataclass
class Args:
    input_dir: str = "runs/explorer_eval"
    """the benchmark's output folder (its records/ are read)"""
    policy: str = "explorer"
    """the policy compared with every other"""
    bootstrap: int = 10_000
    """bootstrap resamples of the paired differences"""
    scene_prefix: str = ""
    """only the scenes whose name starts with this (e.g. procedural_flat: the apartments)"""
    output_dir: str = "benchmarks/results/explorer_candidates"
    """output folder"""
    output_name: str = "evaluation.json"
    """file written in output_dir"""


def main(args: Args) -> dict[str, Any]:
    episodes: dict[tuple[str, str, int], dict[str, float]] = {}
    for path in sorted(Path(args.input_dir, "records").glob("*/*/seed*.json")):
        record = json.loads(path.read_text())
        if record.get("status") != "ok" or not record["scene"].startswith(args.scene_prefix):
            continue
        steps = int(record["config"]["steps"])
        episodes[(record["policy"], record["scene"], int(record["seed"]))] = {
            "final": float(record["coverage_final"]),
            "auc": mean_over_steps(record["coverage_curve"], steps),
            "refusals_per_100_steps": 100 * record["collisions"] / max(record["steps_run"], 1),
        }
    policies = sorted({p for p, _, _ in episodes})
    scenes = sorted({s for _, s, _ in episodes})
    table: dict[str, Any] = {}
    for policy in policies:
        rows = {}
        for scene in scenes:
            runs = [v for (p, s, _), v in episodes.items() if p == policy and s == scene]
            if runs:
                rows[scene] = {
                    key: round(float(np.mean([r[key] for r in runs])), 4)
                    for key in ("final", "auc", "refusals_per_100_steps")
                } | {"seeds": len(runs)}
        every = [v for (p, _, _), v in episodes.items() if p == policy]
        table[policy] = {
            "scenes": rows,
            "mean_auc": round(float(np.mean([r["auc"] for r in every])), 4),
            "mean_final": round(float(np.mean([r["final"] for r in every])), 4),
            "refusals_per_100_steps": round(
                float(np.mean([r["refusals_per_100_steps"] for r in every])), 3
            ),
            "episodes": len(every),
        }
    paired: dict[str, Any] = {}
    mine = {(s, seed): v["auc"] for (p, s, seed), v in episodes.items() if p == args.policy}
    for other in policies:
        if other == args.policy:
            continue
        theirs = {(s, seed): v["auc"] for (p, s, seed), v in episodes.items() if p == other}
        overall = paired_comparison(mine, theirs, resamples=args.bootstrap)["overall"]
        if not overall["n"]:
            continue
        paired[other] = {
            "pairs": overall["n"],
            "scenes": overall["scenes"],
            "mean_auc_difference": round(overall["mean"], 4),
            "interval_95": [round(overall["low"], 4), round(overall["high"], 4)],
        }
    result = {"input_dir": args.input_dir, "table": table, "paired_with": args.policy}
    result["paired"] = paired
    output_dir = Path(args.output_dir)
    output_dir.mkdir(parents=True, exist_ok=True)
    (output_dir / args.output_name).write_text(json.dumps(result, indent=1))
    print(json.dumps({"mean": {p: v["mean_auc"] for p, v in table.items()}, **paired}, indent=1))
    return result


if __name__ == "__main__":
    main(parse_dataclass_args(Args))
