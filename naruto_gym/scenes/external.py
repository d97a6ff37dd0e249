"""The external track: scenes the generator did not make, as a size class of the suite.

A policy fitted to the generated homes of :mod:`naruto_gym.scenes.suite` can win there and
fail on a real scan (low walls, no ceiling, holes, bumpy surfaces). The external class runs
a folder of meshes beside the generated classes, with the same episode seeds, columns and
intervals, so that the leaderboard shows it:

* by default the project's sample scans in ``../shared/scenes`` (:data:`SAMPLE_SCANS`, kept
  outside the repository for their research-only licences): those missing are listed and
  the rest run;
* or a folder of the user's own meshes (ScanNet ``*_vh_clean_2.ply``, Replica ``mesh.ply``,
  MP3D or HM3D ``.glb``, any PLY, OBJ or glTF), every mesh file under it a scene.

Each file is checked before anything runs (:func:`external_scans`): it must load as a
triangle mesh in metres (:func:`~naruto_gym.scenes.units.check_metric_size`), stand the
right way up (:func:`~naruto_gym.scenes.scan_checks.check_up_axis`) and be the size of a
room (:func:`~naruto_gym.scenes.scan_checks.check_room_sized`); every problem of every file is
reported at once, with what to pass. The up axis of a file is, in this order: the one
:data:`SAMPLE_SCANS` gives, the one asked for, the one its dataset layout fixes
(:func:`~naruto_gym.scenes.mesh_scene.dataset_up_axis`), the one its geometry shows clearly
(:func:`~naruto_gym.scenes.scan_checks.likely_up_axis`).

Starts are drawn as for generated homes (the env's seeded start in free space); the budget
follows the floor area of the scan's footprint (:func:`scan_budget`), on the line through the
generated classes' budgets and areas.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from naruto_gym.scenes.mesh_scene import UP_AXES, dataset_up_axis, load_scene
from naruto_gym.scenes.scan_checks import check_room_sized, check_up_axis, likely_up_axis
from naruto_gym.scenes.suite import SuiteScene

EXTERNAL_CLASS = "external"
"""The size class of the external track."""
EXTERNAL_VARIANT = "scan"
"""The variant of every external scene: the mesh as it was scanned or modelled."""
SHARED_SCENES_DIR = Path("..") / "shared" / "scenes"
"""Where the project's sample scans live, from the repository root (the default folder)."""
_CHECKOUT = Path(__file__).resolve().parents[2]
SAMPLE_SCANS: dict[str, str] = {
    "replica_office0/mesh.ply": "z",
    "scenenet_room89/mesh.obj": "y",
    "habitat_simple_room/simple_room.glb": "z",
}
"""The sample scans of ``../shared/scenes`` (path in the folder -> up axis): a Replica office
scan (closed), a SceneNet room model (y-up) and habitat-sim's room of boxes (open)."""
MESH_SUFFIXES = (".ply", ".obj", ".glb", ".gltf")
"""The files of a folder that are scenes."""
_NOT_SCENES = (".labels.ply", "_culled.ply")
"""Mesh files beside a scan that are not scenes of their own (ScanNet's label mesh, the
culled ground truth of Replica)."""
BUDGET_BY_AREA = ((0.0, 200), (50.0, 400), (110.0, 800), (275.0, 1500))
"""(Footprint in m², steps): the generated classes' areas and budgets (small 40-60 m², 400
steps; flat 100-120 m², 800; house 200-350 m², 1500), and 200 steps for the smallest
room; budgets between are interpolated, larger scans get the house budget."""


@dataclass(frozen=True)
class ExternalScan:
    """One checked mesh of the external track.

    Attributes:
        path: the mesh file.
        up_axis: the axis that points up in the file.
        extents_m: its size (x, y, z in metres, z up).
        budget: its step budget (:func:`scan_budget` of its footprint).
    """

    path: Path
    up_axis: str
    extents_m: tuple[float, float, float]
    budget: int

    @property
    def scene(self) -> str:
        """The scene argument of the harness: ``PATH@AXIS``."""
        return f"{self.path}@{self.up_axis}"


def scan_budget(footprint_m2: float) -> int:
    """The step budget of a scan whose footprint (the x-y extent of its bounding box) is
    ``footprint_m2``: :data:`BUDGET_BY_AREA` interpolated, in whole 50 steps."""
    areas, budgets = zip(*BUDGET_BY_AREA, strict=True)
    steps = float(np.interp(footprint_m2, areas, budgets))
    return int(50 * round(steps / 50))


