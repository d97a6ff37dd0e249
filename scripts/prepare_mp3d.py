"""Check the Matterport3D (MP3D) files of NARUTO's table and lay them out the way the benchmarks
read them.

Reads, for each scene, the habitat ``.glb`` (the mesh the agent moves in and sees, as the
published system renders it) and the scan's ``.obj`` house mesh (the ground truth the
published table is scored against), checks every file and lists every problem found, and
writes one folder per scene only when all pass: the ``.glb`` as ``mesh.glb``, the ``.obj`` as
``house.obj``, and a ``ground_truth.json`` that makes ``naruto-benchmark`` score against the
``.obj`` (``naruto_gym.evaluation.ground_truth``). See docs/mp3d.md for the download (the
dataset's own terms; nothing of it ships with this project).

What it reads::

    --habitat-dir  mp3d/GdvgFV5R1Z5/GdvgFV5R1Z5.glb     (mp3d_habitat.zip of the habitat task)
    --scans-dir    GdvgFV5R1Z5/mesh.obj                  (or the one .obj under
                   GdvgFV5R1Z5/matterport_mesh/, the scan's house mesh)

Both y-up by default (``--glb-up-axis``, ``--obj-up-axis``); each is checked to stand upright
once loaded (its floors and ceilings facing up), and the two are checked to line up.

What it writes (``--output-dir``)::

    data/mp3d/mp3d_GdvgFV5R1Z5/
        mesh.glb             the habitat .glb (a link, or a copy with --copy)
        house.obj            the house mesh (a link, or a copy)
        ground_truth.json    {"mesh": "house.obj", "up_axis": "y"}
    data/mp3d/mp3d_scenes.json   what was checked, per scene

Usage::

    python scripts/prepare_mp3d.py --habitat-dir ~/data/mp3d_habitat/mp3d \\
        --scans-dir ~/data/mp3d/v1/scans --output-dir data/mp3d
"""

from __future__ import annotations

import json
import sys
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

MP3D_SCENES = ("GdvgFV5R1Z5", "gZ6f7yhEvPG", "HxpKQynjfin", "pLe4wQe7qrG", "YmJkqBEsHnH")
"""The five MP3D scenes of NARUTO's table (Feng et al., CVPR 2024)."""
MP3D_STEPS = 5000
"""The published step budget of an MP3D episode (one frame per step)."""
UP_AXES = ("y", "z", "x", "-y", "-z", "-x")
# The habitat .glb and the house mesh must cover the same box: the share of each one's box
# (by volume) that the other's covers.
LINE_UP_SHARE = 0.8
# Of the flat surface (faces within ~25 degrees of an axis), the least share facing up once
# loaded: a house's floors and ceilings outweigh its walls' flat area only when upright.
UPRIGHT_SHARE = 0.4
_FLAT_COSINE = 0.9


class Mp3dLayoutError(ValueError):
    """A file is missing or malformed (the message names it and says what to do)."""


@dataclass
class Args:
    """Arguments of the preparation (each field is a ``--flag``)."""

    habitat_dir: str = ""
    """folder of the habitat task's MP3D scenes: <scene>/<scene>.glb (the mp3d/ folder of
    mp3d_habitat.zip)"""
    scans_dir: str = ""
    """folder of the scans' house meshes: <scene>/mesh.obj, or the one .obj under
    <scene>/matterport_mesh/"""
    output_dir: str = "data/mp3d"
    """where the scene folders (mp3d_<scene>/) are written"""
    scenes: list[str] = field(default_factory=lambda: list(MP3D_SCENES))
    """scenes to prepare (default: the five of the published table)"""
    glb_up_axis: str = "y"
    """the axis that points up in the .glb files"""
    obj_up_axis: str = "y"
    """the axis that points up in the .obj files"""
    copy: bool = False
    """copy the files instead of linking them"""


@dataclass
class SceneFiles:
    """One scene's checked files and their summary."""

    name: str
    glb: Path
    obj: Path
    summary: dict[str, Any]


