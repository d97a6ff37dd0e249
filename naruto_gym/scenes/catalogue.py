"""The shipped scene catalogue: named procedural scenes, their mesh files and metadata.

Every catalogue scene is made by :mod:`naruto_gym.scenes.procedural` from a fixed seed and
size, so its mesh never needs to be downloaded:

* In a source checkout (editable install) the meshes are read from ``envs_assets/`` at the
  repository root, with their metadata in ``envs_assets/catalogue.json``
  (``scripts/generate_scenes.py`` writes both).
* Where that folder is missing (an installed wheel) or lacks a file, the mesh is generated
  from its seed into a user cache folder (``$NARUTO_GYM_CACHE_DIR``, else
  ``$XDG_CACHE_HOME/naruto_gym/scenes``, else ``~/.cache/naruto_gym/scenes``) the first time
  it is asked for; generation is deterministic, so the file is byte-identical to the shipped
  one. ``$NARUTO_GYM_ASSETS_DIR`` points the lookup at another assets folder.

``resolve_scene`` is what the environment calls: it accepts a catalogue name, a catalogue
name with scan openings (``"NAME:OPENINGS"``, an open-scan variant built in memory by
:func:`catalogue_open_scan`), one fixed generated scene (``"procedural:<kind>:<seed>"``,
optionally cut open: ``"procedural:house:7:no_ceiling+holes"``; the size classes of the
benchmark suite are cached on disk by :mod:`naruto_gym.scenes.scene_cache`), a mesh file path
or an already built :class:`~naruto_gym.scenes.mesh_scene.Scene`.
"""

from __future__ import annotations

import copy
import hashlib
import json
import os
import warnings
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np

from naruto_gym.scenes.mesh_scene import Scene, UpAxis, load_scene
from naruto_gym.scenes.open_scans import ALIASES, OPENINGS, open_scan_variant, parse_openings
from naruto_gym.scenes.procedural import (
    GENERATOR_VERSION,
    SceneLayout,
    generate_layout,
    save_scene_ply,
    scene_to_ply_bytes,
)

# Re-exported: the cache's folder and variable were first defined here.
from naruto_gym.scenes.scene_cache import CACHE_DIR_ENV as CACHE_DIR_ENV
from naruto_gym.scenes.scene_cache import PLY_COMMENT, cache_dir
from naruto_gym.scenes.stream import parse_procedural_name
from naruto_gym.scenes.units import check_mesh_units

DEFAULT_SCENE = "replica_like_room"
"""The catalogue scene an env uses when given no ``scene``."""
ASSETS_DIR_ENV = "NARUTO_GYM_ASSETS_DIR"
CATALOGUE_FILE = "catalogue.json"

_MESH_SUFFIXES = {".ply", ".obj", ".glb", ".gltf", ".off", ".stl"}


@dataclass(frozen=True)
class CatalogueEntry:
    """How one catalogue scene is generated.

    Attributes:
        name: catalogue name.
        file: mesh file name inside the assets folder.
        description: one line for humans.
        seed: generator seed.
        size: free interior (width, depth, height) in metres.
        num_rooms: number of rooms.
    """

    name: str
    file: str
    description: str
    seed: int
    size: tuple[float, float, float]
    num_rooms: int

    def layout(self) -> SceneLayout:
        """The scene's layout (rooms, doorways, objects, start position)."""
        return generate_layout(self.seed, self.size, self.num_rooms)

    def generate(self) -> Scene:
        """The scene's mesh, generated from its seed."""
        return self.layout().to_scene(self.name)


