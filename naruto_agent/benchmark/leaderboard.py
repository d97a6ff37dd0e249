"""The leaderboard page, generated from a suite run's results folder.

Usage::

    python -m naruto_agent.benchmark.leaderboard benchmarks/results/leaderboard \\
        --img-dir docs/benchmarks/img > docs/benchmarks/leaderboard.md

It reads the records and ``suite.json`` of the folder (written by ``naruto-benchmark --suite``),
or of an archive of compact copies (:mod:`~naruto_agent.benchmark.episode_archive`: a run
spread over sessions), and prints a Markdown page: one table per size class (mean [95 %
bootstrap interval over scenes and seeds], ranked by the area under the completion-ratio
curve), the paired differences between policies, the curves (PNG files written to
``--img-dir``), and the exact commands and machines of the runs. A policy run into the same
folder with the same command (``--policies package.module:ClassName``) appears in it at the
next generation.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections import Counter
from pathlib import Path
from typing import Any

from naruto_agent.benchmark.episode_archive import load_episodes
from naruto_agent.benchmark.records import STATUS_OK
from naruto_agent.benchmark.suite import (
    EXTERNAL_CLASS,
    entry_group,
    ordered_groups,
    read_manifest,
    suite_module,
)
from naruto_agent.benchmark.suite_report import (
    EFFICIENCY_KEYS,
    QUALITY_KEYS,
    class_summary,
    class_table,
    paired_summary,
    paired_table,
)

SKIP = "<!-- docs-test: skip (the suite run takes hours; covered by: suite) -->"
TWIN = """<!-- docs-test: twin suite bash slow
naruto-benchmark --suite test --size-class small --suite-limit 1 --policies random --seeds 0 \\
    --max-episode-steps 3 --workers 0 --image-scale 0.1 --eval-points 1 --eval-samples 2000 \\
    --checkpoint-samples 2000 --eval-samples-per-m2 0 --no-plots --no-progress \\
    --output-dir suite_check
python -m naruto_agent.benchmark.leaderboard suite_check --img-dir img > leaderboard.md
grep -q "## small" leaderboard.md
-->"""
#: The one command that runs a policy on this page's scenes from a clone of the repository:
#: the example policy of docs/policies.md, shipped as examples/my_policies.py.
ADD_YOUR_POLICY = (
    "naruto-benchmark --suite test --policies examples/my_policies.py:TurnerPolicy --seeds 0 \\\n"
    "    --eval-points 4 --output-dir runs/my_suite"
)
ADD_YOUR_POLICY_TWIN = """<!-- docs-test: twin add-policy bash slow
naruto-benchmark --suite test --size-class small --suite-limit 1 \\
    --policies examples/my_policies.py:TurnerPolicy --seeds 0 --max-episode-steps 3 --workers 0 \\
    --image-scale 0.1 --eval-points 1 --eval-samples 2000 --checkpoint-samples 2000 \\
    --eval-samples-per-m2 0 --no-plots --no-progress --output-dir runs/my_suite
grep -q "| TurnerPolicy |" runs/my_suite/statistics.md
-->"""
CURVES_PNG = "leaderboard_curves.png"
PAIRED_PNG = "leaderboard_paired.png"


def _machine_line(machine: dict[str, Any]) -> str:
    gpu = machine.get("gpu") or "no GPU"
    return (
        f"{machine.get('host')}: {machine.get('platform')}, {machine.get('cpus')} CPU cores, "
        f"{gpu}, Python {machine.get('python')}, naruto-gym {machine.get('naruto_gym')}"
        f" (commit {machine.get('commit') or 'unknown'})"
        + (f", load {machine['load_average'][0]:.1f} at the start"
           if machine.get("load_average") else "")
    )


def _add_your_policy() -> list[str]:
    """The page's 'Add your policy' section: one command that runs from a clone."""
    return [
        "## Add your policy",
        "",
        "One command runs a policy on the scenes below with their budgets, the same seed, "
        "camera and scoring, from a clone of the repository. Here it runs the example of the "
        "[policies page](../policies.md#adding-a-policy), shipped as "
        "`examples/my_policies.py`; name yours the same way, by file "
        "(`path/to/file.py:ClassName`) or module (`package.module:ClassName`):",
        "",
        "<!-- docs-test: skip (hours: 24 houses; covered by: add-policy) -->",
        "```bash",
        ADD_YOUR_POLICY,
        "```",
        ADD_YOUR_POLICY_TWIN,
        "",
        "It writes `runs/my_suite/statistics.md`, whose tables have this page's columns and "
        "intervals, so your rows compare with the ones below (`--size-class small` runs one "
        "class, `--suite-limit 1` one house per class, `--variant open` the open scans). "
        "Where you hold the folder of the runs below, run into it instead (`--output-dir`): the "
        "episodes already there are kept, only yours run, and the command at the end of this "
        "page then puts your policy on it.",
        "",
    ]


