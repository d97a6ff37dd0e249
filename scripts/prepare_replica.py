"""Check the Replica release and lay out its scenes the way the benchmarks read them.

Reads the Replica release as NICE-SLAM prepared it (the data Co-SLAM and NARUTO read; see
docs/replica.md for the download), checks every file a benchmark needs, and writes one folder
per scene in the layout of ``../shared/scenes/replica_office0``, which ``naruto-benchmark``,
``benchmarks/replica_passive.py --scene-dir`` and ``benchmarks/naruto_episode.py --scene``
take. Nothing is written when a check fails; every problem found is listed.

The release (``--source``)::

    Replica/
        cam_params.json            the camera of every scene (1200 x 680, fx = fy = 600)
        office0/traj.txt           2000 camera-to-world poses, one 4 x 4 matrix per line
        office0/results/           frame000000.jpg ... and depth000000.png ... (optional here)
        office0_mesh.ply           the ground-truth mesh (z-up, metres)
        ...                        the same for room0-2 and office1-4
    cull_replica_mesh/office0.ply  NICE-SLAM's culled ground truth (optional), inside or beside

What it writes (``--output-dir``)::

    data/replica/replica_office0/
        mesh.ply                   office0_mesh.ply (a link, or a copy with --copy)
        traj.txt                   office0/traj.txt
        cam_params.json            the release's camera
        frames/                    office0/results, when present
        mesh_culled.ply            the culled mesh, when found: naruto-benchmark then scores
                                   against it (naruto_gym.evaluation.ground_truth)
    data/replica/replica_scenes.json   what was checked, per scene

Usage::

    python scripts/prepare_replica.py --source ~/data/Replica --output-dir data/replica
    python scripts/prepare_replica.py --source ~/data/Replica --scenes office0 room0 --copy
"""

from __future__ import annotations

import json
import shutil
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

REPLICA_SCENES = ("room0", "room1", "room2", "office0", "office1", "office2", "office3", "office4")
"""The eight Replica scenes of NICE-SLAM's release, averaged in the published tables."""
CAMERA_KEYS = ("w", "h", "fx", "fy", "cx", "cy", "scale")
"""What ``cam_params.json`` gives under ``"camera"`` (``scale``: depth PNG units per metre)."""
CULLED_FOLDER = "cull_replica_mesh"
# A camera position further than this outside the mesh's bounds means mesh and poses disagree.
BOUNDS_MARGIN_M = 0.5
# Share of the camera positions that must lie inside the mesh's (widened) bounds.
INSIDE_SHARE = 0.9
# A pose's rotation may differ from a proper rotation by this much (entries of R^T R - I).
ROTATION_TOLERANCE = 1e-3


class ReplicaLayoutError(ValueError):
    """A file of the release is missing or malformed (the message names it)."""


@dataclass
class Args:
    """Arguments of the preparation (each field is a ``--flag``)."""

    source: str = ""
    """folder of the Replica release as NICE-SLAM prepared it: cam_params.json, a folder per
    scene (traj.txt, results/) and <scene>_mesh.ply beside it"""
    output_dir: str = "data/replica"
    """where the scene folders (replica_<scene>/) are written"""
    scenes: list[str] = field(default_factory=lambda: list(REPLICA_SCENES))
    """scenes to prepare (default: all eight)"""
    culled_dir: str = ""
    """folder of the culled meshes (<scene>.ply or <scene>_culled.ply); default: the
    cull_replica_mesh/ folder inside or beside --source"""
    copy: bool = False
    """copy the files instead of linking them (the frames stay linked: about 1 GB a scene)"""
    check_frames: bool = True
    """count the RGB-D frames of results/ against the poses and check the first pair's size"""


@dataclass
class SceneCheck:
    """What was found for one scene: the files to lay out and their summary."""

    name: str
    mesh: Path
    trajectory: Path
    frames: Path | None
    culled: Path | None
    summary: dict[str, Any]


