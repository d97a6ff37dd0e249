"""How much does the explorer's choice decide? The leverage of its decisions. Results: docs/rl.md

The explorer (the packaged checkpoint, or ``--model-path``) plays episodes of the train split
through its training wrappers (the egocentric map observation and the candidate goal actions,
:mod:`naruto_gym.rl.goal_actions`, at the training env's settings, :data:`EXPLORER_ENV`). At
each decision it measures, the whole stack (env, map and walker) is copied
(``copy.deepcopy``: the env is deterministic given its state, so a copy steps as the original
would, and stepping a copy leaves the original as it was), and every valid candidate is tried
on a copy of its own: the walker walks it alone (no further decision) for each horizon (by
default ``K``, the decision interval, and ``2 K`` env steps), and the coverage gained from the
decision on is recorded. The episode itself goes on with the model's choice.

Per decision with at least two candidates and per horizon the summary gives, in coverage
points (percent of the scene's surface samples), the distribution (mean, median, 90th
percentile) over decisions of

* ``best_minus_worst``: what the choice can decide at all;
* ``best_minus_nearest``: what a choice can add over always taking candidate 0;
* ``best_minus_chosen`` and ``chosen_minus_nearest``: where the model's own choice stands;
* ``best_minus_<rule>``: the same for each scripted rule of ``goal-walker``
  (:data:`~naruto_agent.rl.scripted_explorer.CHOICE_RULES`),

and the share of decisions with no or one candidate (no leverage by construction); the same
per scene group (a size class and variant of the train split) under ``"groups"``.

``--decision goal`` measures the decision at every goal (``decision="goal"`` of the goal
actions: the walker walks the chosen goal alone, and the next decision comes once it is
viewed or given up, at most ``steps_per_goal`` = 100 steps later). Each candidate's copy
walks its goal to the end, then takes the nearest candidate at every further decision (the
same continuation for every candidate, so the gains differ by the first choice alone), for
at least the longest horizon (default 20 and 40 env steps); the summary's ``"goal"``
horizon is the gain until the copy's next decision (``goal_steps``: its env steps). The
episode itself goes on with ``--advance``: the model's choice (``model``, a checkpoint
trained on this decision) or a scripted rule's (e.g. ``random``). It prints the
whole run's as a Markdown table (:func:`leverage_table`). Every measured decision keeps what
the choice saw (the valid candidates' feature rows, ``table``, and what lies around each on
the walker's map, ``surroundings``): the data of ``benchmarks/train_goal_ranker.py``. The JSON
(``--output-file``) is written after every decision; a rerun with the same settings resumes (an
episode is played again from its seed, its measured decisions skipped).

    nice -n 10 python benchmarks/explorer_leverage.py  # 8 episodes, about 10 min of CPU
    nice -n 10 python benchmarks/explorer_leverage.py --scenes-per-group 8 --seeds 0 1 2 \\
        --output-file benchmarks/results/explorer_leverage/leverage_full.json
    nice -n 10 python benchmarks/explorer_leverage.py --decision goal --advance random \\
        --output-file benchmarks/results/explorer_leverage/leverage_goal.json
"""

from __future__ import annotations

import copy
import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import naruto_gym  # noqa: F401  (registers NarutoRecon-v0)
from naruto_agent.benchmark.records import write_json_atomic
from naruto_agent.cli_args import parse_dataclass_args
from naruto_agent.rl.candidate_ranker import walker_surroundings
from naruto_agent.rl.explorer_policy import DEFAULT_SETTINGS, PACKAGED_MODEL, read_settings
from naruto_agent.rl.scripted_explorer import CHOICE_RULES, choose_candidate
from naruto_gym.rl.egocentric_map import EgocentricMapObservation
from naruto_gym.rl.explorer_env import EXPLORER_ENV
from naruto_gym.rl.goal_actions import GOAL_STEPS, GoalActions
from naruto_gym.rl.goal_lookahead import gain_at, lookahead_curves
from naruto_gym.rl.goal_walker import DECISIONS
from naruto_gym.scenes import suite

#: ``--advance`` of the rollout choice: at every measured decision, the candidate whose walk
#: gained the most (:func:`rollout_slot`), so the decisions come from the states it reaches.
ROLLOUT = "rollout"

#: The summary's distributions, per horizon.
PERCENTILES = {"median": 50.0, "p90": 90.0}


