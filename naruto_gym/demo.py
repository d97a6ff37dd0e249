"""The main job on the default scene: run a short episode and write what a person looks at.

Writes into ``--out`` (default ``outputs/demo``):

* ``frame_XXXX.png``: the env's ``rgb_array`` picture (top-down map with the trajectory,
  current RGB and depth) every ``--picture-every`` steps and at the end;
* ``coverage.png`` and ``coverage.csv``: the coverage curve;
* ``summary.json``: scene, steps, coverage, path length, collisions, time per step.

The policy is a simple explorer built on the discrete actions: it turns a full circle at the
start, then walks forward and turns away when blocked. The comparison of real policies lives
in ``benchmarks/``.
"""

from __future__ import annotations

import csv
import json
import time
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import numpy as np
from PIL import Image
from tqdm import tqdm

import naruto_gym  # noqa: F401  (registers the env ids)
from naruto_gym.cli_args import parse_dataclass_args
from naruto_gym.motion.actions import DISCRETE_ACTIONS

FORWARD = DISCRETE_ACTIONS.index("move_forward")
TURN_LEFT = DISCRETE_ACTIONS.index("turn_left")
TURN_RIGHT = DISCRETE_ACTIONS.index("turn_right")


@dataclass
class DemoArgs:
    scene: str = "replica_like_room"
    steps: int = 200
    seed: int = 0
    image_scale: float = 0.5
    picture_every: int = 50
    out: str = "outputs/demo"


def parse_args(argv: list[str] | None = None) -> DemoArgs:
    return parse_dataclass_args(DemoArgs, argv, __doc__.splitlines()[0])


class WanderExplorer:
    """Turn a full circle, then walk forward; turn a random number of steps when blocked."""

    def __init__(self, seed: int, turn_deg: float = 20.0) -> None:
        self.rng = np.random.default_rng(seed)
        self.pending_turns = int(np.ceil(360.0 / turn_deg))
        self.turn = TURN_LEFT

    def act(self, collided: bool) -> int:
        if collided:
            self.pending_turns = int(self.rng.integers(2, 9))
            self.turn = TURN_LEFT if self.rng.random() < 0.5 else TURN_RIGHT
        if self.pending_turns > 0:
            self.pending_turns -= 1
            return self.turn
        return FORWARD


def run_demo(args: DemoArgs) -> dict:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    env = gym.make(
        "NarutoRecon-v0",
        scene=args.scene,
        action_mode="discrete",
        image_scale=args.image_scale,
        render_mode="rgb_array",
    )
    _, info = env.reset(seed=args.seed)
    policy = WanderExplorer(args.seed)
    coverage = [info["coverage"]]
    collisions = 0
    started = time.perf_counter()
    for step in tqdm(range(1, args.steps + 1), desc=f"demo on {args.scene}"):
        _, _, terminated, truncated, info = env.step(policy.act(info["collided"]))
        coverage.append(info["coverage"])
        collisions += info["collided"]
        if step % args.picture_every == 0 or step == args.steps:
            Image.fromarray(env.render()).save(out / f"frame_{step:04d}.png")
        if terminated or truncated:
            break
    seconds = time.perf_counter() - started
    _write_coverage(out, coverage)
    summary = {
        "scene": args.scene,
        "steps": len(coverage) - 1,
        "coverage": coverage[-1],
        "path_length_m": info["path_length_m"],
        "collisions": collisions,
        "ms_per_step": 1000.0 * seconds / max(len(coverage) - 1, 1),
        "outputs": sorted(p.name for p in out.iterdir()),
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    env.close()
    return summary


def _write_coverage(out: Path, coverage: list[float]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with open(out / "coverage.csv", "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["step", "coverage"])
        writer.writerows(enumerate(coverage))
    figure, axis = plt.subplots(figsize=(6, 4))
    axis.plot(np.arange(len(coverage)), 100.0 * np.asarray(coverage))
    axis.set_xlabel("step")
    axis.set_ylabel("surface seen (%)")
    axis.set_title("coverage")
    axis.grid(alpha=0.3)
    figure.tight_layout()
    figure.savefig(out / "coverage.png", dpi=100)
    plt.close(figure)


def main(argv: list[str] | None = None) -> None:
    summary = run_demo(parse_args(argv))
    print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main()
