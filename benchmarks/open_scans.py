"""Closed scenes against their open variants. Results: docs/benchmarks/open-scans.md

Do policies keep moving, and stay inside, when the scan has no ceiling, holes and a missing
wall? Every policy on closed scenes and their open variants, through the benchmark harness.

For every base scene (catalogue names) the script runs the closed scan (``NAME:fragments``) and
its open variants (``NAME:OPENINGS``, see ``naruto_gym.scenes.open_scans``: ceiling removed,
holes cut in the floor and the walls, a wall missing; all with the same stray fragments outside
that widen the bounds, so closed and open versions share bounds and start poses), plus extra
open meshes without a closed counterpart (the open-top habitat-sim sample room beside the
repository), for every policy and seed, with the ``naruto-benchmark`` harness (resumable
records, the same runner and scoring). Then, per scene and policy:

* refused moves by ``collision_reason`` (surface, bounds, escape);
* path length and coverage, and their ratio to the closed scene's (goal: within 10 %);
* whether every position stayed inside: inside the closed building's envelope (an independent
  test that does not use the env's escape rule), and the share of positions the exact
  scanned-space test judges inside.

With ``--published-policies`` the same policies also run under the published escape rule
(``escape_rule="published"``, whole-sphere no-hit share above 50 %) in a subfolder, for the
before/after comparison.

Example (the run of the docs page; naruto last, it is the slowest)::

    python benchmarks/open_scans.py --policies passive random frontier --workers 1
    python benchmarks/open_scans.py --policies naruto --workers 1

Writes ``records/`` (one JSON per episode), ``results.md`` (the harness table), and
``open_scans.json`` / ``open_scans.md`` (this comparison) under ``--output-dir``.
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections import defaultdict
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from naruto_agent.benchmark.cli import write_reports
from naruto_agent.benchmark.executors import pending_specs, run_local
from naruto_agent.benchmark.records import STATUS_OK, load_records, write_json_atomic
from naruto_agent.benchmark.spec import SceneSpec, build_specs, parse_scene
from naruto_agent.cli_args import dataclass_parser

REPO = Path(__file__).resolve().parents[1]
HABITAT_ROOM = REPO.parent / "shared" / "scenes" / "habitat_simple_room" / "simple_room.glb"
REASONS = ("surface", "bounds", "escape")
CLOSE_ENOUGH = 0.10  # path length and coverage within 10 % of the closed scene's


@dataclass
class Args:
    """Arguments of the open-scan comparison (each field is a ``--flag``)."""

    scenes: list[str] = field(default_factory=lambda: ["replica_like_room", "two_rooms"])
    """closed catalogue scenes; each also runs with every opening"""
    openings: list[str] = field(
        default_factory=lambda: ["no_ceiling", "no_ceiling+holes", "no_ceiling+missing_wall"]
    )
    """open variants of each scene (NAME:OPENING)"""
    extra_scenes: list[str] = field(default_factory=lambda: [str(HABITAT_ROOM)])
    """open meshes without a closed version (skipped when the file is absent)"""
    policies: list[str] = field(default_factory=lambda: ["passive", "random", "frontier"])
    """policies to run (naruto is the slowest: run it last)"""
    seeds: list[int] = field(default_factory=lambda: list(range(10)))
    """episode seeds (10: with 3, a refusal count of 0.3 against 0.7 is one bump in one
    episode, and a path's seed-to-seed spread is about 8 % of it)"""
    max_episode_steps: int = 300
    """step budget of every episode"""
    image_scale: float = 0.25
    """camera resolution factor (0.25: 170 x 300)"""
    escape_rule: str = "scanned_space"
    """the env's escape rule"""
    published_policies: list[str] = field(default_factory=list)
    """policies also run under escape_rule=published on the open scenes (subfolder)"""
    workers: int = 1
    """worker processes (0: in this process)"""
    reconstruct: bool = False
    """also fuse and score the reference TSDF map (completion ratio; about 5x slower)"""
    eval_points: int = 1
    """completion-ratio checkpoints per episode besides the final score"""
    output_dir: str = "benchmarks/results/open_scans"
    """output folder"""
    report_only: bool = False
    """do not run episodes, only rebuild the tables from the records"""
    timing: bool = False
    """also time the escape check per move under each rule (run it under the timing lock)"""
    timing_moves: int = 3000
    """moves of the timed move sequence"""
    progress: bool = True
    """show a progress bar"""


def scene_arguments(args: Args) -> tuple[list[str], list[str]]:
    """(closed scenes, open scenes) as harness scene arguments.

    The closed reference of ``NAME`` is ``NAME:fragments``: the same scan with its ceiling,
    walls and floor whole, and the same stray fragments, so the same bounds and start poses.
    """
    closed = [f"{scene}:fragments" for scene in args.scenes]
    opened = [f"{scene}:{opening}" for scene in args.scenes for opening in args.openings]
    for extra in args.extra_scenes:
        if Path(extra.rpartition("@")[0] or extra).is_file():
            opened.append(extra)
        else:
            print(f"skipping {extra}: not found", flush=True)
    return closed, opened


def run_set(
    args: Args, scenes: list[str], policies: list[str], out_dir: Path, rule: str
) -> int:
    """Run (resumably) scenes x policies x seeds under one escape rule; returns failures."""
    if not scenes or not policies:
        return 0
    specs = build_specs(
        scenes, policies, args.seeds, args.max_episode_steps, image_scale=args.image_scale,
        eval_points=args.eval_points, reconstruct=args.reconstruct,
        env_kwargs={"escape_rule": rule},
    )
    todo = pending_specs(specs, out_dir)
    print(f"{out_dir}: {len(specs)} episodes, {len(todo)} to run, rule {rule}", flush=True)
    failed = run_local(todo, out_dir, args.workers, args.progress) if todo else 0
    write_reports(out_dir, plots=True)
    return failed


# ---------------------------------------------------------------------------------------
# Whether positions stayed inside
# ---------------------------------------------------------------------------------------
def envelope_of(scene: SceneSpec) -> np.ndarray | None:
    """The closed building's bounds for a catalogue scene or its variants (None otherwise)."""
    from naruto_gym.scenes.catalogue import available_scenes, catalogue_entry
    from naruto_gym.scenes.open_scans import building_envelope

    base = scene.scene.partition(":")[0]
    if base not in available_scenes():
        return None
    return building_envelope(catalogue_entry(base).layout())


class InsideChecker:
    """Scores trajectories against a scene's building envelope and exact scanned space."""

    def __init__(self) -> None:
        self._spaces: dict[tuple[str, str], Any] = {}

    def space(self, scene: SceneSpec) -> Any:
        key = (scene.scene, scene.up_axis)
        if key not in self._spaces:
            from naruto_gym.motion.scanned_space import ScannedSpace
            from naruto_gym.scenes.catalogue import resolve_scene
            from naruto_gym.sensors.raycaster import RayCaster

            mesh = resolve_scene(scene.scene, scene.up_axis)
            caster = RayCaster(mesh.vertices, mesh.faces)
            self._spaces[key] = ScannedSpace(caster, mesh.face_normals, mesh.bounds)
        return self._spaces[key]

    def check(self, record: dict[str, Any]) -> dict[str, Any]:
        config = record["config"]
        scene = SceneSpec(config["scene"], config.get("up_axis", "z"))
        positions = np.asarray(record["trajectory"], np.float64)
        envelope = envelope_of(scene)
        outside_m = 0.0
        if envelope is not None:
            excess = np.maximum(envelope[0] - positions, positions - envelope[1])
            outside_m = float(max(excess.max(), 0.0))
        # Recorded positions are rounded to 1 mm: judge the unique ones.
        unique = np.unique(positions, axis=0)
        inside = self.space(scene).evaluate(unique)
        return {
            "outside_envelope_m": outside_m,
            "scanned_inside_share": float(inside.mean()),
        }


# ---------------------------------------------------------------------------------------
# The comparison table
# ---------------------------------------------------------------------------------------
def _mean_std(values: list[float]) -> dict[str, float]:
    array = np.asarray(values, np.float64)
    return {
        "mean": float(array.mean()),
        "std": float(array.std(ddof=1)) if len(array) > 1 else 0.0,
        "n": int(len(array)),
    }


def summarise_open(records: list[dict[str, Any]], checker: InsideChecker) -> list[dict[str, Any]]:
    """One row per (scene, policy): refusals by reason, path, coverage, inside checks."""
    groups: dict[tuple[str, str], list[dict[str, Any]]] = defaultdict(list)
    for record in records:
        if record.get("status") == STATUS_OK:
            groups[(record["config"]["scene"], record["policy"])].append(record)
    rows = []
    for (scene, policy), members in sorted(groups.items()):
        checks = [checker.check(record) for record in members]
        reasons = {
            reason: _mean_std([r.get("collision_reasons", {}).get(reason, 0) for r in members])
            for reason in REASONS
        }
        rows.append({
            "scene": scene,
            "label": members[0]["scene"],
            "policy": policy,
            "seeds": sorted(r["seed"] for r in members),
            "refused": _mean_std([r.get("collisions", 0) for r in members]),
            "refused_by_reason": reasons,
            "path_length_m": _mean_std([r["path_length_m"] for r in members]),
            "coverage_pct": _mean_std([100.0 * r["coverage_final"] for r in members]),
            "env_ms_per_step": _mean_std([r["time_per_step_ms"]["env"] for r in members]),
            "outside_envelope_m": max(c["outside_envelope_m"] for c in checks),
            "scanned_inside_share": min(c["scanned_inside_share"] for c in checks),
        })
    return rows


def compare_to_closed(rows: list[dict[str, Any]], reference: list[dict[str, Any]]) -> None:
    """Add ratios to the closed scene's row (from ``reference``) and the goal checks, in
    place."""
    closed = {
        (row["scene"].partition(":")[0], row["policy"]): row
        for row in reference
        if row["scene"].endswith(":fragments")
    }
    for row in rows:
        base = closed.get((row["scene"].partition(":")[0], row["policy"]))
        row["stayed_inside"] = row["outside_envelope_m"] <= 1e-6
        if base is None or base is row:
            continue
        path = row["path_length_m"]["mean"] / max(base["path_length_m"]["mean"], 1e-9)
        coverage = row["coverage_pct"]["mean"] / max(base["coverage_pct"]["mean"], 1e-9)
        row["vs_closed"] = {
            "path_ratio": path,
            "coverage_ratio": coverage,
            "refused_closed": base["refused"]["mean"],
            "refused_not_more": row["refused"]["mean"] <= base["refused"]["mean"] + 1e-9,
            "path_within_10pct": abs(path - 1.0) <= CLOSE_ENOUGH,
            "coverage_within_10pct": abs(coverage - 1.0) <= CLOSE_ENOUGH,
        }


def _fmt(stat: dict[str, float], decimals: int = 1) -> str:
    return f"{stat['mean']:.{decimals}f} ± {stat['std']:.{decimals}f}"


def markdown(rows: list[dict[str, Any]], title: str) -> str:
    """The comparison as a Markdown table."""
    lines = [
        f"### {title}",
        "",
        "| Scene | Policy | Refused (surface / bounds / escape) | Path (m) | Coverage (%) | "
        "Path / closed | Coverage / closed | Stayed inside | Env ms/step |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        reasons = " / ".join(f"{row['refused_by_reason'][r]['mean']:.1f}" for r in REASONS)
        versus = row.get("vs_closed")
        path_ratio = coverage_ratio = "-"
        if versus:
            mark = "" if versus["path_within_10pct"] else " ✗"
            path_ratio = f"{versus['path_ratio']:.2f}{mark}"
            mark = "" if versus["coverage_within_10pct"] else " ✗"
            coverage_ratio = f"{versus['coverage_ratio']:.2f}{mark}"
            if not versus["refused_not_more"]:
                reasons += f" (closed {versus['refused_closed']:.1f}) ✗"
        inside = "yes" if row["stayed_inside"] else f"no ({row['outside_envelope_m']:.2f} m out)"
        inside += f", {100 * row['scanned_inside_share']:.0f} %"
        lines.append(
            f"| {row['label']} | {row['policy']} | {_fmt(row['refused'])} ({reasons}) | "
            f"{_fmt(row['path_length_m'])} | {_fmt(row['coverage_pct'])} | {path_ratio} | "
            f"{coverage_ratio} | {inside} | {row['env_ms_per_step']['mean']:.1f} |"
        )
    return "\n".join(lines) + "\n"


def report(
    out_dir: Path, title: str, checker: InsideChecker, reference: list[dict[str, Any]] | None = None
) -> list[dict[str, Any]]:
    """Rebuild ``open_scans.json`` / ``open_scans.md`` from the records under ``out_dir``;
    open scenes are compared with the closed rows of ``reference`` (default: these rows)."""
    rows = summarise_open(load_records(out_dir), checker)
    compare_to_closed(rows, rows if reference is None else reference)
    text = markdown(rows, title)
    (out_dir / "open_scans.md").write_text(text)
    write_json_atomic(out_dir / "open_scans.json", {
        "rows": rows,
        "loadavg": list(os.getloadavg()),
        "written": time.strftime("%Y-%m-%d %H:%M:%S"),
    })
    print(text, flush=True)
    return rows


# ---------------------------------------------------------------------------------------
# Cost of the escape check
# ---------------------------------------------------------------------------------------
def recorded_moves(scene: str, moves: int, seed: int = 0) -> np.ndarray:
    """(moves, 2, 3) start and target positions of a seeded random discrete walk."""
    import gymnasium as gym

    import naruto_gym  # noqa: F401
    from naruto_gym.motion.actions import discrete_target_from_action

    env = gym.make("NarutoRecon-v0", scene=scene, image_scale=0.05, coverage_samples=500,
                   panorama_shape=None, action_mode="discrete").unwrapped
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    pairs = []
    while len(pairs) < moves:
        action = int(rng.integers(0, 6)) if rng.random() < 0.8 else int(rng.integers(6, 10))
        if action < 6:  # a move: the position the action asks for, before any check
            target = discrete_target_from_action(
                env.pose, action, env.settings.max_translation_m, env.settings.max_rotation_rad
            )
            pairs.append((env.pose[:3, 3].copy(), target[:3, 3]))
        env.step(action)
    return np.array(pairs)


def time_escape_rules(scene: str, moves: int) -> dict[str, Any]:
    """Seconds per ``CollisionChecker.move`` of one recorded move sequence under each rule.

    The scanned-space lattice is timed cold (first pass, filling it) and warm (second pass);
    the rule "off" (collision checking alone) is the reference, measured in the same process.
    """
    from naruto_gym.motion.collision import CollisionChecker
    from naruto_gym.scenes.catalogue import resolve_scene
    from naruto_gym.sensors.raycaster import RayCaster

    pairs = recorded_moves(scene, moves)
    mesh = resolve_scene(scene)
    caster = RayCaster(mesh.vertices, mesh.faces)
    caster.unsigned_distance(pairs[:1, 0])  # build the native scenes before timing
    results: dict[str, Any] = {"scene": scene, "moves": len(pairs), "loadavg": os.getloadavg()}
    for rule in ("off", "published", "scanned_space"):
        checker = CollisionChecker(caster, mesh.bounds, escape_rule=rule)
        checker.scanned_space.top_m  # noqa: B018 (computed once per scene, not per move)
        passes = 2 if rule == "scanned_space" else 1
        for index in range(passes):
            clock = time.perf_counter()
            for start, end in pairs:
                checker.move(start, end)
            per_move = (time.perf_counter() - clock) / len(pairs)
            key = rule if passes == 1 else f"{rule}_{'cold' if index == 0 else 'warm'}"
            results[key + "_us"] = 1e6 * per_move
    reference = results["off_us"]
    for key in ("published_us", "scanned_space_cold_us", "scanned_space_warm_us"):
        results[key.replace("_us", "_escape_us")] = results[key] - reference
    results["published_over_scanned_warm_escape"] = results["published_escape_us"] / max(
        results["scanned_space_warm_escape_us"], 1e-9
    )
    return results


def main(argv: list[str] | None = None) -> int:
    args = Args(**vars(dataclass_parser(Args, description=__doc__.split("\n\n")[0]).parse_args(
        argv
    )))
    for scene in args.scenes:
        parse_scene(scene)  # validates early
    out_dir = Path(args.output_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "args.json").write_text(json.dumps(asdict(args), indent=2))
    closed, opened = scene_arguments(args)
    started = time.perf_counter()
    failed = 0
    if not args.report_only:
        failed += run_set(args, closed + opened, args.policies, out_dir, args.escape_rule)
        failed += run_set(args, opened, args.published_policies, out_dir / "published",
                          "published")
    if args.timing:
        timing = time_escape_rules(f"{args.scenes[0]}:no_ceiling+holes", args.timing_moves)
        write_json_atomic(out_dir / "escape_timing.json", timing)
        print(
            "escape check per move ({moves} moves, load {load}): published {p:.0f} us, "
            "scanned space {c:.0f} us cold / {w:.0f} us warm, on top of {o:.0f} us of "
            "collision checking; published / scanned warm = {r:.1f}x".format(
                moves=timing["moves"], load=np.round(timing["loadavg"], 2).tolist(),
                p=timing["published_escape_us"], c=timing["scanned_space_cold_escape_us"],
                w=timing["scanned_space_warm_escape_us"], o=timing["off_us"],
                r=timing["published_over_scanned_warm_escape"],
            ),
            flush=True,
        )
    checker = InsideChecker()
    rows = report(out_dir, f"Open scans, escape rule {args.escape_rule!r}", checker)
    if (out_dir / "published" / "records").is_dir():
        report(out_dir / "published", "Open scans, published escape rule", checker, rows)
    print(f"load average {os.getloadavg()}, {time.perf_counter() - started:.0f} s, "
          f"{failed} failed episodes", flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
