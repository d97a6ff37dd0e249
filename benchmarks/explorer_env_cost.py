"""The explorer's training throughput, before and after shared scenes and the panorama band,
in one run. Results: docs/benchmarks/explorer.md

Builds the batched env as ``benchmarks/train_explorer.py`` does (:func:`make_batched_env`) in
three configurations:

* before: the train mix with a scene of its own per agent per episode, every panorama row;
* shared scenes (:func:`naruto_gym.rl.explorer_env.shared_train_mix`; by default with a new
  scene for every episode, so that the episode end timed pays for the groups' new scenes, as
  training pays every ``episodes_per_scene``-th), every panorama row;
* after: shared scenes, and only the panorama rows within ``panorama_horizon_deg`` of the
  horizon (the rows the explorer's map reads).

For each it times the bare batched env (random forward / turn moves, no wrapper, no learner)
over ``max_episode_steps + 20`` steps per agent after a warm-up, crossing one episode end with
its new scenes; for the first and last it also times training end to end: Stable-Baselines3
PPO through the map and goal wrappers for one rollout that crosses an episode end, and its
update (``train_explorer.main``, whose ``profile`` splits the time). It writes env steps per
second of wall-clock time and per CPU second of this process, their ratios to the bare
"before" env, and each training run's ratio to its own bare env. On a machine shared with
other work the wall-clock rates follow the load from one part of the run to the next; the
rates per CPU second do not, and their ratios are the ones to read.

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
    train: bool = True
    """also time PPO training end to end in the before and after configurations"""
    output_file: str = "benchmarks/results/explorer_short/env_configs.json"
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


def bare_rate(settings: train_explorer.Args) -> tuple[float, float]:
    """Env steps per second of wall-clock time and per CPU second of the bare batched env
    over one episode end."""
    env = train_explorer.make_batched_env(settings)
    env.reset(seed=0)
    steps = settings.max_episode_steps
    moves = np.random.default_rng(0).choice([0, 6, 7], size=(steps + 40, settings.num_envs))
    for step in range(20):  # warm-up: compiled loops
        env.step(moves[step])
    started, cpu_started = time.perf_counter(), time.process_time()
    for step in range(20, steps + 40):
        env.step(moves[step])
    wall, cpu = time.perf_counter() - started, time.process_time() - cpu_started
    env.close()
    return settings.num_envs * (steps + 20) / wall, settings.num_envs * (steps + 20) / cpu


def ratios(rates: dict[str, float], base: float) -> dict[str, float]:
    return {name: round(rate / base, 3) for name, rate in rates.items()}


def main(args: Args) -> dict:
    bare_wall: dict[str, float] = {}
    bare_cpu: dict[str, float] = {}
    trained: dict[str, dict[str, Any]] = {}
    names = list(configurations(args))
    with tempfile.TemporaryDirectory() as scratch:
        for name, options in configurations(args).items():
            settings = training_args(args, options, scratch)
            bare_wall[name], bare_cpu[name] = bare_rate(settings)
            print(
                f"{name}: bare env {bare_wall[name]:.1f} env steps/s, "
                f"{bare_cpu[name]:.1f} per CPU second",
                flush=True,
            )
            if args.train and name in (names[0], names[-1]):
                trained[name] = train_explorer.main(settings)["profile"]
                print(
                    f"{name}: training {trained[name]['env_steps_per_s']} env steps/s, "
                    f"{trained[name]['env_steps_per_cpu_s']} per CPU second",
                    flush=True,
                )
    summary: dict[str, Any] = {
        "args": asdict(args),
        "load_end": os.getloadavg(),
        "bare_env_steps_per_cpu_s": {k: round(v, 1) for k, v in bare_cpu.items()},
        "bare_env_steps_per_s": {k: round(v, 1) for k, v in bare_wall.items()},
        "bare_ratio_to_before_cpu": ratios(bare_cpu, bare_cpu[names[0]]),
        "bare_ratio_to_before_wall": ratios(bare_wall, bare_wall[names[0]]),
    }
    if trained:
        cpu = {k: p["env_steps_per_cpu_s"] for k, p in trained.items()}
        wall = {k: p["env_steps_per_s"] for k, p in trained.items()}
        summary["training_env_steps_per_cpu_s"] = cpu
        summary["training_env_steps_per_s"] = wall
        summary["training_ratio_to_own_bare_env_cpu"] = {
            k: round(v / bare_cpu[k], 3) for k, v in cpu.items()
        }
        summary["training_ratio_to_own_bare_env_wall"] = {
            k: round(v / bare_wall[k], 3) for k, v in wall.items()
        }
        summary["training_ratio_after_to_before_cpu"] = round(cpu[names[-1]] / cpu[names[0]], 2)
        summary["training_ratio_after_to_before_wall"] = round(wall[names[-1]] / wall[names[0]], 2)
        summary["training_profiles"] = trained
    Path(args.output_file).parent.mkdir(parents=True, exist_ok=True)
    Path(args.output_file).write_text(json.dumps(summary, indent=1) + "\n")
    print(json.dumps({k: v for k, v in summary.items() if k != "training_profiles"}, indent=1))
    return summary


if __name__ == "__main__":
    main(parse_dataclass_args(Args))
