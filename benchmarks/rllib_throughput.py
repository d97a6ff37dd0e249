"""Env steps/s of RLlib's env runners on the batched env, against the number of env runners.
Results: docs/benchmarks/throughput.md ("RLlib env runners")

The algorithm is ``examples/rllib_ppo.py``'s PPO on the new API stack: a 32 x 32 camera, the
panorama off, discrete actions, the learning observations flattened for RLlib's default MLP,
the default two-room scene. Each env runner steps one vector env of ``num_envs`` agents, built
as ``vectorization_mode`` says: ``vector_entry_point`` (the batched ``NarutoReconVectorEnv``,
one process stepping all agents) or ``sync`` (Gymnasium's ``SyncVectorEnv`` of single envs,
RLlib's default), so the batched env is compared with RLlib's own vectorization in the same
run. For each mode and each runner count (0: the driver samples; N: N Ray actors of one CPU
each, sampling in parallel) two figures are reported, with the load average beside them:

* ``sample_steps_per_s``: env steps per second of sampling alone (env steps and the
  RLModule's action inference on every runner), timed over calls of ``EnvRunner.sample`` on
  all runners at once for ``seconds``;
* ``train_steps_per_s``: env steps per second of whole ``Algorithm.train()`` iterations
  (sampling, then the learner's PPO update in the driver), over ``train_iterations``
  iterations of ``train_batch_size`` steps.

The driver's torch runs on ``torch_threads`` threads (1 by default, as Ray gives each env
runner actor of one CPU): on a loaded machine torch's default of one thread per core makes
the small inference batches of a sampler in the driver many times slower.

Runs on a local Ray instance (all the machine's CPUs, or ``--num-cpus``) or on a cluster
(``--address auto`` on a node of a cluster started with ``ray start``).

    python benchmarks/rllib_throughput.py
    python benchmarks/rllib_throughput.py --counts 0 1 2 4 8 --address auto   # on a cluster
"""

from __future__ import annotations

import importlib.util
import json
import os
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import gymnasium as gym
import torch

from naruto_agent.cli_args import parse_dataclass_args

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "rllib_ppo.py"


@dataclass
class Args:
    counts: list[int] = field(default_factory=lambda: [0, 1, 2])
    """numbers of remote env runners to time (0: the driver samples)"""
    modes: list[str] = field(default_factory=lambda: ["vector_entry_point", "sync"])
    """how each runner builds its vector env (see examples/rllib_ppo.py)"""
    num_envs: int = 16
    """agents per env runner"""
    max_episode_steps: int = 100
    """episode budget (each runner's agents are reset when it ends)"""
    sample_steps: int = 512
    """env steps each runner samples per call (all its agents together)"""
    seconds: float = 8.0
    """sampling time per row, after one warm-up call"""
    train_batch_size: int = 1024
    """env steps per training iteration"""
    train_iterations: int = 2
    """timed training iterations per row, after one warm-up iteration"""
    address: str | None = None
    """Ray cluster to join (auto, or ray://host:10001); none: start a local instance"""
    num_cpus: int | None = None
    """CPUs of the local Ray instance (none: all the machine has)"""
    torch_threads: int | None = 1
    """torch threads of the driver (the sampler with 0 runners, and the learner); 1 as Ray
    gives each env-runner actor of one CPU; none: torch's default (all cores)"""
    output_file: str = "benchmarks/results/rllib_throughput.json"
    """JSON summary"""


def load_example() -> Any:
    """``examples/rllib_ppo.py`` as a module (the env creator and PPO settings timed here)."""
    spec = importlib.util.spec_from_file_location("rllib_ppo", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    sys.modules["rllib_ppo"] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def load() -> list[float]:
    return [round(value, 2) for value in os.getloadavg()]


def sample_rate(algorithm: Any, runners: int, steps: int, seconds: float) -> float:
    """Env steps/s of ``EnvRunner.sample`` called on every runner at once."""

    def sample(runner: Any) -> int:
        return sum(len(episode) for episode in runner.sample(num_timesteps=steps))

    def one_round() -> int:
        if runners == 0:
            return sample(algorithm.env_runner)
        return sum(algorithm.env_runner_group.foreach_env_runner(sample,
                                                                 local_env_runner=False))

    one_round()  # warm-up: first resets, compiled kernels, the first inference
    total, started = 0, time.perf_counter()
    while time.perf_counter() - started < seconds:
        total += one_round()
    return total / (time.perf_counter() - started)


def train_rate(algorithm: Any, iterations: int) -> float:
    """Env steps/s of whole training iterations (sampling plus the learner's update)."""

    def lifetime(result: dict[str, Any]) -> float:
        return float(result["env_runners"]["num_env_steps_sampled_lifetime"])

    before = lifetime(algorithm.train())  # warm-up iteration
    started = time.perf_counter()
    for _ in range(iterations):
        after = lifetime(algorithm.train())
    return (after - before) / (time.perf_counter() - started)


def time_row(example: Any, PPOConfig: Any, args: Args, mode: str,  # noqa: N803
             runners: int) -> dict[str, Any]:
    example_args = replace(
        example.Args(), num_env_runners=runners, num_envs_per_env_runner=args.num_envs,
        vectorization_mode=mode, episode_steps=args.max_episode_steps,
        train_batch_size=args.train_batch_size, minibatch_size=256,
    )
    algorithm = example.build_algorithm(PPOConfig, example_args)
    try:
        sampled = sample_rate(algorithm, runners, args.sample_steps, args.seconds)
        load_sampling = load()
        trained = train_rate(algorithm, args.train_iterations)
    finally:
        algorithm.stop()
    return {"mode": mode, "env_runners": runners, "num_envs_per_env_runner": args.num_envs,
            "sample_steps_per_s": round(sampled, 1), "train_steps_per_s": round(trained, 1),
            "load_sampling": load_sampling, "load": load()}


def main(args: Args) -> dict[str, Any]:
    if args.torch_threads:
        torch.set_num_threads(args.torch_threads)
    example = load_example()
    for mode in args.modes:
        example.env_config(replace(example.Args(), vectorization_mode=mode))  # checks the mode
    ray, PPOConfig, register_env = example.import_rllib()  # noqa: N806 (RLlib's class name)
    register_env(example.ENV_NAME, example.make_rllib_env)
    example.init_ray(ray, example.Args(address=args.address, num_cpus=args.num_cpus))
    results: dict[str, Any] = {
        "args": asdict(args), "cpus": os.cpu_count(), "ray_cpus": ray.cluster_resources().get(
            "CPU"), "ray": ray.__version__, "gymnasium": gym.__version__,
        "torch_threads": torch.get_num_threads(),
        "load_start": load(), "rows": [],
    }
    print(f"Ray {ray.__version__}, {results['ray_cpus']} CPUs, load average at start: "
          f"{results['load_start']}")
    try:
        for mode in args.modes:
            for runners in args.counts:
                row = time_row(example, PPOConfig, args, mode, runners)
                results["rows"].append(row)
                print(f"{mode:>18}, {runners} env runners x {args.num_envs} envs: sampling "
                      f"{row['sample_steps_per_s']:.0f} steps/s (load {row['load_sampling']}), "
                      f"training {row['train_steps_per_s']:.0f} steps/s (load {row['load']})")
    finally:
        ray.shutdown()
    output = Path(args.output_file)
    output.parent.mkdir(parents=True, exist_ok=True)
    output.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {output}")
    return results


if __name__ == "__main__":
    main(parse_dataclass_args(Args))
