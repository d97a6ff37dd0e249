"""Which scripted choice of the explorer's candidates explores best? Results: docs/rl.md

Runs scripted choices through the explorer's wrappers (the egocentric map observation and the
candidate goal actions, :mod:`naruto_gym.rl.goal_actions`) and the harness's ``frontier`` and
``random`` baselines on the same scenes and seed, and writes the coverage curves (every env
step) and their area (the mean coverage over the episode's steps) to ``output_dir/check.json``.
The scripted choices are the rules of the ``goal-walker`` policy
(:data:`naruto_agent.rl.scripted_explorer.CHOICE_RULES`: ``nearest`` is always candidate 0,
``random`` a candidate drawn uniformly among the valid slots at every decision); on the train
split this run picks the policy's default rule. ``--decision goal`` runs the rules on the
decision at every goal (``decision="goal"`` of the goal actions: the rule picks every goal
the walker walks), so that the spread between the rules over whole episodes says how much
either decision lets a choice decide.

Coverage only (no reconstruction), the harness's env settings at ``--image-scale``; the
wrappers' env has the explorer's (32, 64) panorama (the panorama does not count towards
coverage). Baseline curves already in ``check.json`` for the same settings are reused
(``--rerun-baselines`` runs them again).

    nice -n 10 python benchmarks/explorer_scripted_check.py \\
        --output-dir benchmarks/results/explorer_candidates
    nice -n 10 python benchmarks/explorer_scripted_check.py --baselines \\
        --scenes procedural:small:0 procedural:small:1 procedural:small:2 \\
        --output-dir benchmarks/results/explorer_rules/small
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import naruto_gym  # noqa: F401  (registers NarutoRecon-v0)
from naruto_agent.benchmark.efficiency import mean_over_steps
from naruto_agent.benchmark.runner import run_episode
from naruto_agent.benchmark.spec import EpisodeSpec
from naruto_agent.cli_args import parse_dataclass_args
from naruto_agent.rl.scripted_explorer import CHOICE_RULES, choose_candidate
from naruto_gym.rl.egocentric_map import EgocentricMapObservation
from naruto_gym.rl.explorer_env import EXPLORER_ENV
from naruto_gym.rl.goal_actions import GOAL_STEPS, GoalActions
from naruto_gym.rl.goal_walker import DECISIONS

BASELINES = ("frontier", "random")


@dataclass
class Args:
    scenes: list[str] = field(
        default_factory=lambda: [f"procedural:small:{1_000_000 + k}" for k in range(3)]
    )
    """scenes (the small class's first test scenes by default)"""
    seed: int = 0
    """episode seed (the env's reset and the random choices)"""
    rules: list[str] = field(default_factory=lambda: list(CHOICE_RULES))
    """the scripted choices run (goal-walker's rules)"""
    baselines: bool = True
    """run the harness's frontier and random too (--no-baselines: the rules alone)"""
    max_episode_steps: int = 400
    """episode length in env steps"""
    steps_per_goal: int | None = None
    """env steps per goal action (K; the most with --decision goal); default 20, and
    GOAL_STEPS (100) with --decision goal"""
    decision: str = "interval"
    """when a rule chooses: "interval" (every K steps) or "goal" (at every goal)"""
    image_scale: float = 0.1
    """camera resolution factor of every run"""
    rerun_baselines: bool = False
    """run frontier and random again even when check.json holds them"""
    output_dir: str = "benchmarks/results/explorer_candidates"
    """output folder"""


class CoverageCurve(gym.Wrapper):
    """Keeps the env's coverage after every step (and the refused moves)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.curve: list[float] = []
        self.refusals = 0

    def step(self, action: Any):
        result = self.env.step(action)
        self.curve.append(float(result[4]["coverage"]))
        self.refusals += int(bool(result[4].get("collided", False)))
        return result


def scripted(args: Args, scene: str, rule: str) -> dict[str, Any]:
    """One episode of a scripted choice rule through the wrappers."""
    env = gym.make(
        "NarutoRecon-v0",
        scene=scene,
        max_episode_steps=args.max_episode_steps,
        image_scale=args.image_scale,
        action_mode="discrete",
        panorama_shape=EXPLORER_ENV["panorama_shape"],
    )
    recorder = CoverageCurve(env)
    at_goal = args.decision == "goal"
    steps = args.steps_per_goal or (GOAL_STEPS if at_goal else 20)
    wrapped = GoalActions(
        EgocentricMapObservation(recorder),
        steps,
        primitive_actions=not at_goal,
        decision=args.decision,
    )
    rng = np.random.default_rng(args.seed)
    observation, _ = wrapped.reset(seed=args.seed)
    decisions, valid = 0, 0
    while len(recorder.curve) < args.max_episode_steps:
        count = int(observation["candidates"][:, 0].sum())
        valid += count
        action = choose_candidate(observation["candidates"], rule, rng)
        observation, _, terminated, truncated, _ = wrapped.step(action)
        decisions += 1
        if terminated or truncated:
            break
    wrapped.close()
    return {
        "coverage_curve": np.round(recorder.curve, 5).tolist(),
        "refusals": recorder.refusals,
        "mean_valid_candidates": round(valid / max(decisions, 1), 2),
    }


def baseline(args: Args, scene: str, policy: str) -> dict[str, Any]:
    """One harness episode of a baseline policy, coverage only."""
    spec = EpisodeSpec(
        scene,
        policy,
        args.seed,
        args.max_episode_steps,
        image_scale=args.image_scale,
        reconstruct=False,
        eval_points=0,
    )
    record = run_episode(spec)
    return {"coverage_curve": record["coverage_curve"], "refusals": record["collisions"]}


def rule_label(rule: str) -> str:
    """A rule's name in ``check.json`` (apart from the harness's ``random`` policy)."""
    return f"{rule} candidate"


def _reusable(stored: dict[str, Any], settings: dict[str, Any], policy: str) -> bool:
    """Whether a stored run of ``policy`` was made with these settings: the episode's (a
    baseline does not walk the candidates, so it ignores ``steps_per_goal`` and
    ``decision``)."""
    ignored = {"rules", "baselines", "steps_per_goal", "decision"}
    if policy not in BASELINES:
        ignored -= {"steps_per_goal", "decision"}
    before = stored.get("settings", {})
    return {k: v for k, v in before.items() if k not in ignored} == {
        k: v for k, v in settings.items() if k not in ignored
    }


def main(args: Args) -> dict[str, Any]:
    if args.decision not in DECISIONS:
        raise ValueError(f"--decision must be one of {DECISIONS}, got {args.decision!r}")
    for rule in args.rules:
        if rule not in CHOICE_RULES:
            raise ValueError(f"unknown rule {rule!r}; use some of {', '.join(CHOICE_RULES)}")
    output_dir = Path(args.output_dir)
    output_dir.mkdir(parents=True, exist_ok=True)
    path = output_dir / "check.json"
    settings = {key: value for key, value in asdict(args).items() if key != "rerun_baselines"}
    stored = json.loads(path.read_text()) if path.exists() else {}
    policies = (*map(rule_label, args.rules), *(BASELINES if args.baselines else ()))
    runs: dict[str, dict[str, Any]] = {}
    for scene in args.scenes:
        for policy in policies:
            key = f"{scene}/{policy}"
            again = policy in BASELINES and args.rerun_baselines
            if key in stored.get("runs", {}) and not again and _reusable(stored, settings, policy):
                runs[key] = stored["runs"][key]
                continue
            run = (
                baseline(args, scene, policy)
                if policy in BASELINES
                else scripted(args, scene, args.rules[policies.index(policy)])
            )
            run["final"] = run["coverage_curve"][-1]
            run["auc"] = round(mean_over_steps(run["coverage_curve"], args.max_episode_steps), 4)
            runs[key] = run
            print(f"{key}: final {run['final']:.3f} auc {run['auc']:.3f}", flush=True)
            path.write_text(json.dumps({"settings": settings, "runs": runs}, indent=1))
    table = {
        policy: {
            "final": [runs[f"{s}/{policy}"]["final"] for s in args.scenes],
            "auc": [runs[f"{s}/{policy}"]["auc"] for s in args.scenes],
            "mean_auc": round(
                float(np.mean([runs[f"{s}/{policy}"]["auc"] for s in args.scenes])), 4
            ),
        }
        for policy in policies
    }
    result = {"settings": settings, "table": table, "runs": runs}
    path.write_text(json.dumps(result, indent=1))
    print(json.dumps(table, indent=1))
    return result


if __name__ == "__main__":
    main(parse_dataclass_args(Args))
