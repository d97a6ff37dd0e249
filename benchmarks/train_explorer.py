"""PPO over the egocentric map with goal actions. Results: docs/benchmarks/explorer.md

Stable-Baselines3 PPO on the batched env, on generated scenes of the closed and open variants
of the suite's small and flat classes (:data:`naruto_gym.rl.explorer_env.TRAIN_MIX`):
the agents in groups of ``agents_per_scene`` that share a scene for ``episodes_per_scene``
episodes, then the next of their stream (:func:`naruto_gym.rl.explorer_env.shared_train_mix`;
``--no-shared-scenes``: every agent draws and builds a scene of its own every episode, the
dearer way). ``--panorama-horizon-deg 30`` casts only the panorama rows the map reads (a
third of the rays); it is saved with the model's settings, and the policy must then be shown
the same band at evaluation (``EquirectangularCamera.keep_cast_rows``). The env and its
map and goal wrappers step in worker processes, each a share of the scene groups
(``--env-workers``, :class:`naruto_gym.vector.sharded_wrapped.ShardedWrappedEnv`), while
the learner waits; ``--update-dtype bfloat16`` runs the features extractor's CNNs in the
PPO update under autocast.

The agent sees the egocentric map (occupied,
free, seen surface, frontier and trail, near and far, :mod:`naruto_gym.rl.egocentric_map`),
the depth panorama and its pose relative to the start; every ``steps_per_goal`` env steps it
picks a goal on the far map (or a repeated discrete move), which a planner over its own map
walks (:mod:`naruto_gym.rl.goal_actions`). The reward is the env's: coverage gain in
percentage points minus the collision penalty, summed over the macro-step.

One readable file in the manner of CleanRL: the arguments are the dataclass below (each field
a ``--flag``). Writes under ``output_dir``: ``learning_curve.csv`` and ``.png`` after every
rollout (mean final coverage of the episodes finished, per training scene kind, refusals per
100 steps, env steps per second), ``progress.csv`` (PPO's statistics per update: losses,
explained variance, KL; a resumed run moves the earlier file to ``progress_until_<env
steps>_steps.csv``), ``profile.json`` (where a step's time goes: the env, the map
and goal wrappers, the policy's forward passes, the PPO update), checkpoints every
``checkpoint_every`` env steps, ``final_model.zip``, and ``explorer.zip`` (the final model
without the optimiser's state, at most 5 MB: what ``naruto_agent/rl/checkpoints/`` ships), each
with its settings beside it (``.json``, read by the policy). ``--resume`` continues from the
latest checkpoint of ``output_dir`` (the curve continues too).

    nice -n 10 python benchmarks/train_explorer.py --total-timesteps 20000000 --max-hours 2
    python benchmarks/train_explorer.py --total-timesteps 16000 --num-envs 4  # smoke run

Evaluate with ``naruto-benchmark --policies explorer`` (see
:mod:`naruto_agent.rl.explorer_policy`).
"""

from __future__ import annotations

import csv
import json
import os
import re
import time
from dataclasses import asdict, dataclass
from functools import partial
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium.vector import AutoresetMode
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.logger import configure
from stable_baselines3.common.vec_env import VecEnv, VecNormalize

from naruto_agent.cli_args import parse_dataclass_args
from naruto_agent.rl.explorer_policy import export_checkpoint, save_settings
from naruto_gym.rl.explorer_env import (
    EXPLORER_ENV,
    TRAIN_MIX,
    shared_train_mix,
    train_mix,
    wrap_explorer,
)
from naruto_gym.rl.explorer_sb3 import ExplorerFeaturesExtractor
from naruto_gym.rl.sb3 import Sb3VecEnv
from naruto_gym.utils.threads import default_thread_count
from naruto_gym.vector import make_vector_env
from naruto_gym.vector.sharded_wrapped import ShardedWrappedEnv