@dataclass
class Args:
    size_classes: list[str] = field(default_factory=lambda: ["small", "flat"])
    """size classes of the train split"""
    variants: list[str] = field(default_factory=lambda: ["closed", "open"])
    """variants of the train split"""
    scenes_per_group: int = 2
    """train scenes per size class and variant (the first training seeds)"""
    scenes: list[str] = field(default_factory=list)
    """scenes instead of the train split's (each with --max-episode-steps, default 400)"""
    seeds: list[int] = field(default_factory=lambda: [0])
    """episode seeds"""
    max_episode_steps: int | None = None
    """episode length (default: each class's budget, 400 for --scenes)"""
    horizons: list[int] = field(default_factory=list)
    """env steps each candidate is walked after the decision (default: K and 2 K; 20 and
    40 for --decision goal)"""
    decision: str | None = None
    """the decision measured: "interval" (every K steps) or "goal" (at every goal); default:
    the model's settings"""
    advance: str = "model"
    """what chooses the episode's own decisions: "model", a goal-walker rule (random...) or
    "rollout" (the measured candidate of the largest mean gain over the longest horizon)"""
    decision_every: int = 1
    """measure every n-th decision"""
    model_path: str | None = None
    """the explorer checkpoint (default: the packaged one; with --decision goal and a
    scripted --advance, none is needed)"""
    deterministic: bool = False
    """the model acts with its distribution's mode (default: it samples, as in the harness)"""
    output_file: str = "benchmarks/results/explorer_leverage/leverage.json"
    """the JSON file (resumed when its settings match)"""


def episodes_of(args: Args) -> list[tuple[str, int]]:
    """The (scene, budget) pairs of the run."""
    if args.scenes:
        return [(scene, args.max_episode_steps or 400) for scene in args.scenes]
    out = []
    for size_class in args.size_classes:
        budget = args.max_episode_steps or suite.budget(size_class)
        for variant in args.variants:
            for seed in suite.train_seeds(size_class)[: args.scenes_per_group]:
                out.append((suite.scene_name(size_class, seed, variant, "train"), budget))
    return out


def make_stack(scene: str, steps: int, settings: dict[str, Any]) -> GoalActions:
    """The explorer's training stack over one scene: env, egocentric map, goal actions."""
    env_kwargs = dict(EXPLORER_ENV)
    if settings.get("panorama_horizon_deg") is not None:
        env_kwargs["panorama_horizon_deg"] = settings["panorama_horizon_deg"]
    env = gym.make("NarutoRecon-v0", scene=scene, max_episode_steps=steps, **env_kwargs)
    return GoalActions(
        EgocentricMapObservation(env, **settings["map_options"]),
        int(settings["steps_per_goal"]),
        num_candidates=int(settings["num_candidates"]),
        primitive_actions=bool(settings["primitive_actions"]),
        decision=settings.get("decision", "interval"),
    )


def candidate_gains(
    stack: GoalActions, count: int, coverage: float, horizons: list[int]
) -> dict[str, list[float]]:
    """Coverage gained by each of the ``count`` candidates, walked alone on a copy of the
    stack for each horizon (an episode that ends sooner keeps its last coverage)."""
    gains: dict[str, list[float]] = {str(h): [] for h in horizons}
    for slot in range(count):
        trial = copy.deepcopy(stack)
        trial.walker.set_actions(np.array([slot]))
        reached = coverage
        for step in range(1, max(horizons) + 1):
            _, _, terminated, truncated, info = trial.env.step(int(trial.walker.next_moves()[0]))
            reached = float(info["coverage"])
            if str(step) in gains:
                gains[str(step)].append(reached - coverage)
            if terminated or truncated:
                for h in horizons:
                    if h > step:
                        gains[str(h)].append(reached - coverage)
                break
    return gains


def goal_gains(
    stack: GoalActions, count: int, coverage: float, horizons: list[int]
) -> tuple[dict[str, list[float]], list[int]]:
    """Coverage gained by each of the ``count`` candidates of a decision at every goal,
    walked on a copy of the stack (:func:`~naruto_gym.rl.goal_lookahead.lookahead_curves`):
    until the copy's next decision (``"goal"``, and its env steps) and for each horizon, the
    nearest candidate taken at every later decision."""
    curves, steps_to_decision = lookahead_curves(stack, count, coverage, max(horizons))
    gains = {str(h): [gain_at(curve, h) for curve in curves] for h in horizons}
    gains["goal"] = [gain_at(curve, s) for curve, s in zip(curves, steps_to_decision, strict=True)]
    return gains, steps_to_decision


