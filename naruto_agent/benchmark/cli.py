"""``naruto-benchmark``: compare policies on scenes x seeds with a step budget.

Runs every (scene, policy, seed) episode in spawned worker processes (or as Ray tasks with
``--ray-address``), writes one JSON record per episode as soon as it finishes, then a Markdown
table (mean +- std over seeds), a JSON summary and plots. A rerun skips the episodes already
recorded with the same settings and retries the failed ones; every failed episode is listed
with its reason and the record that holds its traceback.

Example::

    naruto-benchmark --scenes replica_like_room apartment \\
        ../shared/scenes/replica_office0/mesh.ply --policies passive random frontier \\
        --seeds 0 1 2 --max-episode-steps 1000 --workers 2 --output-dir runs/compare_policies
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from naruto_agent.benchmark import suite
from naruto_agent.benchmark.checks import leaderboard_differences, leaderboard_note
from naruto_agent.benchmark.executors import pending_specs, run_local, run_ray
from naruto_agent.benchmark.plots import plot_curves, plot_trajectories
from naruto_agent.benchmark.records import load_records, write_json_atomic
from naruto_agent.benchmark.runner import run_episode_safe
from naruto_agent.benchmark.spec import EpisodeSpec, build_specs
from naruto_agent.benchmark.suite_report import write_statistics
from naruto_agent.benchmark.tables import (
    failure_lines,
    markdown_table,
    protocol_lines,
    summarise,
)
from naruto_agent.cli_args import dataclass_parser

DEFAULT_MAX_EPISODE_STEPS = 500
DEFAULT_EVAL_POINTS = 4


@dataclass
class Args:
    """Arguments of the policy comparison (each field is a ``--flag``)."""

    scenes: list[str] = field(default_factory=lambda: ["replica_like_room"])
    """scenes, each a catalogue name (listed below), NAME:OPENINGS (an open scan, e.g.
    two_rooms:no_ceiling+holes), procedural:room:SEED (a generated room), or a mesh path
    (PATH@AXIS gives that file's up axis, e.g. room.obj@y)"""
    policies: list[str] = field(default_factory=lambda: ["passive", "random", "frontier"])
    """policies, each a registered name (listed below), package.module:ClassName (a module in
    the working directory is found) or path/to/file.py:ClassName"""
    seeds: list[int] = field(default_factory=lambda: [0, 1, 2])
    """episode seeds"""
    max_episode_steps: int | None = None
    """length of every episode in steps (default 500; with --suite each scene's class
    budget)"""
    up_axis: str | None = None
    """up axis of the mesh paths written without @AXIS: z, y, -y, x, -x, -z or auto (from a
    recognised dataset layout, for the external class also from the geometry); default z for
    --scenes, auto for the external class"""
    mesh_units: str = "m"
    """length unit of the mesh paths (m, cm or mm), rescaled to metres on loading; catalogue
    and procedural scenes are in metres"""
    image_scale: float = 0.25
    """camera resolution factor of the 680 x 1200 (H x W) camera (0.25: 170 x 300)"""
    workers: int = 2
    """parallel worker processes (0: run in this process)"""
    ray_address: str | None = None
    """run on Ray instead: auto, HOST:PORT, or local"""
    output_dir: str = "runs/compare_policies"
    """output folder (records/, results.md, summary.json, plots)"""
    eval_points: int | None = None
    """completion-ratio evaluation points per episode besides the final score (0: final
    only; default 4, with --suite 9)"""
    eval_samples: int = 200_000
    """surface samples per mesh of the final score"""
    checkpoint_samples: int = 50_000
    """surface samples per mesh at the evaluation points"""
    eval_samples_per_m2: float = 2_000.0
    """least sample density (per m^2) of the surface distances are measured to; 0: the sample
    counts alone, as published (large scenes then score sample spacing, not the map)"""
    reconstruct: bool = True
    """fuse frames with the reference TSDF mapper and score them"""
    reference_device: str = "auto"
    """Open3D device of the reference TSDF mapper (auto, cpu, cuda); the device of a policy's
    own mapper goes in --policy-kwargs, e.g. '{"naruto": {"device": "cuda"}}'"""
    policy_kwargs: str = "{}"
    """JSON object of constructor arguments keyed by policy, e.g. '{"random":
    {"max_run_steps": 20}}'; with one policy also its arguments directly, e.g.
    '{"max_run_steps": 20}' (as naruto-demo takes them)"""
    env_kwargs: str = "{}"
    """JSON dict of extra env arguments, e.g. '{"max_depth_m": 5.0}'"""
    suite: str | None = None
    """run the scene suite's split (test or train) instead of --scenes, every scene with its
    size class's budget"""
    size_class: list[str] = field(default_factory=list)
    """size classes of --suite (small, flat, house; default all three), or external:
    the scans of --scenes-dir, scenes the generator did not make"""
    scenes_dir: str | None = None
    """folder of meshes the external class runs, every mesh file under it a scene (default
    ../shared/scenes, the sample scans)"""
    variant: str = "closed"
    """variant of the --suite scenes: closed or open (no ceiling, holes)"""
    suite_limit: int = 0
    """run only the first N scenes of each --suite class (0: all; for quick checks)"""
    plots: bool = True
    """write the plots"""
    record: bool = False
    """write a Rerun recording of every episode run, OUTPUT_DIR/recordings/EPISODE.rrd (needs
    the viewer extra; local workers only)"""
    progress: bool = True
    """show a progress bar"""
    # How the scores are made (docs/replica.md, docs/mp3d.md).
    ground_truth: str = "auto"
    """what the scores are measured against: auto (a Replica scene's mesh_culled.ply when
    its folder holds one, a ground_truth.json's mesh, else the scene mesh) or full (never
    the culled mesh)"""
    reference_image_scale: float = 0.25
    """camera resolution factor the reference map is fused at, whatever --image-scale the
    policy sees (0.25: the leaderboard's, so its scores compare with the leaderboard's)"""
    release_reading: bool = False
    """add the published release's reading of the same scores to results.md (its accuracy is
    our completion, its completion ratio our precision)"""


def build_parser() -> argparse.ArgumentParser:
    """An ``argparse`` parser made from the fields of :class:`Args`."""
    from naruto_agent.policies import policy_names
    from naruto_gym.scenes import available_scenes

    description = __doc__.split("\n\n")[1].replace("\n", " ")
    parser = dataclass_parser(Args, description=description, prog="naruto-benchmark")
    parser.epilog = (
        f"registered policies: {', '.join(policy_names())}; any other Policy subclass as "
        "package.module:ClassName or path/to/file.py:ClassName. Catalogue scenes: "
        f"{', '.join(available_scenes())}; also NAME:OPENINGS, procedural:room:SEED and mesh "
        "paths (PATH@AXIS)."
    )
    return parser


def parse_args(argv: list[str] | None = None) -> Args:
    """The command line's :class:`Args`; a size class of an earlier name stops the command
    with the name to use (exit status 2, as any bad flag)."""
    parser = build_parser()
    namespace = parser.parse_args(argv)
    for name in namespace.size_class:
        message = suite.suite_module().renamed_size_class_message(name)
        if message:
            parser.error(message)
    return Args(**vars(namespace))


def _json_dict(text: str, name: str) -> dict[str, Any]:
    try:
        value = json.loads(text)
    except json.JSONDecodeError as error:
        raise ValueError(f"--{name} must be a JSON object: {error}") from error
    if not isinstance(value, dict):
        raise ValueError(f"--{name} must be a JSON object, got {text!r}")
    return value


def write_reports(
    output_dir: str | Path, plots: bool = True, release_reading: bool = False
) -> dict[str, Any]:
    """Table, summary and plots of every record under ``output_dir``; returns the summary.

    ``release_reading`` adds the published release's reading of the scores to the table;
    the lines under it say what the scores were measured against and how the run's settings
    differ from the leaderboard's (:func:`~naruto_agent.benchmark.tables.protocol_lines`)."""
    output_dir = Path(output_dir)
    records = load_records(output_dir)
    rows = summarise(records)
    protocol = protocol_lines(records)
    table = markdown_table(rows, release_reading)
    (output_dir / "results.md").write_text(table + "".join(f"\n{line}\n" for line in protocol))
    summary = {"rows": rows, "episodes": len(records), "protocol": protocol}
    write_json_atomic(output_dir / "summary.json", summary)
    if plots and records:
        plot_curves(records, output_dir / "curves.png")
        plot_trajectories(records, output_dir)
    write_statistics(output_dir, records, plots)
    return summary


def check_policies(policies: list[str]) -> None:
    """Load every policy given by import or file path, so that a missing module, file or class
    stops the run with one clear error before any episode starts.

    Raises:
        ValueError: a policy that cannot be loaded (the message says why).
    """
    from naruto_agent.policies import policy_class, policy_names

    registered = set(policy_names())
    for policy in policies:
        if policy not in registered:
            policy_class(policy)


def recording_fn(args: Args) -> dict[str, Any]:
    """``run_local``'s ``episode_fn`` that records each episode under
    ``OUTPUT_DIR/recordings`` with ``--record`` (empty otherwise).

    Raises:
        SystemExit: ``--record`` with Ray, or without rerun-sdk (the message says what to do).
    """
    if not args.record:
        return {}
    from naruto_agent.recording import rerun_available
    from naruto_agent.recording.live import RERUN_EXTRA_HINT

    if args.ray_address:
        raise SystemExit(
            "naruto-benchmark: --record runs with local workers only (drop --ray-address)"
        )
    if not rerun_available():
        raise SystemExit(f"naruto-benchmark: --record needs rerun-sdk: {RERUN_EXTRA_HINT}")
    folder = str(Path(args.output_dir) / "recordings")
    return {"episode_fn": functools.partial(run_episode_safe, record_dir=folder)}


def episode_specs(args: Args, argv: list[str] | None = None) -> list[EpisodeSpec]:
    """The run's episodes: ``--scenes``, or the ``--suite`` selection (whose scenes, command
    and machine then go to the output folder's ``suite.json``)."""
    suite_points = suite.DEFAULT_EVAL_POINTS if args.suite else DEFAULT_EVAL_POINTS
    settings = dict(
        up_axis=args.up_axis or "z",
        mesh_units=args.mesh_units,
        image_scale=args.image_scale,
        eval_points=suite_points if args.eval_points is None else args.eval_points,
        eval_samples=args.eval_samples,
        checkpoint_samples=args.checkpoint_samples,
        eval_samples_per_m2=args.eval_samples_per_m2,
        reconstruct=args.reconstruct,
        device=args.reference_device,
        policy_kwargs=_json_dict(args.policy_kwargs, "policy-kwargs"),
        env_kwargs=_json_dict(args.env_kwargs, "env-kwargs"),
        ground_truth=args.ground_truth,
        reference_image_scale=args.reference_image_scale,
    )
    if not args.suite:
        return build_specs(
            args.scenes,
            args.policies,
            args.seeds,
            args.max_episode_steps or DEFAULT_MAX_EPISODE_STEPS,
            **settings,
        )
    if args.scenes_dir is not None and suite.EXTERNAL_CLASS not in args.size_class:
        raise ValueError("--scenes-dir is the external class's folder: add --size-class external")
    scenes = suite.select_scenes(
        args.suite,
        args.size_class,
        args.variant,
        args.suite_limit,
        scenes_dir=args.scenes_dir,
        up_axis=args.up_axis or "auto",
        mesh_units=args.mesh_units,
    )
    specs = suite.suite_specs(scenes, args.policies, args.seeds, args.max_episode_steps, **settings)
    suite.write_manifest(
        args.output_dir, suite.manifest_entries(scenes, args.max_episode_steps), args.suite, argv
    )
    return specs


def run(args: Args, argv: list[str] | None = None) -> int:
    """Run the comparison; returns the number of failed episodes."""
    check_policies(args.policies)
    specs = episode_specs(args, argv)
    todo = pending_specs(specs, args.output_dir)
    _print_leaderboard_notes(specs)
    print(
        f"{len(specs)} episodes, {len(specs) - len(todo)} already done, running {len(todo)} "
        f"({'Ray ' + args.ray_address if args.ray_address else f'{args.workers} workers'})",
        flush=True,
    )
    started = time.perf_counter()
    failed = 0
    if todo:
        if args.ray_address:
            failed = run_ray(todo, args.output_dir, args.ray_address, args.progress)
        else:
            failed = run_local(
                todo, args.output_dir, args.workers, args.progress, **recording_fn(args)
            )
    summary = write_reports(args.output_dir, args.plots, args.release_reading)
    output_dir = Path(args.output_dir)
    print((output_dir / "results.md").read_text())
    print(
        f"{summary['episodes']} records in {output_dir}; this run: {len(todo)} episodes, "
        f"{failed} failed, {time.perf_counter() - started:.0f} s"
    )
    failures = failure_lines(specs, output_dir)
    if failures:
        print(f"{len(failures)} failed episode(s); the traceback is in each record:")
        print("\n".join(failures))
    return failed


def _print_leaderboard_notes(specs: list[EpisodeSpec]) -> None:
    """Say, before the run, how its settings differ from the leaderboard's (nothing when they
    do not)."""
    notes = []
    for spec in specs:
        found = leaderboard_differences(spec.as_dict())
        note = leaderboard_note(found["differences"], found["scores_comparable"])
        if note and note not in notes:
            notes.append(note)
    for note in notes:
        print(f"note: {note}", flush=True)


def main(argv: list[str] | None = None) -> int:
    """Console entry point (``naruto-benchmark``)."""
    args = parse_args(argv)
    try:
        failed = run(args, argv)
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
