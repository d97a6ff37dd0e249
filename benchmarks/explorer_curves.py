"""Learning curves of explorer training runs side by side. Results: docs/benchmarks/explorer.md

Reads the ``learning_curve.csv`` of each run folder (``benchmarks/train_explorer.py``'s
output), bins the final coverage of the training episodes by env steps (each rollout's mean
weighted by its episodes), and writes a Markdown table and a plot of the bins every run
reached: the way to tell whether a change of the recipe (the update's precision, say) learns
as well, at equal env steps. Where a run folder holds a ``progress.csv`` (PPO's statistics per
update), a second table gives the critic's explained variance and value loss per bin: whether
and when the value function starts to explain the returns.

    python benchmarks/explorer_curves.py --runs runs/float32 runs/bfloat16 \\
        --labels float32 bfloat16 --output-file runs/curves.md
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from naruto_agent.cli_args import parse_dataclass_args


@dataclass
class Args:
    runs: list[str] = field(default_factory=list)
    """run folders, each with a learning_curve.csv"""
    labels: list[str] = field(default_factory=list)
    """a label per run (default: the folders' names)"""
    bin_steps: int = 100_000
    """env steps per bin"""
    output_file: str = "curves.md"
    """the Markdown table written; the plot goes beside it (.png)"""


def binned(path: Path, bin_steps: int) -> dict[int, tuple[float, int]]:
    """Per bin (its first env step): the mean final coverage of the episodes that ended in
    it and their count."""
    sums: dict[int, list[float]] = {}
    with path.open() as handle:
        for row in csv.DictReader(handle):
            if not row["final_coverage"]:
                continue
            start = int(row["env_steps"]) // bin_steps * bin_steps
            episodes = int(row["episodes"])
            entry = sums.setdefault(start, [0.0, 0])
            entry[0] += float(row["final_coverage"]) * episodes
            entry[1] += episodes
    return {start: (total / count, count) for start, (total, count) in sorted(sums.items())}


def binned_updates(progress: Path, curve: Path, bin_steps: int
                   ) -> dict[int, tuple[float, float]]:
    """Per bin (its first env step): PPO's mean explained variance and value loss over the
    updates in it. ``progress.csv`` counts decisions; the learning curve beside it (the same
    rollouts, in env steps) gives env steps per decision."""
    with curve.open() as handle:
        env_steps = [int(row["env_steps"]) for row in csv.DictReader(handle)]
    with progress.open() as handle:
        every = list(csv.DictReader(handle))
    rows = [row for row in every if row.get("train/explained_variance")]
    if not rows or not env_steps:
        return {}
    per_decision = max(env_steps) / max(int(row["time/total_timesteps"]) for row in every)
    sums: dict[int, list[float]] = {}
    for row in rows:
        steps = int(row["time/total_timesteps"]) * per_decision
        entry = sums.setdefault(int(steps) // bin_steps * bin_steps, [0.0, 0.0, 0])
        entry[0] += float(row["train/explained_variance"])
        entry[1] += float(row["train/value_loss"])
        entry[2] += 1
    return {start: (ev / count, loss / count)
            for start, (ev, loss, count) in sorted(sums.items())}


def updates_table(updates: dict[str, dict[int, tuple[float, float]]], bin_steps: int) -> str:
    """One row per bin any run reached: explained variance and value loss of each run."""
    labels = list(updates)
    starts = sorted(set().union(*(set(bins) for bins in updates.values())))
    lines = [
        "| env steps | " + " | ".join(f"{label} explained variance | {label} value loss"
                                       for label in labels) + " |",
        "|---|" + "---|---|" * len(labels),
    ]
    for start in starts:
        cells = " | ".join(
            f"{round(updates[label][start][0], 2) + 0.0:.2f} | {updates[label][start][1]:.3g}"
            if start in updates[label] else "- | -" for label in labels
        )
        lines.append(f"| {start:,}-{start + bin_steps:,} | {cells} |")
    return "\n".join(lines) + "\n"


def common_bins(curves: dict[str, dict[int, tuple[float, int]]]) -> list[int]:
    """The bins every run reached."""
    return sorted(set.intersection(*(set(curve) for curve in curves.values())))


def table(curves: dict[str, dict[int, tuple[float, int]]], bin_steps: int) -> str:
    """The bins every run reached, one row each, and the mean over them."""
    common = common_bins(curves)
    labels = list(curves)
    lines = [
        "| env steps | " + " | ".join(f"{label} final coverage (%)" for label in labels) + " |",
        "|---|" + "---|" * len(labels),
    ]
    for start in common:
        cells = " | ".join(f"{100 * curves[label][start][0]:.1f}" for label in labels)
        lines.append(f"| {start:,}-{start + bin_steps:,} | {cells} |")
    means = " | ".join(
        f"{100 * np.mean([curves[label][start][0] for start in common]):.1f}" for label in labels
    )
    lines.append(f"| mean of the bins | {means} |")
    return "\n".join(lines) + "\n"


def plot(curves: dict[str, dict[int, tuple[float, int]]], bin_steps: int, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    common = common_bins(curves)
    figure, axis = plt.subplots(figsize=(6.5, 3.8))
    for label, curve in curves.items():
        means = [100 * curve[start][0] for start in common]
        axis.plot(np.array(common) + bin_steps / 2, means, label=label)
    axis.set_xlabel("env steps")
    axis.set_ylabel("final coverage of training episodes (%)")
    axis.legend()
    figure.tight_layout()
    figure.savefig(path, dpi=120)


def main(args: Args) -> str:
    if not args.runs:
        raise SystemExit("give the run folders to compare (each with a learning_curve.csv)")
    labels = args.labels or [Path(run).name for run in args.runs]
    if len(labels) != len(args.runs):
        raise SystemExit(f"{len(labels)} labels for {len(args.runs)} runs: give one per run")
    curves, updates = {}, {}
    for label, run in zip(labels, args.runs, strict=True):
        path = Path(run) / "learning_curve.csv"
        if not path.is_file():
            raise SystemExit(f"{path} not found: give folders written by train_explorer.py")
        curves[label] = binned(path, args.bin_steps)
        if (Path(run) / "progress.csv").is_file():
            updates[label] = binned_updates(Path(run) / "progress.csv", path, args.bin_steps)
    text = table(curves, args.bin_steps)
    if any(updates.values()):
        text += "\nPPO's critic per bin (`progress.csv`):\n\n" + updates_table(
            {label: bins for label, bins in updates.items() if bins}, args.bin_steps)
    output = Path(args.output_file)
    output.parent.mkdir(parents=True, exist_ok=True)
    output.with_suffix(".md").write_text(text)
    plot(curves, args.bin_steps, output.with_suffix(".png"))
    print(text)
    return text


if __name__ == "__main__":
    main(parse_dataclass_args(Args))
