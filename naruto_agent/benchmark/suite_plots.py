"""Plots of a benchmark run's classes: completion-ratio curves over the budget and over path
length (mean with its bootstrap band), and the paired differences between policies."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only; no display on servers and in workers
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from naruto_agent.benchmark.efficiency import checkpoint_paths, completion_points  # noqa: E402
from naruto_agent.benchmark.records import STATUS_OK  # noqa: E402
from naruto_agent.benchmark.statistics import bootstrap_ci, excludes_zero  # noqa: E402
from naruto_agent.benchmark.suite import group_of, ordered_groups  # noqa: E402

_COLOURS = plt.get_cmap("tab10")
GRID_POINTS = 41
BAND_RESAMPLES = 1_000
"""Resamples of the bands (a pointwise interval at every grid point; the tables use more)."""


def episode_curves(record: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Budget fraction, path length (m) and completion ratio (%) at the record's checkpoints,
    from ``(0, 0, 0)``."""
    steps, ratios = completion_points(record)
    budget = float((record.get("config") or {}).get("steps") or max(steps[-1], 1.0))
    return steps / budget, checkpoint_paths(record, steps), ratios


def _band(
    x_grid: np.ndarray, curves: list[tuple[np.ndarray, np.ndarray]], scenes: list[str]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean and pointwise bootstrap band of curves sampled on ``x_grid`` (held after the end)."""
    stack = np.stack([np.interp(x_grid, x, y) for x, y in curves])
    mean = stack.mean(axis=0)
    low, high = np.empty_like(mean), np.empty_like(mean)
    for index in range(len(x_grid)):
        stat = bootstrap_ci(stack[:, index], scenes, resamples=BAND_RESAMPLES)
        low[index], high[index] = stat["low"], stat["high"]
    return mean, low, high


def plot_class_curves(
    records: list[dict[str, Any]], manifest: dict[str, Any] | None, path: str | Path
) -> Path | None:
    """Completion ratio against the fraction of the budget (top) and the path walked (bottom),
    a column per class, a line per policy (mean over scenes and seeds, shaded 95 % band)."""
    grouped: dict[str, dict[str, list[dict[str, Any]]]] = defaultdict(lambda: defaultdict(list))
    for record in records:
        if record.get("status") == STATUS_OK and record.get("completion_curve"):
            grouped[group_of(record, manifest)][record["policy"]].append(record)
    if not grouped:
        return None
    classes = ordered_groups(grouped)
    policies = sorted({policy for by_policy in grouped.values() for policy in by_policy})
    colours = {policy: _COLOURS(index % 10) for index, policy in enumerate(policies)}
    figure, axes = plt.subplots(2, len(classes), figsize=(5 * len(classes), 7.5), squeeze=False)
    for column, size_class in enumerate(classes):
        top, bottom = axes[0, column], axes[1, column]
        members = grouped[size_class]
        curves = {policy: [episode_curves(r) for r in rs] for policy, rs in members.items()}
        longest = max(float(c[1][-1]) for cs in curves.values() for c in cs) or 1.0
        fraction_grid = np.linspace(0.0, 1.0, GRID_POINTS)
        metre_grid = np.linspace(0.0, longest, GRID_POINTS)
        for policy, policy_curves in sorted(curves.items()):
            scenes = [record["scene"] for record in members[policy]]
            colour = colours[policy]
            label = f"{policy} (n={len(policy_curves)})"
            for axis, grid, pick in ((top, fraction_grid, 0), (bottom, metre_grid, 1)):
                mean, low, high = _band(
                    grid, [(_increasing(c[pick]), c[2]) for c in policy_curves], scenes
                )
                axis.plot(grid, mean, color=colour, label=label)
                axis.fill_between(grid, low, high, color=colour, alpha=0.2)
        top.set_title(size_class)
        top.set_xlabel("fraction of the step budget")
        bottom.set_xlabel("path walked (m)")
        for axis in (top, bottom):
            axis.set_ylabel("completion ratio @5 cm (%)")
            axis.grid(alpha=0.3)
        top.legend(loc="lower right", fontsize=8)
    figure.tight_layout()
    return _save(figure, path)


def _increasing(x: np.ndarray) -> np.ndarray:
    """``x`` nudged to be strictly increasing (a camera that stood still between checkpoints),
    as ``np.interp`` needs."""
    out = np.asarray(x, np.float64).copy()
    for index in range(1, len(out)):
        out[index] = max(out[index], out[index - 1] + 1e-9)
    return out


def plot_paired(
    paired: dict[str, list[dict[str, Any]]], path: str | Path, metric: str = "auc_steps"
) -> Path | None:
    """Mean paired difference ``A - B`` of ``metric`` with its 95 % interval, a panel per
    class, a row per policy pair (filled: the interval excludes 0)."""
    classes = [name for name in paired if any(e["metric"] == metric for e in paired[name])]
    if not classes:
        return None
    classes = ordered_groups(classes)
    rows = max(sum(e["metric"] == metric for e in paired[name]) for name in classes)
    figure, axes = plt.subplots(
        1, len(classes), figsize=(5 * len(classes), 1.0 + 0.45 * rows), squeeze=False
    )
    for axis, size_class in zip(axes[0], classes, strict=True):
        entries = [e for e in paired[size_class] if e["metric"] == metric]
        for row, entry in enumerate(entries):
            overall = entry["overall"]
            if overall["mean"] is None:
                continue
            significant = excludes_zero(overall)
            axis.errorbar(
                overall["mean"],
                row,
                xerr=[[overall["mean"] - overall["low"]], [overall["high"] - overall["mean"]]],
                fmt="o",
                color="tab:blue",
                markerfacecolor="tab:blue" if significant else "white",
                capsize=3,
            )
        axis.axvline(0.0, color="grey", linewidth=0.8)
        axis.set_yticks(range(len(entries)))
        axis.set_yticklabels([f"{e['a']} - {e['b']}" for e in entries], fontsize=8)
        axis.set_title(f"{size_class}: paired difference of {metric}", fontsize=10)
        axis.grid(alpha=0.3, axis="x")
    figure.tight_layout()
    return _save(figure, path)


def _save(figure: Any, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path
