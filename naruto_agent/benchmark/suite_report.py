"""Per-class statistics of a benchmark run: means with bootstrap intervals, efficiency metrics
and paired policy comparisons, as JSON and Markdown (``statistics.json``, ``statistics.md``).

Episodes are grouped by size class (read from the run's ``suite.json``; a run of ``--scenes``
forms one group, ``all``). Every mean comes with its 95 % bootstrap interval over scenes and
seeds (:mod:`~naruto_agent.benchmark.statistics`); the efficiency metrics are those of
:mod:`~naruto_agent.benchmark.efficiency`. Steps and metres to a level are averaged over the
episodes that reached it, and the table says how many did.
"""

from __future__ import annotations

from collections import defaultdict
from itertools import combinations
from pathlib import Path
from typing import Any

from naruto_agent.benchmark.efficiency import THRESHOLDS_PCT, episode_efficiency
from naruto_agent.benchmark.records import STATUS_OK, write_json_atomic
from naruto_agent.benchmark.statistics import (
    CONFIDENCE,
    RESAMPLES,
    SEED,
    bootstrap_ci,
    excludes_zero,
    paired_comparison,
)
from naruto_agent.benchmark.suite import group_of, ordered_groups, read_manifest

STATISTICS_JSON = "statistics.json"
STATISTICS_MD = "statistics.md"

# (column title, episode value key, decimals)
METRICS: tuple[tuple[str, str, int], ...] = (
    ("Comp. ratio (%)", "completion_ratio_pct", 1),
    ("Obs. comp. ratio (%)", "observable_completion_ratio_pct", 1),
    ("AUC steps", "auc_steps", 3),
    ("AUC path", "auc_path", 3),
    *((f"Steps to {p} %", f"steps_to_{p}", 0) for p in THRESHOLDS_PCT),
    *((f"Metres to {p} %", f"metres_to_{p}", 1) for p in THRESHOLDS_PCT),
    ("Acc. (cm)", "accuracy_cm", 2),
    ("Comp. (cm)", "completion_cm", 2),
    ("MAD (cm)", "mad_cm", 2),
    ("Path (m)", "path_m", 1),
    ("Refusals", "refusals", 1),
    ("Stalled steps", "stalled_steps", 1),
)
EFFICIENCY_KEYS: tuple[str, ...] = (
    "observable_completion_ratio_pct", "auc_steps", "auc_path",
    *(f"steps_to_{p}" for p in THRESHOLDS_PCT), *(f"metres_to_{p}" for p in THRESHOLDS_PCT),
)
"""The leaderboard's first table: how far and how fast."""
QUALITY_KEYS: tuple[str, ...] = (
    "completion_ratio_pct", "accuracy_cm", "completion_cm", "mad_cm", "path_m", "refusals",
    "stalled_steps",
)
"""The leaderboard's second table: the map's quality and the walk."""
PAIRED_METRICS: tuple[str, ...] = (
    "observable_completion_ratio_pct", "completion_ratio_pct", "auc_steps", "auc_path")
"""The values compared pair by pair (the others depend on whether a level was reached)."""


def episode_values(record: dict[str, Any]) -> dict[str, float | None]:
    """The numbers of one successful episode that the statistics aggregate."""
    metrics = record.get("metrics") or {}
    values: dict[str, float | None] = {
        key: _number(metrics.get(key))
        for key in ("completion_ratio_pct", "observable_completion_ratio_pct", "accuracy_cm",
                    "completion_cm", "mad_cm")
    }
    values.update(episode_efficiency(record))
    values["refusals"] = _number(record.get("collisions"))
    values["stalled_steps"] = _number(record.get("stalled_steps"))
    return values


def _number(value: Any) -> float | None:
    return None if value is None else float(value)