_ENTRIES: dict[str, CatalogueEntry] = {
    entry.name: entry
    for entry in (
        CatalogueEntry(
            name="replica_like_room",
            file="replica_like_room.ply",
            description=(
                "One closed living room, 5 x 5 x 3 m free interior like a Replica room: sofa, "
                "TV unit, bookshelves, dining table with chairs, plants, lamp, rug, paintings."
            ),
            seed=0,
            size=(5.0, 5.0, 3.0),
            num_rooms=1,
        ),
        CatalogueEntry(
            name="apartment",
            file="apartment.ply",
            description=(
                "A Matterport3D-sized apartment: 6 furnished rooms (living room, kitchen, "
                "bedrooms, office, dining room) on a 12 x 9 m footprint, 2.8 m high, joined by "
                "doorways with loops."
            ),
            seed=12,
            size=(12.0, 9.0, 2.8),
            num_rooms=6,
        ),
        CatalogueEntry(
            name="two_rooms",
            file="two_rooms.ply",
            description=(
                "A small, cheap scene for fast tests: a living room and a bedroom joined by one "
                "doorway, 6.5 x 4 m footprint, 2.7 m high."
            ),
            seed=1,
            size=(6.5, 4.0, 2.7),
            num_rooms=2,
        ),
    )
}


# ---------------------------------------------------------------------------------------
# Where files live
# ---------------------------------------------------------------------------------------
def assets_dir() -> Path:
    """Folder of the shipped meshes: ``$NARUTO_GYM_ASSETS_DIR`` or ``<repo>/envs_assets``."""
    override = os.environ.get(ASSETS_DIR_ENV)
    if override:
        return Path(override).expanduser()
    return Path(__file__).resolve().parents[2] / "envs_assets"


def available_scenes() -> list[str]:
    """Names of the catalogue scenes, default first."""
    return list(_ENTRIES)


def catalogue_entry(name: str) -> CatalogueEntry:
    """The generation recipe of a catalogue scene.

    Raises:
        ValueError: ``name`` is not in the catalogue (the message lists the names).
    """
    try:
        return _ENTRIES[name]
    except (KeyError, TypeError):
        raise ValueError(
            f"unknown scene {name!r}; available catalogue scenes: "
            f"{', '.join(available_scenes())} (or pass a path to a mesh file)"
        ) from None


def scene_path(name: str) -> Path:
    """Path of a catalogue scene's PLY file, generating it into the cache if it is missing.

    Raises:
        ValueError: ``name`` is not in the catalogue.
    """
    entry = catalogue_entry(name)
    shipped = assets_dir() / entry.file
    if shipped.is_file():
        return shipped
    cached = cache_dir() / entry.file
    if not cached.is_file():
        # Atomic write (temporary file + rename): concurrent workers never read half a file.
        save_scene_ply(entry.generate(), cached, comment=PLY_COMMENT)
        record = _read_catalogue_json().get(name)
        if record is not None and _sha256(cached) != record["sha256"]:
            warnings.warn(
                f"the regenerated {cached} differs from the shipped record of {name!r}; the "
                "generator changed without scripts/generate_scenes.py being rerun",
                stacklevel=2,
            )
    return cached


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def load_catalogue_scene(name: str) -> Scene:
    """Load a catalogue scene (z-up, metres) by name."""
    return load_scene(scene_path(name), up_axis="z", name=name)


# ---------------------------------------------------------------------------------------
# Metadata
# ---------------------------------------------------------------------------------------
def _round(values, digits: int = 4) -> list[float]:
    return [round(float(v), digits) for v in values]


