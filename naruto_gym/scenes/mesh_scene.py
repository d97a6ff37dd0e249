"""A loaded indoor scene: triangles in a z-up metric world, and the colour of every surface point.

``load_scene`` reads any mesh trimesh can read (PLY, OBJ, GLB/glTF). Colour comes from
per-vertex colours, face colours, a material's base colour, or a texture sampled at the hit's
UV; everything is unified into per-triangle-corner colours, plus per-corner UVs and a texture
index for textured triangles, so that the colour of a ray hit is one barycentric lookup.
"""

from __future__ import annotations

import logging
import re
import warnings
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import Literal

import numpy as np
import trimesh

from naruto_gym.geometry.sorted_search import searchsorted_right
from naruto_gym.scenes.units import check_mesh_units, check_metric_size
from naruto_gym.sensors.kernels import interpolate_corner_colours

UpAxis = Literal["z", "y", "-y", "x", "-x", "-z", "auto"]

# Rotations taking each stored up axis to +z (proper rotations, det = +1).
_UP_AXIS_TO_Z: dict[str, np.ndarray] = {
    "z": np.eye(3),
    "y": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
    "-y": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),
    "x": np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]),
    "-x": np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]),
    "-z": np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]),
}
#: Every ``up_axis`` a mesh file can be read with.
UP_AXES: tuple[str, ...] = (*_UP_AXIS_TO_Z, "auto")

# File layouts whose up axis is fixed by the dataset (``up_axis="auto"``).
_SCANNET_MESH = re.compile(r"^scene\d{4}_\d{2}_vh_clean(_2)?\.ply$")
_REPLICA_SIBLINGS = ("habitat", "textures")
# The Replica release as NICE-SLAM prepared it (``office0_mesh.ply`` beside ``office0/``), and
# a scene folder of it as ``scripts/prepare_replica.py`` writes it (``mesh.ply`` beside the
# release's ``cam_params.json``).
_NICE_SLAM_REPLICA_MESH = re.compile(r"^(room[0-2]|office[0-4])_mesh\.ply$")
_PREPARED_REPLICA_FILE = "cam_params.json"

_LOG = logging.getLogger(__name__)

DEFAULT_SURFACE_RGB = (180, 180, 180)


def face_normals_of(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 3) unit triangle normals by the right-hand rule of each face's corners."""
    triangles = np.asarray(vertices, np.float64)[np.asarray(faces)]
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    return normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-20)


def check_mesh_arrays(vertices: np.ndarray, faces: np.ndarray, what: str) -> None:
    """Check that (V, 3) ``vertices`` and (F, 3) ``faces`` make a triangle mesh a scene can
    be built from: at least one triangle, every index a vertex, every vertex finite.

    Degenerate (zero-area) and duplicate triangles are allowed: ray casts never hit them,
    and scans are full of them.

    Raises:
        ValueError: what is wrong, and what to do about it.
    """
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise ValueError(f"{what}: vertices must have shape (V, 3), got {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise ValueError(
            f"{what} has no triangles (faces shape {faces.shape}); pass a triangle mesh "
            "(a point cloud or a line set cannot be ray cast)"
        )
    if faces.min() < 0 or faces.max() >= len(vertices):
        bad = int(np.count_nonzero((faces < 0) | (faces >= len(vertices))))
        raise ValueError(
            f"{what}: {bad} face indices lie outside the {len(vertices)} vertices (indices "
            f"from {int(faces.min())} to {int(faces.max())}); the file is damaged or was cut "
            "short: re-export the mesh"
        )
    finite = np.isfinite(vertices).all(axis=1)
    if not finite.all():
        first = int(np.flatnonzero(~finite)[0])
        raise ValueError(
            f"{what} has {int(np.count_nonzero(~finite))} vertices with NaN or infinite "
            f"coordinates (the first is vertex {first}: {vertices[first].tolist()}); remove "
            "them and the faces that use them, e.g. with trimesh: "
            "mesh.update_vertices(numpy.isfinite(mesh.vertices).all(axis=1))"
        )