@dataclass
class Args:
    total_timesteps: int = 2_000_000
    """env steps to train for (all agents together; one PPO step is steps_per_goal of them)"""
    num_envs: int = 16
    """agents stepped together by the batched env (a multiple of 4 mixes the train scenes)"""
    max_episode_steps: int = 400
    """episode length in env steps (the small class's budget; a multiple of steps_per_goal)"""
    steps_per_goal: int = 20
    """env steps walked per goal (K)"""
    num_candidates: int = 8
    """candidate goals offered per decision (the nearest first)"""
    primitive_actions: bool = True
    """the 10 discrete moves are actions too (repeated for the K steps, guarded by the map)"""
    n_steps: int = 32
    """PPO steps (goals) per agent per rollout"""
    batch_size: int = 128
    """minibatch size"""
    n_epochs: int = 4
    """optimisation epochs per rollout"""
    learning_rate: float = 3e-4
    """Adam learning rate"""
    gamma: float = 0.95
    """discount per goal (0.95 over K=20 steps is about 0.9975 per env step)"""
    ent_coef: float = 0.01
    """entropy bonus"""
    normalize_reward: bool = False
    """scale the rewards PPO learns from by a running estimate of the discounted return's
    spread (``VecNormalize``; coverage gains in percentage points otherwise give returns in
    the hundreds); saved beside each checkpoint and read back on --resume"""
    features_dim: int = 128
    """size of the features extractor's output"""
    update_dtype: str = "auto"
    """precision of the features extractor in the PPO update: "bfloat16" runs its CNNs under
    autocast (about twice as fast on CPUs with bfloat16 instructions), "float32" as they are,
    "auto" bfloat16 where the CPU has those instructions; the policy's and value's heads, the
    parameters, the optimiser and the rollouts' forward passes stay float32"""
    seed: int = 0
    """seed of the envs and of PPO"""
    torch_threads: int | None = None
    """torch threads (None: every CPU this process may use; the learner and the env take
    turns, so each gets them all)"""
    env_threads: int | None = None
    """threads of the env's compiled loops (None: every CPU this process may use; with
    env_workers above 1, the CPUs split between the worker processes)"""
    env_workers: int | None = None
    """processes that step the env with the map and goal wrappers, each a share of the
    agents (whole groups of agents_per_scene); 1: in this process, the env's time and the
    wrappers' timed apart; None: the most, up to one per CPU, that share the groups evenly"""
    shared_scenes: bool = True
    """agents in groups on shared scenes, each kept for episodes_per_scene episodes (a scene
    built once for many episodes, a group's rays cast in one call); --no-shared-scenes: every
    agent draws and builds its own scene every episode"""
    agents_per_scene: int | None = None
    """agents sharing a scene (None: num_envs / 4, so that each of the four train streams
    gets one group)"""
    episodes_per_scene: int = 4
    """episodes each agent plays in a shared scene before its group draws the next"""
    panorama_horizon_deg: float | None = None
    """cast only the panorama rows within this elevation of the horizon (30: the rows the map
    reads, a third of the rays; None: every row); the policy must see the same band"""
    checkpoint_every: int = 200_000
    """env steps between checkpoints"""
    max_hours: float | None = None
    """stop after this much wall-clock time (checked every PPO step), whatever the steps"""
    resume: bool = False
    """continue from the latest checkpoint in output_dir"""
    output_dir: str = "runs/explorer"
    """output folder"""


class Timed(gym.vector.VectorWrapper):
    """Adds the seconds spent in the wrapped env's ``step`` and ``reset`` to ``seconds``."""

    def __init__(self, env: gym.vector.VectorEnv) -> None:
        super().__init__(env)
        self.seconds = 0.0

    def reset(self, **kwargs: Any):
        started = time.perf_counter()
        try:
            return self.env.reset(**kwargs)
        finally:
            self.seconds += time.perf_counter() - started

    def step(self, actions: Any):
        started = time.perf_counter()
        try:
            return self.env.step(actions)
        finally:
            self.seconds += time.perf_counter() - started


def make_batched_env(args: Args) -> gym.vector.VectorEnv:
    """The bare batched env the explorer trains in (in this process: the learner takes the
    other core)."""
    return make_vector_env(
        args.num_envs,
        workers=1,
        scene=training_scenes(args),
        max_episode_steps=args.max_episode_steps,
        autoreset_mode=AutoresetMode.SAME_STEP,
        **env_settings(args),
    )


def make_env(args: Args) -> tuple[Sb3VecEnv, Timed | None, Timed]:
    """The training env, with timers around the bare env (None when the chain steps in
    worker processes) and around the whole chain."""
    wrap = partial(
        wrap_explorer,
        steps_per_goal=args.steps_per_goal,
        num_candidates=args.num_candidates,
        primitive_actions=args.primitive_actions,
    )
    workers = env_workers(args)
    if workers > 1:
        chain = Timed(
            ShardedWrappedEnv(
                wrap,
                args.num_envs,
                workers,
                training_scenes(args),
                max_episode_steps=args.max_episode_steps,
                autoreset_mode=AutoresetMode.SAME_STEP,
                **env_settings(args),
            )
        )
        return Sb3VecEnv(chain), None, chain
    bare = Timed(make_batched_env(args))
    chain = Timed(wrap(bare))
    return Sb3VecEnv(chain), bare, chain


