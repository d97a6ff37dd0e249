"""The paper's Tables 1, 2 and 6 on our data. Results: docs/benchmarks/policies.md

The comparison at the published budgets in one report.

Reads the ``naruto-benchmark`` records of the three runs at the published budgets (the Replica
sample and ``replica_like_room`` at 2000 steps, the apartment at 5000, the MP3D budget) and the
neural NARUTO episodes of ``benchmarks/naruto_episode.py``, and writes one Markdown report with,
per scene: every policy's mean +- std over seeds (coverage, completion ratio of the whole and of
the observable surface, accuracy, completion, MAD of the reference TSDF map, the policy's own
map where it has one, path, collisions, failed episodes, time per step by phase), the
published references beside them, which policy has the best completion ratio, and the
coverage curves at ten checkpoints with the check that NARUTO is at least as high as frontier
at every checkpoint after step 500, in the mean over seeds and per seed. It runs no episode;
the commands that make the records are on its docs page.

Example::

    python benchmarks/published_budgets.py --output-file benchmarks/results/published_budgets.md
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from naruto_agent.benchmark.records import load_records, write_json_atomic
from naruto_agent.benchmark.tables import summarise
from naruto_agent.cli_args import dataclass_parser

RESULTS = Path(__file__).resolve().parent / "results"

# (column title, summary key, decimals)
COLUMNS: tuple[tuple[str, str, int], ...] = (
    ("coverage (%)", "coverage_pct", 1),
    ("comp. ratio (%)", "metrics.completion_ratio_pct", 1),
    ("obs. comp. ratio (%)", "metrics.observable_completion_ratio_pct", 1),
    ("acc. (cm)", "metrics.accuracy_cm", 2),
    ("comp. (cm)", "metrics.completion_cm", 2),
    ("MAD (cm)", "metrics.mad_cm", 2),
    ("obs. MAD (cm)", "metrics.observable_mad_cm", 2),
    ("own map: obs. comp. ratio (%)", "own_map_metrics.observable_completion_ratio_pct", 1),
    ("own map: MAD (cm)", "own_map_metrics.mad_cm", 2),
    ("path (m)", "path_length_m", 1),
    ("collisions", "collisions", 1),
)
PHASES = ("policy", "env", "mapping")
CHECKPOINTS = 10  # coverage checkpoints per episode, evenly spaced
COMPARE_AFTER = 500  # the checkpoint check starts after this step

# Published figures (NARUTO, CVPR 2024, and later systems on its protocol), per scene label:
# (row name, completion ratio %, accuracy cm, completion cm, MAD cm), as printed there.
PUBLISHED: dict[str, list[tuple[str, str, str, str, str]]] = {
    "replica_office0": [
        ("published NARUTO (neural, mean of 8 Replica scenes)", "97.20", "1.61", "1.66", "-"),
        ("published passive scan (Co-SLAM without tracking)", "93.79", "1.96", "2.00", "-"),
        ("published NARUTO without active ray sampling", "96.89", "-", "-", "-"),
    ],
}
"""The published MP3D rows are not set beside the generated apartment (another kind of scene,
not the same houses): ``docs/mp3d.md`` holds them with the protocol that reproduces them."""


@dataclass
class Args:
    """Arguments of the report (each field is a ``--flag``)."""

    runs: list[str] = field(
        default_factory=lambda: [
            str(RESULTS / "replica_2000"),
            str(RESULTS / "replica_like_room_2000"),
            str(RESULTS / "apartment_5000"),
        ]
    )
    """harness output folders (one scene each)"""
    neural_episodes: list[str] = field(
        default_factory=lambda: [
            str(RESULTS / "naruto_neural_office0" / "naruto_episode_office0_neural_2000steps.json"),
        ]
    )
    """naruto_episode.py records of the neural agent on the Replica sample (labelled by
    their ``--tag``)"""
    neural_replays: list[str] = field(default_factory=list)
    """replica_passive.py --trajectory replays of those episodes' poses, in the same order:
    the MAD of their reference maps (episodes recorded before MAD was scored)"""
    output_file: str = str(RESULTS / "published_budgets.md")
    """the Markdown report (a JSON of the same rows is written beside it)"""


def _cell(stat: dict[str, float] | None, decimals: int) -> str:
    if stat is None:
        return "-"
    if stat["n"] == 1:
        return f"{stat['mean']:.{decimals}f}"
    return f"{stat['mean']:.{decimals}f} ± {stat['std']:.{decimals}f}"


def _number(value: float | None, decimals: int) -> str:
    return "-" if value is None else f"{value:.{decimals}f}"


def best_policy(rows: list[dict[str, Any]], key: str) -> tuple[str, float] | None:
    """The policy with the highest mean of ``key`` among ``rows`` (None if none has it)."""
    scored = [(row[key]["mean"], row["policy"]) for row in rows if row.get(key)]
    if not scored:
        return None
    mean, policy = max(scored)
    return policy, mean


def neural_rows(paths: list[str], replays: list[str], scene: str) -> list[list[str]]:
    """Table rows of the neural episodes on ``scene``: reference map / the agent's own mesh.

    ``replays`` (same order as ``paths``, may be shorter) are replays of the episodes' poses
    whose reference-map MAD fills in for episodes recorded without one.
    """
    rows = []
    for index, path in enumerate(paths):
        if not Path(path).is_file():
            continue
        record = json.loads(Path(path).read_text())
        if Path(record["args"]["scene"]).parent.name != scene:
            continue
        reference = dict(record["reference_tsdf_metrics"])
        replay = Path(replays[index]) if index < len(replays) else None
        if reference.get("mad_cm") is None and replay is not None and replay.is_file():
            replayed = json.loads(replay.read_text())["metrics_culled"]
            for key in ("mad_cm", "observable_mad_cm"):
                reference[key] = replayed.get(key)
        maps = (reference, record["agent_mesh_metrics"])

        def both(key: str, decimals: int, maps: tuple[dict, dict] = maps) -> str:
            return " / ".join(_number(metrics.get(key), decimals) for metrics in maps)

        settings = record["args"].get("settings") or ""
        camera = record["camera"]
        label = (f"NARUTO (neural, seed {record['args']['seed']}, {camera['height']} x "
                 f"{camera['width']}): reference map / own mesh")
        if "active_sampling" in settings:
            label += ", without active ray sampling"
        if record["args"].get("tag"):
            label += f" [{record['args']['tag']}]"
        phases = record.get("phases_ms_per_step", {})
        rows.append([
            label, "1", "0",
            _number(100.0 * record["coverage_final"], 1),
            both("completion_ratio_pct", 2),
            both("observable_completion_ratio_pct", 2),
            both("accuracy_cm", 2),
            both("completion_cm", 2),
            both("mad_cm", 2),
            both("observable_mad_cm", 2),
            _number(maps[1].get("observable_completion_ratio_pct"), 1),
            _number(maps[1].get("mad_cm"), 2),
            _number(record["path_length_m"], 1),
            str(record["collisions"]),
            " / ".join(_number(phases.get(name), 0) for name in ("simulation", "mapping"))
            + " (sim. / mapping)",
        ])
    return rows


def coverage_at_checkpoints(
    records: list[dict[str, Any]], checkpoints: int = CHECKPOINTS
) -> tuple[list[int], dict[str, dict[int, list[float]]]]:
    """Checkpoint steps and, per policy, per seed, the coverage (%) at each (episodes that
    finished, with a coverage curve)."""
    done = [r for r in records if r.get("status") == "ok" and r.get("coverage_curve")]
    if not done:
        return [], {}
    steps = min(len(r["coverage_curve"]) - 1 for r in done)
    marks = [round(steps * (k + 1) / checkpoints) for k in range(checkpoints)]
    curves: dict[str, dict[int, list[float]]] = {}
    for record in sorted(done, key=lambda r: (r["policy"], r["seed"])):
        curve = record["coverage_curve"]
        curves.setdefault(record["policy"], {})[int(record["seed"])] = [
            100.0 * curve[mark] for mark in marks]
    return marks, curves


def checkpoint_verdict(
    marks: list[int], curves: dict[str, dict[int, list[float]]], policy: str = "naruto",
    rival: str = "frontier", after: int = COMPARE_AFTER,
) -> dict[str, Any] | None:
    """Is ``policy``'s coverage at least ``rival``'s at every checkpoint after ``after``?
    In the mean over the seeds both ran, and per seed. None when one of them is missing."""
    if policy not in curves or rival not in curves:
        return None
    seeds = sorted(set(curves[policy]) & set(curves[rival]))
    if not seeds:
        return None
    index = [k for k, mark in enumerate(marks) if mark > after]

    def margins(ours: list[list[float]], theirs: list[list[float]]) -> list[float]:
        return [sum(o[k] for o in ours) / len(ours) - sum(t[k] for t in theirs) / len(theirs)
                for k in index]

    mean = margins([curves[policy][s] for s in seeds], [curves[rival][s] for s in seeds])
    per_seed = {s: margins([curves[policy][s]], [curves[rival][s]]) for s in seeds}

    def summary(values: list[float]) -> dict[str, Any]:
        worst = min(range(len(values)), key=values.__getitem__)
        return {"at_least_as_high": sum(v >= 0.0 for v in values), "checkpoints": len(values),
                "lowest_margin_pct": values[worst], "lowest_at_step": marks[index[worst]]}

    return {"policy": policy, "rival": rival, "after_step": after, "seeds": seeds,
            "mean": summary(mean), "per_seed": {s: summary(v) for s, v in per_seed.items()}}


def checkpoint_lines(records: list[dict[str, Any]]) -> tuple[list[str], dict[str, Any]]:
    """The coverage-at-checkpoints table and the NARUTO-against-frontier verdict."""
    marks, curves = coverage_at_checkpoints(records)
    if not marks:
        return [], {}
    lines = ["", "Coverage (%) at checkpoints, mean over seeds:", "",
             "| policy | " + " | ".join(str(mark) for mark in marks) + " |",
             "|" + "---|" * (len(marks) + 1)]
    for policy, seeds in curves.items():
        means = [sum(curve[k] for curve in seeds.values()) / len(seeds) for k in range(len(marks))]
        lines.append(f"| {policy} | " + " | ".join(f"{m:.1f}" for m in means) + " |")
    verdict = checkpoint_verdict(marks, curves)
    if verdict is not None:
        mean = verdict["mean"]

        def said(part: dict[str, Any]) -> str:
            return (f"{part['at_least_as_high']} of {part['checkpoints']} (lowest margin "
                    f"{part['lowest_margin_pct']:+.2f} points at step {part['lowest_at_step']})")

        per_seed = "; ".join(f"seed {seed}: {said(part)}"
                             for seed, part in verdict["per_seed"].items())
        lines += ["", f"{verdict['policy']} at least as high as {verdict['rival']} at the "
                  f"checkpoints after step {verdict['after_step']}: in the mean over seeds "
                  f"{said(mean)}; {per_seed}."]
    return lines, {"checkpoints": marks, "coverage_pct": curves, "verdict": verdict}


def scene_report(
    run_dir: Path, neural: list[str], replays: tuple[str, ...] | list[str] = ()
) -> tuple[str, dict[str, Any]]:
    """The Markdown section and the JSON summary of one harness run."""
    records = load_records(run_dir)
    if not records:
        raise FileNotFoundError(
            f"no episode records under {run_dir}/records; run naruto-benchmark there first"
        )
    rows = summarise(
        records,
        tuple(key for _, key, _ in COLUMNS) + tuple(f"time_per_step_ms.{p}" for p in PHASES),
    )
    scene = rows[0]["scene"]
    steps = sorted({step for row in rows for step in row["steps"]})
    header = ["policy", "episodes", "failed", *[title for title, _, _ in COLUMNS],
              "policy / env / map ms per step"]
    lines = [f"### {scene}, {'/'.join(map(str, steps))} steps (`{run_dir.name}`)", "",
             "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for row in rows:
        timing = " / ".join(
            _cell(row.get(f"time_per_step_ms.{phase}"), 0) for phase in PHASES
        )
        cells = [row["policy"], str(len(row["seeds"])), str(row["failed"]),
                 *[_cell(row[key], decimals) for _, key, decimals in COLUMNS], timing]
        lines.append("| " + " | ".join(cells) + " |")
    for cells in neural_rows(neural, list(replays), scene):
        lines.append("| " + " | ".join(cells) + " |")
    for name, ratio, accuracy, completion, mad in PUBLISHED.get(scene, []):
        cells = [name, "", "", "", ratio, "", accuracy, completion, mad, *[""] * 6]
        lines.append("| " + " | ".join(cells) + " |")
    verdict = {}
    for title, key in (("whole surface", "metrics.completion_ratio_pct"),
                       ("observable surface", "metrics.observable_completion_ratio_pct")):
        best = best_policy(rows, key)
        if best is not None:
            verdict[key] = {"policy": best[0], "mean": best[1]}
            lines.append("")
            lines.append(f"Best completion ratio of the {title}: **{best[0]}** ({best[1]:.2f} %).")
    curve_lines, curves = checkpoint_lines(records)
    lines += curve_lines
    return "\n".join(lines) + "\n", {"scene": scene, "rows": rows, "best": verdict,
                                      "coverage_checkpoints": curves}


def main(argv: list[str] | None = None) -> int:
    parser = dataclass_parser(Args, description=__doc__.split("\n\n")[0])
    args = Args(**vars(parser.parse_args(argv)))
    sections, summaries = [], []
    for run in args.runs:
        section, summary = scene_report(Path(run), args.neural_episodes, args.neural_replays)
        sections.append(section)
        summaries.append(summary)
    report = "## The comparison at the published budgets\n\n" + "\n".join(sections)
    out = Path(args.output_file)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(report)
    write_json_atomic(out.with_suffix(".json"), {"scenes": summaries})
    print(report)
    print(f"written {out} and {out.with_suffix('.json')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
