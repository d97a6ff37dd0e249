"""Does the learned ranking add coverage? ``goal-ranker`` against its untrained twin and the
scripted choices of the same walker, on the test split. Results: docs/benchmarks/goal-ranker.md

Every policy plays every scene of the chosen size classes and variants of the suite's test
split, each class with its step budget, at the leaderboard's camera (image scale 0.25), the
same episode seeds for every policy. Per episode it records the *coverage area*: the mean over
the episode's steps of the env's coverage (the share of the scene's observable surface samples
the camera has seen), which is what the leaderboard's AUC steps measures on the reconstruction,
without reconstructing (so a check of 96 episodes per policy takes minutes, not hours). The
table gives each policy's mean area and the paired differences ``goal-ranker - B`` over the
same scenes and seeds with their 95 % bootstrap intervals (scenes, then seeds), per size class
and variant and over all of them.

It is resumable: every finished episode is written at once to ``check.json`` under
``--output-dir``, and a rerun with the same settings skips the episodes there.

    nice -n 10 python benchmarks/goal_ranker_check.py --output-dir runs/goal_ranker/check
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from naruto_agent.benchmark.records import write_json_atomic
from naruto_agent.benchmark.statistics import excludes_zero, paired_comparison
from naruto_agent.cli_args import parse_dataclass_args
from naruto_gym.scenes import suite

#: The policies compared, by label: a registered name and its keywords.
POLICIES: dict[str, tuple[str, dict[str, Any]]] = {
    "goal-ranker": ("goal-ranker", {}),
    "goal-ranker-untrained": ("goal-ranker-untrained", {}),
    "nearest": ("goal-walker", {"rule": "nearest", "decision": "goal"}),
    "size-per-metre": ("goal-walker", {"rule": "size-per-metre", "decision": "goal"}),
    "largest": ("goal-walker", {"rule": "largest", "decision": "goal"}),
}
LEARNED = "goal-ranker"


@dataclass
class Args:
    size_classes: list[str] = field(default_factory=lambda: ["small", "flat"])
    """size classes of the test split"""
    variants: list[str] = field(default_factory=lambda: ["closed", "open"])
    """variants"""
    scenes_per_group: int = 8
    """test scenes per size class and variant"""
    seeds: list[int] = field(default_factory=lambda: [0, 1, 2])
    """episode seeds"""
    policies: list[str] = field(default_factory=lambda: list(POLICIES))
    """labels of :data:`POLICIES` to run"""
    model_path: str | None = None
    """the ranker of ``goal-ranker`` and its twin (default: the packaged one)"""
    image_scale: float = 0.25
    """camera resolution factor (0.25: the leaderboard's)"""
    max_episode_steps: int | None = None
    """episode length (default: each class's budget)"""
    output_dir: str = "runs/goal_ranker/check"
    """folder of check.json and check.md"""


def episodes_of(args: Args) -> list[tuple[str, str, int]]:
    """(group, scene, steps) of every test scene of the run."""
    out = []
    for size_class in args.size_classes:
        steps = args.max_episode_steps or suite.budget(size_class)
        for variant in args.variants:
            for seed in suite.test_seeds(size_class)[: args.scenes_per_group]:
                scene = suite.scene_name(size_class, seed, variant, "test")
                out.append((f"{size_class} {variant}", scene, steps))
    return out


def coverage_area(scene: str, label: str, seed: int, steps: int, args: Args) -> dict[str, Any]:
    """One episode of the policy labelled ``label``; its coverage area and walk."""
    import gymnasium as gym

    import naruto_gym  # noqa: F401
    from naruto_agent.episode_loop import StepRecords, run_episode_loop
    from naruto_agent.policies import make_policy

    name, kwargs = POLICIES[label]
    if name.startswith("goal-ranker") and args.model_path:
        kwargs = {**kwargs, "model_path": args.model_path}
    policy = make_policy(name, **kwargs)
    env = gym.make(
        "NarutoRecon-v0",
        scene=scene,
        action_mode=policy.preferred_action_mode,
        image_scale=args.image_scale,
        max_episode_steps=steps,
    )
    records = StepRecords()
    clock = time.perf_counter()
    run_episode_loop(env, policy, steps, seed, [records])
    coverage = np.asarray(records.coverage[1:])
    result = {
        "area": round(float(coverage.mean()), 5),
        "final": round(float(coverage[-1]), 5),
        "refusals": int(sum(records.collisions.values())),
        "stalled_steps": int(policy.stalled_steps),
        "seconds": round(time.perf_counter() - clock, 1),
    }
    env.close()
    policy.close()
    return result


def summary(episodes: dict[str, dict[str, Any]], labels: list[str]) -> dict[str, Any]:
    """Mean area per policy and group, and the paired differences ``goal-ranker - B``."""
    groups = sorted({e["group"] for e in episodes.values()})
    out: dict[str, Any] = {}
    for group in [*groups, "all"]:
        own = [e for e in episodes.values() if group in ("all", e["group"])]
        values = {
            label: {(e["scene"], e["seed"]): e["area"] for e in own if e["policy"] == label}
            for label in labels
        }
        entry: dict[str, Any] = {
            "mean_area": {
                label: round(float(np.mean(list(v.values()))), 4)
                for label, v in values.items()
                if v
            },
            "paired": {},
        }
        if LEARNED in values:
            for other in labels:
                if other == LEARNED or not values.get(other):
                    continue
                overall = paired_comparison(values[LEARNED], values[other])["overall"]
                entry["paired"][other] = {
                    **{k: round(v, 4) if isinstance(v, float) else v for k, v in overall.items()},
                    "excludes_zero": excludes_zero(overall),
                }
        out[group] = entry
    return out


def table(result: dict[str, Any], labels: list[str]) -> str:
    """The summary as Markdown: mean areas, then ``goal-ranker - B`` with its interval."""
    others = [label for label in labels if label != LEARNED]
    lines = [
        "| group | " + " | ".join(labels) + " | "
        + " | ".join(f"{LEARNED} - {o}" for o in others) + " |",
        "|---" * (1 + len(labels) + len(others)) + "|",
    ]  # fmt: skip
    for group, entry in result["summary"].items():
        areas = [f"{entry['mean_area'].get(label, float('nan')):.3f}" for label in labels]
        diffs = []
        for other in others:
            p = entry["paired"].get(other)
            diffs.append(
                "-"
                if not p or p["mean"] is None
                else f"{p['mean']:+.4f} [{p['low']:+.4f}, {p['high']:+.4f}]"
                + (" *" if p["excludes_zero"] else "")
            )
        lines.append(f"| {group} | " + " | ".join(areas + diffs) + " |")
    return "\n".join(lines)


def main(args: Args) -> dict[str, Any]:
    unknown = [label for label in args.policies if label not in POLICIES]
    if unknown:
        raise ValueError(f"unknown policies {unknown}; choose among {list(POLICIES)}")
    out = Path(args.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "check.json"
    settings = json.loads(json.dumps({k: v for k, v in asdict(args).items() if k != "policies"}))
    result: dict[str, Any] = {"settings": settings, "episodes": {}}
    if path.exists():
        result = json.loads(path.read_text())
        if result["settings"] != settings:
            raise ValueError(f"{path} holds a run with other settings: give another --output-dir")
    for seed in args.seeds:
        for group, scene, steps in episodes_of(args):
            for label in args.policies:
                key = f"{scene}/{label}/seed{seed}"
                if key in result["episodes"]:
                    continue
                episode = coverage_area(scene, label, seed, steps, args)
                result["episodes"][key] = {
                    "group": group, "scene": scene, "policy": label, "seed": seed, **episode
                }  # fmt: skip
                write_json_atomic(path, result)
                print(f"{key}: area {episode['area']:.4f} ({episode['seconds']} s)", flush=True)
    result["summary"] = summary(result["episodes"], args.policies)
    write_json_atomic(path, result)
    (out / "check.md").write_text(table(result, args.policies) + "\n")
    print(table(result, args.policies))
    return result


if __name__ == "__main__":
    main(parse_dataclass_args(Args))