def find_scans(folder: str | os.PathLike) -> list[Path]:
    """Every mesh file under ``folder`` (:data:`MESH_SUFFIXES`, sorted), leaving out the
    files beside a scan that are not scenes (label meshes, culled ground truth)."""
    root = Path(folder)
    found = [
        path
        for path in root.rglob("*")
        if path.is_file()
        and path.suffix.lower() in MESH_SUFFIXES
        and not path.name.lower().endswith(_NOT_SCENES)
    ]
    return sorted(found)


def sample_scans_dir() -> Path:
    """The sample scans' folder: :data:`SHARED_SCENES_DIR` from the working directory, else
    beside the checkout this package runs from (the first that exists; the first if none)."""
    for folder in (SHARED_SCENES_DIR, _CHECKOUT / SHARED_SCENES_DIR):
        if folder.is_dir():
            return folder
    return SHARED_SCENES_DIR


def missing_sample_scans(folder: str | os.PathLike = SHARED_SCENES_DIR) -> list[str]:
    """The sample scans (:data:`SAMPLE_SCANS`) that ``folder`` does not hold."""
    return [name for name in SAMPLE_SCANS if not (Path(folder) / name).is_file()]


def _up_axis_of(path: Path, relative: str, up_axis: str, mesh_units: str) -> str:
    if relative in SAMPLE_SCANS:
        return SAMPLE_SCANS[relative]
    if up_axis != "auto":
        return up_axis
    try:
        return dataset_up_axis(path)
    except ValueError:
        pass
    scene = load_scene(path, up_axis="z", mesh_units=mesh_units)
    seen = likely_up_axis(scene.vertices, scene.faces)
    if seen is None:
        check_room_sized(scene.vertices, str(path))  # an object is named as such first
        raise ValueError(
            f"{path}: its geometry does not show which axis points up (no side faces clearly "
            "more of its surface than the others) and its layout is not a known dataset's; "
            "give the axis with --up-axis (or PATH@AXIS in --scenes)"
        )
    return seen


def external_scans(
    folder: str | os.PathLike | None = None, up_axis: str = "auto", mesh_units: str = "m"
) -> list[ExternalScan]:
    """The checked scans of ``folder`` (every mesh file under it, :func:`find_scans`).

    Args:
        folder: the meshes' folder (default the sample scans, :func:`sample_scans_dir`).
        up_axis: the up axis of every file not in :data:`SAMPLE_SCANS`; ``"auto"`` (default)
            reads it from the file's dataset layout, else from its geometry.
        mesh_units: the length unit of the files (``"m"``, ``"cm"`` or ``"mm"``).

    Raises:
        ValueError: the folder does not exist or holds no mesh file, or files that are not
            scans the track can run: every problem of every file is listed, with what to
            pass or do.
    """
    root = sample_scans_dir() if folder is None else Path(folder)
    if up_axis not in UP_AXES:
        raise ValueError(f"up_axis must be one of {', '.join(UP_AXES)}, got {up_axis!r}")
    if not root.is_dir():
        raise ValueError(
            f"the external track's folder {str(root)!r} does not exist; give a folder of "
            "scans (PLY, OBJ, GLB/glTF meshes) with --scenes-dir"
        )
    files = find_scans(root)
    if not files:
        raise ValueError(
            f"{str(root)!r} holds no mesh file ({', '.join(MESH_SUFFIXES)}); give a folder "
            "of scans with --scenes-dir"
        )
    scans, problems = [], []
    for path in files:
        relative = path.relative_to(root).as_posix()
        try:
            axis = _up_axis_of(path, relative, up_axis, mesh_units)
            scene = load_scene(path, up_axis=axis, mesh_units=mesh_units)
            what = f"{path}"
            check_up_axis(scene.vertices, scene.faces, what, axis)
            check_room_sized(scene.vertices, what)
        except (ValueError, FileNotFoundError) as error:
            problems.append(str(error))
            continue
        extents = np.ptp(scene.vertices, axis=0)
        scans.append(
            ExternalScan(
                path=path,
                up_axis=axis,
                extents_m=(float(extents[0]), float(extents[1]), float(extents[2])),
                budget=scan_budget(float(extents[0] * extents[1])),
            )
        )
    if problems:
        raise ValueError(
            f"{len(problems)} of the {len(files)} mesh files under {str(root)!r} are not scans "
            "the external track can run; fix or remove them:\n"
            + "\n".join(f"  - {problem}" for problem in problems)
        )
    return scans


def external_suite_scenes(scans: list[ExternalScan]) -> list[SuiteScene]:
    """The scans as suite scenes of the external class (test split, seed = index)."""
    return [
        SuiteScene(
            scene=scan.scene,
            size_class=EXTERNAL_CLASS,
            split="test",
            seed=index,
            variant=EXTERNAL_VARIANT,
            budget=scan.budget,
        )
        for index, scan in enumerate(scans)
    ]
