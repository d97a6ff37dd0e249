"""Learning curves of explorer training runs side by side. Results: docs/benchmarks/explorer.md

Reads the ``learning_curve.csv`` of each run folder (``benchmarks/train_explorer.py``'s or
``benchmarks/train_goal_explorer.py``'s output), bins a coverage column of the training
episodes by env steps (each rollout's mean weighted by its episodes), and writes a Markdown
table and a plot of the bins every run reached: the way to tell whether a recipe learns, and
whether a change of it (the update's precision, say) learns as well, at equal env steps.

Runs given the same label are training seeds of one recipe: they make one column and one
curve, the mean over the seeds per bin with their spread (min to max for two seeds, mean ±
the sample standard deviation for three or more). Reference levels (``--reference
NAME=VALUE``, or the policies of ``benchmarks/explorer_scripted_check.py``'s ``check.json``
through ``--reference-file``) are drawn as horizontal lines and listed as rows: the level an
untrained twin or a scripted choice reaches, which a learning curve has to rise above. Where a
run folder holds a ``progress.csv`` (PPO's statistics per update), a second table gives the
critic's explained variance (mean and spread over the seeds) and value loss per bin: whether
and when the value function starts to explain the returns.

    python benchmarks/explorer_curves.py --runs runs/float32 runs/bfloat16 \\
        --labels float32 bfloat16 --output-file runs/curves.md
    python benchmarks/explorer_curves.py --runs runs/goal/seed0 runs/goal/seed1 runs/goal/seed2 \\
        --labels goal goal goal --metric mean_coverage --reference untrained=0.536 \\
        --reference-file benchmarks/results/explorer_rules/goal/check.json \\
        --output-file runs/goal/curves.md
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from naruto_agent.cli_args import parse_dataclass_args

METRICS = {
    "final_coverage": "final coverage",
    "mean_coverage": "mean coverage over the steps",
}
"""The learning-curve columns that can be drawn, and their names in the table."""

REFERENCE_FILE_KEYS = {"final_coverage": "final", "mean_coverage": "auc"}
"""Per metric, the per-scene list of ``check.json``'s table that gives the same quantity."""

Bins = dict[int, tuple[float, int]]
"""Per bin (its first env step): the mean of the metric over the episodes in it, their count."""
UpdateBins = dict[int, tuple[float, float]]
"""Per bin (its first env step): the mean explained variance and value loss of its updates."""


@dataclass
class Args:
    runs: list[str] = field(default_factory=list)
    """run folders, each with a learning_curve.csv"""
    labels: list[str] = field(default_factory=list)
    """a label per run (default: the folders' names); runs with the same label are seeds of
    one recipe, drawn as one curve with their spread"""
    metric: str = "final_coverage"
    """the learning-curve column drawn: final_coverage or mean_coverage (the area, written by
    train_goal_explorer.py)"""
    bin_steps: int = 100_000
    """env steps per bin"""
    references: list[str] = field(default_factory=list)
    """reference levels NAME=VALUE (coverage as a fraction, e.g. untrained=0.536)"""
    reference_file: str | None = None
    """a check.json of explorer_scripted_check.py: its policies' mean levels over its scenes as
    references (comparable where its scenes and episode steps are the training's)"""
    reference_policies: list[str] = field(default_factory=list)
    """the policies of --reference-file drawn (default: all of them)"""
    output_file: str = "curves.md"
    """the Markdown table written; the plot goes beside it (.png)"""


def binned(path: Path, bin_steps: int, metric: str = "final_coverage") -> Bins:
    """Per bin (its first env step): the mean ``metric`` of the episodes that ended in it and
    their count."""
    sums: dict[int, list[float]] = {}
    with path.open() as handle:
        reader = csv.DictReader(handle)
        if metric not in (reader.fieldnames or []):
            raise SystemExit(
                f"{path} has no {metric} column (it has {', '.join(reader.fieldnames or [])}): "
                f"choose --metric among its columns"
            )
        for row in reader:
            if not row[metric]:
                continue
            start = int(row["env_steps"]) // bin_steps * bin_steps
            episodes = int(row["episodes"])
            entry = sums.setdefault(start, [0.0, 0])
            entry[0] += float(row[metric]) * episodes
            entry[1] += episodes
    return {start: (total / count, count) for start, (total, count) in sorted(sums.items())}


def binned_updates(progress: Path, curve: Path, bin_steps: int) -> UpdateBins:
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
    return {start: (ev / count, loss / count) for start, (ev, loss, count) in sorted(sums.items())}


def spread(values: list[float]) -> tuple[float, float, float]:
    """The mean of the seeds' values and the band around it: min and max for two seeds, the
    mean ± the sample standard deviation for three or more (for one, the value itself)."""
    mean = float(np.mean(values))
    if len(values) >= 3:
        deviation = float(np.std(values, ddof=1))
        return mean, mean - deviation, mean + deviation
    return mean, float(min(values)), float(max(values))


