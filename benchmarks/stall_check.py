"""Stall check on open scans: does any shipped policy stay put while there is still to see?

Runs every policy (each with its stall watchdog, as shipped) on the open variants of the
catalogue (``NAME:no_ceiling+holes``: no ceiling, holes in the floor and walls) and of a few
scenes of the suite's test split (``procedural:small:SEED:no_ceiling+holes``), and reports per
episode:

* the longest stay: the most steps in a row within 0.5 m of where the agent ended them while
  coverage was below 90 % (:func:`naruto_agent.policies.watchdog.longest_stay`; the issue's
  bound is 30 steps);
* final coverage, path length, the watchdog's triggers by kind and its stalled steps.

and per scene whether NARUTO walked at least frontier's path or covered more, on the mean of
the seeds run (``--seeds 0 1 2``).

It is resumable: every finished episode is written at once into ``stall_check.json`` under
``--output-dir`` (with its table, ``stall_check.md``), and a rerun skips the episodes found
there. Runs side by side (a process per seed, ``--seeds 1``) add to the same file: each
takes a lock on it while it reads and writes it. Example::

    nice -n 10 python benchmarks/stall_check.py
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from naruto_agent.benchmark.records import write_json_atomic
from naruto_agent.cli_args import dataclass_parser

RESULT_FILE = "stall_check.json"
#: The episodes' table, written beside the result file (the open-scans page includes it).
TABLE_FILE = "stall_check.md"
#: The longest stay the issue allows (steps within ``STAY_RADIUS_M`` below ``COVERED``).
MAX_STAY_STEPS = 30
STAY_RADIUS_M = 0.5
COVERED = 0.9


@dataclass
class Args:
    """Arguments of the stall check (each field is a ``--flag``)."""

    scenes: list[str] = field(
        default_factory=lambda: [
            "replica_like_room:no_ceiling+holes",
            "two_rooms:no_ceiling+holes",
            "apartment:no_ceiling+holes",
            *(
                f"procedural:{kind}:{1000000 + k}:no_ceiling+holes"
                for kind in ("small", "flat")
                for k in range(8)
            ),
        ]
    )
    """open scenes, in the order run: the catalogue's two rooms and apartment, and the
    suite's eight small and eight flat test scenes"""
    policies: list[str] = field(
        default_factory=lambda: ["passive", "random", "frontier", "naruto", "explorer"]
    )
    """policies to run, each with its default settings (watchdog included); ``explorer``
    needs Stable-Baselines3"""
    seeds: list[int] = field(default_factory=lambda: [0, 1, 2])
    """episode seeds (NARUTO is judged against frontier on each scene's mean over them)"""
    max_episode_steps: int = 300
    """length of every episode"""
    image_scale: float = 0.125
    """camera resolution factor (0.125: 85 x 150, as the behaviour fingerprint)"""
    output_dir: str = "benchmarks/results/open_scans"
    """folder of stall_check.json"""


def run_episode(scene: str, policy_name: str, seed: int, args: Args) -> dict[str, Any]:
    """One episode; what the check reports of it."""
    import gymnasium as gym

    import naruto_gym  # noqa: F401
    from naruto_agent.episode_loop import StepRecords, run_episode_loop
    from naruto_agent.policies import make_policy
    from naruto_agent.policies.watchdog import longest_stay

    policy = make_policy(policy_name)
    env = gym.make(
        "NarutoRecon-v0",
        scene=scene,
        action_mode=policy.preferred_action_mode,
        image_scale=args.image_scale,
        max_episode_steps=args.max_episode_steps,
    )
    records = StepRecords()
    clock = time.perf_counter()
    run_episode_loop(env, policy, args.max_episode_steps, seed, [records])
    seconds = time.perf_counter() - clock
    positions = np.asarray(records.positions[1:])
    coverage = np.asarray(records.coverage[1:])
    steps = np.linalg.norm(np.diff(np.asarray(records.positions), axis=0), axis=1)
    kinds: dict[str, int] = {}
    for event in policy.stall_events:
        kinds[event.kind] = kinds.get(event.kind, 0) + 1
    result = {
        "scene": scene,
        "policy": policy_name,
        "seed": seed,
        "steps": int(len(coverage)),
        "image_scale": args.image_scale,
        "longest_stay_steps": longest_stay(positions, coverage, STAY_RADIUS_M, COVERED),
        "coverage": round(float(coverage[-1]), 4),
        "path_m": round(float(steps.sum()), 3),
        "stall_events": kinds,
        "stalled_steps": int(policy.stalled_steps),
        "refusals": dict(records.collisions),
        "seconds": round(seconds, 1),
    }
    env.close()
    policy.close()
    return result


def summary(episodes: list[dict[str, Any]]) -> dict[str, Any]:
    """The issue's two tests over the episodes run: the stays over ``MAX_STAY_STEPS``, and
    per scene NARUTO's path and coverage against frontier's (:func:`naruto_against_frontier`)."""
    long_stays = [
        f"{e['policy']}@{e['scene']}#{e['seed']}: {e['longest_stay_steps']}"
        for e in episodes
        if e["longest_stay_steps"] > MAX_STAY_STEPS
    ]
    return {"stays_over_limit": long_stays, "naruto_vs_frontier": naruto_against_frontier(episodes)}