def grouped_values(
    records: list[dict[str, Any]], manifest: dict[str, Any] | None, by_scene: bool = False
) -> dict[str, dict[str, list[tuple[str, int, dict[str, Any]]]]]:
    """class (or scene, with ``by_scene``) -> policy -> [(scene, seed, episode values)] of the
    successful records."""
    groups: dict[str, dict[str, list[tuple[str, int, dict[str, Any]]]]] = defaultdict(
        lambda: defaultdict(list)
    )
    for record in records:
        if record.get("status") != STATUS_OK:
            continue
        group = record["scene"] if by_scene else group_of(record, manifest)
        groups[group][record["policy"]].append(
            (record["scene"], int(record["seed"]), episode_values(record))
        )
    return groups


def class_summary(
    records: list[dict[str, Any]],
    manifest: dict[str, Any] | None = None,
    resamples: int = RESAMPLES,
    seed: int = SEED,
    by_scene: bool = False,
) -> dict[str, dict[str, dict[str, Any]]]:
    """class -> policy -> metric -> ``{"mean", "low", "high", "n"}`` (plus ``episodes``,
    ``scenes`` and, for the levels, ``reached`` out of ``episodes``); with ``by_scene`` the
    same per scene (the interval then spans its seeds)."""
    summary: dict[str, dict[str, dict[str, Any]]] = {}
    for size_class, by_policy in grouped_values(records, manifest, by_scene).items():
        summary[size_class] = {}
        for policy, members in sorted(by_policy.items()):
            row: dict[str, Any] = {
                "episodes": len(members),
                "scenes": len({scene for scene, _, _ in members}),
            }
            for _, key, _ in METRICS:
                present = [(scene, values[key]) for scene, _, values in members
                           if values.get(key) is not None]
                row[key] = bootstrap_ci(
                    [value for _, value in present],
                    [scene for scene, _ in present],
                    CONFIDENCE,
                    resamples,
                    seed,
                )
                if key.startswith(("steps_to_", "metres_to_")):
                    row[key]["reached"] = len(present)
            summary[size_class][policy] = row
    return summary


def paired_summary(
    records: list[dict[str, Any]],
    manifest: dict[str, Any] | None = None,
    resamples: int = RESAMPLES,
    seed: int = SEED,
) -> dict[str, list[dict[str, Any]]]:
    """class -> one entry per policy pair ``(a, b)`` and metric: the paired difference
    ``a - b`` over the (scene, seed) episodes both ran, overall and per scene."""
    out: dict[str, list[dict[str, Any]]] = {}
    for size_class, by_policy in grouped_values(records, manifest).items():
        entries = []
        for first, second in combinations(sorted(by_policy), 2):
            for key in PAIRED_METRICS:
                a = {(scene, s): values[key] for scene, s, values in by_policy[first]}
                b = {(scene, s): values[key] for scene, s, values in by_policy[second]}
                result = paired_comparison(a, b, CONFIDENCE, resamples, seed)
                entries.append({"a": first, "b": second, "metric": key, **result})
        out[size_class] = entries
    return out


def _cell(stat: dict[str, Any] | None, decimals: int) -> str:
    if not stat or stat.get("mean") is None:
        return "-"
    text = f"{stat['mean']:.{decimals}f}"
    if stat.get("n", 0) > 1:
        text += f" [{stat['low']:.{decimals}f}, {stat['high']:.{decimals}f}]"
    return text