def spread_cell(values: list[float], scale: float = 100.0, digits: int = 1) -> str:
    """A table cell: the value of one seed, ``mean (min to max)`` of two, ``mean ± sd`` of
    three or more (``+ 0.0`` keeps a rounded -0 from printing as ``-0.0``)."""

    def number(value: float) -> str:
        return f"{round(scale * value, digits) + 0.0:.{digits}f}"

    mean, low, high = spread(values)
    if len(values) == 1:
        return number(mean)
    if len(values) == 2:
        return f"{number(mean)} ({number(low)} to {number(high)})"
    return f"{number(mean)} ± {number(mean - low)}"


def seeds_note(count: int) -> str:
    """How a column of ``count`` seeds is summarised, for its header."""
    if count == 1:
        return ""
    if count == 2:
        return ", mean (min to max) of 2 seeds"
    return f", mean ± sd of {count} seeds"


def common_bins(curves: dict[str, list[Bins]]) -> list[int]:
    """The bins every run (every seed of every label) reached."""
    return sorted(set.intersection(*(set(bins) for runs in curves.values() for bins in runs)))


def table(
    curves: dict[str, list[Bins]],
    bin_steps: int,
    references: dict[str, float] | None = None,
    metric: str = "final_coverage",
) -> str:
    """The bins every run reached, one row each, the mean over them, and a row per reference
    level (the same level in every column)."""
    common = common_bins(curves)
    labels = list(curves)
    lines = [
        "| env steps | "
        + " | ".join(
            f"{label} {METRICS[metric]} (%){seeds_note(len(curves[label]))}" for label in labels
        )
        + " |",
        "|---|" + "---|" * len(labels),
    ]
    for start in common:
        cells = " | ".join(
            spread_cell([bins[start][0] for bins in curves[label]]) for label in labels
        )
        lines.append(f"| {start:,}-{start + bin_steps:,} | {cells} |")
    means = " | ".join(
        spread_cell([float(np.mean([bins[start][0] for start in common])) for bins in runs])
        for runs in curves.values()
    )
    lines.append(f"| mean of the bins | {means} |")
    for name, level in (references or {}).items():
        lines.append(
            f"| {name} (reference) | " + " | ".join([f"{100 * level:.1f}"] * len(labels)) + " |"
        )
    return "\n".join(lines) + "\n"


def updates_table(updates: dict[str, list[UpdateBins]], bin_steps: int) -> str:
    """One row per bin any run reached: per label, the explained variance (mean and spread
    over the seeds with updates in the bin) and the mean value loss."""
    labels = list(updates)
    starts = sorted(set().union(*(set(bins) for runs in updates.values() for bins in runs)))
    lines = [
        "| env steps | "
        + " | ".join(
            f"{label} explained variance{seeds_note(len(updates[label]))} | {label} value loss"
            for label in labels
        )
        + " |",
        "|---|" + "---|---|" * len(labels),
    ]
    for start in starts:
        cells = []
        for label in labels:
            present = [bins[start] for bins in updates[label] if start in bins]
            if not present:
                cells.append("- | -")
                continue
            variance = spread_cell([ev for ev, _ in present], scale=1.0, digits=2)
            cells.append(f"{variance} | {np.mean([loss for _, loss in present]):.3g}")
        lines.append(f"| {start:,}-{start + bin_steps:,} | {' | '.join(cells)} |")
    return "\n".join(lines) + "\n"


