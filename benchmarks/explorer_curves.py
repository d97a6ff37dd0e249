"""Learning curves of explorer training runs side by side. Results: docs/benchmarks/explorer.md

Reads the ``learning_curve.csv`` of each run folder (``benchmarks/train_explorer.py``'s
output), bins the final coverage of the training episodes by env steps (each rollout's mean
weighted by its episodes), and writes a Markdown table and a plot of the bins every run
reached: the way to tell whether a change of the recipe (the update's precision, say) learns
as well, at equal env steps.

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
    curves = {}
    for label, run in zip(labels, args.runs, strict=True):
        path = Path(run) / "learning_curve.csv"
        if not path.is_file():
            raise SystemExit(f"{path} not found: give folders written by train_explorer.py")
        curves[label] = binned(path, args.bin_steps)
    text = table(curves, args.bin_steps)
    output = Path(args.output_file)
    output.parent.mkdir(parents=True, exist_ok=True)
    output.with_suffix(".md").write_text(text)
    plot(curves, args.bin_steps, output.with_suffix(".png"))
    print(text)
    return text


if __name__ == "__main__":
    main(parse_dataclass_args(Args))
