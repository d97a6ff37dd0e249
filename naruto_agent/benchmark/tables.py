"""Aggregate episode records into mean +- std over seeds per scene and policy, as Markdown,
and list the failed episodes with their reasons."""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from naruto_agent.benchmark.checks import leaderboard_differences, leaderboard_note
from naruto_agent.benchmark.records import STATUS_FAILED, STATUS_OK, read_record
from naruto_agent.benchmark.spec import EpisodeSpec

#: Longest reason printed for a failed episode (the whole error is in its record).
REASON_CHARS = 200

# (column title, how to read the value from a record, decimals)
COLUMNS: tuple[tuple[str, str, int], ...] = (
    ("Coverage (%)", "coverage_pct", 1),
    ("Comp. ratio (%)", "metrics.completion_ratio_pct", 1),
    ("Obs. comp. ratio (%)", "metrics.observable_completion_ratio_pct", 1),
    ("Comp. (cm)", "metrics.completion_cm", 2),
    ("Acc. (cm)", "metrics.accuracy_cm", 2),
    ("MAD (cm)", "metrics.mad_cm", 2),
    ("Own map obs. comp. ratio (%)", "own_map_metrics.observable_completion_ratio_pct", 1),
    ("Own map MAD (cm)", "own_map_metrics.mad_cm", 2),
    ("Path (m)", "path_length_m", 1),
    ("Collisions", "collisions", 1),
    ("Stalled steps", "stalled_steps", 1),
    ("Policy ms/step", "time_per_step_ms.policy", 1),
    ("Env ms/step", "time_per_step_ms.env", 1),
    ("Map ms/step", "time_per_step_ms.mapping", 1),
)
#: The published release's reading of the same reference-map scores
#: (:data:`naruto_gym.evaluation.metrics.RELEASE_READING`: it passes the meshes in swapped
#: order), for setting a run beside published tables.
RELEASE_COLUMNS: tuple[tuple[str, str, int], ...] = (
    ("Release acc. (cm)", "metrics.completion_cm", 2),
    ("Release comp. (cm)", "metrics.accuracy_cm", 2),
    ("Release comp. ratio (%)", "metrics.precision_pct", 1),
)


def record_value(record: dict[str, Any], key: str) -> float | None:
    """A number from a record by dotted key (``coverage_pct`` is ``coverage_final`` in %)."""
    if key == "coverage_pct":
        value = record.get("coverage_final")
        return None if value is None else 100.0 * float(value)
    value: Any = record
    for part in key.split("."):
        if not isinstance(value, dict) or part not in value:
            return None
        value = value[part]
    return None if value is None else float(value)


def summarise(
    records: list[dict[str, Any]], keys: tuple[str, ...] | None = None
) -> list[dict[str, Any]]:
    """One row per (scene, policy): seeds, failures, and mean / std of every column.

    Args:
        records: episode records.
        keys: the values to aggregate (:func:`record_value` keys); default: the table's
            columns.

    The std is the sample standard deviation over seeds (0 with one seed).
    """
    keys = keys or tuple(dict.fromkeys(key for _, key, _ in COLUMNS + RELEASE_COLUMNS))
    groups: dict[tuple[str, str], list[dict[str, Any]]] = defaultdict(list)
    for record in records:
        groups[(record["scene"], record["policy"])].append(record)
    rows = []
    for (scene, policy), members in sorted(groups.items()):
        ok = [record for record in members if record.get("status") == STATUS_OK]
        row: dict[str, Any] = {
            "scene": scene,
            "policy": policy,
            "seeds": sorted(record["seed"] for record in ok),
            "failed": len(members) - len(ok),
            "steps": sorted({record.get("steps_run") for record in ok}),
        }
        for key in keys:
            values = [v for v in (record_value(record, key) for record in ok) if v is not None]
            if values:
                array = np.array(values)
                std = float(array.std(ddof=1)) if len(array) > 1 else 0.0
                row[key] = {"mean": float(array.mean()), "std": std, "n": len(array)}
            else:
                row[key] = None
        rows.append(row)
    return rows


def markdown_table(rows: list[dict[str, Any]], release_reading: bool = False) -> str:
    """Markdown table of :func:`summarise` rows (mean +- std over seeds).

    Args:
        rows: :func:`summarise` rows.
        release_reading: add :data:`RELEASE_COLUMNS`, the published release's reading of the
            same scores, after the table's columns.
    """
    columns = COLUMNS + RELEASE_COLUMNS if release_reading else COLUMNS
    header = ["Scene", "Policy", "Seeds", "Failed", "Steps", *[title for title, _, _ in columns]]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for row in rows:
        cells = [row["scene"], row["policy"], str(len(row["seeds"])), str(row["failed"])]
        cells.append("/".join(str(step) for step in row["steps"]) or "-")
        for _, key, decimals in columns:
            stat = row.get(key)
            cells.append(
                "-" if stat is None else f"{stat['mean']:.{decimals}f} ± {stat['std']:.{decimals}f}"
            )
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def ground_truth_label(record: dict[str, Any]) -> str:
    """What an episode was scored against (``"culled ground truth (mesh_culled.ply)"``,
    ``"full mesh"``, ...); a record without the field was scored against its scene's mesh."""
    return (record.get("ground_truth") or {}).get("label") or "full mesh"


def record_leaderboard(record: dict[str, Any]) -> dict[str, Any]:
    """An episode's differences from the leaderboard's settings
    (:func:`~naruto_agent.benchmark.checks.leaderboard_differences`). A record without a
    ``reference_camera`` fused its reference map from the policy's frames, so a policy
    camera other than the leaderboard's makes its scores incomparable."""
    found = record.get("leaderboard") or leaderboard_differences(record.get("config") or {})
    if "reference_camera" not in record and found["differences"]:
        return {**found, "scores_comparable": False}
    return found


def protocol_lines(records: list[dict[str, Any]]) -> list[str]:
    """The lines printed beside a table that say how its scores were made: the ground truth
    of each scene, and the settings that differ from the leaderboard's (with whether the
    scores still compare)."""
    scenes: dict[str, set[str]] = defaultdict(set)
    for record in records:
        scenes[ground_truth_label(record)].add(record["scene"])
    lines = [
        f"Ground truth: {label}: {', '.join(sorted(names))}."
        for label, names in sorted(scenes.items())
    ]
    notes = {}
    for record in records:
        found = record_leaderboard(record)
        note = leaderboard_note(found["differences"], found["scores_comparable"])
        if note:
            notes.setdefault(note, []).append(record["episode_id"])
    for note, episodes in notes.items():
        lines.append(f"Note ({len(episodes)} episodes): {note}")
    return lines


def failure_reason(record: dict[str, Any]) -> str:
    """One line saying why an episode failed: the first line of its error, shortened."""
    lines = [line.strip() for line in str(record.get("error") or "").splitlines()]
    reason = next((line for line in lines if line), "no error message recorded")
    return reason if len(reason) <= REASON_CHARS else reason[: REASON_CHARS - 3] + "..."


def failure_lines(specs: Iterable[EpisodeSpec], out_dir: str | Path) -> list[str]:
    """``"  EPISODE: REASON (traceback: RECORD PATH)"`` for each of ``specs`` whose record
    under ``out_dir`` says it failed."""
    lines = []
    for spec in specs:
        path = spec.record_path(out_dir)
        record = read_record(path)
        if record is not None and record.get("status") == STATUS_FAILED:
            lines.append(f"  {spec.episode_id}: {failure_reason(record)} (traceback: {path})")
    return lines