def plot(
    curves: dict[str, list[Bins]],
    bin_steps: int,
    path: Path,
    references: dict[str, float] | None = None,
    metric: str = "final_coverage",
) -> None:
    """Each label's mean over its seeds per bin, their spread as a band, and each reference
    level as a dashed horizontal line, into the PNG at ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    common = common_bins(curves)
    centres = np.array(common) + bin_steps / 2
    figure, axis = plt.subplots(figsize=(6.5, 3.8))
    for index, (label, runs) in enumerate(curves.items()):
        bands = np.array([spread([bins[start][0] for bins in runs]) for start in common])
        colour = f"C{index % 10}"
        axis.plot(centres, 100 * bands[:, 0], color=colour, label=label + seeds_note(len(runs)))
        if len(runs) > 1:
            axis.fill_between(
                centres, 100 * bands[:, 1], 100 * bands[:, 2], color=colour, alpha=0.2, linewidth=0
            )
    for index, (name, level) in enumerate((references or {}).items(), start=len(curves)):
        axis.axhline(100 * level, color=f"C{index % 10}", linestyle="--", label=name)
    axis.set_xlabel("env steps")
    axis.set_ylabel(f"{METRICS[metric]} (%)")
    axis.set_title("training episodes", fontsize="medium")
    axis.legend(fontsize="small")
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def parse_references(texts: list[str]) -> dict[str, float]:
    """``NAME=VALUE`` texts as levels by name; a clear error for anything else."""
    levels: dict[str, float] = {}
    for text in texts:
        name, equals, value = text.partition("=")
        name = name.strip()
        if not equals or not name:
            raise SystemExit(
                f"--reference {text!r} is not NAME=VALUE: write e.g. --reference untrained=0.536"
            )
        try:
            level = float(value)
        except ValueError:
            raise SystemExit(
                f"--reference {text!r}: {value!r} is not a number; give the level as a "
                f"coverage fraction, e.g. {name}=0.536"
            ) from None
        if not 0.0 <= level <= 1.0:
            raise SystemExit(
                f"--reference {text!r}: {level} is not a coverage fraction between 0 and 1 "
                f"(a percentage? write {level / 100:g})"
            )
        if name in levels:
            raise SystemExit(f"--reference names {name!r} twice: give each level once")
        levels[name] = level
    return levels


def file_references(path: Path, metric: str, policies: list[str]) -> dict[str, float]:
    """The mean level of each policy (or of ``policies``) in the table of
    ``explorer_scripted_check.py``'s ``check.json``: over its scenes, the mean area (for
    ``mean_coverage``) or final coverage (``final_coverage``)."""
    if not path.is_file():
        raise SystemExit(
            f"--reference-file {path} not found: give a check.json written by "
            f"explorer_scripted_check.py"
        )
    stored = json.loads(path.read_text())
    rows = stored.get("table") if isinstance(stored, dict) else None
    if not isinstance(rows, dict) or not rows:
        raise SystemExit(
            f"--reference-file {path} has no table of policies: give a "
            f"check.json written by explorer_scripted_check.py"
        )
    missing = [policy for policy in policies if policy not in rows]
    if missing:
        raise SystemExit(
            f"--reference-policies {', '.join(missing)} not in {path}; it has {', '.join(rows)}"
        )
    key = REFERENCE_FILE_KEYS[metric]
    return {policy: float(np.mean(rows[policy][key])) for policy in policies or list(rows)}


def read_runs(
    args: Args,
) -> tuple[dict[str, list[Bins]], dict[str, list[UpdateBins]]]:
    """Each label's runs binned (a list, a run per seed) and the critic's bins of those with
    a ``progress.csv`` holding updates."""
    labels = args.labels or [Path(run).name for run in args.runs]
    if len(labels) != len(args.runs):
        raise SystemExit(
            f"{len(labels)} labels for {len(args.runs)} runs: give one per run "
            f"(the same label for the seeds of one recipe)"
        )
    curves: dict[str, list[Bins]] = {}
    updates: dict[str, list[UpdateBins]] = {}
    for label, run in zip(labels, args.runs, strict=True):
        folder = Path(run)
        if not folder.is_dir():
            raise SystemExit(
                f"run folder {folder} not found: give the --output-dir of a training run"
            )
        path = folder / "learning_curve.csv"
        if not path.is_file():
            raise SystemExit(
                f"{path} not found: {folder} is not a finished training run; give folders "
                f"written by train_explorer.py or train_goal_explorer.py"
            )
        curves.setdefault(label, []).append(binned(path, args.bin_steps, args.metric))
        if (folder / "progress.csv").is_file():
            bins = binned_updates(folder / "progress.csv", path, args.bin_steps)
            if bins:
                updates.setdefault(label, []).append(bins)
    return curves, updates


def main(args: Args) -> str:
    if not args.runs:
        raise SystemExit("give the run folders to compare (each with a learning_curve.csv)")
    if args.metric not in METRICS:
        raise SystemExit(f"--metric {args.metric!r}: use one of {', '.join(METRICS)}")
    if args.reference_policies and not args.reference_file:
        raise SystemExit("--reference-policies names policies of --reference-file: give both")
    references = parse_references(args.references)
    if args.reference_file:
        for name, level in file_references(
            Path(args.reference_file), args.metric, args.reference_policies
        ).items():
            references.setdefault(name, level)
    curves, updates = read_runs(args)
    if not common_bins(curves):
        raise SystemExit(
            f"the runs share no bin of {args.bin_steps:,} env steps with finished "
            f"episodes: give a larger --bin-steps"
        )
    text = table(curves, args.bin_steps, references, args.metric)
    if updates:
        text += "\nPPO's critic per bin (`progress.csv`):\n\n" + updates_table(
            updates, args.bin_steps
        )
    output = Path(args.output_file)
    output.parent.mkdir(parents=True, exist_ok=True)
    output.with_suffix(".md").write_text(text)
    plot(curves, args.bin_steps, output.with_suffix(".png"), references, args.metric)
    print(text)
    return text


if __name__ == "__main__":
    main(parse_dataclass_args(Args))