def check_mesh_area(vertices: np.ndarray, faces: np.ndarray, what: str) -> None:
    """Raise ``ValueError`` when every triangle of a mesh has zero area (nothing to see)."""
    corners = np.asarray(vertices, np.float64)[np.asarray(faces)]
    doubled_areas = np.linalg.norm(
        np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1
    )
    if not doubled_areas.max() > 0.0:
        raise ValueError(
            f"{what} is degenerate: all of its {len(faces)} triangles have zero area; pass a "
            "mesh with surfaces"
        )


def sample_mesh_surface(
    vertices: np.ndarray,
    faces: np.ndarray,
    count: int,
    seed: int = 0,
    what: str = "mesh",
    axes: slice | list[int] = slice(None),
) -> np.ndarray:
    """``count`` points drawn uniformly by area on a triangle mesh (seeded, reproducible).

    The one surface sampler of the project: ground-truth and reconstruction samples of the
    metrics, coverage samples of the env and the scene's height statistics all come from it.

    Args:
        vertices: (V, 3) vertex positions.
        faces: (F, 3) triangle vertex indices.
        count: number of samples (> 0).
        seed: seed of the random generator.
        what: name used in error messages.
        axes: the coordinates to return (default all three; ``[2]`` for heights only, the
            same numbers as the points' third column, at a third of the cost).

    Returns:
        (count, 3) float64 points, or (count, len(axes)).

    Raises:
        ValueError: no triangles, bad indices, non-finite vertices or zero total area.
    """
    if count <= 0:
        raise ValueError(f"count must be positive, got {count}")
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise ValueError(f"{what}: vertices must have shape (V, 3), got {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise ValueError(
            f"{what} has no triangles (faces shape {faces.shape}); an empty reconstruction "
            "cannot be scored: integrate frames or pass points instead"
        )
    faces = faces.astype(np.int64)
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise ValueError(f"{what}: face indices out of range for {len(vertices)} vertices")
    triangles = vertices[faces]
    if not np.isfinite(triangles).all():
        raise ValueError(f"{what} has NaN or infinite vertex coordinates")
    edge1 = triangles[:, 1] - triangles[:, 0]
    edge2 = triangles[:, 2] - triangles[:, 0]
    areas = 0.5 * np.linalg.norm(np.cross(edge1, edge2), axis=1)
    total = float(areas.sum())
    if not total > 0.0:
        raise ValueError(f"{what} is degenerate: its triangles have zero total area")
    rng = np.random.default_rng(seed)
    # Inverse-CDF draw of triangles by area: faster than rng.choice(p=...) for large meshes.
    cumulative = np.cumsum(areas)
    chosen = searchsorted_right(cumulative, rng.random(count) * cumulative[-1])
    chosen = np.minimum(chosen, len(areas) - 1)
    r1, r2 = rng.random(count), rng.random(count)
    flip = r1 + r2 > 1.0
    r1[flip], r2[flip] = 1.0 - r1[flip], 1.0 - r2[flip]
    first, edge1, edge2 = triangles[:, 0, axes], edge1[:, axes], edge2[:, axes]
    return first[chosen] + r1[:, None] * edge1[chosen] + r2[:, None] * edge2[chosen]