EXTERNAL_INTRO = (
    "Scenes the generator did not make, each with the budget of its footprint: a policy "
    "ahead on the generated classes and behind here fits the generator. A folder of your "
    "own scans runs the same way ([your own scans](../scans.md))."
)


def _runs_section(manifest: dict[str, Any]) -> list[str]:
    lines = ["## How it was run", ""]
    seen: set[tuple[str, str]] = set()
    for run in manifest.get("runs", []):
        key = (run["command"], _machine_line(run["machine"]))
        if key in seen:
            continue
        seen.add(key)
        lines += [SKIP, "```bash", run["command"], "```", "", f"on {key[1]}.", ""]
    return lines


def _scenes_by_group(manifest: dict[str, Any]) -> list[tuple[str, list[tuple[str, dict]]]]:
    """The manifest's (scene label, entry) pairs by group, groups in table order."""
    by_group: dict[str, list[tuple[str, dict[str, Any]]]] = {}
    for label, entry in sorted(manifest.get("scenes", {}).items()):
        by_group.setdefault(entry_group(entry), []).append((label, entry))
    return [(group, by_group[group]) for group in ordered_groups(by_group)]


def _partial_note(manifest: dict[str, Any]) -> str | None:
    """A warning when the run is shorter than the suite: fewer test scenes or a cut budget."""
    suite = suite_module()
    partial = []
    for group, labelled in _scenes_by_group(manifest):
        entries = [entry for _, entry in labelled]
        size_class = entries[0]["size_class"]
        if size_class not in suite.SIZE_CLASSES:
            continue
        budgets = sorted({entry["budget"] for entry in entries})
        full = suite.budget(size_class)
        listed = len(suite.test_seeds(size_class))
        if budgets != [full] or (manifest.get("split") == "test" and len(entries) < listed):
            partial.append(f"{group}: {len(entries)} of {listed} test scenes, "
                           f"{'/'.join(map(str, budgets))} of {full} steps")
    if not partial:
        return None
    return ("**A shortened run, not the suite's figures** (" + "; ".join(partial)
            + "): run the whole split for the leaderboard.")


def _missing_note(manifest: dict[str, Any]) -> str | None:
    """The test split's size classes the run holds no scene of, or None."""
    if manifest.get("split") != "test":
        return None
    suite = suite_module()
    present = {entry["size_class"] for entry in manifest.get("scenes", {}).values()}
    missing = [f"{size_class} ({len(suite.test_seeds(size_class))} test scenes of "
               f"{suite.budget(size_class)} steps)"
               for size_class in suite.SIZE_CLASSES if size_class not in present]
    if not missing:
        return None
    return ("**Not in this run**: " + ", ".join(missing) + "; run them with "
            "`--size-class` into the same folder to rank the policies there too.")


def _scenes_section(manifest: dict[str, Any], records: list[dict[str, Any]]) -> list[str]:
    episodes = Counter(record["scene"] for record in records if record.get("status") == STATUS_OK)
    lines = ["## Scenes", "", "| Class | Scenes | Budget (steps) | Variant | Episodes |",
             "|---|---|---|---|---|"]
    for _, entries in _scenes_by_group(manifest):
        size_class = entries[0][1]["size_class"]
        budgets = sorted({entry["budget"] for _, entry in entries})
        variants = sorted({entry["variant"] for _, entry in entries})
        count = sum(episodes.get(label, 0) for label, _ in entries)
        names = ", ".join(f"`{entry['scene']}`" for _, entry in entries)
        lines.append(
            f"| {size_class} | {names} | {'/'.join(map(str, budgets))} | "
            f"{', '.join(variants)} | {count} |"
        )
    return [*lines, ""]


