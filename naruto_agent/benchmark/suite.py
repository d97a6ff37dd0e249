"""The scene suite as benchmark episodes: ``naruto-benchmark --suite test``.

The suite itself (scenes, size classes, budgets, the fixed test seeds) is named data in
:mod:`naruto_gym.scenes.suite`; this module turns a selection of it into harness episodes,
each with its scene's class budget, and keeps a manifest (``suite.json`` in the output folder)
that says which class, variant and split each scene label belongs to, with the command and the
machine of each run. Reports read the manifest to group results by class; the episodes
themselves are ordinary harness episodes, so local workers, Ray and resuming work unchanged.
"""

from __future__ import annotations

import json
import os
import platform
import shlex
import sys
from pathlib import Path
from typing import Any

from naruto_agent.benchmark.records import read_record, source_commit, write_json_atomic
from naruto_agent.benchmark.spec import EpisodeSpec, build_specs, parse_scene
from naruto_gym.scenes.external import (
    EXTERNAL_CLASS,
    EXTERNAL_VARIANT,
    SAMPLE_SCANS,
    SHARED_SCENES_DIR,
    ExternalScan,
    external_scans,
    external_suite_scenes,
    missing_sample_scans,
    sample_scans_dir,
)

MANIFEST_FILE = "suite.json"
SPLITS = ("test", "train")
DEFAULT_EVAL_POINTS = 9
"""Completion-ratio checkpoints of a suite episode besides the final score: one every tenth
of the budget, so the efficiency metrics (:mod:`~naruto_agent.benchmark.efficiency`) resolve a
tenth of the budget."""


def suite_module() -> Any:
    """:mod:`naruto_gym.scenes.suite`, or a ValueError saying that this install lacks it."""
    try:
        from naruto_gym.scenes import suite
    except ImportError as error:
        raise ValueError(
            "this naruto-gym has no scene suite (naruto_gym.scenes.suite); update naruto-gym"
        ) from error
    return suite


def select_scenes(
    split: str,
    size_classes: list[str] | None = None,
    variant: str = "closed",
    limit: int = 0,
    scenes_dir: str | os.PathLike | None = None,
    up_axis: str = "auto",
    mesh_units: str = "m",
) -> list[Any]:
    """The suite's :class:`SuiteScene` entries of a split, classes and variant.

    Args:
        split: ``"test"`` or ``"train"``.
        size_classes: the classes (default: the generated ones); ``"external"`` adds the
            external track (:mod:`naruto_gym.scenes.external`), test split only.
        variant: ``"closed"`` or ``"open"`` (the generated classes; external scans are run
            as they are).
        limit: keep the first ``limit`` scenes of each class (0: all), for quick checks.
        scenes_dir: the external track's folder of meshes (default ``../shared/scenes``,
            the sample scans).
        up_axis: the up axis of the external meshes (``"auto"``: from each file's dataset
            layout, else its geometry).
        mesh_units: the length unit of the external meshes.

    Raises:
        ValueError: an unknown split, class or variant (the message lists the known ones), a
            negative limit, or an external folder with files that are not scans (every
            problem listed).
    """
    if limit < 0:
        raise ValueError(f"the suite limit must be >= 0 (0: every scene), got {limit}")
    suite = suite_module()
    if split not in SPLITS:
        raise ValueError(f"unknown suite split {split!r}; use one of {', '.join(SPLITS)}")
    classes = tuple(size_classes) if size_classes else tuple(suite.SIZE_CLASSES)
    known = (*suite.SIZE_CLASSES, EXTERNAL_CLASS)
    unknown = [name for name in classes if name not in known]
    renamed = [suite.renamed_size_class_message(name) for name in unknown]
    if any(renamed):
        raise ValueError("; ".join(message for message in renamed if message))
    if unknown:
        raise ValueError(f"unknown size class(es) {unknown}; use some of {', '.join(known)}")
    if variant not in suite.VARIANTS:
        raise ValueError(f"unknown variant {variant!r}; use one of {', '.join(suite.VARIANTS)}")
    generated = tuple(name for name in classes if name != EXTERNAL_CLASS)
    scenes = (
        list(suite.suite_scenes(split=split, size_classes=generated, variants=(variant,)))
        if generated
        else []
    )
    if EXTERNAL_CLASS in classes:
        if split != "test":
            raise ValueError(
                "the external class has test scenes only (scans no policy trains on); run it "
                "with --suite test"
            )
        scenes += external_suite_scenes(external_track(scenes_dir, up_axis, mesh_units))
    if limit:
        taken: dict[str, int] = {}
        kept = []
        for entry in scenes:
            taken[entry.size_class] = taken.get(entry.size_class, 0) + 1
            if taken[entry.size_class] <= limit:
                kept.append(entry)
        scenes = kept
    return scenes