@dataclass
class Scene:
    """An indoor triangle mesh, z-up, metres.

    Attributes:
        vertices: (V, 3) float64 positions.
        faces: (F, 3) int64 triangle vertex indices.
        corner_colours: (F, 3, 3) uint8 RGB at each triangle corner.
        name: human-readable name (file stem or catalogue name).
        corner_uvs: (F, 3, 2) float32 texture coordinates, or None when nothing is textured.
        face_texture_ids: (F,) int32 index into ``textures``, -1 for untextured triangles.
        textures: list of (H, W, 3) uint8 images.
    """

    vertices: np.ndarray
    faces: np.ndarray
    corner_colours: np.ndarray
    name: str = "scene"
    corner_uvs: np.ndarray | None = None
    face_texture_ids: np.ndarray | None = None
    textures: list[np.ndarray] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.vertices = np.asarray(self.vertices, dtype=np.float64)
        self.faces = np.asarray(self.faces, dtype=np.int64)
        check_mesh_arrays(self.vertices, self.faces, f"scene {self.name!r}")
        self.corner_colours = np.asarray(self.corner_colours, dtype=np.uint8)
        if self.corner_colours.shape != (len(self.faces), 3, 3):
            raise ValueError(
                f"scene {self.name!r}: corner_colours must have shape ({len(self.faces)}, 3, 3) "
                f"(RGB at each triangle corner), got {self.corner_colours.shape}"
            )
        # float32 copy used at render time: avoids a uint8 -> float conversion per frame.
        self._corner_colours_f = self.corner_colours.astype(np.float32)
        # Per triangle: its colour and whether all three corners share it (most triangles of
        # flat-shaded scenes), whose hits then need no interpolation.
        self._flat_colours = np.zeros((len(self.corner_colours), 4), np.uint8)
        self._flat_colours[:, :3] = self.corner_colours[:, 0]
        self._flat_colours[:, 3] = (self.corner_colours == self.corner_colours[:, :1]).all(
            axis=(1, 2)
        )

    @cached_property
    def faces_needing_barycentrics(self) -> np.ndarray:
        """(F,) bool: the triangles whose colour varies over them (corner colours that differ,
        or a texture), so that :meth:`colour_at` reads a hit's barycentric (u, v) there."""
        needed = self._flat_colours[:, 3] == 0
        if self.face_texture_ids is not None and self.textures:
            needed |= np.asarray(self.face_texture_ids) >= 0
        return needed

    # -- geometry --------------------------------------------------------------------
    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) axis-aligned bounds [min, max] in metres."""
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    @property
    def extents(self) -> np.ndarray:
        return self.bounds[1] - self.bounds[0]

    @cached_property
    def face_normals(self) -> np.ndarray:
        """(F, 3) unit triangle normals by the right-hand rule of each face's corners."""
        return face_normals_of(self.vertices, self.faces)

    def to_trimesh(self) -> trimesh.Trimesh:
        """A plain trimesh copy with per-vertex colours (corner colours averaged)."""
        colours = np.zeros((len(self.vertices), 3), dtype=np.float64)
        counts = np.zeros(len(self.vertices), dtype=np.float64)
        np.add.at(colours, self.faces.ravel(), self.corner_colours.reshape(-1, 3))
        np.add.at(counts, self.faces.ravel(), 1.0)
        colours /= np.maximum(counts, 1.0)[:, None]
        rgba = np.concatenate(
            [colours.astype(np.uint8), np.full((len(colours), 1), 255, np.uint8)], axis=1
        )
        return trimesh.Trimesh(self.vertices, self.faces, vertex_colors=rgba, process=False)

    def sample_surface(self, count: int, seed: int = 0) -> np.ndarray:
        """``count`` area-uniform points on the surface, (count, 3) float64, seeded (see
        :func:`sample_mesh_surface`)."""
        return sample_mesh_surface(
            self.vertices, self.faces, count, seed, what=f"scene {self.name!r}"
        )

    # -- colour ----------------------------------------------------------------------
    def colour_at(
        self, triangle_ids: np.ndarray, barycentric_uv: np.ndarray, out: np.ndarray | None = None
    ) -> np.ndarray:
        """RGB uint8 (N, 3) of hit points given their triangles and barycentric (u, v).

        Misses (triangle id < 0) come back black. ``out``: a C-contiguous (N, 3) uint8 array
        to write them into (a batched env's observation rows), returned.
        """
        triangle_ids = np.ascontiguousarray(triangle_ids)
        barycentric_uv = np.ascontiguousarray(barycentric_uv, dtype=np.float32)
        if out is None:
            rgb = np.empty((len(triangle_ids), 3), dtype=np.uint8)
        elif (
            out.shape != (len(triangle_ids), 3)
            or out.dtype != np.uint8
            or not (out.flags.c_contiguous)
        ):
            raise ValueError(
                f"out must be a C-contiguous ({len(triangle_ids)}, 3) uint8 array, got "
                f"{out.dtype} {out.shape}"
            )
        else:
            rgb = out
        interpolate_corner_colours(
            triangle_ids, barycentric_uv, self._corner_colours_f, self._flat_colours, rgb
        )
        if self.face_texture_ids is not None and self.textures:
            texture_ids = np.where(triangle_ids >= 0, self.face_texture_ids[triangle_ids], -1)
            for texture_index in np.unique(texture_ids[texture_ids >= 0]):
                selected = np.flatnonzero(texture_ids == texture_index)
                uv_corners = self.corner_uvs[triangle_ids[selected]]
                u = barycentric_uv[selected, 0:1]
                v = barycentric_uv[selected, 1:2]
                tex_uv = (
                    uv_corners[:, 0]
                    + u * (uv_corners[:, 1] - uv_corners[:, 0])
                    + v * (uv_corners[:, 2] - uv_corners[:, 0])
                )
                rgb[selected] = sample_texture(self.textures[texture_index], tex_uv).astype(
                    np.uint8
                )
        return rgb