def naruto_against_frontier(episodes: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per scene, NARUTO's mean path and coverage over the seeds both it and frontier ran,
    against frontier's over the same seeds. The test holds where NARUTO's mean path is at
    least frontier's or its mean coverage higher: one 300-step episode is a single draw of
    where each policy's first goals lead, so a scene is judged on all its seeds.
    ``seeds_holding`` counts the seeds on which the test holds episode by episode."""
    by_key = {(e["scene"], e["seed"], e["policy"]): e for e in episodes}
    pairs: dict[str, list[tuple[dict[str, Any], dict[str, Any]]]] = {}
    for (scene, seed, policy), naruto in sorted(by_key.items()):
        frontier = by_key.get((scene, seed, "frontier"))
        if policy == "naruto" and frontier is not None:
            pairs.setdefault(scene, []).append((naruto, frontier))
    rows = []
    for scene, scene_pairs in pairs.items():
        naruto_path, frontier_path, naruto_coverage, frontier_coverage = (
            float(np.mean([pair[side][key] for pair in scene_pairs]))
            for key, side in (("path_m", 0), ("path_m", 1), ("coverage", 0), ("coverage", 1))
        )
        rows.append(
            {
                "scene": scene,
                "seeds": [naruto["seed"] for naruto, _ in scene_pairs],
                "naruto_path_m": naruto_path,
                "frontier_path_m": frontier_path,
                "naruto_coverage": naruto_coverage,
                "frontier_coverage": frontier_coverage,
                "seeds_holding": sum(
                    naruto["path_m"] >= frontier["path_m"]
                    or naruto["coverage"] > frontier["coverage"]
                    for naruto, frontier in scene_pairs
                ),
                "holds": naruto_path >= frontier_path or naruto_coverage > frontier_coverage,
            }
        )
    return rows


def table(episodes: list[dict[str, Any]]) -> str:
    """The episodes as a Markdown table, by scene, seed and policy, and one line per scene on
    NARUTO against frontier over the seeds."""
    lines = [
        "| Scene | Seed | Policy | Longest stay (steps) | Coverage (%) | Path (m) "
        "| Watchdog triggers |",
        "|---|---|---|---|---|---|---|",
    ]
    for e in sorted(episodes, key=lambda e: (e["scene"], e["seed"], e["policy"])):
        kinds = e["stall_events"]
        triggers = ", ".join(f"{kind} {count}" for kind, count in sorted(kinds.items()))
        lines.append(
            f"| {e['scene']} | {e['seed']} | {e['policy']} | {e['longest_stay_steps']} | "
            f"{100 * e['coverage']:.1f} | {e['path_m']:.1f} | {triggers or 'none'} |"
        )
    lines.append("")
    for row in naruto_against_frontier(episodes):
        verdict = "holds" if row["holds"] else "does not hold"
        seeds = len(row["seeds"])
        lines.append(
            f"* `{row['scene']}`, mean of {seeds} seed{'s' if seeds > 1 else ''}: NARUTO "
            f"{row['naruto_path_m']:.1f} m, {100 * row['naruto_coverage']:.1f} % against "
            f"frontier's {row['frontier_path_m']:.1f} m, {100 * row['frontier_coverage']:.1f} % "
            f"(a longer path or more coverage: {verdict}; episode by episode on "
            f"{row['seeds_holding']} of {seeds})"
        )
    return "\n".join(lines) + "\n"


def machine() -> dict[str, Any]:
    """Where the check ran (timings are of a shared, loaded machine unless said otherwise)."""
    return {
        "host": platform.node(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
    }


def main(argv: list[str] | None = None) -> int:
    args = Args(
        **vars(dataclass_parser(Args, description=__doc__.split("\n\n")[0]).parse_args(argv))
    )
    path = Path(args.output_dir) / RESULT_FILE
    have = {_key(e) for e in _read(path)}
    for scene in args.scenes:
        for seed in args.seeds:
            for policy in args.policies:
                if (scene, policy, seed, args.max_episode_steps, args.image_scale) in have:
                    continue
                print(f"{policy} on {scene}, seed {seed}", flush=True)
                episode = run_episode(scene, policy, seed, args)
                episode["load_average"] = [round(v, 2) for v in os.getloadavg()]
                print(
                    f"  stay {episode['longest_stay_steps']}, coverage "
                    f"{100 * episode['coverage']:.1f} %, path {episode['path_m']:.1f} m, "
                    f"{episode['seconds']:.0f} s",
                    flush=True,
                )
                _write(path, args, [episode])
    result = _write(path, args, [])
    print(json.dumps(result, indent=1))
    return 1 if result["stays_over_limit"] else 0


def _key(episode: dict[str, Any]) -> tuple:
    return (
        episode["scene"],
        episode["policy"],
        episode["seed"],
        episode["steps"],
        episode["image_scale"],
    )


def _read(path: Path) -> list[dict[str, Any]]:
    return json.loads(path.read_text())["episodes"] if path.is_file() else []


@contextmanager
def _locked(path: Path) -> Iterator[None]:
    """An exclusive lock on ``path``'s lock file while the block runs, so that runs side by
    side (a process per seed, say) do not drop each other's episodes between a read and a
    write. Where ``fcntl`` is missing (Windows) the block runs unlocked."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        yield
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path.with_name(path.name + ".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def _write(path: Path, args: Args, new: list[dict[str, Any]]) -> dict[str, Any]:
    """Add ``new`` to the episodes in the file as it is now (a second run of the script, say
    for another seed, may have added some meanwhile) and write it; returns the summary."""
    with _locked(path):
        episodes = {_key(e): e for e in _read(path)}
        episodes.update({_key(e): e for e in new})
        result = summary(list(episodes.values()))
        write_json_atomic(
            path,
            {
                "args": asdict(args),
                "machine": machine(),
                "episodes": list(episodes.values()),
                "summary": result,
            },
        )
        (path.parent / TABLE_FILE).write_text(table(list(episodes.values())))
    return result


if __name__ == "__main__":
    sys.exit(main())
