"""Seeded procedural indoor scenes: closed rooms joined by doorways, furnished and coloured.

The generator works in two pure steps:

1. :func:`generate_layout` draws a floor plan from a seed: the footprint is split into rooms
   by axis-aligned walls (a binary space partition), every split wall gets a doorway, then
   each room gets furniture, wall paintings, a rug and a ceiling light. Nothing is placed in
   front of a doorway and every piece of furniture keeps a gap of ``object_gap_m`` to the
   others, so an agent (a sphere of radius 0.05 m) can walk into every room and around every
   object. The result is a :class:`SceneLayout`: rooms, doorways, objects (each a list of
   primitive parts) and a collision-free start position.
2. :meth:`SceneLayout.to_scene` turns the layout into triangles with per-vertex colours.
   Walls, floor and ceiling are solid slabs (walls ``wall_thickness`` thick, floor and
   ceiling 0.1 m) that overlap at every junction, so no ray can leak out of a room.
   Colours are flat per surface with a fixed directional shade baked in (no textures),
   so the same object looks different from different sides.

Coordinates: metres, z up. The free floor of the footprint is ``[0, W] x [0, D]`` and the
free height is ``[0, H]`` for ``size = (W, D, H)``; the mesh's bounds therefore extend one
wall thickness beyond the footprint and 0.1 m below the floor and above the ceiling.

Determinism: all randomness comes from ``numpy.random.default_rng(seed)``, circles use
Python's ``math`` functions and vertex positions are rounded to 0.1 mm and stored as
float32 values, so the same seed gives a byte-identical PLY file.

Modules, one job each:

* :mod:`~naruto_gym.scenes.procedural.plan`: plan geometry (rectangles, rooms, doorways,
  placed parts) and the partition of a footprint into rooms;
* :mod:`~naruto_gym.scenes.procedural.furniture`: furniture and decorations as coloured
  primitives in a local frame;
* :mod:`~naruto_gym.scenes.procedural.furnishing`: placing them in a room;
* :mod:`~naruto_gym.scenes.procedural.mesh_builder`: shaded triangles of primitives;
* :mod:`~naruto_gym.scenes.procedural.layout`: :class:`SceneLayout` and its mesh (slabs,
  walls, floor tiles, skirting boards);
* :mod:`~naruto_gym.scenes.procedural.corridors`: house plans with corridors;
* :mod:`~naruto_gym.scenes.procedural.clutter`: small clutter objects for lived-in houses;
* :mod:`~naruto_gym.scenes.procedural.generators`: the public generators;
* :mod:`~naruto_gym.scenes.procedural.size_classes`: the benchmark suite's size classes
  (``small``, ``flat``, ``house``);
* :mod:`~naruto_gym.scenes.procedural.ply`: binary PLY output.
"""

from naruto_gym.scenes.procedural.generators import (
    GENERATOR_VERSION,
    START_HEIGHT_M,
    SceneKind,
    generate_apartment,
    generate_layout,
    generate_room,
    make_random_scene,
    random_layout,
)
from naruto_gym.scenes.procedural.layout import FLOOR_THICKNESS_M, SceneLayout
from naruto_gym.scenes.procedural.plan import Doorway, Part, PlacedObject, Rect, Room
from naruto_gym.scenes.procedural.ply import save_scene_ply, scene_to_ply_bytes
from naruto_gym.scenes.procedural.size_classes import (
    SIZE_CLASS_KINDS,
    SIZE_CLASSES_VERSION,
    size_class_layout,
    size_class_scene,
)

__all__ = [
    "FLOOR_THICKNESS_M",
    "GENERATOR_VERSION",
    "SIZE_CLASSES_VERSION",
    "SIZE_CLASS_KINDS",
    "START_HEIGHT_M",
    "Doorway",
    "Part",
    "PlacedObject",
    "Rect",
    "Room",
    "SceneKind",
    "SceneLayout",
    "generate_apartment",
    "generate_layout",
    "generate_room",
    "make_random_scene",
    "random_layout",
    "save_scene_ply",
    "scene_to_ply_bytes",
    "size_class_layout",
    "size_class_scene",
]