def env_workers(args: Args) -> int:
    """The processes that step the chain: ``env_workers``, or one per group of agents on a
    shared scene (one per agent without shared scenes), at most one per CPU."""
    if args.env_workers is not None:
        return args.env_workers
    groups = args.num_envs // group_size(args) if args.shared_scenes else args.num_envs
    cpus = args.env_threads or default_thread_count()
    # Whole groups per worker: the most workers that divide the groups evenly.
    return max(k for k in range(1, max(1, min(groups, cpus)) + 1) if groups % k == 0)


def training_scenes(args: Args) -> Any:
    """The batched env's ``scene``: the train mix on shared scenes, or one stream per agent."""
    if args.shared_scenes:
        return shared_train_mix(group_size(args), args.episodes_per_scene)
    return train_mix(args.num_envs)


def group_size(args: Args) -> int:
    """Agents per shared scene: ``agents_per_scene``, or a quarter of the agents (one group
    per train stream; at least one agent)."""
    if args.agents_per_scene is not None:
        return args.agents_per_scene
    return max(1, args.num_envs // len(TRAIN_MIX))


def agent_streams(args: Args) -> list[str]:
    """Each agent's train stream (for the learning curve's per-kind columns)."""
    scenes = training_scenes(args)
    return scenes.agent_streams(args.num_envs) if args.shared_scenes else scenes


def env_settings(args: Args) -> dict[str, Any]:
    """The batched env's settings: the explorer's, the threads and the panorama band."""
    return {
        **EXPLORER_ENV,
        "threads": args.env_threads or default_thread_count(),
        "panorama_horizon_deg": args.panorama_horizon_deg,
    }


class LearningCurve(BaseCallback):
    """Per rollout: mean final coverage of the finished episodes (all, and per train scene),
    refusals per 100 env steps, env steps per second; appended to a CSV, plotted at the end;
    and the time split of ``profile.json``."""

    def __init__(self, args: Args, bare: Timed | None, chain: Timed, first_row: int) -> None:
        super().__init__()
        self.args = args
        self.path = Path(args.output_dir) / "learning_curve.csv"
        self.bare, self.chain = bare, chain
        self.kinds = agent_streams(args)
        self.finished: list[tuple[str, float]] = []
        self.refusals = 0
        self.rollouts = first_row
        self.forward_seconds = 0.0  # in a rollout, outside the env chain
        self.chain_mark = 0.0
        self.update_seconds = 0.0
        self.mark = time.perf_counter()
        self.started = time.perf_counter()
        self.ended: float | None = None
        self.env_seconds_at_start = 0.0
        self.chain_seconds_at_start = 0.0
        # This process's CPU time too: on a machine shared with other work, rates per CPU
        # second compare runs where wall-clock rates follow the load.
        self.cpu_started = time.process_time()
        self.cpu_ended: float | None = None
        self.in_rollout = False
        self.steps_at_start: int | None = None

    def _on_training_start(self) -> None:
        # The clocks start after the first reset (its scenes built once per run, not per
        # step); the profile counts the env's and the wrappers' seconds from here too.
        self.steps_at_start = self.num_timesteps
        self.started = self.mark = time.perf_counter()
        self.cpu_started = time.process_time()
        self.env_seconds_at_start = self.env_seconds()
        self.chain_seconds_at_start = self.chain.seconds

    def _on_training_end(self) -> None:
        self.ended = time.perf_counter()
        self.cpu_ended = time.process_time()
        if not self.in_rollout:  # the last update (none when stopped inside a rollout)
            self.update_seconds += self.ended - self.mark

    def _on_rollout_start(self) -> None:
        now = time.perf_counter()
        if self.rollouts:
            self.update_seconds += now - self.mark
        self.mark = now
        self.chain_mark = self.chain.seconds
        self.in_rollout = True

    def _on_step(self) -> bool:
        for i, (info, done) in enumerate(
            zip(self.locals["infos"], self.locals["dones"], strict=True)
        ):
            self.refusals += int(info.get("refusals", 0))
            if done and "final_info" in info:
                self.finished.append((self.kinds[i], float(info["final_info"]["coverage"])))
        return True

    def env_steps(self) -> int:
        return self.num_timesteps * self.args.steps_per_goal

    def env_seconds(self) -> float:
        """Seconds in the bare env so far; with the chain in worker processes, in the whole
        chain (its env and wrappers cannot be timed apart from here)."""
        return (self.bare or self.chain).seconds

    def _on_rollout_end(self) -> None:
        now = time.perf_counter()
        self.forward_seconds += now - self.mark - (self.chain.seconds - self.chain_mark)
        self.mark = now
        self.in_rollout = False
        self.rollouts += 1
        hours = (now - self.started) / 3600
        steps = (self.num_timesteps - (self.steps_at_start or 0)) * self.args.steps_per_goal
        row: dict[str, Any] = {
            "env_steps": self.env_steps(),
            "hours": round(hours, 4),
            "env_steps_per_s": round(steps / max(now - self.started, 1e-9), 1),
            "episodes": len(self.finished),
            "final_coverage": (
                float(np.mean([c for _, c in self.finished])) if self.finished else ""
            ),
            "refusals_per_100_steps": round(
                100
                * self.refusals
                / max(self.args.num_envs * self.args.n_steps * self.args.steps_per_goal, 1),
                3,
            ),
        }
        for kind in sorted(set(self.kinds)):
            values = [c for k, c in self.finished if k == kind]
            row[kind] = float(np.mean(values)) if values else ""
        self.finished, self.refusals = [], 0
        new = not self.path.exists()
        with self.path.open("a", newline="") as handle:
            writer = csv.DictWriter(handle, fieldnames=list(row))
            if new:
                writer.writeheader()
            writer.writerow(row)
        if row["final_coverage"] != "":
            self.logger.record("rollout/final_coverage", row["final_coverage"])

    def profile(self) -> dict[str, Any]:
        """Where the time went: seconds and shares of the env, the wrappers, the policy's
        forward passes and the PPO update, and env steps per second end to end."""
        total = (self.ended or time.perf_counter()) - self.started
        cpu = (self.cpu_ended or time.process_time()) - self.cpu_started
        env = self.env_seconds() - self.env_seconds_at_start
        wrappers = self.chain.seconds - self.chain_seconds_at_start - env
        forward = self.forward_seconds
        # With the chain in worker processes its env and wrappers are one part.
        chain_parts = (
            {"env": env, "map_and_goal_wrappers": wrappers}
            if self.bare is not None
            else {"env_and_wrappers_in_workers": env}
        )
        parts = {
            **chain_parts,
            "policy_forward_and_sb3": forward,
            "ppo_update": self.update_seconds,
        }
        steps = (self.num_timesteps - (self.steps_at_start or 0)) * self.args.steps_per_goal
        return {
            "seconds": {k: round(v, 2) for k, v in parts.items()},
            "shares": {k: round(v / max(total, 1e-9), 3) for k, v in parts.items()},
            "env_steps": steps,
            "wall_seconds": round(total, 1),
            "env_steps_per_s": round(steps / max(total, 1e-9), 1),
            "cpu_seconds": round(cpu, 1),
            "env_steps_per_cpu_s": round(steps / max(cpu, 1e-9), 1),
            **(
                {"wrapper_cost_per_env_step_over_env": round(wrappers / max(env, 1e-9), 3)}
                if self.bare is not None
                else {}
            ),
            "load_end": os.getloadavg(),
        }


def explorer_settings(args: Args) -> dict[str, Any]:
    """What the explorer policy needs to act as in training (saved beside every model)."""
    return {
        "steps_per_goal": args.steps_per_goal,
        "num_candidates": args.num_candidates,
        "primitive_actions": args.primitive_actions,
        "map_options": {},
        "panorama_shape": list(EXPLORER_ENV["panorama_shape"]),
        "panorama_horizon_deg": args.panorama_horizon_deg,
    }


class Checkpoints(BaseCallback):
    """Saves ``checkpoints/explorer_<env steps>_steps.zip`` (and its settings) every ``every``
    env steps."""

    def __init__(self, folder: Path, every: int, args: Args) -> None:
        super().__init__()
        self.folder, self.every, self.steps_per_goal = folder, every, args.steps_per_goal
        self.settings = explorer_settings(args)
        self.next = 0

    def _on_training_start(self) -> None:
        self.next = (self.num_timesteps * self.steps_per_goal // self.every + 1) * self.every

    def _on_step(self) -> bool:
        steps = self.num_timesteps * self.steps_per_goal
        if steps >= self.next:
            self.folder.mkdir(parents=True, exist_ok=True)
            path = self.folder / f"explorer_{steps}_steps.zip"
            self.model.save(path)
            save_settings(path, self.settings)
            normalizer = self.model.get_vec_normalize_env()
            if normalizer is not None:
                normalizer.save(str(reward_stats_path(path)))
            self.next += self.every
        return True


class WallClockBudget(BaseCallback):
    """Stops training once ``hours`` of wall-clock time have passed."""

    def __init__(self, hours: float) -> None:
        super().__init__()
        self.deadline = time.perf_counter() + hours * 3600

    def _on_step(self) -> bool:
        return time.perf_counter() < self.deadline


def reward_stats_path(checkpoint: Path) -> Path:
    """Where the reward normaliser's statistics of ``checkpoint`` are kept."""
    return checkpoint.with_name(f"{checkpoint.stem}_reward_stats.pkl")


def normalized_rewards(venv: VecEnv, args: Args, checkpoint: Path | None) -> VecEnv:
    """``venv`` with its rewards normalised (``--normalize-reward``), the statistics read
    from beside ``checkpoint`` when resuming; ``venv`` itself otherwise."""
    if not args.normalize_reward:
        return venv
    if checkpoint is not None and reward_stats_path(checkpoint).is_file():
        return VecNormalize.load(str(reward_stats_path(checkpoint)), venv)
    return VecNormalize(venv, norm_obs=False, norm_reward=True, gamma=args.gamma)


def latest_checkpoint(output_dir: Path) -> Path | None:
    """The checkpoint of ``output_dir`` with the most env steps, None when there is none."""
    found = [
        (int(m.group(1)), path)
        for path in (output_dir / "checkpoints").glob("*.zip")
        if (m := re.search(r"_(\d+)_steps\.zip$", path.name))
    ]
    return max(found)[1] if found else None


def plot(path: Path) -> None:
    """learning_curve.png from learning_curve.csv."""
    with path.open() as handle:
        rows = [row for row in csv.DictReader(handle) if row["final_coverage"]]
    if not rows:
        return
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(6.5, 3.8))
    steps = [int(row["env_steps"]) for row in rows]
    axis.plot(steps, [100 * float(row["final_coverage"]) for row in rows], label="all", lw=2)
    for kind in [key for key in rows[0] if key.startswith("procedural:")]:
        points = [
            (s, 100 * float(row[kind])) for s, row in zip(steps, rows, strict=True) if row[kind]
        ]
        if points:
            axis.plot(*zip(*points, strict=True), lw=0.8, label=kind.split(":", 1)[1])
    axis.set_xlabel("env steps")
    axis.set_ylabel("final coverage of training episodes (%)")
    axis.legend(fontsize=7)
    axis.set_title("explorer (map + goal actions) on the suite's train split")
    figure.tight_layout()
    figure.savefig(path.with_suffix(".png"), dpi=120)


UPDATE_DTYPES = {"float32": None, "bfloat16": torch.bfloat16}
#: CPU flags (Linux ``/proc/cpuinfo``) of instructions that compute in bfloat16.
BFLOAT16_CPU_FLAGS = ("avx512_bf16", "amx_bf16")


def cpu_has_bfloat16(cpuinfo: str | None = None) -> bool:
    """Whether the CPU computes in bfloat16 natively (elsewhere autocast to it is slower);
    read from ``cpuinfo`` (default: ``/proc/cpuinfo``; False where there is none)."""
    if cpuinfo is None:
        try:
            cpuinfo = Path("/proc/cpuinfo").read_text()
        except OSError:
            return False
    flags = set()
    for line in cpuinfo.splitlines():
        if line.startswith("flags"):
            flags.update(line.partition(":")[2].split())
    return any(flag in flags for flag in BFLOAT16_CPU_FLAGS)


def update_dtype(args: Args) -> str:
    """The update's precision: ``update_dtype``, with "auto" resolved for this CPU."""
    if args.update_dtype == "auto":
        return "bfloat16" if cpu_has_bfloat16() else "float32"
    return args.update_dtype


class AutocastPPO(PPO):
    """PPO whose update (``train``) runs the explorer's features extractor in
    ``update_dtype`` (a key of :data:`UPDATE_DTYPES`; "float32": as PPO): the CNNs, most of an
    update's arithmetic, under autocast, the policy's and value's heads in float32
    (``ExplorerFeaturesExtractor.compute_dtype``); the rollouts' forward passes stay float32."""

    update_dtype = "float32"

    def train(self) -> None:
        extractors = [
            module
            for module in self.policy.modules()
            if isinstance(module, ExplorerFeaturesExtractor)
        ]
        for extractor in extractors:
            extractor.compute_dtype = UPDATE_DTYPES[self.update_dtype]
        try:
            super().train()
        finally:
            for extractor in extractors:
                extractor.compute_dtype = None


def main(args: Args) -> dict[str, Any]:
    if args.update_dtype not in (*UPDATE_DTYPES, "auto"):
        raise SystemExit(
            f"--update-dtype must be one of {['auto', *sorted(UPDATE_DTYPES)]}, "
            f"got {args.update_dtype!r}"
        )
    output_dir = Path(args.output_dir)
    output_dir.mkdir(parents=True, exist_ok=True)
    if args.max_episode_steps % args.steps_per_goal:
        raise SystemExit(
            f"--max-episode-steps ({args.max_episode_steps}) must be a multiple "
            f"of --steps-per-goal ({args.steps_per_goal})"
        )
    torch.set_num_threads(args.torch_threads or default_thread_count())
    venv, bare, chain = make_env(args)
    missing = sorted(set(TRAIN_MIX) - set(agent_streams(args)))
    if missing:
        print(
            f"note: {args.num_envs} agents do not reach every train stream; not trained on: "
            f"{', '.join(missing)} (give each stream a group: --num-envs 4 * agents-per-scene)"
        )
    venv.seed(args.seed)
    checkpoint = latest_checkpoint(output_dir) if args.resume else None
    if args.resume and checkpoint is None:
        raise SystemExit(
            f"--resume: no checkpoint in {output_dir / 'checkpoints'}; train without --resume first"
        )
    venv = normalized_rewards(venv, args, checkpoint)
    if checkpoint is not None:
        model = AutocastPPO.load(checkpoint, env=venv, device="cpu")
        print(f"resuming from {checkpoint} ({model.num_timesteps * args.steps_per_goal} steps)")
    else:
        model = AutocastPPO(
            "MultiInputPolicy",
            venv,
            n_steps=args.n_steps,
            batch_size=args.batch_size,
            n_epochs=args.n_epochs,
            learning_rate=args.learning_rate,
            gamma=args.gamma,
            ent_coef=args.ent_coef,
            seed=args.seed,
            device="cpu",
            policy_kwargs={
                "features_extractor_class": ExplorerFeaturesExtractor,
                "features_extractor_kwargs": {"features_dim": args.features_dim},
            },
        )
    model.update_dtype = update_dtype(args)
    rows = 0
    if (output_dir / "learning_curve.csv").exists():
        rows = sum(1 for _ in (output_dir / "learning_curve.csv").open()) - 1
        if checkpoint is None:
            (output_dir / "learning_curve.csv").unlink()  # a fresh run: a fresh curve
            rows = 0
    # PPO's own statistics per update (losses, explained variance, KL) into progress.csv; a
    # resumed run keeps the earlier ones (the logger starts its file anew).
    progress = output_dir / "progress.csv"
    if checkpoint is not None and progress.exists():
        steps = model.num_timesteps * args.steps_per_goal
        progress.rename(output_dir / f"progress_until_{steps}_steps.csv")
    model.set_logger(configure(str(output_dir), ["csv"]))
    curve = LearningCurve(args, bare, chain, rows)
    callbacks: list[BaseCallback] = [
        curve,
        Checkpoints(output_dir / "checkpoints", args.checkpoint_every, args),
    ]
    if args.max_hours is not None:
        callbacks.append(WallClockBudget(args.max_hours))
    remaining = max(args.total_timesteps // args.steps_per_goal - model.num_timesteps, 0)
    model.learn(remaining, callback=CallbackList(callbacks), reset_num_timesteps=checkpoint is None)
    model.save(output_dir / "final_model.zip")
    save_settings(output_dir / "final_model.zip", explorer_settings(args))
    export_checkpoint(output_dir / "final_model.zip", output_dir / "explorer.zip")
    plot(output_dir / "learning_curve.csv")
    profile = curve.profile()
    summary = {
        "args": asdict(args),
        "update_dtype": update_dtype(args),
        "env_workers": env_workers(args),
        "env_steps": model.num_timesteps * args.steps_per_goal,
        "resumed_from": str(checkpoint) if checkpoint else None,
        "profile": profile,
    }
    (output_dir / "profile.json").write_text(json.dumps(summary, indent=1))
    print(json.dumps(profile, indent=1))
    venv.close()
    return summary


if __name__ == "__main__":
    main(parse_dataclass_args(Args))
