"""Length units of mesh files: the ``mesh_units`` keyword and the check that a mesh is in metres.

The env's world is in metres. Many scans and CAD exports are written in millimetres or
centimetres instead; read as metres, a 6 x 4 x 2.7 m room becomes 6 km across, and every
per-metre structure (the 5 cm escape lattice, the 2 cm reference map, the observable-surface
grid) asks for memory beyond any machine. :func:`check_metric_size` refuses such a mesh when it
is loaded, naming the likely unit and the ``mesh_units`` value that rescales it.

What says "not metres": an indoor scene in metres is at most a few tens of metres across its
second-longest side (a large hall or a whole floor of a building), while the same space in
centimetres measures hundreds of units and in millimetres thousands. The second-longest side is
used, not the longest, so that a long corridor in metres passes; a flat scan (a floor only)
still has two long sides. The triangle scale settles the huge spaces: a dense scan in metres has
edges of centimetres (a median well under ``DENSE_EDGE_M``), where the same scan in millimetres
or centimetres has edges of one unit or more, so a large dense scan in metres passes.
"""

from __future__ import annotations

import math

import numpy as np

#: Every ``mesh_units`` value, with the factor that turns one unit into metres.
MESH_UNITS: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001}

#: The most metres an indoor scene spans along its second-longest side before its size says
#: "not metres" (unless its triangles are those of a dense scan in metres).
MAX_SCENE_SIDE_M = 100.0
#: The median triangle edge under which a mesh reads as a dense scan in metres, whatever its
#: size (scans have edges of 1 to 10 cm; the same scan in centimetres or millimetres has edges
#: of one unit or more).
DENSE_EDGE_M = 0.25
#: The side of a typical room, to which the likely unit brings the mesh closest.
TYPICAL_ROOM_SIDE_M = 5.0


def check_mesh_units(mesh_units: object) -> float:
    """The factor from ``mesh_units`` to metres, or a ``ValueError`` listing the units."""
    if not isinstance(mesh_units, str) or mesh_units not in MESH_UNITS:
        raise ValueError(
            f"mesh_units must be one of {tuple(MESH_UNITS)} (the length unit of the mesh "
            f"file), got {mesh_units!r}"
        )
    return MESH_UNITS[mesh_units]


def scene_side_m(vertices: np.ndarray) -> float:
    """The second-longest side of a mesh's axis-aligned box (in the mesh's units)."""
    extents = np.sort(np.ptp(np.asarray(vertices, dtype=np.float64), axis=0))
    return float(extents[-2])


def median_edge(vertices: np.ndarray, faces: np.ndarray) -> float:
    """The median length of the triangles' first edges (in the mesh's units)."""
    corners = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)[:, :2]]
    return float(np.median(np.linalg.norm(corners[:, 1] - corners[:, 0], axis=1)))


def check_metric_size(
    vertices: np.ndarray, faces: np.ndarray, what: str, mesh_units: str = "m"
) -> None:
    """Refuse a mesh (already rescaled to metres from ``mesh_units``) whose size and triangle
    scale say it is not in metres: wider than ``MAX_SCENE_SIDE_M`` along its second-longest
    side, with triangles coarser than a dense scan's.

    Raises:
        ValueError: naming the likely unit of the file and the ``mesh_units`` value that
            rescales it.
    """
    if len(faces) == 0:
        return
    side = scene_side_m(vertices)
    if not math.isfinite(side) or side <= MAX_SCENE_SIDE_M:
        return
    edge = median_edge(vertices, faces)
    if edge < DENSE_EDGE_M:
        return
    factor = MESH_UNITS[mesh_units]
    smaller = [unit for unit in MESH_UNITS if MESH_UNITS[unit] < factor]
    read_as = f"read with mesh_units={mesh_units!r}"
    if not smaller:
        raise ValueError(
            f"{what} is {side:,.0f} m across (its second-longest side, {read_as}) with a "
            f"median triangle edge of {edge:,.2f} m: an indoor scene in metres is at most "
            f"{MAX_SCENE_SIDE_M:g} m across; check the file's unit and rescale it to metres"
        )
    unit = min(
        smaller, key=lambda u: abs(math.log(side / factor * MESH_UNITS[u] / TYPICAL_ROOM_SIDE_M))
    )
    rescaled = side / factor * MESH_UNITS[unit]
    raise ValueError(
        f"{what} is {side:,.0f} m across (its second-longest side, {read_as}) with a median "
        f"triangle edge of {edge:,.2f} m: an indoor scene in metres is at most "
        f"{MAX_SCENE_SIDE_M:g} m across, so the file is likely in {_UNIT_NAMES[unit]} "
        f"({rescaled:,.1f} m across in metres). Pass mesh_units={unit!r} (to the env, the "
        "batched env, resolve_scene or load_scene; --mesh-units of naruto-demo and "
        "naruto-benchmark) to rescale it, "
        "or rescale the file to metres. For a space that really is this large in metres, load "
        "it with trimesh and pass naruto_gym.scenes.scene_from_trimesh(mesh) as scene= (a "
        "Scene is not checked)"
    )


_UNIT_NAMES = {"m": "metres", "cm": "centimetres", "mm": "millimetres"}
