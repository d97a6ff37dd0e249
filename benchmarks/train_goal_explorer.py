"""PPO on the decision at every goal, scored per candidate. Results: docs/benchmarks/explorer.md

Stable-Baselines3 PPO with :class:`~naruto_gym.rl.goal_choice_sb3.CandidateScorerPolicy` (one
small network scores every candidate; a softmax over the valid ones) on
:class:`~naruto_gym.rl.goal_choice_sb3.GoalDecisionVecEnv`: each agent on its own env, map and
goal actions with ``decision="goal"`` (:mod:`naruto_gym.rl.goal_actions`), so a decision
lasts until its goal is viewed or given up (at most ``steps_per_goal`` env steps) and the
walker walks only the chosen goal. The agents play generated scenes of the suite's train split
(:data:`~naruto_gym.rl.explorer_env.TRAIN_MIX`: closed and open, small and apartment
classes), a new scene every ``episodes_per_scene`` episodes. The reward is the env's: coverage
gain in percentage points over the decision, minus the collision penalty; the discount is per
decision.

One readable file in the manner of CleanRL: the arguments are the dataclass below (each field
a ``--flag``). Writes under ``output_dir``: ``learning_curve.csv`` (per rollout: env steps,
decisions, minutes, the finished episodes' mean final coverage and mean coverage over their
steps, env steps per decision, refusals per 100 steps), ``progress.csv`` (PPO's statistics
per update: losses, ``train/explained_variance``...), ``final_model.zip`` and ``explorer.zip``
(without the optimiser's state, what the ``explorer`` policy loads through ``model_path``),
each with its settings beside it (``.json``).

    OMP_NUM_THREADS=1 python benchmarks/train_goal_explorer.py --max-minutes 20 \\
        --output-dir /tmp/goal_explorer/seed0
"""

from __future__ import annotations

import csv
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.vec_env import VecNormalize

from naruto_agent.cli_args import parse_dataclass_args
from naruto_agent.rl.explorer_policy import export_checkpoint, save_settings
from naruto_gym.rl.explorer_env import EXPLORER_ENV
from naruto_gym.rl.goal_actions import GOAL_STEPS
from naruto_gym.rl.goal_choice_sb3 import CandidateScorerPolicy, GoalDecisionVecEnv


@dataclass
class Args:
    total_env_steps: int = 10_000_000
    """env steps to train for (all agents together)"""
    max_minutes: float | None = None
    """stop after this many minutes of wall-clock time, whatever the steps"""
    num_envs: int = 8
    """agents (a multiple of 4 mixes the four train streams evenly)"""
    max_episode_steps: int = 400
    """episode length in env steps"""
    steps_per_goal: int = GOAL_STEPS
    """the most env steps of one decision"""
    num_candidates: int = 8
    """candidate slots"""
    episodes_per_scene: int = 4
    """episodes an agent plays on a generated scene before it draws the next"""
    n_steps: int = 8
    """decisions per agent per rollout (a decision is about 29 env steps)"""
    batch_size: int = 32
    """minibatch size (decisions)"""
    n_epochs: int = 10
    """optimisation epochs per rollout (decisions are dear, updates cheap: many passes)"""
    learning_rate: float = 3e-4
    """Adam learning rate"""
    gamma: float = 0.95
    """discount per decision (about 13 decisions in a 400-step episode)"""
    gae_lambda: float = 0.95
    """GAE's lambda"""
    ent_coef: float = 0.01
    """entropy bonus"""
    normalize_reward: bool = True
    """scale the rewards by a running estimate of the discounted return's spread"""
    hidden: int = 64
    """width of the per-candidate scorer"""
    seed: int = 0
    """seed of the scene draws and of PPO"""
    torch_threads: int = 1
    """torch threads"""
    output_dir: str = "runs/goal_explorer"
    """output folder"""


def explorer_settings(args: Args) -> dict[str, Any]:
    """What the ``explorer`` policy needs to act as in training (saved beside every model)."""
    return {
        "decision": "goal",
        "steps_per_goal": args.steps_per_goal,
        "num_candidates": args.num_candidates,
        "primitive_actions": False,
        "map_options": {},
        "panorama_shape": list(EXPLORER_ENV["panorama_shape"]),
    }