def external_track(
    scenes_dir: str | os.PathLike | None, up_axis: str = "auto", mesh_units: str = "m"
) -> list[ExternalScan]:
    """The external track's checked scans: those of ``scenes_dir``, or the sample scans of
    ``../shared/scenes`` (those missing are named on stderr; the rest run).

    Raises:
        ValueError: no such folder (for the sample scans: where they come from), or files
            that are not scans.
    """
    if scenes_dir is None:
        folder = sample_scans_dir()
        if not folder.is_dir():
            raise ValueError(
                f"the sample scans' folder {SHARED_SCENES_DIR} is not here (it lies beside "
                "the repository's checkout, outside it for the scans' research-only "
                "licences); give a folder of your own scans with --scenes-dir"
            )
        missing = missing_sample_scans(folder)
        if missing:
            print(
                f"external track: {len(missing)} of the {len(SAMPLE_SCANS)} sample scans are "
                f"missing from {folder} ({', '.join(missing)}); running the rest",
                file=sys.stderr,
            )
        scenes_dir = folder
    return external_scans(scenes_dir, up_axis, mesh_units)


def suite_specs(
    scenes: list[Any],
    policies: list[str],
    seeds: list[int],
    steps: int | None = None,
    **settings: Any,
) -> list[EpisodeSpec]:
    """The episodes of suite scenes x policies x seeds, each with its scene's class budget.

    Args:
        scenes: :class:`SuiteScene` entries (:func:`select_scenes`).
        policies: policy names or import paths.
        seeds: episode seeds.
        steps: a budget for every scene instead of the class budgets (short test runs).
        **settings: further :class:`EpisodeSpec` fields, as :func:`build_specs` takes them.
    """
    if not scenes:
        raise ValueError("the suite selection holds no scene")
    specs: list[EpisodeSpec] = []
    for entry in scenes:
        budget = int(steps) if steps else int(entry.budget)
        specs += build_specs([entry.scene], policies, seeds, budget, **dict(settings))
    ids = [spec.episode_id for spec in specs]
    if len(set(ids)) != len(ids):
        raise ValueError("two suite scenes share a label; the suite must name them apart")
    return specs


def manifest_entries(scenes: list[Any], steps: int | None = None) -> dict[str, dict[str, Any]]:
    """Scene label -> its class, variant, split, scene seed, scene string and budget."""
    entries = {}
    for entry in scenes:
        entries[parse_scene(entry.scene).label] = {
            "scene": entry.scene,
            "size_class": entry.size_class,
            "split": entry.split,
            "seed": int(entry.seed),
            "variant": entry.variant,
            "budget": int(steps) if steps else int(entry.budget),
        }
    return entries