def read_camera(path: Path) -> dict[str, float]:
    """The ``"camera"`` entry of a ``cam_params.json``.

    Raises:
        ReplicaLayoutError: the file is missing, not JSON, or lacks a positive number for one
            of :data:`CAMERA_KEYS`.
    """
    if not path.is_file():
        raise ReplicaLayoutError(
            f"{path} is missing: the release's cam_params.json lies beside the scene folders; "
            "pass --source with the Replica folder"
        )
    try:
        camera = json.loads(path.read_text())["camera"]
    except (ValueError, KeyError, TypeError) as error:
        raise ReplicaLayoutError(
            f'{path} is not a cam_params.json: expected {{"camera": {{...}}}} ({error!r})'
        ) from error
    bad = [
        key
        for key in CAMERA_KEYS
        if not isinstance(camera.get(key), (int, float)) or not camera[key] > 0
    ]
    if bad:
        raise ReplicaLayoutError(f"{path}: camera entries {bad} are missing or not positive")
    return {key: float(camera[key]) for key in CAMERA_KEYS}


def read_trajectory(path: Path) -> np.ndarray:
    """(N, 4, 4) camera-to-world poses of a ``traj.txt`` (16 numbers a line).

    Raises:
        ReplicaLayoutError: a missing or empty file, a line without 16 numbers, or a matrix
            that is not a rigid transform (the message gives the line).
    """
    if not path.is_file():
        raise ReplicaLayoutError(f"{path} is missing: each scene folder holds its traj.txt")
    poses = []
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        if not line.strip():
            continue
        try:
            values = np.array([float(value) for value in line.split()])
        except ValueError as error:
            raise ReplicaLayoutError(f"{path} line {number}: not numbers ({error})") from error
        if values.size != 16 or not np.isfinite(values).all():
            raise ReplicaLayoutError(
                f"{path} line {number}: expected 16 finite numbers (a 4 x 4 camera-to-world "
                f"matrix, row-major), got {values.size}"
            )
        pose = values.reshape(4, 4)
        rotation = pose[:3, :3]
        rigid = (
            np.allclose(pose[3], [0.0, 0.0, 0.0, 1.0], atol=1e-6)
            and np.abs(rotation.T @ rotation - np.eye(3)).max() < ROTATION_TOLERANCE
            and np.linalg.det(rotation) > 0
        )
        if not rigid:
            raise ReplicaLayoutError(
                f"{path} line {number}: not a rigid camera-to-world transform (last row "
                "0 0 0 1 and a rotation)"
            )
        poses.append(pose)
    if not poses:
        raise ReplicaLayoutError(f"{path} holds no poses")
    return np.stack(poses)


def check_mesh(path: Path, positions: np.ndarray) -> dict[str, Any]:
    """Load a mesh and check that the camera positions lie inside its bounds.

    Raises:
        ReplicaLayoutError: a missing or unreadable file, no triangles, or a trajectory
            outside the mesh (a mesh of another scene, or not z-up).
    """
    import trimesh

    if not path.is_file():
        raise ReplicaLayoutError(
            f"{path} is missing: the release keeps <scene>_mesh.ply beside the scene folders"
        )
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as error:  # trimesh raises many types for broken files
        raise ReplicaLayoutError(
            f"{path} is not a readable mesh ({type(error).__name__}: {error})"
        ) from error
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ReplicaLayoutError(f"{path} holds no triangles")
    low, high = mesh.bounds[0] - BOUNDS_MARGIN_M, mesh.bounds[1] + BOUNDS_MARGIN_M
    inside = float(((positions >= low) & (positions <= high)).all(axis=1).mean())
    if inside < INSIDE_SHARE:
        raise ReplicaLayoutError(
            f"{path}: only {100 * inside:.0f} % of the camera positions of traj.txt lie inside "
            "the mesh's bounds; the mesh and the trajectory are not of the same scene"
        )
    return {
        "triangles": int(len(mesh.faces)),
        "bounds_m": np.round(mesh.bounds, 3).tolist(),
    }