def describe_entry(entry: CatalogueEntry) -> dict:
    """The catalogue record of a scene, computed from its generator (what the JSON holds).

    Keys: name, file, description, generator (function, seed, size, num_rooms), extents_m,
    bounds_m, triangles, vertices, file_bytes, sha256, start_position, start_clearance_m,
    free_points (one per room), rooms (name, kind, interior [x0, y0, x1, y1]) and doorways
    (centre [x, y], width, height, rooms).
    """
    layout = entry.layout()
    scene = layout.to_scene(entry.name)
    data = scene_to_ply_bytes(scene, comment=PLY_COMMENT)
    start = np.asarray(layout.start_position)
    return {
        "name": entry.name,
        "file": entry.file,
        "description": entry.description,
        "generator": {
            "function": "naruto_gym.scenes.procedural.generate_layout",
            "seed": entry.seed,
            "size": list(entry.size),
            "num_rooms": entry.num_rooms,
        },
        "extents_m": _round(scene.extents, 3),
        "bounds_m": [_round(scene.bounds[0], 3), _round(scene.bounds[1], 3)],
        "triangles": int(len(scene.faces)),
        "vertices": int(len(scene.vertices)),
        "file_bytes": len(data),
        "sha256": hashlib.sha256(data).hexdigest(),
        "start_position": _round(start),
        "start_clearance_m": round(float(layout.start_clearance), 3),
        "free_points": [_round(p) for p in layout.room_points],
        "rooms": [
            {"name": room.name, "kind": room.kind, "interior": room.interior.as_list()}
            for room in layout.rooms
        ],
        "doorways": [
            {
                "centre": _round(door.centre),
                "width": round(door.hi - door.lo, 3),
                "height": round(door.height, 3),
                "rooms": [layout.rooms[i].name for i in door.rooms],
            }
            for door in layout.doorways
        ],
    }


def _read_catalogue_json() -> dict:
    path = assets_dir() / CATALOGUE_FILE
    if not path.is_file():
        return {}
    with path.open(encoding="utf-8") as handle:
        records = json.load(handle).get("scenes", [])
    return {record["name"]: record for record in records}


def scene_info(name: str) -> dict:
    """Metadata of a catalogue scene (see :func:`describe_entry` for the keys).

    Read from ``catalogue.json`` beside the shipped meshes, or computed from the generator
    when that file is not there.
    """
    catalogue_entry(name)  # validates the name
    record = _read_catalogue_json().get(name)
    if record is None:
        record = _computed_record(name)
    return copy.deepcopy(record)


@cache
def _computed_record(name: str) -> dict:
    return describe_entry(_ENTRIES[name])


def catalogue_document() -> dict:
    """The whole ``catalogue.json`` document, computed from the generator."""
    return {
        "format": 1,
        "generator_version": GENERATOR_VERSION,
        "note": (
            "Generated by naruto-gym (scripts/generate_scenes.py); meshes are metres, z up, "
            "binary PLY with per-vertex RGB. Licence: MIT, like the project."
        ),
        "default": DEFAULT_SCENE,
        "scenes": [describe_entry(entry) for entry in _ENTRIES.values()],
    }


# ---------------------------------------------------------------------------------------
# Open-scan variants of catalogue scenes
# ---------------------------------------------------------------------------------------
def catalogue_open_scan(name: str, seed: int = 0) -> Scene:
    """A catalogue scene opened up: ``"NAME:OPENINGS"``, e.g. ``"two_rooms:no_ceiling+holes"``.

    Raises:
        ValueError: an unknown catalogue name or opening.
    """
    base, _, openings = name.partition(":")
    entry = catalogue_entry(base)
    if not openings:
        raise ValueError(
            f"scene {name!r} names no opening; use NAME:OPENINGS with openings among "
            f"{', '.join(OPENINGS + tuple(ALIASES))} joined by '+'"
        )
    names = parse_openings(openings)
    return open_scan_variant(
        entry.layout(),
        names,
        seed=seed,
        scene=load_catalogue_scene(base),
        name=f"{base}:{'+'.join(names) or 'fragments'}",
    )