def find_house_mesh(scans: Path, name: str) -> Path:
    """The scan's house mesh: ``<scene>/mesh.obj``, else the one ``.obj`` under
    ``<scene>/matterport_mesh/``.

    Raises:
        Mp3dLayoutError: none, or several candidates.
    """
    folder = scans / name
    if (folder / "mesh.obj").is_file():
        return folder / "mesh.obj"
    found = sorted((folder / "matterport_mesh").glob("**/*.obj"))
    if len(found) == 1:
        return found[0]
    if not found:
        raise Mp3dLayoutError(
            f"{folder}: no mesh.obj and no .obj under matterport_mesh/ (unzip the scan's "
            "matterport_mesh.zip there, or pass --scans-dir with the folder of the scans)"
        )
    raise Mp3dLayoutError(
        f"{folder}/matterport_mesh holds {len(found)} .obj files ({', '.join(map(str, found))}); "
        f"link the house mesh as {folder / 'mesh.obj'}"
    )


def upright_share(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Of a z-up mesh's flat surface (faces nearly facing an axis), the share by area that
    faces up or down: floors, ceilings and table tops."""
    triangles = vertices[faces]
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    areas = np.linalg.norm(normals, axis=1)
    unit = np.abs(normals[areas > 0]) / areas[areas > 0, None]
    areas = areas[areas > 0]
    flat = unit.max(axis=1) > _FLAT_COSINE
    total = float(areas[flat].sum())
    return float(areas[flat & (unit[:, 2] > _FLAT_COSINE)].sum()) / total if total else 0.0


def check_mesh(path: Path, up_axis: str, flag: str) -> tuple[Any, list[str]]:
    """Load a mesh with its up axis and check that it stands upright.

    Returns:
        (the z-up scene or None, the problems found).
    """
    from naruto_gym.scenes.mesh_scene import load_scene

    if not path.is_file():
        return None, [f"{path} is missing"]
    try:
        with warnings.catch_warnings():  # a scene on its side is reported below, with the flag
            warnings.simplefilter("ignore", UserWarning)
            scene = load_scene(path, up_axis=up_axis)
    except (OSError, ValueError) as error:
        return None, [f"{path} is not a readable mesh in metres ({error})"]
    share = upright_share(scene.vertices, scene.faces)
    if share < UPRIGHT_SHARE:
        others = ", ".join(axis for axis in ("y", "z") if axis != up_axis)
        return scene, [
            f"{path} lies on its side when loaded with {flag} {up_axis}: only "
            f"{100 * share:.0f} % of its flat surface faces up (floors, ceilings); pass the "
            f"axis that points up in the file ({flag} {others})"
        ]
    return scene, []


def box_overlap(a: np.ndarray, b: np.ndarray) -> float:
    """The smaller of the shares of two (2, 3) boxes' volumes that their intersection covers."""
    low, high = np.maximum(a[0], b[0]), np.minimum(a[1], b[1])
    common = float(np.prod(np.clip(high - low, 0.0, None)))
    volumes = [float(np.prod(box[1] - box[0])) for box in (a, b)]
    return common / max(volumes) if max(volumes) > 0 else 0.0


def check_scene(args: Args, name: str) -> tuple[SceneFiles | None, list[str]]:
    """Check one scene's two files; returns them (None when a problem was found) and every
    problem found."""
    habitat, scans = Path(args.habitat_dir).expanduser(), Path(args.scans_dir).expanduser()
    glb = habitat / name / f"{name}.glb"
    problems: list[str] = []
    if not glb.is_file():
        problems.append(f"{glb} is missing (the habitat task's mp3d/<scene>/<scene>.glb)")
        glb_scene = None
    else:
        glb_scene, found = check_mesh(glb, args.glb_up_axis, "--glb-up-axis")
        problems += found
    try:
        obj = find_house_mesh(scans, name)
    except Mp3dLayoutError as error:
        problems.append(str(error))
        obj, obj_scene = None, None
    else:
        obj_scene, found = check_mesh(obj, args.obj_up_axis, "--obj-up-axis")
        problems += found
    if glb_scene is not None and obj_scene is not None and not problems:
        overlap = box_overlap(glb_scene.bounds, obj_scene.bounds)
        if overlap < LINE_UP_SHARE:
            problems.append(
                f"{glb} and {obj} do not line up: their boxes share {100 * overlap:.0f} % "
                f"(glb {np.round(glb_scene.bounds, 2).tolist()}, obj "
                f"{np.round(obj_scene.bounds, 2).tolist()}); two scenes, or another up axis"
            )
    if problems or glb_scene is None or obj_scene is None or obj is None:
        return None, problems
    summary = {
        "glb_triangles": int(len(glb_scene.faces)),
        "house_triangles": int(len(obj_scene.faces)),
        "bounds_m": np.round(glb_scene.bounds, 3).tolist(),
        "house_area_m2": round(float(_area(obj_scene.vertices, obj_scene.faces)), 1),
    }
    return SceneFiles(name, glb, obj, summary), []


def _area(vertices: np.ndarray, faces: np.ndarray) -> float:
    from naruto_gym.evaluation.metrics import mesh_area

    return mesh_area(vertices, faces)


def write_scene(files: SceneFiles, out: Path, obj_up_axis: str, copy: bool) -> Path:
    """Lay out one checked scene under ``out/mp3d_<scene>/``; returns that folder."""
    from naruto_gym.evaluation.ground_truth import GROUND_TRUTH_FILE
    from naruto_gym.scenes.scene_folders import link_or_copy

    folder = out / f"mp3d_{files.name}"
    folder.mkdir(parents=True, exist_ok=True)
    link_or_copy(files.glb, folder / "mesh.glb", copy)
    link_or_copy(files.obj, folder / "house.obj", copy)
    truth = {"mesh": "house.obj", "up_axis": obj_up_axis}
    (folder / GROUND_TRUTH_FILE).write_text(json.dumps(truth, indent=1) + "\n")
    return folder


def prepare(args: Args) -> dict[str, Any]:
    """Check every scene of ``args.scenes``, then lay them out under ``args.output_dir``.

    Returns:
        the report written to ``mp3d_scenes.json``: per scene its folder, triangles, bounds
        and the house mesh's area.

    Raises:
        Mp3dLayoutError: every problem found, one per line; nothing is written then.
    """
    problems = []
    for flag, folder in (("--habitat-dir", args.habitat_dir), ("--scans-dir", args.scans_dir)):
        if not folder:
            problems.append(f"pass {flag}")
        elif not Path(folder).expanduser().is_dir():
            problems.append(f"{flag} {folder} is not a folder")
    for flag, axis in (("--glb-up-axis", args.glb_up_axis), ("--obj-up-axis", args.obj_up_axis)):
        if axis not in UP_AXES:
            problems.append(f"{flag} {axis!r} is not one of {', '.join(UP_AXES)}")
    if not args.scenes:
        problems.append(f"pass --scenes (the table's: {' '.join(MP3D_SCENES)})")
    if problems:
        raise Mp3dLayoutError("\n".join(problems))
    checked = []
    for name in args.scenes:
        files, found = check_scene(args, name)
        problems += [f"{name}: {problem}" for problem in found]
        if files is not None:
            checked.append(files)
    if problems:
        raise Mp3dLayoutError("\n".join(problems))
    out = Path(args.output_dir).expanduser()
    report: dict[str, Any] = {
        "habitat_dir": str(Path(args.habitat_dir).expanduser().resolve()),
        "scans_dir": str(Path(args.scans_dir).expanduser().resolve()),
        "up_axis": {"glb": args.glb_up_axis, "obj": args.obj_up_axis},
        "steps": MP3D_STEPS,
        "scenes": {},
    }
    for files in checked:
        folder = write_scene(files, out, args.obj_up_axis, args.copy)
        report["scenes"][files.name] = {"folder": str(folder), **files.summary}
    (out / "mp3d_scenes.json").write_text(json.dumps(report, indent=1))
    return report


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status (2 when a check fails)."""
    from naruto_agent.cli_args import dataclass_parser

    parser = dataclass_parser(
        Args, description=__doc__.split("\n\n")[1].replace("\n", " "), prog="prepare_mp3d.py"
    )
    args = Args(**vars(parser.parse_args(argv)))
    try:
        report = prepare(args)
    except Mp3dLayoutError as error:
        print(f"prepare_mp3d.py: error (nothing written):\n{error}", file=sys.stderr)
        return 2
    print("| scene | folder | glb triangles | house triangles | house surface (m^2) |")
    print("|---|---|---|---|---|")
    for name, scene in report["scenes"].items():
        print(
            f"| {name} | {scene['folder']} | {scene['glb_triangles']:,} | "
            f"{scene['house_triangles']:,} | {scene['house_area_m2']:,.1f} |"
        )
    print(
        f"\nwrote {Path(args.output_dir) / 'mp3d_scenes.json'}; run each scene's mesh.glb "
        f"(up axis {args.glb_up_axis}) for {MP3D_STEPS} steps: docs/mp3d.md"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