def rollout_slot(entry: dict[str, Any], horizons: list[int]) -> int:
    """The rollout choice at a measured decision: the candidate of the largest gain averaged
    over the longest horizon (trapezoids over the measured horizons, from 0 at the decision;
    the goal ranker's target)."""
    steps = [0, *sorted(horizons)]
    curves = np.array([[0.0] * entry["candidates"], *(entry["gains"][str(h)] for h in steps[1:])])
    return int(np.argmax(np.trapezoid(curves, steps, axis=0)))


def rule_slots(candidates: np.ndarray, seed: int, decision: int) -> dict[str, int]:
    """The slot each scripted rule picks (``random`` drawn from the seed and decision)."""
    rng = np.random.default_rng([seed, decision])
    return {rule: choose_candidate(candidates, rule, rng) for rule in CHOICE_RULES}


def play_episode(
    args: Args,
    model: Any,
    settings: dict[str, Any],
    scene: str,
    steps: int,
    seed: int,
    stored: dict[int, dict[str, Any]],
    save: Any,
) -> list[dict[str, Any]]:
    """One explorer episode, measuring its decisions (those in ``stored`` are kept as they
    are); ``save(decisions)`` is called after each measured one."""
    horizons = horizons_of(args, settings)
    at_goal = settings.get("decision") == "goal"
    stack = make_stack(scene, steps, settings)
    if model is not None:
        model.set_random_seed(seed)
    observation, info = stack.reset(seed=seed)
    coverage = float(info["coverage"])
    decisions: list[dict[str, Any]] = []
    step = 0
    for decision in range(steps):
        candidates = observation["candidates"]
        if model is not None:
            action, _ = model.predict(observation, deterministic=args.deterministic)
            action = int(action)
        elif args.advance != ROLLOUT:
            action = rule_slots(candidates, seed, decision)[args.advance]
        else:
            action = 0  # the measured candidate of the largest mean gain, below
        measured = decision % args.decision_every == 0 and step + max(horizons) <= steps
        if decision in stored:
            entry = stored[decision]
        elif measured:
            count = int((candidates[:, 0] > 0).sum())
            # The slot the walker walks for the model's action: an empty slot is candidate
            # 0; a discrete move (primitive_actions) is no candidate (None).
            slot = action if action < count else 0
            entry = {
                "decision": decision,
                "step": step,
                "coverage": round(coverage, 5),
                "candidates": count,
                "chosen": action,
                "chosen_slot": slot if action < int(settings["num_candidates"]) else None,
                "rules": rule_slots(candidates, seed, decision),
                # What the choice saw: the valid candidates' feature rows (a ranker's data).
                "table": np.round(candidates[:count], 5).tolist(),
                "surroundings": np.round(walker_surroundings(stack.walker, 0, count), 5).tolist(),
                "budget": steps,
                "gains": {},
            }
            if count and at_goal:
                gains, entry["goal_steps"] = goal_gains(stack, count, coverage, horizons)
            else:
                gains = candidate_gains(stack, count, coverage, horizons) if count else {}
            entry["gains"] = {h: np.round(g, 5).tolist() for h, g in gains.items()}
        else:
            entry = None
        if args.advance == ROLLOUT and entry is not None and entry["candidates"]:
            action = entry["chosen"] = entry["chosen_slot"] = rollout_slot(entry, horizons)
        observation, _, terminated, truncated, info = stack.step(action)
        step += int(info["primitive_steps"])
        if entry is not None:
            entry["realised"] = round(float(info["coverage"]) - coverage, 5)
            entry["realised_steps"] = int(info["primitive_steps"])
            decisions.append(entry)
            if decision not in stored:
                save(decisions)
        coverage = float(info["coverage"])
        if terminated or truncated:
            break
    stack.close()
    return decisions


def horizons_of(args: Args, settings: dict[str, Any]) -> list[int]:
    """The horizons measured: ``--horizons``, else K and 2 K (20 and 40 steps for the
    decision at every goal, the interval decision's)."""
    if args.horizons:
        return list(args.horizons)
    if settings.get("decision") == "goal":
        return [20, 40]
    period = int(settings["steps_per_goal"])
    return [period, 2 * period]