class GoalCurve(BaseCallback):
    """Per rollout, a row of ``learning_curve.csv`` (module docstring); stops training at
    the step or time budget."""

    def __init__(self, args: Args) -> None:
        super().__init__()
        self.args = args
        self.path = Path(args.output_dir) / "learning_curve.csv"
        self.started = time.perf_counter()
        self.env_steps = self.decisions = self.refusals = 0
        self.rollout_steps = 0
        self.areas = np.zeros(args.num_envs)  # coverage x steps so far, per agent's episode
        self.last = np.zeros(args.num_envs)  # coverage after the agent's last decision
        self.finished: list[tuple[float, float]] = []  # (final coverage, mean coverage)

    def minutes(self) -> float:
        return (time.perf_counter() - self.started) / 60

    def _on_step(self) -> bool:
        for i, (info, done) in enumerate(
            zip(self.locals["infos"], self.locals["dones"], strict=True)
        ):
            steps = int(info.get("primitive_steps", 0))
            coverage = float(info.get("coverage", self.last[i]))
            self.env_steps += steps
            self.rollout_steps += steps
            self.decisions += 1
            self.refusals += int(info.get("refusals", 0))
            self.areas[i] += 0.5 * (self.last[i] + coverage) * steps
            self.last[i] = coverage
            if done:
                self.finished.append((coverage, self.areas[i] / self.args.max_episode_steps))
                self.areas[i], self.last[i] = 0.0, 0.0
        over_time = self.args.max_minutes is not None and self.minutes() >= self.args.max_minutes
        return self.env_steps < self.args.total_env_steps and not over_time

    def _on_rollout_end(self) -> None:
        finals = [f for f, _ in self.finished]
        means = [m for _, m in self.finished]
        row = {
            "env_steps": self.env_steps,
            "decisions": self.decisions,
            "minutes": round(self.minutes(), 2),
            "episodes": len(self.finished),
            "final_coverage": round(float(np.mean(finals)), 4) if finals else "",
            "mean_coverage": round(float(np.mean(means)), 4) if means else "",
            "env_steps_per_decision": round(self.env_steps / max(self.decisions, 1), 2),
            "refusals_per_100_steps": round(100 * self.refusals / max(self.rollout_steps, 1), 3),
        }
        self.finished, self.refusals, self.rollout_steps = [], 0, 0
        new = not self.path.exists()
        with self.path.open("a", newline="") as handle:
            writer = csv.DictWriter(handle, fieldnames=list(row))
            if new:
                writer.writeheader()
            writer.writerow(row)
        if row["mean_coverage"] != "":
            self.logger.record("rollout/mean_coverage", row["mean_coverage"])


def main(args: Args) -> Path:
    torch.set_num_threads(args.torch_threads)
    out = Path(args.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    for name in ("learning_curve.csv", "progress.csv"):
        (out / name).unlink(missing_ok=True)
    venv: Any = GoalDecisionVecEnv(
        args.num_envs,
        max_episode_steps=args.max_episode_steps,
        steps_per_goal=args.steps_per_goal,
        num_candidates=args.num_candidates,
        episodes_per_scene=args.episodes_per_scene,
        seed=args.seed,
    )
    if args.normalize_reward:
        venv = VecNormalize(venv, norm_obs=False, norm_reward=True, gamma=args.gamma)
    model = PPO(
        CandidateScorerPolicy,
        venv,
        n_steps=args.n_steps,
        batch_size=args.batch_size,
        n_epochs=args.n_epochs,
        learning_rate=args.learning_rate,
        gamma=args.gamma,
        gae_lambda=args.gae_lambda,
        ent_coef=args.ent_coef,
        policy_kwargs={"hidden": args.hidden},
        seed=args.seed,
        device="cpu",
    )
    model.set_logger(configure(str(out), ["csv"]))
    (out / "args.json").write_text(json.dumps(asdict(args), indent=1))
    model.learn(total_timesteps=10**12, callback=GoalCurve(args))
    final = out / "final_model.zip"
    model.save(final)
    save_settings(final, explorer_settings(args))
    export_checkpoint(final, out / "explorer.zip")
    venv.close()
    return final


if __name__ == "__main__":
    main(parse_dataclass_args(Args))
