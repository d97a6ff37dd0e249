"""PPO that learns to explore generated rooms. Results: docs/benchmarks/ppo.md

Stable-Baselines3 PPO on the batched vector env, a new procedural room every episode.

One readable file in the manner of CleanRL: the arguments are the dataclass below (each field a
``--flag``). The agent sees low-resolution frames (the default camera at ``image_scale``,
resized to ``size`` square), depth as an image, and its pose as position + 6D rotation; it
acts with the 10 discrete moves; every episode is a new generated room from the training
split (``procedural:room``). The reward is the env's: coverage gain in percentage points minus
a collision penalty.

Writes under ``output_dir``: checkpoints every ``checkpoint_every`` steps, ``final_model.zip``,
``learning_curve.csv`` and ``.png`` (mean final coverage of the episodes finished in each
rollout), and TensorBoard logs when ``tensorboard`` is installed. Evaluate with
``naruto-benchmark`` (see ``naruto_agent/rl/ppo_policy.py``).

    nice -n 19 python benchmarks/train_ppo.py --total-timesteps 1000000 --max-hours 1
    python benchmarks/train_ppo.py --total-timesteps 2048 --num-envs 4   # smoke run
"""

from __future__ import annotations

import csv
import importlib.util
import json
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback, CallbackList, CheckpointCallback

from naruto_agent.cli_args import parse_dataclass_args
from naruto_gym.rl.sb3 import NarutoFeaturesExtractor, make_sb3_vec_env
from naruto_gym.sensors.pinhole import PinholeCamera


@dataclass
class Args:
    total_timesteps: int = 200_000
    """env steps to train for (all envs together)"""
    num_envs: int = 16
    """agents stepped together by the batched vector env"""
    scene: str = "procedural:room"
    """scene stream (or one scene) to train on"""
    image_scale: float = 0.1
    """camera resolution factor of the default 680 x 1200 camera (0.1: 68 x 120)"""
    size: int = 64
    """square side the frames are resized to"""
    top_down_map: bool = False
    """add the egocentric top-down map of what the episode has seen and what is occupied"""
    max_episode_steps: int = 250
    """episode budget in steps (250, as the reported runs and their evaluation)"""
    coverage_samples: int = 5000
    """coverage samples per scene (fewer makes a new scene cheaper)"""
    n_steps: int = 128
    """rollout length per env between updates"""
    batch_size: int = 256
    """minibatch size"""
    n_epochs: int = 4
    """optimisation epochs per rollout"""
    learning_rate: float = 3e-4
    """Adam learning rate"""
    gamma: float = 0.99
    """discount"""
    ent_coef: float = 0.01
    """entropy bonus"""
    features_dim: int = 256
    """size of the features extractor's output"""
    seed: int = 0
    """seed of the envs and of PPO"""
    torch_threads: int = 1
    """torch threads (the envs use the other core)"""
    checkpoint_every: int = 50_000
    """env steps between checkpoints"""
    max_hours: float | None = None
    """stop after this much wall-clock time (at the end of a rollout), whatever the steps"""
    output_dir: str = "runs/ppo"
    """output folder"""


class CoverageCurve(BaseCallback):
    """Final coverage of finished episodes per rollout: logged, written to CSV, plotted."""

    def __init__(self, path: Path) -> None:
        super().__init__()
        self.path = path
        self.finished: list[float] = []
        self.rows: list[dict[str, float]] = []
        self.started = time.perf_counter()

    def _on_step(self) -> bool:
        for info, done in zip(self.locals["infos"], self.locals["dones"], strict=True):
            if done and "final_info" in info:
                self.finished.append(float(info["final_info"]["coverage"]))
        return True

    def _on_rollout_end(self) -> None:
        if not self.finished:
            return
        row = {"timesteps": self.num_timesteps, "episodes": len(self.finished),
               "final_coverage": float(np.mean(self.finished)),
               "hours": (time.perf_counter() - self.started) / 3600}
        self.rows.append(row)
        self.logger.record("rollout/final_coverage", row["final_coverage"])
        self.finished = []
        with self.path.open("w", newline="") as handle:
            writer = csv.DictWriter(handle, fieldnames=list(row))
            writer.writeheader()
            writer.writerows(self.rows)

    def plot(self) -> None:
        if not self.rows:
            return
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        figure, axis = plt.subplots(figsize=(6, 3.5))
        axis.plot([r["timesteps"] for r in self.rows],
                  [100 * r["final_coverage"] for r in self.rows])
        axis.set_xlabel("env steps")
        axis.set_ylabel("final coverage of training episodes (%)")
        axis.set_title("PPO on procedural rooms")
        figure.tight_layout()
        figure.savefig(self.path.with_suffix(".png"), dpi=120)


class WallClockBudget(BaseCallback):
    """Stops training once ``hours`` of wall-clock time have passed (checked every step)."""

    def __init__(self, hours: float) -> None:
        super().__init__()
        self.deadline = time.perf_counter() + hours * 3600

    def _on_step(self) -> bool:
        return time.perf_counter() < self.deadline


class ProgressBar(BaseCallback):
    """A tqdm bar over the env steps."""

    def _on_training_start(self) -> None:
        from tqdm.auto import tqdm

        self.bar = tqdm(total=self.locals["total_timesteps"], unit="step", smoothing=0.05)

    def _on_step(self) -> bool:
        self.bar.update(self.training_env.num_envs)
        return True

    def _on_training_end(self) -> None:
        self.bar.close()


def main(args: Args) -> dict[str, Any]:
    run_dir = Path(args.output_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(args.torch_threads)
    camera = PinholeCamera().scaled(args.image_scale)
    venv = make_sb3_vec_env(
        args.num_envs, size=args.size, top_down_map=args.top_down_map, scene=args.scene,
        camera=camera,
        max_episode_steps=args.max_episode_steps, coverage_samples=args.coverage_samples,
    )
    venv.seed(args.seed)
    tensorboard = str(run_dir / "tensorboard") if importlib.util.find_spec("tensorboard") else None
    model = PPO(
        "MultiInputPolicy", venv, n_steps=args.n_steps, batch_size=args.batch_size,
        n_epochs=args.n_epochs, learning_rate=args.learning_rate, gamma=args.gamma,
        ent_coef=args.ent_coef, seed=args.seed, tensorboard_log=tensorboard, device="cpu",
        policy_kwargs={"features_extractor_class": NarutoFeaturesExtractor,
                       "features_extractor_kwargs": {"features_dim": args.features_dim}},
    )
    curve = CoverageCurve(run_dir / "learning_curve.csv")
    checkpoints = CheckpointCallback(max(args.checkpoint_every // args.num_envs, 1),
                                     str(run_dir / "checkpoints"), name_prefix="ppo")
    started = time.perf_counter()
    callbacks = [curve, checkpoints, ProgressBar()]
    if args.max_hours is not None:
        callbacks.append(WallClockBudget(args.max_hours))
    model.learn(args.total_timesteps, callback=CallbackList(callbacks))
    hours = (time.perf_counter() - started) / 3600
    model.save(run_dir / "final_model.zip")
    curve.plot()
    summary = {"args": asdict(args), "hours": hours, "timesteps": model.num_timesteps,
               "load_end": os.getloadavg(), "curve": curve.rows}
    (run_dir / "summary.json").write_text(json.dumps(summary, indent=1))
    print(f"trained {model.num_timesteps} steps in {hours:.2f} h; wrote {run_dir}")
    return summary


if __name__ == "__main__":
    main(parse_dataclass_args(Args))
