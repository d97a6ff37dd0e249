"""Triangle soup with per-vertex colours and a fixed light baked in.

:class:`MeshBuilder` accumulates boxes, quads, frustums and spheres as triangles whose
colours are shaded by a fixed directional light (:func:`shade`), so the same object looks
different from different sides without textures. Every shading operation is written as plain
IEEE double arithmetic in a fixed order, and vertices are rounded to 0.1 mm and stored as
float32, so the same primitives give the same bytes on every machine.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import trimesh

from naruto_gym.scenes.procedural.furniture import RGB
from naruto_gym.scenes.procedural.plan import Part

# Fixed light direction for the baked shading: faces towards it are brighter.
_LIGHT_NORM = math.sqrt(0.35**2 + 0.55**2 + 0.76**2)
_LIGHT = (0.35 / _LIGHT_NORM, 0.55 / _LIGHT_NORM, 0.76 / _LIGHT_NORM)


def shade(rgb: Sequence[int], normals: np.ndarray) -> np.ndarray:
    """Colour lit by a fixed light: (N, 3) uint8 for (N, 3) unit normals."""
    # Element-wise products rather than a matrix product: BLAS kernels may round differently
    # from machine to machine, and the colours must be bit-identical everywhere.
    lit = normals[:, 0] * _LIGHT[0] + normals[:, 1] * _LIGHT[1] + normals[:, 2] * _LIGHT[2]
    factor = 0.78 + 0.22 * lit
    return np.clip(np.asarray(rgb, np.float64)[None, :] * factor[:, None] + 0.5, 0, 255).astype(
        np.uint8
    )


_BOX_FACES = (
    # (normal, four corner selectors (ix, iy, iz) in counter-clockwise order seen from outside)
    ((-1.0, 0.0, 0.0), ((0, 0, 0), (0, 0, 1), (0, 1, 1), (0, 1, 0))),
    ((1.0, 0.0, 0.0), ((1, 0, 0), (1, 1, 0), (1, 1, 1), (1, 0, 1))),
    ((0.0, -1.0, 0.0), ((0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1))),
    ((0.0, 1.0, 0.0), ((0, 1, 0), (0, 1, 1), (1, 1, 1), (1, 1, 0))),
    ((0.0, 0.0, -1.0), ((0, 0, 0), (0, 1, 0), (1, 1, 0), (1, 0, 0))),
    ((0.0, 0.0, 1.0), ((0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1))),
)


# The box's 24 corners (four per face, in _BOX_FACES order) as selectors into [lo, hi].
_BOX_CORNER_SELECTORS = np.array([corner for _, corners in _BOX_FACES for corner in corners])
_BOX_AXES = np.arange(3)[None, :]
_BOX_TRIANGLES = np.array(
    [(4 * f, 4 * f + a, 4 * f + a + 1) for f in range(len(_BOX_FACES)) for a in (1, 2)], np.int64
)
_QUAD_TRIANGLES = np.array([(0, 1, 2), (0, 2, 3)], np.int64)


def flat_shade(rgb: Sequence[int], normal: Sequence[float]) -> tuple[int, int, int]:
    """:func:`shade` of one colour and one normal in plain floats (the same IEEE double
    operations in the same order, so the same bytes), without NumPy's per-call cost: a scene
    shades every box face and floor tile this way, thousands of times."""
    nx, ny, nz = (float(n) for n in normal)
    factor = 0.78 + 0.22 * (nx * _LIGHT[0] + ny * _LIGHT[1] + nz * _LIGHT[2])
    red, green, blue = (int(min(max(float(c) * factor + 0.5, 0.0), 255.0)) for c in rgb)
    return red, green, blue


class MeshBuilder:
    """Accumulates triangles with per-vertex colours."""

    def __init__(self) -> None:
        self._vertices: list[np.ndarray] = []
        self._faces: list[np.ndarray] = []
        self._colours: list[np.ndarray] = []
        self._count = 0

    def add(self, vertices: np.ndarray, faces: np.ndarray, colours: np.ndarray) -> None:
        """Append triangles; ``faces`` index into ``vertices`` (offset here)."""
        self._vertices.append(np.asarray(vertices, np.float64))
        self._faces.append(np.asarray(faces, np.int64) + self._count)
        self._colours.append(np.asarray(colours, np.uint8))
        self._count += len(vertices)

    def box(self, lo: Sequence[float], hi: Sequence[float], colours: Sequence[RGB]) -> None:
        """Solid box; ``colours`` has one RGB or six (faces -x, +x, -y, +y, -z, +z)."""
        corners = np.array([lo, hi], np.float64)
        vertices = corners[_BOX_CORNER_SELECTORS, _BOX_AXES]
        shaded = [
            flat_shade(colours[index] if len(colours) == 6 else colours[0], normal)
            for index, (normal, _) in enumerate(_BOX_FACES)
        ]
        self.add(vertices, _BOX_TRIANGLES, np.repeat(np.array(shaded, np.uint8), 4, axis=0))

    def quad(self, corners: np.ndarray, colour: RGB, normal: Sequence[float]) -> None:
        """One flat quad; corners (4, 3) counter-clockwise seen from the normal's side."""
        shaded = np.repeat(np.array([flat_shade(colour, normal)], np.uint8), 4, axis=0)
        self.add(corners, _QUAD_TRIANGLES, shaded)

    def frustum(
        self,
        cx: float,
        cy: float,
        z0: float,
        bottom_radius: float,
        top_radius: float,
        height: float,
        colour: RGB,
        sections: int = 16,
    ) -> None:
        """Closed truncated cone (a cylinder when both radii match), axis along z."""
        angles = [2.0 * math.pi * k / sections for k in range(sections)]
        ring = np.array([(math.cos(a), math.sin(a)) for a in angles])
        z1 = z0 + height
        bottom = np.column_stack(
            [cx + bottom_radius * ring[:, 0], cy + bottom_radius * ring[:, 1],
             np.full(sections, z0)]
        )
        top = np.column_stack(
            [cx + top_radius * ring[:, 0], cy + top_radius * ring[:, 1], np.full(sections, z1)]
        )
        # Side: smooth shading from radial normals.
        side_normals = np.column_stack([ring, np.zeros(sections)])
        k = np.arange(sections)
        k1 = (k + 1) % sections
        side_faces = np.concatenate(
            [np.column_stack([k, k1, sections + k1]), np.column_stack([k, sections + k1,
                                                                        sections + k])]
        )
        self.add(
            np.concatenate([bottom, top]),
            side_faces,
            np.concatenate([shade(colour, side_normals)] * 2),
        )
        # Caps: flat shading, fan around a centre vertex.
        for ring_points, z, normal in ((bottom, z0, -1.0), (top, z1, 1.0)):
            vertices = np.concatenate([[[cx, cy, z]], ring_points])
            fan = np.column_stack([np.zeros(sections, np.int64), 1 + k, 1 + k1])
            if normal < 0:
                fan = fan[:, [0, 2, 1]]
            shaded = np.repeat(shade(colour, np.array([[0.0, 0.0, normal]])), sections + 1, 0)
            self.add(vertices, fan, shaded)

    def sphere(
        self, cx: float, cy: float, cz: float, radius: float, colour: RGB,
        rings: int = 8, segments: int = 12,
    ) -> None:
        """UV sphere with smooth shading."""
        normals = [(0.0, 0.0, -1.0)]
        for i in range(1, rings):
            polar = math.pi * i / rings - 0.5 * math.pi
            for j in range(segments):
                azimuth = 2.0 * math.pi * j / segments
                normals.append(
                    (math.cos(polar) * math.cos(azimuth), math.cos(polar) * math.sin(azimuth),
                     math.sin(polar))
                )
        normals.append((0.0, 0.0, 1.0))
        normal_array = np.array(normals)
        faces = []
        top = len(normals) - 1
        for j in range(segments):
            j1 = (j + 1) % segments
            faces.append((0, 1 + j1, 1 + j))
            last = 1 + (rings - 2) * segments
            faces.append((top, last + j, last + j1))
        for i in range(rings - 2):
            row, nxt = 1 + i * segments, 1 + (i + 1) * segments
            for j in range(segments):
                j1 = (j + 1) % segments
                faces += [(row + j, row + j1, nxt + j1), (row + j, nxt + j1, nxt + j)]
        vertices = np.array([cx, cy, cz]) + radius * normal_array
        self.add(vertices, np.array(faces), shade(colour, normal_array))

    def part(self, part: Part) -> None:
        """One world-frame primitive of a placed object."""
        if part.kind == "box":
            self.box(part.data[:3], part.data[3:], part.colours)
        elif part.kind == "frustum":
            self.frustum(*part.data, colour=part.colours[0])
        else:
            self.sphere(*part.data, colour=part.colours[0])

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(vertices (V, 3) float64, faces (F, 3) int64, colours (V, 3) uint8) so far."""
        vertices = np.concatenate(self._vertices)
        # 0.1 mm grid, then float32: the file stores float32 and a reloaded scene matches.
        vertices = np.round(vertices, 4).astype(np.float32).astype(np.float64)
        return vertices, np.concatenate(self._faces), np.concatenate(self._colours)


def to_trimesh(vertices: np.ndarray, faces: np.ndarray, colours: np.ndarray) -> trimesh.Trimesh:
    """An unprocessed trimesh (vertices kept as they are) with opaque vertex colours."""
    rgba = np.concatenate([colours, np.full((len(colours), 1), 255, np.uint8)], axis=1)
    return trimesh.Trimesh(vertices, faces, vertex_colors=rgba, process=False)