def leaderboard_markdown(
    results_dir: str | Path, img_dir: str | Path, img_link: str = "img"
) -> str:
    """The page's Markdown; writes its two PNG files into ``img_dir``.

    Args:
        results_dir: a ``naruto-benchmark --suite`` output folder, or an archive of one.
        img_dir: where the curve pictures go.
        img_link: how the page links ``img_dir`` (relative to the page).

    Raises:
        ValueError: a folder without ``suite.json`` or without records.
    """
    from naruto_agent.benchmark.suite_plots import plot_class_curves, plot_paired

    manifest = read_manifest(results_dir)
    if manifest is None:
        raise ValueError(
            f"{results_dir} holds no suite.json; run naruto-benchmark --suite test "
            f"--output-dir {results_dir} first"
        )
    records = load_episodes(results_dir)
    if not records:
        raise ValueError(f"{results_dir} holds no episode records or archived episodes")
    summary = class_summary(records, manifest)
    paired = paired_summary(records, manifest)
    img_dir = Path(img_dir)
    plot_class_curves(records, manifest, img_dir / CURVES_PNG)
    plot_paired(paired, img_dir / PAIRED_PNG)
    lines = [
        "# Leaderboard",
        "",
        "<!-- generated by python -m naruto_agent.benchmark.leaderboard; do not edit -->",
        "",
        f"Policies on [the scene suite](../scenes.md#the-benchmark-suite) (version "
        f"{manifest.get('suite_version')}, "
        f"{manifest.get('split')} split): every scene of a size class with the class's step "
        "budget, the same episode seeds for every policy. Each cell is the mean over scenes and "
        "seeds with its 95 % bootstrap interval (10,000 resamples of scenes, then of seeds "
        "inside each scene). Rows are ranked by **AUC steps**, the area under the "
        "completion-ratio curve of the observable surface over the budget (1.0: everything at "
        "once); the whole surface's ratio also counts faces no camera inside can see, such as "
        "the outer faces of walls. **AUC path** is the "
        "area over the path walked, up to the longest path the budget allows. Steps and metres "
        "to a level average the episodes that reached it (reached / episodes). The definitions "
        "are in `naruto_agent.benchmark.efficiency`; the [policies page](policies.md) says "
        "what each policy does.",
        "",
        *([note, ""] if (note := _partial_note(manifest)) else []),
        *([missing, ""] if (missing := _missing_note(manifest)) else []),
        *_add_your_policy(),
    ]
    for size_class in ordered_groups(summary):
        lines += [
            f"## {size_class}",
            "",
            *([EXTERNAL_INTRO, ""] if size_class == EXTERNAL_CLASS else []),
            class_table(summary[size_class], EFFICIENCY_KEYS),
            "Map quality and the walk (refusals: moves the env refused; stalled steps: steps "
            "the policy's stall watchdog counted as stalled):",
            "",
            class_table(summary[size_class], QUALITY_KEYS),
        ]
        if paired.get(size_class):
            lines += [
                f"Paired differences A - B over the same scenes and seeds ({size_class}):",
                "",
                paired_table(paired[size_class]),
            ]
    lines += [
        "## Curves",
        "",
        "Completion ratio against the fraction of the budget and against the path walked "
        "(mean, shaded 95 % band), a column per class:",
        "",
        f"![completion-ratio curves per class]({img_link}/{CURVES_PNG})",
        "",
        "Paired differences of AUC steps (filled: the interval excludes 0):",
        "",
        f"![paired differences]({img_link}/{PAIRED_PNG})",
        "",
    ]
    lines += _scenes_section(manifest, records)
    lines += _runs_section(manifest)
    lines += [
        "This page:",
        "",
        SKIP,
        "```bash",
        f"python -m naruto_agent.benchmark.leaderboard {_relative(results_dir)} "
        f"--img-dir {_relative(img_dir)} > docs/benchmarks/leaderboard.md",
        "```",
        "",
        TWIN,
        "",
    ]
    return "\n".join(lines)


def _relative(path: str | Path) -> str:
    try:
        return os.path.relpath(Path(path).resolve(), Path.cwd())
    except ValueError:  # another drive on Windows
        return str(path)


def main(argv: list[str] | None = None) -> int:
    """Print the leaderboard page of a results folder (see the module docstring)."""
    parser = argparse.ArgumentParser(
        prog="python -m naruto_agent.benchmark.leaderboard",
        description="Print the leaderboard page of a naruto-benchmark --suite results folder.",
    )
    parser.add_argument("results_dir", help="the --output-dir of the suite run")
    parser.add_argument("--img-dir", default="docs/benchmarks/img",
                        help="where the curve pictures are written")
    parser.add_argument("--img-link", default="img",
                        help="how the page links --img-dir (relative to the page)")
    args = parser.parse_args(argv)
    try:
        print(leaderboard_markdown(args.results_dir, args.img_dir, args.img_link))
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
