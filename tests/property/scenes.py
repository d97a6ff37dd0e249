"""Small scenes and mesh files for the property-based suites (cheap to reset and step)."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import trimesh

from naruto_gym.scenes.mesh_scene import Scene
from naruto_gym.scenes.procedural import generate_layout

#: Settings that keep an env cheap: tiny frames, few coverage samples, a small panorama.
CHEAP = {"image_scale": 0.05, "coverage_samples": 300, "panorama_shape": (16, 32)}


@cache
def small_room() -> Scene:
    """A furnished 3 x 3 x 2.5 m room (about 2,000 triangles)."""
    return generate_layout(0, (3.0, 3.0, 2.5), 1, furniture_density=0.5).to_scene("small_room")


def room_mesh(scale: float = 1.0) -> trimesh.Trimesh:
    """The small room as a trimesh, its coordinates times ``scale``."""
    mesh = small_room().to_trimesh()
    mesh.vertices = mesh.vertices * scale
    return mesh


def write_mesh(mesh: trimesh.Trimesh, path: Path) -> Path:
    """Export ``mesh`` to ``path`` (the suffix picks the format)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    mesh.export(path)
    return path


def write_ascii_ply(path: Path, vertices: np.ndarray, faces: np.ndarray) -> Path:
    """An ASCII PLY written by hand, so that it may hold what exporters refuse (NaN
    coordinates, face indices past the vertices)."""
    lines = [
        "ply", "format ascii 1.0", f"element vertex {len(vertices)}",
        "property float x", "property float y", "property float z",
        f"element face {len(faces)}", "property list uchar int vertex_indices", "end_header",
    ]
    lines += [" ".join(repr(float(v)) for v in vertex) for vertex in vertices]
    lines += ["3 " + " ".join(str(int(i)) for i in face) for face in faces]
    path.write_text("\n".join(lines) + "\n")
    return path
