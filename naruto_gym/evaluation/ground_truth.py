"""Which surface a reconstruction is scored against: the scene's mesh, or the ground truth a
dataset's protocol names beside it.

A scene folder may hold the ground truth its protocol scores against next to the mesh the
agent moves in:

* **Replica** (``scripts/prepare_replica.py``): ``mesh_culled.ply`` beside ``mesh.ply``, the
  culled ground truth NICE-SLAM distributes for its evaluation (the surface no camera of the
  recorded scans saw removed). It is in the frame of ``mesh.ply``. Protocol: *culled ground
  truth*.
* **Any dataset** (``scripts/prepare_mp3d.py`` writes one for MP3D): ``ground_truth.json``
  beside the mesh, ``{"mesh": "<file>", "up_axis": "<axis>"}``, naming a mesh file of the same
  folder and the axis that points up in it (MP3D: the scan's ``.obj``, y-up, while the agent
  moves in the habitat ``.glb``). Protocol: *full mesh* (nothing of the file is removed).

Otherwise the scene's own mesh is the ground truth (protocol: *full mesh*). ``choice="full"``
ignores ``mesh_culled.ply`` (the NARUTO release scores Replica against the whole ``mesh.ply``);
a ``ground_truth.json`` is always followed, since the scene mesh is then not the surface the
protocol scores.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from naruto_gym.scenes.mesh_scene import Scene, dataset_up_axis, load_scene

CULLED_MESH_FILE = "mesh_culled.ply"
"""The culled ground truth beside a Replica ``mesh.ply``."""
GROUND_TRUTH_FILE = "ground_truth.json"
"""Names the ground-truth mesh of a scene folder and its up axis."""
PROTOCOL_CULLED = "culled ground truth"
PROTOCOL_FULL = "full mesh"
GROUND_TRUTH_CHOICES = ("auto", "full")
"""``auto``: the culled ground truth where the folder holds one; ``full``: never culled."""
_UP_AXES = ("x", "y", "z", "-x", "-y", "-z")


@dataclass(frozen=True)
class GroundTruth:
    """The surface a scene's reconstructions are scored against.

    Attributes:
        protocol: ``"culled ground truth"`` or ``"full mesh"``.
        path: the ground-truth mesh file, or None for the scene's own surface (a catalogue or
            generated scene, or a mesh file scored whole).
        up_axis: the axis that points up in ``path`` (None with no path).
    """

    protocol: str
    path: str | None = None
    up_axis: str | None = None

    @property
    def label(self) -> str:
        """``"culled ground truth (mesh_culled.ply)"``, ``"full mesh"``, ..."""
        return self.protocol + (f" ({Path(self.path).name})" if self.path else "")

    def as_dict(self) -> dict[str, Any]:
        """Plain ``dict`` (JSON-serialisable), with :attr:`label`."""
        return {**asdict(self), "label": self.label}


def _read_ground_truth_file(path: Path) -> GroundTruth:
    """The :class:`GroundTruth` a ``ground_truth.json`` names.

    Raises:
        ValueError: not JSON, a missing mesh file or an unknown up axis (the message says
            what the file must hold).
    """
    expected = '{"mesh": "<file beside it>", "up_axis": "x|y|z|-x|-y|-z"}'
    try:
        data = json.loads(path.read_text())
        mesh, up_axis = data["mesh"], data["up_axis"]
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise ValueError(f"{path} must hold {expected} ({error!r})") from error
    if up_axis not in _UP_AXES:
        raise ValueError(f"{path}: up_axis {up_axis!r} is not one of {', '.join(_UP_AXES)}")
    mesh_path = path.parent / str(mesh)
    if not mesh_path.is_file():
        raise ValueError(
            f"{path} names the ground-truth mesh {mesh_path}, which does not exist; prepare "
            "the folder again (scripts/prepare_mp3d.py) or remove the file"
        )
    return GroundTruth(PROTOCOL_FULL, str(mesh_path), up_axis)


def find_ground_truth(
    scene: str | Path | None, up_axis: str = "z", choice: str = "auto"
) -> GroundTruth:
    """The ground truth a scene is scored against (see the module docstring).

    Args:
        scene: the scene's mesh file; None (or a catalogue name, which is not a file) for a
            scene scored against its own surface.
        up_axis: the up axis the scene mesh is loaded with (``"auto"``: from its dataset
            layout); ``mesh_culled.ply`` shares it.
        choice: ``"auto"`` or ``"full"`` (:data:`GROUND_TRUTH_CHOICES`).

    Raises:
        ValueError: an unknown ``choice``, or a malformed ``ground_truth.json``.
    """
    if choice not in GROUND_TRUTH_CHOICES:
        raise ValueError(
            f"unknown ground truth {choice!r}; use one of {', '.join(GROUND_TRUTH_CHOICES)} "
            "(auto: the culled ground truth where the scene folder holds mesh_culled.ply)"
        )
    path = None if scene is None else Path(scene).expanduser()
    if path is None or not path.is_file():
        return GroundTruth(PROTOCOL_FULL)
    named = path.parent / GROUND_TRUTH_FILE
    if named.is_file():
        return _read_ground_truth_file(named)
    culled = path.parent / CULLED_MESH_FILE
    if choice == "auto" and culled.is_file() and culled.resolve() != path.resolve():
        axis = dataset_up_axis(path) if up_axis == "auto" else up_axis
        return GroundTruth(PROTOCOL_CULLED, str(culled), axis)
    return GroundTruth(PROTOCOL_FULL)


def load_ground_truth(ground_truth: GroundTruth, scene: Scene, mesh_units: str = "m") -> Scene:
    """The ground-truth surface as a z-up :class:`Scene` in metres: ``scene`` itself when the
    ground truth has no file of its own, else that file loaded with its up axis and the
    scene's length unit."""
    if ground_truth.path is None:
        return scene
    return load_scene(
        ground_truth.path,
        up_axis=ground_truth.up_axis or "z",
        name=f"{scene.name} ground truth",
        mesh_units=mesh_units,
    )