def measured_settings(args: Args) -> tuple[Any, dict[str, Any]]:
    """The model (None where a scripted rule advances the episode) and the walker's
    settings of the run.

    Raises:
        ValueError: an unknown ``--advance`` or ``--decision``, or a model whose decision
            is not the one asked for.
    """
    from stable_baselines3 import PPO

    if args.advance not in ("model", ROLLOUT, *CHOICE_RULES):
        raise ValueError(
            f"--advance must be 'model', {ROLLOUT!r} or one of {CHOICE_RULES}, got {args.advance}"
        )
    if args.advance == ROLLOUT and (args.decision != "goal" or args.decision_every != 1):
        raise ValueError(
            f"--advance {ROLLOUT} chooses among measured candidates: it needs --decision goal "
            f"and every decision measured (--decision-every 1)"
        )
    if args.decision not in (None, *DECISIONS):
        raise ValueError(f"--decision must be one of {DECISIONS}, got {args.decision!r}")
    model_path = Path(args.model_path) if args.model_path else PACKAGED_MODEL
    if args.advance != "model" and args.decision == "goal" and not args.model_path:
        goal = {"decision": "goal", "steps_per_goal": GOAL_STEPS, "primitive_actions": False}
        return None, {**DEFAULT_SETTINGS, **goal}
    settings = read_settings(model_path)
    own = settings.get("decision", "interval")
    if args.decision not in (None, own):
        raise ValueError(
            f"{model_path} was trained on the {own!r} decision, not {args.decision!r}: give "
            f"a model of that decision (--model-path) or a scripted --advance"
        )
    model = PPO.load(model_path, device="cpu") if args.advance == "model" else None
    return model, settings


def _stats(values: list[float]) -> dict[str, float | int | None]:
    if not values:
        return {"mean": None, **{name: None for name in PERCENTILES}, "n": 0}
    points = 100.0 * np.asarray(values)
    return {
        "mean": round(float(points.mean()), 3),
        **{name: round(float(np.percentile(points, q)), 3) for name, q in PERCENTILES.items()},
        "n": len(values),
    }


def scene_group(episode: str) -> str:
    """The group of an episode key (``SCENE/seedN``): a generated scene's name with its seed
    as ``*`` (``procedural:small:*:no_ceiling+holes``), any other scene itself."""
    parts = episode.rpartition("/")[0].split(":")
    if len(parts) >= 3 and parts[0] == "procedural" and parts[2].isdigit():
        parts[2] = "*"
    return ":".join(parts)


def grouped_summary(episodes: dict[str, dict[str, Any]], horizons: list[Any]) -> dict[str, Any]:
    """:func:`leverage_summary` of every episode, with the same per scene group
    (:func:`scene_group`) under ``"groups"``."""
    groups: dict[str, dict[str, dict[str, Any]]] = {}
    for key, episode in episodes.items():
        groups.setdefault(scene_group(key), {})[key] = episode
    return {
        **leverage_summary(episodes, horizons),
        "groups": {name: leverage_summary(own, horizons) for name, own in groups.items()},
    }


def leverage_summary(episodes: dict[str, dict[str, Any]], horizons: list[Any]) -> dict[str, Any]:
    """Per horizon, the distributions over decisions with two or more candidates (module
    docstring), in coverage points, and the counts of decisions by candidates."""
    decisions = [d for episode in episodes.values() for d in episode["decisions"]]
    counts = [d["candidates"] for d in decisions]
    summary: dict[str, Any] = {
        "decisions": len(decisions),
        "no_candidate": sum(c == 0 for c in counts),
        "one_candidate": sum(c == 1 for c in counts),
        "mean_candidates": round(float(np.mean(counts)), 2) if counts else None,
        "horizons": {},
    }
    lengths = [s for d in decisions for s in d.get("goal_steps", [])]
    if lengths:
        summary["goal_steps"] = {
            "mean": round(float(np.mean(lengths)), 1),
            **{name: float(np.percentile(lengths, q)) for name, q in PERCENTILES.items()},
        }
        horizons = [*horizons, "goal"]
    for horizon in horizons:
        rows: dict[str, list[float]] = {}
        for d in decisions:
            gains = d["gains"].get(str(horizon), [])
            if len(gains) < 2:
                continue
            best = max(gains)
            values = {
                "nearest_gain": gains[0],
                "best_minus_worst": best - min(gains),
                "best_minus_nearest": best - gains[0],
                **{f"best_minus_{r}": best - gains[s] for r, s in d["rules"].items()},
            }
            if d["chosen_slot"] is not None:
                values["best_minus_chosen"] = best - gains[d["chosen_slot"]]
                values["chosen_minus_nearest"] = gains[d["chosen_slot"]] - gains[0]
            for key, value in values.items():
                rows.setdefault(key, []).append(value)
        summary["horizons"][str(horizon)] = {key: _stats(v) for key, v in rows.items()}
    return summary