# ---------------------------------------------------------------------------------------
# One entry point for the environment
# ---------------------------------------------------------------------------------------
def check_scene_name(name_or_path: str | os.PathLike | Scene) -> None:
    """Check what a user passed as ``scene=`` the way :func:`resolve_scene` reads it, without
    loading or generating anything, so that a tool running many episodes can refuse a typo
    before the first one starts.

    Raises:
        ValueError: an unknown name, opening or procedural scene, or a scene stream.
        FileNotFoundError: a path that does not exist.
    """
    if isinstance(name_or_path, Scene) or (
        isinstance(name_or_path, str) and name_or_path in _ENTRIES
    ):
        return
    if isinstance(name_or_path, str) and name_or_path.partition(":")[0] in _ENTRIES:
        openings = name_or_path.partition(":")[2]
        if not openings:
            raise ValueError(f"scene {name_or_path!r} names no opening; use NAME:OPENINGS")
        parse_openings(openings)
        return
    if isinstance(name_or_path, str) and name_or_path.startswith("procedural:"):
        if parse_procedural_name(name_or_path).is_stream:
            raise ValueError(
                f"scene {name_or_path!r} is a stream (a new scene every reset), not one scene; "
                "give a seed ('procedural:room:123')"
            )
        return
    if not isinstance(name_or_path, (str, os.PathLike)):
        raise ValueError(
            f"scene must be a catalogue name, a mesh path or a Scene, got "
            f"{type(name_or_path).__name__}"
        )
    path = Path(name_or_path).expanduser()
    if path.is_file():
        return
    if (
        isinstance(name_or_path, os.PathLike)
        or path.suffix.lower() in _MESH_SUFFIXES
        or len(path.parts) > 1
    ):
        raise FileNotFoundError(
            f"scene file {str(path)!r} does not exist; pass a mesh path or a catalogue name "
            "(see naruto_gym.scenes.available_scenes())"
        )
    raise ValueError(
        f"unknown scene {str(name_or_path)!r}: not a catalogue name ("
        f"{', '.join(available_scenes())}) and not an existing mesh file"
    )


def resolve_scene(
    name_or_path: str | os.PathLike | Scene, up_axis: UpAxis = "z", mesh_units: str = "m"
) -> Scene:
    """Turn what a user passed as ``scene=`` into a :class:`Scene`.

    Args:
        name_or_path: a catalogue name (see :func:`available_scenes`), a catalogue name with
            scan openings (``"replica_like_room:no_ceiling+holes"``, see
            :mod:`naruto_gym.scenes.open_scans`), a generated scene
            (``"procedural:<kind>:<seed>[:<openings>]"``, see :mod:`naruto_gym.scenes.stream`),
            a path to a mesh file, or a :class:`Scene` (returned unchanged).
        up_axis: the up axis of a mesh *file*; catalogue scenes are always z-up and ignore it.
        mesh_units: the length unit of a mesh *file* (``"m"``, ``"cm"``, ``"mm"``), rescaled to
            metres; catalogue and generated scenes are in metres and ignore it.

    Raises:
        ValueError: a name that is neither in the catalogue nor an existing file.
        FileNotFoundError: a path (it has a mesh suffix or a folder part) that does not exist.
    """
    check_mesh_units(mesh_units)
    if isinstance(name_or_path, Scene):
        return name_or_path
    if isinstance(name_or_path, str) and name_or_path in _ENTRIES:
        return load_catalogue_scene(name_or_path)
    if isinstance(name_or_path, str) and name_or_path.partition(":")[0] in _ENTRIES:
        return catalogue_open_scan(name_or_path)  # "NAME:OPENINGS", an open-scan variant
    if isinstance(name_or_path, str) and name_or_path.startswith("procedural:"):
        spec = parse_procedural_name(name_or_path)
        if spec.is_stream:
            raise ValueError(
                f"scene {name_or_path!r} is a stream (a new scene every reset), not one scene; "
                "give a seed ('procedural:room:123') or use the vector env, which draws from "
                "streams"
            )
        return spec.scene(int(spec.seed))
    if not isinstance(name_or_path, (str, os.PathLike)):
        raise ValueError(
            f"scene must be a catalogue name, a mesh path or a Scene, got "
            f"{type(name_or_path).__name__}; catalogue scenes: {', '.join(available_scenes())}"
        )
    path = Path(name_or_path).expanduser()
    looks_like_path = (
        isinstance(name_or_path, os.PathLike)
        or path.suffix.lower() in _MESH_SUFFIXES
        or len(path.parts) > 1
    )
    if path.is_file() or looks_like_path:
        return load_scene(path, up_axis=up_axis, mesh_units=mesh_units)
    raise ValueError(
        f"unknown scene {str(name_or_path)!r}: not a catalogue name ("
        f"{', '.join(available_scenes())}) and not an existing mesh file"
    )
