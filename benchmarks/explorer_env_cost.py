"""The explorer's training throughput, before and after shared scenes, the panorama band,
the chain in worker processes and the bfloat16 update, in one run. Results:
docs/benchmarks/explorer.md

Builds the batched env as ``benchmarks/train_explorer.py`` does (:func:`make_batched_env`) in
three configurations:

* before: the train mix with a scene of its own per agent per episode, every panorama row;
* shared scenes (:func:`naruto_gym.rl.explorer_env.shared_train_mix`; by default with a new
  scene for every episode, so that the episode end timed pays for the groups' new scenes, as
  training pays every ``episodes_per_scene``-th), every panorama row;
* after: shared scenes, and only the panorama rows within ``panorama_horizon_deg`` of the
  horizon (the rows the explorer's map reads).

The machine this runs on is shared with other work whose load changes from minute to minute,
so the configurations are timed interleaved, each seeing the same load:

* the bare batched env (random forward / turn moves, no wrapper, no learner): one env per
  configuration, stepped in turn ``chunk_steps`` steps at a time, ``max_episode_steps + 20``
  steps per agent after a warm-up, so that each crosses one episode end with its new scenes;
* training end to end: Stable-Baselines3 PPO through the map and goal wrappers
  (``train_explorer.main``) for one rollout that crosses an episode end and its update, in
  four configurations (:func:`training_configurations`): "before" in one process, "after"
  in one process, then with the env and its wrappers stepped in worker processes
  (``--env-workers``, the script's default), then with the update in bfloat16 as well
  (``--update-dtype bfloat16``); run in that order and then in reverse. Its profile splits
  the time (the env's share of it is how far training falls below its own env, measured
  under one load).

It writes env steps per second, their ratios to "before", and the profiles.

    nice -n 10 python benchmarks/explorer_env_cost.py
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import train_explorer  # the training script beside this one: the env it trains in

from naruto_agent.cli_args import parse_dataclass_args
from naruto_gym.rl.explorer_env import EXPLORER_PANORAMA_HORIZON_DEG


@dataclass
class Args:
    num_envs: int = 16
    """agents"""
    max_episode_steps: int = 400
    """episode length; every timed run crosses one episode end"""
    agents_per_scene: int = 4
    """agents sharing a scene in the shared configurations"""
    episodes_per_scene: int = 1
    """episodes per shared scene: 1 builds the groups' new scenes at the episode end every
    timed run crosses, the dearest case (training's default of 4 builds a quarter as often)"""
    panorama_horizon_deg: float = EXPLORER_PANORAMA_HORIZON_DEG
    """the panorama band of the "after" configuration (the rows the explorer's map reads)"""
    chunk_steps: int = 10
    """bare env steps of one configuration before the next takes its turn"""
    train: bool = True
    """also time PPO training end to end in the before and after configurations"""
    output_file: str = "benchmarks/results/explorer_candidates/env_configs.json"
    """JSON written (replaced)"""


def configurations(args: Args) -> dict[str, dict[str, Any]]:
    """The training script's arguments of each configuration timed."""
    return {
        "before: a scene per agent per episode, every panorama row": {
            "shared_scenes": False,
            "panorama_horizon_deg": None,
        },
        "shared scenes, every panorama row": {
            "shared_scenes": True,
            "panorama_horizon_deg": None,
        },
        f"after: shared scenes, panorama rows within {args.panorama_horizon_deg:g} deg": {
            "shared_scenes": True,
            "panorama_horizon_deg": args.panorama_horizon_deg,
        },
    }


def training_args(args: Args, options: dict[str, Any], output_dir: str) -> train_explorer.Args:
    """The training script's arguments: one rollout that crosses an episode end."""
    goals = args.max_episode_steps // train_explorer.Args.steps_per_goal + 1
    return replace(
        train_explorer.Args(),
        num_envs=args.num_envs,
        max_episode_steps=args.max_episode_steps,
        agents_per_scene=args.agents_per_scene,
        episodes_per_scene=args.episodes_per_scene,
        n_steps=goals,
        batch_size=max(1, goals * args.num_envs // 4),
        total_timesteps=goals * args.num_envs * train_explorer.Args.steps_per_goal,
        checkpoint_every=10**9,
        output_dir=output_dir,
        **options,
    )


def bare_rates(args: Args, scratch: str) -> dict[str, float]:
    """Env steps per second of each configuration's bare batched env over one episode end,
    the envs stepped in turn ``chunk_steps`` steps at a time."""
    envs = {
        name: train_explorer.make_batched_env(training_args(args, options, scratch))
        for name, options in configurations(args).items()
    }
    steps = args.max_episode_steps + 20
    moves = np.random.default_rng(0).choice([0, 6, 7], size=(steps + 20, args.num_envs))
    for env in envs.values():
        env.reset(seed=0)
        for step in range(20):  # warm-up: compiled loops
            env.step(moves[step])
    seconds = dict.fromkeys(envs, 0.0)
    for first in range(20, steps + 20, args.chunk_steps):
        for name, env in envs.items():
            started = time.perf_counter()
            for step in range(first, min(first + args.chunk_steps, steps + 20)):
                env.step(moves[step])
            seconds[name] += time.perf_counter() - started
    for env in envs.values():
        env.close()
    return {name: args.num_envs * steps / seconds[name] for name in envs}


def training_configurations(args: Args) -> dict[str, dict[str, Any]]:
    """The training script's arguments of each training configuration timed: "before", the
    env changes in one process, then the chain in worker processes, then the bfloat16
    update."""
    env = configurations(args)
    (before, before_env), *_, (after, after_env) = env.items()
    one_process = {"env_workers": 1, "update_dtype": "float32"}
    workers = {"env_workers": None, "update_dtype": "float32"}
    return {
        before: {**before_env, **one_process},
        f"{after}, one process": {**after_env, **one_process},
        "and the chain in worker processes": {**after_env, **workers},
        "and the update in bfloat16": {**after_env, **workers, "update_dtype": "bfloat16"},
    }


def training_profiles(args: Args, scratch: str) -> dict[str, list[dict[str, Any]]]:
    """The profiles of one-rollout training runs of every training configuration, in their
    order and then in reverse (each pair of runs sees the same load on average)."""
    runs = training_configurations(args)
    profiles: dict[str, list[dict[str, Any]]] = {name: [] for name in runs}
    for name in [*runs, *reversed(runs)]:
        profile = train_explorer.main(training_args(args, runs[name], scratch))["profile"]
        profiles[name].append(profile)
        print(f"{name}: training {profile['env_steps_per_s']} env steps/s", flush=True)
    return profiles


def ratios(rates: dict[str, float], base: float) -> dict[str, float]:
    return {name: round(rate / base, 2) for name, rate in rates.items()}


def main(args: Args) -> dict:
    names = list(configurations(args))
    with tempfile.TemporaryDirectory() as scratch:
        bare = bare_rates(args, scratch)
        for name, rate in bare.items():
            print(f"{name}: bare env {rate:.1f} env steps/s", flush=True)
        trained = training_profiles(args, scratch) if args.train else {}
    summary: dict[str, Any] = {
        "args": asdict(args),
        "load_end": os.getloadavg(),
        "bare_env_steps_per_s": {k: round(v, 1) for k, v in bare.items()},
        "bare_ratio_to_before": ratios(bare, bare[names[0]]),
    }
    if trained:
        # Both runs of a configuration together: their steps over their seconds.
        rates = {
            name: sum(p["env_steps"] for p in runs) / sum(p["wall_seconds"] for p in runs)
            for name, runs in trained.items()
        }
        summary["training_env_steps_per_s"] = {k: round(v, 1) for k, v in rates.items()}
        summary["training_ratio_to_before"] = ratios(rates, rates[names[0]])
        summary["training_shares"] = {
            name: {
                part: round(
                    sum(p["seconds"][part] for p in runs) / sum(p["wall_seconds"] for p in runs),
                    3,
                )
                for part in runs[0]["seconds"]
            }
            for name, runs in trained.items()
        }
        summary["training_profiles"] = trained
    Path(args.output_file).parent.mkdir(parents=True, exist_ok=True)
    Path(args.output_file).write_text(json.dumps(summary, indent=1) + "\n")
    print(json.dumps({k: v for k, v in summary.items() if k != "training_profiles"}, indent=1))
    return summary


if __name__ == "__main__":
    main(parse_dataclass_args(Args))