def check_frames(folder: Path, poses: int, camera: dict[str, float]) -> int:
    """Count the RGB-D frames of a ``results/`` folder and check the first pair.

    Returns:
        the number of frame pairs.

    Raises:
        ReplicaLayoutError: counts that differ from each other or from the poses, or a first
            frame whose size is not the camera's.
    """
    from PIL import Image

    colour = sorted(folder.glob("frame*.jpg"))
    depth = sorted(folder.glob("depth*.png"))
    if len(colour) != poses or len(depth) != poses:
        raise ReplicaLayoutError(
            f"{folder}: {len(colour)} frame*.jpg and {len(depth)} depth*.png for {poses} poses "
            "in traj.txt; an interrupted download? (--no-check-frames skips this check; the "
            "benchmarks render their own frames)"
        )
    size = (int(camera["w"]), int(camera["h"]))
    for image_path in (colour[0], depth[0]):
        try:
            with Image.open(image_path) as image:
                found, mode = image.size, image.mode
        except OSError as error:
            raise ReplicaLayoutError(f"{image_path} is not a readable image ({error})") from error
        if found != size:
            raise ReplicaLayoutError(
                f"{image_path} is {found[1]} x {found[0]} (H x W); cam_params.json says "
                f"{size[1]} x {size[0]}"
            )
        if image_path in depth and mode not in ("I;16", "I", "I;16B"):
            raise ReplicaLayoutError(f"{image_path} is not a 16-bit depth image (mode {mode})")
    return poses


def find_culled(name: str, folders: list[Path]) -> Path | None:
    """The culled mesh of a scene (``<scene>.ply`` or ``<scene>_culled.ply``), or None."""
    for folder in folders:
        for candidate in (folder / f"{name}.ply", folder / f"{name}_culled.ply"):
            if candidate.is_file():
                return candidate
    return None


def check_scene(
    source: Path,
    name: str,
    camera: dict[str, float],
    culled_folders: list[Path],
    frames: bool = True,
) -> SceneCheck:
    """Check one scene of the release.

    Raises:
        ReplicaLayoutError: the first problem found (the message names the file).
    """
    folder = source / name
    if not folder.is_dir():
        present = sorted(s for s in REPLICA_SCENES if (source / s).is_dir())
        raise ReplicaLayoutError(
            f"{folder} is missing (scenes found in {source}: {present or 'none'}); pass "
            "--scenes with the ones you have"
        )
    trajectory = folder / "traj.txt"
    poses = read_trajectory(trajectory)
    positions = poses[:, :3, 3]
    mesh = source / f"{name}_mesh.ply"
    summary: dict[str, Any] = {
        "poses": len(poses),
        "trajectory_length_m": round(
            float(np.linalg.norm(np.diff(positions, axis=0), axis=1).sum()), 2
        ),
        **check_mesh(mesh, positions),
    }
    results = folder / "results"
    if results.is_dir():
        summary["frames"] = check_frames(results, len(poses), camera) if frames else None
    culled = find_culled(name, culled_folders)
    summary["culled_mesh"] = culled is not None
    return SceneCheck(
        name, mesh, trajectory, results if results.is_dir() else None, culled, summary
    )


def write_scene(check: SceneCheck, camera_file: Path, out: Path, copy: bool) -> Path:
    """Lay out one checked scene under ``out/replica_<scene>/``; returns that folder."""
    from naruto_gym.scenes.scene_folders import link_or_copy

    folder = out / f"replica_{check.name}"
    folder.mkdir(parents=True, exist_ok=True)
    link_or_copy(check.mesh, folder / "mesh.ply", copy)
    link_or_copy(check.trajectory, folder / "traj.txt", copy)
    shutil.copyfile(camera_file, folder / "cam_params.json")
    if check.frames is not None:
        link_or_copy(check.frames, folder / "frames", False)
    if check.culled is not None:
        link_or_copy(check.culled, folder / "mesh_culled.ply", copy)
    return folder


