"""A suite run's episodes kept in git: compact copies of its records, so that a leaderboard run
spread over several sessions or machines loses nothing already computed.

A record (:mod:`naruto_agent.benchmark.records`) holds the episode's whole trajectory and
per-step coverage, tens of kB for an apartment, and stays out of git. Its compact copy keeps
what the leaderboard reads: the settings and their hash, the metrics, the completion curve,
the refusals and stalls, the commit that ran it, and, in place of the trajectory, the path
walked at each checkpoint of the curve and the efficiency metrics computed from it
(:func:`~naruto_agent.benchmark.efficiency.episode_efficiency`). About 3 kB an episode.

An archive is a folder of two files: ``suite.json``, as in a run folder (the scenes, and every
archived run's command and machine), and ``episodes.json``, the compact copies by episode id.
The leaderboard is generated from it as from a run folder (:func:`load_episodes` reads
both kinds)::

    naruto-benchmark --suite test --size-class small --policies explorer --seeds 0 1 2 \\
        --eval-points 4 --output-dir runs/suite
    python -m naruto_agent.benchmark.episode_archive runs/suite benchmarks/results/leaderboard
    python -m naruto_agent.benchmark.leaderboard benchmarks/results/leaderboard > leaderboard.md

Archiving an episode again (a policy re-run after a change) replaces its copy.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from naruto_agent.benchmark.efficiency import (
    checkpoint_paths,
    completion_points,
    episode_efficiency,
)
from naruto_agent.benchmark.records import (
    STATUS_OK,
    load_records,
    read_record,
    write_json_atomic,
)
from naruto_agent.benchmark.suite import MANIFEST_FILE, read_manifest

#: The file of an archive that holds the compact copies, by episode id.
EPISODES_FILE = "episodes.json"
#: What a compact copy keeps of its record as it is.
KEPT = (
    "episode_id",
    "status",
    "config",
    "config_hash",
    "scene",
    "policy",
    "seed",
    "steps_run",
    "action_mode",
    "metrics",
    "own_map_metrics",
    "coverage_final",
    "completion_curve",
    "path_length_m",
    "collisions",
    "collision_reasons",
    "stalled_steps",
    "host",
    "commit",
)


def compact_record(record: dict[str, Any]) -> dict[str, Any]:
    """The compact copy of a successful record (see the module docstring).

    Raises:
        ValueError: a failed record (nothing to keep: run it again), or one without a
            trajectory (already compact).
    """
    if record.get("status") != STATUS_OK:
        raise ValueError(
            f"episode {record.get('episode_id')} failed ({record.get('error')}): only "
            "successful episodes are archived; run it again"
        )
    if record.get("trajectory") is None:
        raise ValueError(f"episode {record.get('episode_id')} holds no trajectory to compact")
    copy = {key: record[key] for key in KEPT if key in record}
    steps, _ = completion_points(record)
    copy["checkpoint_path_m"] = [
        [int(step), round(float(metres), 4)]
        for step, metres in zip(steps, checkpoint_paths(record, steps), strict=True)
    ]
    copy["efficiency"] = episode_efficiency(record)
    return copy


def archive_run(run_dir: str | Path, archive_dir: str | Path) -> tuple[int, int]:
    """Copy the successful episodes of the suite run in ``run_dir`` into ``archive_dir``
    (compact, replacing earlier copies of the same episodes) and merge its ``suite.json``
    into the archive's; returns (episodes archived, of which new).

    Raises:
        ValueError: ``run_dir`` holds no suite run, or one of another suite version or split
            than the archive.
    """
    run_dir, archive_dir = Path(run_dir), Path(archive_dir)
    manifest = read_manifest(run_dir)
    if manifest is None:
        raise ValueError(f"{run_dir} holds no {MANIFEST_FILE}: give a naruto-benchmark --suite "
                         "--output-dir")
    archived = read_manifest(archive_dir) or {"scenes": {}, "runs": []}
    for key in ("suite_version", "split"):
        if archived.get(key) not in (None, manifest.get(key)):
            raise ValueError(
                f"{archive_dir} archives {key} {archived[key]!r}, {run_dir} ran "
                f"{manifest.get(key)!r}: archive it into another folder"
            )
        archived[key] = manifest.get(key)
    episodes = read_record(archive_dir / EPISODES_FILE) or {}
    count = new = 0
    for record in load_records(run_dir):
        if record.get("status") != STATUS_OK:
            continue
        new += record["episode_id"] not in episodes
        episodes[record["episode_id"]] = compact_record(record)
        count += 1
    write_json_atomic(archive_dir / EPISODES_FILE, dict(sorted(episodes.items())))
    archived["scenes"].update(manifest.get("scenes", {}))
    for run in manifest.get("runs", []):
        if run not in archived["runs"]:
            archived["runs"].append(run)
    write_json_atomic(archive_dir / MANIFEST_FILE, archived)
    return count, new


def load_episodes(folder: str | Path) -> list[dict[str, Any]]:
    """The episodes of a run folder (its records) or an archive (its compact copies), sorted
    by episode id; where a folder holds both for one episode, the record."""
    episodes: dict[str, dict[str, Any]] = dict(read_record(Path(folder) / EPISODES_FILE) or {})
    for record in load_records(folder):
        episodes[record["episode_id"]] = record
    return [episodes[key] for key in sorted(episodes)]


def main(argv: list[str] | None = None) -> int:
    """Archive a suite run (see the module docstring)."""
    parser = argparse.ArgumentParser(
        prog="python -m naruto_agent.benchmark.episode_archive",
        description="Keep compact copies of a naruto-benchmark --suite run's episodes in an "
        "archive folder the leaderboard is generated from.",
    )
    parser.add_argument("run_dir", help="the --output-dir of the suite run")
    parser.add_argument("archive_dir", help="the archive (created when missing)")
    args = parser.parse_args(argv)
    try:
        count, new = archive_run(args.run_dir, args.archive_dir)
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    print(f"archived {count} episodes ({new} new) into {args.archive_dir}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