def machine() -> dict[str, Any]:
    """The machine a run happens on: host, OS, CPU count, GPU, Python and package version."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        package = version("naruto-gym")
    except PackageNotFoundError:
        package = "unknown"
    gpu = None
    try:
        import torch

        if torch.cuda.is_available():
            gpu = torch.cuda.get_device_name(0)
    except ImportError:
        pass
    return {
        "host": platform.node(),
        "platform": platform.platform(),
        "processor": platform.machine(),
        "cpus": os.cpu_count(),
        "gpu": gpu,
        "python": platform.python_version(),
        "naruto_gym": package,
        "commit": source_commit(),
        "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
    }


def write_manifest(
    output_dir: str | Path,
    scenes: dict[str, dict[str, Any]],
    split: str,
    argv: list[str] | None = None,
) -> dict[str, Any]:
    """Add a run's scenes, command and machine to ``output_dir/suite.json``; returns it.

    Scenes of earlier runs into the same folder stay (a class run later joins the table); the
    command and machine of each run are kept in ``runs``.

    Raises:
        ValueError: the folder holds results of another suite version or split.
    """
    path = Path(output_dir) / MANIFEST_FILE
    manifest = read_manifest(output_dir) or {"scenes": {}, "runs": []}
    suite = suite_module()
    earlier = manifest.get("suite_version")
    if earlier is not None and earlier != suite.SUITE_VERSION:
        raise ValueError(
            f"{output_dir} holds results of suite version {earlier}, this naruto-gym has version "
            f"{suite.SUITE_VERSION} (its scenes or budgets differ): give another --output-dir"
        )
    if manifest.get("split") not in (None, split):
        raise ValueError(
            f"{output_dir} holds results of the {manifest['split']} split: give another "
            f"--output-dir for the {split} split"
        )
    manifest["suite_version"] = suite.SUITE_VERSION
    manifest["split"] = split
    manifest["scenes"].update(scenes)
    words = ["naruto-benchmark", *(sys.argv[1:] if argv is None else argv)]
    manifest["runs"].append({"command": shlex.join(words), "machine": machine()})
    write_json_atomic(path, manifest)
    return manifest


def read_manifest(output_dir: str | Path) -> dict[str, Any] | None:
    """``output_dir/suite.json``, or None when the folder holds no suite run.

    A scene recorded under a size class's earlier name is read under its current one
    (:func:`current_manifest`), so archived runs group with new ones."""
    manifest = read_record(Path(output_dir) / MANIFEST_FILE)
    return None if manifest is None else current_manifest(manifest)


def current_manifest(manifest: dict[str, Any]) -> dict[str, Any]:
    """``manifest`` with every size class under its current name
    (``naruto_gym.scenes.suite.RENAMED_SIZE_CLASSES``), in its scenes and in the
    ``--size-class`` words of its run commands (the commands a reader copies from a report)."""
    current = suite_module().current_size_class
    scenes = {
        label: {**entry, "size_class": current(entry["size_class"])}
        if "size_class" in entry
        else entry
        for label, entry in manifest.get("scenes", {}).items()
    }
    runs = [
        {**run, "command": current_command(run["command"])} if "command" in run else run
        for run in manifest.get("runs", [])
    ]
    return {**manifest, "scenes": scenes, "runs": runs}


def current_command(command: str) -> str:
    """A recorded ``naruto-benchmark`` command with its ``--size-class`` values under their
    current names (the rest of the command as recorded)."""
    current = suite_module().current_size_class
    words = shlex.split(command)
    in_classes = False
    for index, word in enumerate(words):
        if word.startswith("--"):
            in_classes = word == "--size-class"
        elif in_classes:
            words[index] = current(word)
    return shlex.join(words)


GROUP_ORDER = ("small", "flat", "house", EXTERNAL_CLASS, "all", "other")
"""How tables and plots order the groups: the size classes from small to house, then the
external track."""


def entry_group(entry: dict[str, Any]) -> str:
    """The group of a manifest entry: its size class, with ``" (open)"`` for the open variant
    (the variants are a second axis, never averaged together)."""
    variant = entry.get("variant", "closed")
    plain = variant in ("closed", EXTERNAL_VARIANT)
    return str(entry["size_class"]) + ("" if plain else f" ({variant})")


def group_of(record: dict[str, Any], manifest: dict[str, Any] | None) -> str:
    """A record's group from the manifest (see :func:`entry_group`; ``"all"`` outside a suite
    run, ``"other"`` for a scene the manifest does not list)."""
    if not manifest:
        return "all"
    entry = manifest.get("scenes", {}).get(record.get("scene"))
    return entry_group(entry) if entry else "other"


def ordered_groups(names: Any) -> list[str]:
    """Group names by size class (:data:`GROUP_ORDER`), each class's closed variant first."""
    rank = {name: index for index, name in enumerate(GROUP_ORDER)}

    def key(name: str) -> tuple[int, str]:
        size_class = name.split(" (", 1)[0]
        return rank.get(size_class, len(rank)), name

    return sorted(names, key=key)


def manifest_json(manifest: dict[str, Any]) -> str:
    """The manifest as indented JSON (for printing)."""
    return json.dumps(manifest, indent=1)