def class_table(rows: dict[str, dict[str, Any]], keys: tuple[str, ...] | None = None) -> str:
    """Markdown table of one class's :func:`class_summary` rows: mean [95 % interval].

    Args:
        rows: policy -> its row.
        keys: the columns (keys of :data:`METRICS`; default all).
    """
    columns = [column for column in METRICS if keys is None or column[1] in keys]
    header = ["Policy", "Episodes", "Scenes", *[title for title, _, _ in columns]]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    ranked = sorted(rows.items(), key=lambda item: -(item[1]["auc_steps"]["mean"] or -1.0))
    for policy, row in ranked:
        cells = [policy, str(row["episodes"]), str(row["scenes"])]
        for _, key, decimals in columns:
            cell = _cell(row[key], decimals)
            if "reached" in row[key]:
                cell += f" ({row[key]['reached']}/{row['episodes']})"
            cells.append(cell)
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def paired_table(entries: list[dict[str, Any]]) -> str:
    """Markdown table of one class's paired differences (a - b, mean [95 % interval])."""
    lines = [
        "| A | B | Metric | A - B | Scenes | Pairs | Interval excludes 0 |",
        "|---|---|---|---|---|---|---|",
    ]
    decimals = {"completion_ratio_pct": 2, "observable_completion_ratio_pct": 2,
                "auc_steps": 4, "auc_path": 4}
    for entry in entries:
        overall = entry["overall"]
        lines.append(
            f"| {entry['a']} | {entry['b']} | {entry['metric']} | "
            f"{_cell(overall, decimals[entry['metric']])} | {overall['scenes']} | "
            f"{overall['n']} | {'yes' if excludes_zero(overall) else 'no'} |"
        )
    return "\n".join(lines) + "\n"


def per_scene_table(entries: list[dict[str, Any]], metric: str = "auc_steps") -> str:
    """Markdown table of the per-scene paired differences of one metric."""
    lines = ["| A | B | Scene | A - B | Seeds |", "|---|---|---|---|---|"]
    for entry in entries:
        if entry["metric"] != metric:
            continue
        for scene, stat in entry["per_scene"].items():
            lines.append(
                f"| {entry['a']} | {entry['b']} | {scene} | {_cell(stat, 4)} | {stat['n']} |"
            )
    return "\n".join(lines) + "\n"


def statistics_markdown(
    summary: dict[str, dict[str, dict[str, Any]]],
    paired: dict[str, list[dict[str, Any]]],
    per_scene: dict[str, dict[str, dict[str, Any]]] | None = None,
) -> str:
    """Every class's table, then its paired comparisons; then, given ``per_scene``, the
    efficiency table of every scene."""
    parts = [
        "Mean [95 % bootstrap interval over scenes and seeds]; steps and metres to a level are "
        "averaged over the episodes that reached it (reached / episodes). Rows by AUC steps.\n"
    ]
    for size_class in ordered_groups(summary):
        parts.append(f"## {size_class}\n\n{class_table(summary[size_class])}")
        entries = paired.get(size_class) or []
        if entries:
            parts.append(f"### Paired differences ({size_class})\n\n{paired_table(entries)}")
            parts.append(f"Per scene, AUC steps:\n\n{per_scene_table(entries)}")
    if per_scene:
        parts.append("## Per scene (mean [interval over seeds])\n")
        for scene in sorted(per_scene):
            parts.append(f"### {scene}\n\n{class_table(per_scene[scene], EFFICIENCY_KEYS)}")
    return "\n".join(parts)


def write_statistics(
    out_dir: str | Path, records: list[dict[str, Any]], plots: bool = True
) -> dict[str, Any]:
    """Write ``statistics.json``, ``statistics.md`` and (with ``plots``) the class curves and
    paired-difference plots of ``records`` into ``out_dir``; returns the JSON's content."""
    out_dir = Path(out_dir)
    manifest = read_manifest(out_dir)
    summary = class_summary(records, manifest)
    paired = paired_summary(records, manifest)
    per_scene = class_summary(records, manifest, by_scene=True)
    data = {
        "confidence": CONFIDENCE,
        "resamples": RESAMPLES,
        "seed": SEED,
        "suite_version": (manifest or {}).get("suite_version"),
        "classes": summary,
        "paired": paired,
        "scenes": per_scene,
    }
    write_json_atomic(out_dir / STATISTICS_JSON, data)
    (out_dir / STATISTICS_MD).write_text(statistics_markdown(summary, paired, per_scene))
    if plots and summary:
        from naruto_agent.benchmark.suite_plots import plot_class_curves, plot_paired

        plot_class_curves(records, manifest, out_dir / "class_curves.png")
        plot_paired(paired, out_dir / "paired_differences.png")
    return data
