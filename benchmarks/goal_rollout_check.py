"""How much can the choice of goal add to an episode? The rollout choice against the nearest.
Results: docs/benchmarks/goal-ranker.md

The walker of the decision at every goal (``decision="goal"`` of the goal actions, the walker of
``goal-ranker`` and ``goal-walker``) plays the test split's scenes at the explorer's env
settings, its goal chosen at every decision by

* ``nearest``: candidate 0, the scripted choice the ranker's data continue with;
* ``rollout-H``: every candidate walked on a copy of the env, map and walker
  (:func:`~naruto_gym.rl.goal_lookahead.lookahead_curves`: its goal, then the nearest at every
  later decision) for ``H`` env steps, and the one with the largest mean gain over them taken.
  This is one step of policy improvement over the nearest choice with the simulator as its
  model: it knows what no policy sees, so it bounds what a choice learned from the nearest
  choice's measured gains (the goal ranker's data) can add;
* ``goal-ranker``: the packaged ranker (or ``--model-path``), scoring the same candidate table
  and surroundings as in the policy.

Per episode it records the coverage area (the mean over the episode's env steps of the share
of the observable surface seen, what the leaderboard's AUC steps measures without
reconstructing); the table gives each choice's mean and the paired differences ``X - nearest``
over the same scenes and seeds, with 95 % bootstrap intervals (scenes, then seeds). There is no
stall watchdog: every choice walks with the same walker alone.

Resumable: every finished episode is written at once to ``rollout.json`` under
``--output-dir``; a rerun with the same settings skips the episodes there.

    nice -n 10 python benchmarks/goal_rollout_check.py --output-dir runs/goal_rollout
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import naruto_gym  # noqa: F401  (registers NarutoRecon-v0)
from naruto_agent.benchmark.records import write_json_atomic
from naruto_agent.benchmark.statistics import excludes_zero, paired_comparison
from naruto_agent.cli_args import parse_dataclass_args
from naruto_agent.rl.candidate_ranker import load_ranker, walker_surroundings
from naruto_agent.rl.ranker_policy import PACKAGED_RANKER
from naruto_gym.rl.egocentric_map import EgocentricMapObservation
from naruto_gym.rl.explorer_env import EXPLORER_ENV
from naruto_gym.rl.goal_actions import GOAL_STEPS, GoalActions
from naruto_gym.rl.goal_lookahead import gain_area, lookahead_curves
from naruto_gym.rl.goal_walker import AWAIT_DECISION
from naruto_gym.scenes import suite

#: The choice every other is compared with.
REFERENCE = "nearest"


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
    choices: list[str] = field(
        default_factory=lambda: ["nearest", "rollout-20", "rollout-100", "goal-ranker"]
    )
    """the choices played: nearest, rollout-H (H env steps of lookahead), goal-ranker"""
    model_path: str | None = None
    """the ranker of goal-ranker (default: the packaged one)"""
    max_episode_steps: int | None = None
    """episode length (default: each class's budget)"""
    output_dir: str = "runs/goal_rollout"
    """folder of rollout.json and rollout.md"""


def rollout_horizon(choice: str) -> int | None:
    """The lookahead of a ``rollout-H`` choice (None for any other).

    Raises:
        ValueError: a choice that is neither ``nearest``, ``goal-ranker`` nor ``rollout-H``
            with a positive ``H``.
    """
    if choice in (REFERENCE, "goal-ranker"):
        return None
    head, _, horizon = choice.partition("-")
    if head != "rollout" or not horizon.isdigit() or int(horizon) < 1:
        raise ValueError(
            f"unknown choice {choice!r}: give 'nearest', 'goal-ranker' or 'rollout-H' with H "
            f"env steps of lookahead (e.g. rollout-100)"
        )
    return int(horizon)


def make_stack(scene: str, steps: int) -> GoalActions:
    """The walker of the decision at every goal over one scene, at the explorer's settings."""
    env = gym.make("NarutoRecon-v0", scene=scene, max_episode_steps=steps, **EXPLORER_ENV)
    return GoalActions(
        EgocentricMapObservation(env), GOAL_STEPS, primitive_actions=False, decision="goal"
    )


def choose(choice: str, stack: GoalActions, table: np.ndarray, coverage: float, ranker: Any) -> int:
    """The slot ``choice`` walks at a decision whose candidate table is ``table``."""
    count = int((table[:, 0] > 0).sum())
    if count < 2 or choice == REFERENCE:
        return 0
    if choice == "goal-ranker":
        return int(ranker.choose(table, walker_surroundings(stack.walker, 0, count)))
    horizon = rollout_horizon(choice)
    assert horizon is not None
    curves, _ = lookahead_curves(stack, count, coverage, horizon)
    return int(np.argmax([gain_area(curve, horizon) for curve in curves]))


def play(scene: str, steps: int, seed: int, choice: str, ranker: Any) -> dict[str, Any]:
    """One episode with ``choice`` at every decision: its coverage area and walk."""
    stack = make_stack(scene, steps)
    observation, info = stack.reset(seed=seed)
    table = observation["candidates"]
    coverage = [float(info["coverage"])]
    refusals = decisions = 0
    clock = time.perf_counter()
    done = False
    while not done:
        # One decision and its goal, as GoalActions.step walks them, coverage kept per step.
        stack.walker.set_actions(np.array([choose(choice, stack, table, coverage[-1], ranker)]))
        decisions += 1
        for _ in range(stack.steps_per_goal):
            move = int(stack.walker.next_moves()[0])
            if move == AWAIT_DECISION:
                break
            _, _, terminated, truncated, info = stack.env.step(move)
            coverage.append(float(info["coverage"]))
            refusals += int(bool(info.get("collided", False)))
            done = terminated or truncated
            if done:
                break
        table = stack.walker.refresh_candidates()[0]
    stack.close()
    return {
        "area": round(float(np.mean(coverage[1:])), 5),
        "final": round(coverage[-1], 5),
        "decisions": decisions,
        "refusals": refusals,
        "seconds": round(time.perf_counter() - clock, 1),
    }


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


def summary(episodes: dict[str, dict[str, Any]], choices: list[str]) -> dict[str, Any]:
    """Per group and over all: each choice's mean area and ``X - nearest`` with its interval
    over the scene-seed pairs both played."""
    groups = sorted({e["group"] for e in episodes.values()})
    out: dict[str, Any] = {}
    for group in [*groups, "all"]:
        own = [e for e in episodes.values() if group in ("all", e["group"])]
        areas = {
            choice: {(e["scene"], e["seed"]): e["area"] for e in own if e["choice"] == choice}
            for choice in choices
        }
        paired = {}
        for choice in choices:
            if choice == REFERENCE or not areas[choice] or not areas.get(REFERENCE):
                continue
            overall = paired_comparison(areas[choice], areas[REFERENCE])["overall"]
            paired[choice] = {
                **{k: round(v, 4) if isinstance(v, float) else v for k, v in overall.items()},
                "excludes_zero": excludes_zero(overall),
            }
        out[group] = {
            "mean_area": {
                c: round(float(np.mean(list(v.values()))), 4) for c, v in areas.items() if v
            },
            "pairs": {c: len(v) for c, v in areas.items()},
            "paired": paired,
        }
    return out


def table(result: dict[str, Any], choices: list[str]) -> str:
    """The summary as Markdown: mean areas, then ``X - nearest`` with its interval."""
    others = [c for c in choices if c != REFERENCE]
    lines = [
        "| group | pairs | " + " | ".join(choices) + " | "
        + " | ".join(f"{c} - {REFERENCE}" for c in others) + " |",
        "|---" * (2 + len(choices) + len(others)) + "|",
    ]  # fmt: skip
    for group, entry in result["summary"].items():
        areas = [f"{entry['mean_area'].get(c, float('nan')):.3f}" for c in choices]
        diffs = []
        for other in others:
            p = entry["paired"].get(other)
            diffs.append(
                "-"
                if not p or p["mean"] is None
                else f"{p['mean']:+.4f} [{p['low']:+.4f}, {p['high']:+.4f}]"
                + (" *" if p["excludes_zero"] else "")
            )
        pairs = min(entry["pairs"].values())
        lines.append(f"| {group} | {pairs} | " + " | ".join(areas + diffs) + " |")
    return "\n".join(lines)


def main(args: Args) -> dict[str, Any]:
    for choice in args.choices:
        rollout_horizon(choice)
    ranker = None
    if "goal-ranker" in args.choices:
        ranker, _ = load_ranker(args.model_path or PACKAGED_RANKER)
    out = Path(args.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "rollout.json"
    settings = json.loads(json.dumps({k: v for k, v in asdict(args).items() if k != "choices"}))
    result: dict[str, Any] = {"settings": settings, "episodes": {}}
    if path.exists():
        result = json.loads(path.read_text())
        if result["settings"] != settings:
            raise ValueError(f"{path} holds a run with other settings: give another --output-dir")
    for seed in args.seeds:
        for group, scene, steps in episodes_of(args):
            for choice in args.choices:
                key = f"{scene}/{choice}/seed{seed}"
                if key in result["episodes"]:
                    continue
                episode = play(scene, steps, seed, choice, ranker)
                result["episodes"][key] = {
                    "group": group, "scene": scene, "choice": choice, "seed": seed, **episode
                }  # fmt: skip
                write_json_atomic(path, result)
                print(f"{key}: area {episode['area']:.4f} ({episode['seconds']} s)", flush=True)
    result["summary"] = summary(result["episodes"], args.choices)
    write_json_atomic(path, result)
    (out / "rollout.md").write_text(table(result, args.choices) + "\n")
    print(table(result, args.choices))
    return result


if __name__ == "__main__":
    main(parse_dataclass_args(Args))