#: The rows of the Markdown table, in order, with their titles.
TABLE_ROWS = {
    "nearest_gain": "gain of candidate 0 (nearest)",
    "best_minus_worst": "best - worst",
    "best_minus_nearest": "best - nearest",
    **{f"best_minus_{rule}": f"best - {rule}" for rule in CHOICE_RULES if rule != "nearest"},
    "best_minus_chosen": "best - the model's choice",
    "chosen_minus_nearest": "the model's choice - nearest",
}


def leverage_table(summary: dict[str, Any]) -> str:
    """The summary as a Markdown table: a row per quantity, mean / median / 90th percentile
    in coverage points per horizon."""
    horizons = list(summary["horizons"])
    header = [
        "coverage points",
        *(
            "until the next decision: mean / median / p90"
            if h == "goal"
            else f"{h} steps: mean / median / p90"
            for h in horizons
        ),
    ]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for key, title in TABLE_ROWS.items():
        cells = []
        for horizon in horizons:
            stat = summary["horizons"][horizon].get(key)
            cells.append(
                "-"
                if not stat or stat["mean"] is None
                else f"{stat['mean']:.2f} / {stat['median']:.2f} / {stat['p90']:.2f}"
            )
        lines.append(f"| {title} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(args: Args) -> dict[str, Any]:
    if args.decision_every < 1:
        raise ValueError(f"--decision-every must be at least 1, got {args.decision_every}")
    model, settings = measured_settings(args)
    horizons = horizons_of(args, settings)
    if min(horizons) < 1:
        raise ValueError(f"--horizons must be positive step counts, got {horizons}")
    path = Path(args.output_file)
    run_settings = {**asdict(args), "horizons": horizons, "walker": settings}
    result: dict[str, Any] = {"settings": run_settings, "episodes": {}}
    if path.exists():
        stored = json.loads(path.read_text())
        if stored.get("settings") != json.loads(json.dumps(run_settings)):
            raise ValueError(
                f"{path} holds a run with other settings; give another --output-file (or delete "
                f"it to start again)"
            )
        result = stored
    for scene, steps in episodes_of(args):
        for seed in args.seeds:
            key = f"{scene}/seed{seed}"
            episode = result["episodes"].setdefault(key, {"done": False, "decisions": []})
            if episode["done"]:
                continue
            started = time.perf_counter()

            def save(decisions: list[dict[str, Any]], episode: dict[str, Any] = episode) -> None:
                episode["decisions"] = decisions
                write_json_atomic(path, result)

            stored_decisions = {d["decision"]: d for d in episode["decisions"]}
            episode["decisions"] = play_episode(
                args, model, settings, scene, steps, seed, stored_decisions, save
            )
            episode["done"] = True
            result["summary"] = grouped_summary(result["episodes"], horizons)
            write_json_atomic(path, result)
            first = result["summary"]["horizons"][str(horizons[0])]
            spread = first.get("best_minus_worst", {}).get("mean")
            print(
                f"{key}: {len(episode['decisions'])} decisions in "
                f"{time.perf_counter() - started:.0f} s; so far best - worst at "
                f"{horizons[0]} steps {spread} points",
                flush=True,
            )
    result["summary"] = grouped_summary(result["episodes"], horizons)
    write_json_atomic(path, result)
    summary = result["summary"]
    print(
        f"{summary['decisions']} decisions, {summary['mean_candidates']} candidates on average; "
        f"{summary['no_candidate']} with none, {summary['one_candidate']} with one"
    )
    print(leverage_table(summary))
    return result


if __name__ == "__main__":
    main(parse_dataclass_args(Args))