def prepare(args: Args) -> dict[str, Any]:
    """Check every scene of ``args.scenes``, then lay them out under ``args.output_dir``.

    Returns:
        the report written to ``replica_scenes.json``: the camera and, per scene, its poses,
        trajectory length, triangles, bounds, frames and whether a culled mesh was found.

    Raises:
        ReplicaLayoutError: every problem found, one per line; nothing is written then.
    """
    if not args.source:
        raise ReplicaLayoutError("pass --source: the folder of the Replica release")
    source = Path(args.source).expanduser()
    if not source.is_dir():
        raise ReplicaLayoutError(f"--source {source} is not a folder")
    unknown = sorted(set(args.scenes) - set(REPLICA_SCENES))
    if unknown or not args.scenes:
        raise ReplicaLayoutError(
            f"unknown scenes {unknown}; choose among {', '.join(REPLICA_SCENES)}"
        )
    camera_file = source / "cam_params.json"
    camera = read_camera(camera_file)
    if args.culled_dir:
        culled_folders = [Path(args.culled_dir).expanduser()]
        if not culled_folders[0].is_dir():
            raise ReplicaLayoutError(f"--culled-dir {culled_folders[0]} is not a folder")
    else:
        culled_folders = [source / CULLED_FOLDER, source.parent / CULLED_FOLDER]
    checks, problems = [], []
    for name in args.scenes:
        try:
            checks.append(check_scene(source, name, camera, culled_folders, args.check_frames))
        except ReplicaLayoutError as error:
            problems.append(f"{name}: {error}")
    if problems:
        raise ReplicaLayoutError("\n".join(problems))
    out = Path(args.output_dir).expanduser()
    report = {"source": str(source.resolve()), "camera": camera, "scenes": {}}
    for check in checks:
        folder = write_scene(check, camera_file, out, args.copy)
        report["scenes"][check.name] = {"folder": str(folder), **check.summary}
    (out / "replica_scenes.json").write_text(json.dumps(report, indent=1))
    return report


def _camera_note(camera: dict[str, float]) -> str:
    """A line saying whether the release's camera is the env's default one."""
    from naruto_gym.sensors.pinhole import PinholeCamera

    default = PinholeCamera()
    same = all(
        abs(camera[key] - value) < 1e-6
        for key, value in (
            ("w", default.width),
            ("h", default.height),
            ("fx", default.fx),
            ("fy", default.fy),
            ("cx", default.cx),
            ("cy", default.cy),
        )
    )
    size = f"{camera['h']:.0f} x {camera['w']:.0f} (H x W)"
    if same:
        return f"camera: {size}, fx = fy = {camera['fx']:g}: the env's default camera"
    return (
        f"camera: {size}, fx {camera['fx']:g}, fy {camera['fy']:g}: NOT the env's default; "
        "replica_passive.py reads it from cam_params.json, other tools need camera=..."
    )


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status (2 when a check fails)."""
    from naruto_agent.cli_args import dataclass_parser

    parser = dataclass_parser(
        Args, description=__doc__.split("\n\n")[1].replace("\n", " "), prog="prepare_replica.py"
    )
    args = Args(**vars(parser.parse_args(argv)))
    try:
        report = prepare(args)
    except ReplicaLayoutError as error:
        print(f"prepare_replica.py: error:\n{error}", file=sys.stderr)
        return 2
    print(_camera_note(report["camera"]))
    print("| scene | folder | poses | trajectory (m) | triangles | frames | culled mesh |")
    print("|---|---|---|---|---|---|---|")
    for name, scene in report["scenes"].items():
        print(
            f"| {name} | {scene['folder']} | {scene['poses']} | "
            f"{scene['trajectory_length_m']:.2f} | {scene['triangles']:,} | "
            f"{scene.get('frames', '-')} | {'yes' if scene['culled_mesh'] else 'no'} |"
        )
    print(f"\nwrote {Path(args.output_dir) / 'replica_scenes.json'}; next: docs/replica.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
