"""The explorer's env cost per configuration. Results: docs/benchmarks/explorer.md

Steps the bare ``NarutoReconVectorEnv`` (no wrapper, no learner) with the explorer's settings
(:data:`naruto_gym.rl.explorer_env.EXPLORER_ENV`) in four configurations: the training mix's
four scene streams (every agent draws its own new scene at every episode end) or one fixed
scene all agents share, each with and without the depth panorama. ``max_episode_steps``
random forward / turn moves per agent after a warm-up, crossing one episode end. Writes the
env steps per second of each and their ratios to the training configuration; on a shared
machine only the ratios mean anything.

    nice -n 10 python benchmarks/explorer_env_cost.py
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from naruto_agent.cli_args import parse_dataclass_args
from naruto_gym.rl.explorer_env import EXPLORER_ENV, train_mix
from naruto_gym.vector import NarutoReconVectorEnv


@dataclass
class Args:
    num_envs: int = 16
    """agents"""
    max_episode_steps: int = 400
    """timed steps per agent (the episode length: one episode end is crossed)"""
    fixed_scene: str = "procedural:small:17"
    """the scene every agent shares in the fixed-scene rows"""
    output_file: str = "benchmarks/results/explorer_short/env_configs.json"
    """JSON written"""


def main(args: Args) -> dict:
    configs = {
        "train mix (4 streams), panorama 32x64": {"scene": train_mix(args.num_envs)},
        "train mix (4 streams), no panorama": {
            "scene": train_mix(args.num_envs),
            "panorama_shape": None,
        },
        "one shared scene, panorama 32x64": {"scene": args.fixed_scene},
        "one shared scene, no panorama": {"scene": args.fixed_scene, "panorama_shape": None},
    }
    rates = {}
    for name, extra in configs.items():
        env = NarutoReconVectorEnv(
            args.num_envs,
            max_episode_steps=args.max_episode_steps,
            autoreset_mode="SameStep",
            threads=1,
            **{**EXPLORER_ENV, **extra},
        )
        env.reset(seed=0)
        steps = args.max_episode_steps
        moves = np.random.default_rng(0).choice([0, 6, 7], size=(steps + 20, args.num_envs))
        for step in range(20):  # warm-up: compiled loops
            env.step(moves[step])
        started = time.perf_counter()
        for step in range(20, args.max_episode_steps + 20):
            env.step(moves[step])
        rates[name] = args.num_envs * args.max_episode_steps / (time.perf_counter() - started)
        env.close()
        print(f"{name}: {rates[name]:.1f} env steps/s", flush=True)
    base = rates["train mix (4 streams), panorama 32x64"]
    summary = {
        "args": asdict(args),
        "load_end": os.getloadavg(),
        "env_steps_per_s": {k: round(v, 1) for k, v in rates.items()},
        "ratio_to_training_config": {k: round(v / base, 2) for k, v in rates.items()},
    }
    Path(args.output_file).parent.mkdir(parents=True, exist_ok=True)
    Path(args.output_file).write_text(json.dumps(summary, indent=1) + "\n")
    return summary


if __name__ == "__main__":
    main(parse_dataclass_args(Args))