def sample_texture(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Nearest-texel lookup with wrap-around; uv origin at the bottom-left (OpenGL/glTF)."""
    height, width = image.shape[:2]
    column = np.floor(np.mod(uv[:, 0], 1.0) * width).astype(np.int64).clip(0, width - 1)
    row = np.floor((1.0 - np.mod(uv[:, 1], 1.0)) * height).astype(np.int64).clip(0, height - 1)
    return image[row, column, :3].astype(np.float32)


def _geometry_colours(
    mesh: trimesh.Trimesh,
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Corner colours, and corner UVs plus texture image when the mesh is textured."""
    faces = mesh.faces
    visual = mesh.visual
    if isinstance(visual, trimesh.visual.TextureVisuals):
        material = visual.material
        image = getattr(material, "image", None)
        if image is None:
            image = getattr(material, "baseColorTexture", None)
        if image is not None and visual.uv is not None and len(visual.uv) == len(mesh.vertices):
            rgb_image = np.asarray(image.convert("RGB"), dtype=np.uint8)
            if (rgb_image == rgb_image[0, 0]).all():
                # A constant texture is a plain colour: no per-hit texture lookup needed.
                return np.broadcast_to(rgb_image[0, 0], (len(faces), 3, 3)).copy(), None, None
            corner_uvs = np.asarray(visual.uv, dtype=np.float32)[faces]
            corner_rgb = sample_texture(rgb_image, corner_uvs.reshape(-1, 2)).reshape(-1, 3, 3)
            return corner_rgb.astype(np.uint8), corner_uvs, rgb_image
        base = getattr(material, "baseColorFactor", None)
        if base is None:
            base = getattr(material, "main_color", None)
        rgb = np.asarray(base if base is not None else DEFAULT_SURFACE_RGB, dtype=np.float64)[:3]
        if rgb.max() <= 1.0 and np.issubdtype(np.asarray(base).dtype, np.floating):
            rgb = rgb * 255.0
        return np.broadcast_to(rgb.astype(np.uint8), (len(faces), 3, 3)).copy(), None, None
    if isinstance(visual, trimesh.visual.ColorVisuals):
        if visual.kind == "vertex":
            return np.asarray(visual.vertex_colors[:, :3], np.uint8)[faces], None, None
        if visual.kind == "face":
            face_rgb = np.asarray(visual.face_colors[:, :3], np.uint8)
            return np.repeat(face_rgb[:, None, :], 3, axis=1), None, None
    return np.full((len(faces), 3, 3), DEFAULT_SURFACE_RGB, dtype=np.uint8), None, None


def rotation_to_z_up(up_axis: str) -> np.ndarray:
    """The rotation that turns a file's ``up_axis`` (``"x"``, ``"-y"``, ...) to +z."""
    if up_axis not in _UP_AXIS_TO_Z:
        raise ValueError(f"up_axis must be one of {sorted(_UP_AXIS_TO_Z)}, got {up_axis!r}")
    return _UP_AXIS_TO_Z[up_axis].copy()


def scene_from_trimesh(
    geometry: trimesh.Trimesh | trimesh.Scene, name: str = "scene", up_axis: UpAxis = "z"
) -> Scene:
    """Build a :class:`Scene` from a trimesh mesh or scene, rotating ``up_axis`` to +z."""
    if up_axis not in _UP_AXIS_TO_Z:
        raise ValueError(f"up_axis must be one of {sorted(_UP_AXIS_TO_Z)}, got {up_axis!r}")
    if isinstance(geometry, trimesh.Scene):
        meshes = [g for g in geometry.dump(concatenate=False) if isinstance(g, trimesh.Trimesh)]
    else:
        meshes = [geometry]
    meshes = [m for m in meshes if len(m.faces) > 0]
    if not meshes:
        raise ValueError(f"scene {name!r} contains no triangles; pass a triangle mesh")

    vertices, faces, corner_colours, corner_uvs, texture_ids, textures = [], [], [], [], [], []
    offset = 0
    any_texture = False
    for mesh in meshes:
        colours, uvs, image = _geometry_colours(mesh)
        vertices.append(np.asarray(mesh.vertices, dtype=np.float64))
        faces.append(np.asarray(mesh.faces, dtype=np.int64) + offset)
        offset += len(mesh.vertices)
        corner_colours.append(colours)
        if image is not None:
            any_texture = True
            texture_ids.append(np.full(len(mesh.faces), len(textures), np.int32))
            textures.append(image)
            corner_uvs.append(uvs)
        else:
            texture_ids.append(np.full(len(mesh.faces), -1, np.int32))
            corner_uvs.append(np.zeros((len(mesh.faces), 3, 2), np.float32))

    all_vertices = np.concatenate(vertices) @ _UP_AXIS_TO_Z[up_axis].T
    return Scene(
        vertices=all_vertices,
        faces=np.concatenate(faces),
        corner_colours=np.concatenate(corner_colours),
        name=name,
        corner_uvs=np.concatenate(corner_uvs) if any_texture else None,
        face_texture_ids=np.concatenate(texture_ids) if any_texture else None,
        textures=textures,
    )


def dataset_up_axis(path: str | Path) -> str:
    """The up axis fixed by a recognised dataset layout (what ``up_axis="auto"`` uses).

    Recognised: ScanNet (``sceneXXXX_XX_vh_clean_2.ply`` or ``..._vh_clean.ply``, z-up),
    Replica (``mesh.ply`` beside its ``habitat/`` or ``textures/`` folder, z-up) and the
    Replica release of NICE-SLAM (``office0_mesh.ply`` and the other seven scenes, or a
    ``mesh.ply`` beside its ``cam_params.json`` as ``scripts/prepare_replica.py`` lays it out,
    z-up). Nothing else
    is guessed: glTF files are y-up by the glTF specification, but MP3D/HM3D exports differ
    and habitat-sim's own test files are z-up.

    Raises:
        ValueError: the layout is not recognised (the message says what to pass).
    """
    path = Path(path)
    if _SCANNET_MESH.match(path.name):
        return "z"
    if path.name == "mesh.ply" and any((path.parent / d).is_dir() for d in _REPLICA_SIBLINGS):
        return "z"
    if _NICE_SLAM_REPLICA_MESH.match(path.name):
        return "z"
    if path.name == "mesh.ply" and (path.parent / _PREPARED_REPLICA_FILE).is_file():
        return "z"
    raise ValueError(
        f"up_axis='auto' does not recognise the layout of {str(path)!r} (it knows ScanNet "
        "sceneXXXX_XX_vh_clean_2.ply, Replica mesh.ply with habitat/, textures/ or "
        "cam_params.json beside it, and NICE-SLAM's Replica office0_mesh.ply...); pass the "
        "axis that points up in the file: up_axis='z' for ScanNet, Replica and "
        "most PLY scans, 'y' for y-up glTF/GLB files such as MP3D/HM3D exports and SceneNet "
        "(habitat-sim's test .glb files are z-up)"
    )


def load_scene(
    path: str | Path, up_axis: UpAxis = "z", name: str | None = None, mesh_units: str = "m"
) -> Scene:
    """Load a triangle mesh file (PLY, OBJ, GLB/glTF, ...) as a z-up :class:`Scene` in metres.

    Args:
        path: mesh file.
        up_axis: the axis that points up in the file (``"y"`` for most glTF and SceneNet
            files); it is rotated to +z. Never guessed: ``"auto"`` only reads it from a
            recognised dataset layout (see :func:`dataset_up_axis`) and raises otherwise.
        name: display name, defaults to the file stem.
        mesh_units: the length unit of the file, ``"m"``, ``"cm"`` or ``"mm"``; the mesh is
            rescaled to metres.

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: the file cannot be read as a mesh, or holds no triangles, or
            ``up_axis="auto"`` does not recognise its layout, or its size says it is not in
            ``mesh_units`` (a room in millimetres read as metres; the message names the
            likely unit, see :func:`naruto_gym.scenes.units.check_metric_size`).
    """
    to_metres = check_mesh_units(mesh_units)
    path = Path(path).expanduser()
    if not path.is_file():
        raise FileNotFoundError(
            f"scene file {str(path)!r} does not exist; pass a mesh path or a catalogue name "
            "(see naruto_gym.scenes.available_scenes())"
        )
    if up_axis == "auto":
        up_axis = dataset_up_axis(path)  # type: ignore[assignment]
        _LOG.info("%s: up axis %s from its dataset layout", path, up_axis)
    try:
        geometry = trimesh.load(path, force="scene", process=False)
    except Exception as error:  # trimesh raises many types for broken files
        raise ValueError(
            f"could not read {str(path)!r} as a triangle mesh ({type(error).__name__}: {error}); "
            "use a PLY, OBJ or GLB/glTF file"
        ) from error
    scene = scene_from_trimesh(geometry, name=name or path.stem, up_axis=up_axis)
    if to_metres != 1.0:
        scene = replace(scene, vertices=scene.vertices * to_metres)
    check_metric_size(scene.vertices, scene.faces, f"mesh file {str(path)!r}", mesh_units)
    if up_axis == "z" and looks_y_up(scene.vertices, scene.faces):
        warnings.warn(
            f"{str(path)!r} looks y-up (its shortest side and most of its flat surface lie "
            "along y) but was loaded z-up, so the scene lies on its side; pass up_axis='y' if "
            "y points up in the file (the scene is kept as loaded)",
            stacklevel=2,
        )
    return scene


def looks_y_up(vertices: np.ndarray, faces: np.ndarray) -> bool:
    """Whether a room-like mesh read z-up looks stored y-up: its shortest extent is along y
    and more of its surface faces along y (floors and ceilings, table tops) than along z.

    Rooms are wider than they are tall, and their floors and ceilings are their largest flat
    surfaces; a z-up file of a long, narrow corridor keeps its shortest side along x or y but
    its largest flat surfaces facing z, so it does not pass both tests.
    """
    extents = np.ptp(vertices, axis=0)
    if not np.all(np.isfinite(extents)) or int(np.argmin(extents)) != 1:
        return False
    corners = vertices[faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    area_along = np.abs(normals).sum(axis=0)  # twice the area projected along each axis
    return bool(area_along[1] > area_along[2])
