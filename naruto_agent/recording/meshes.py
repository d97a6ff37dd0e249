"""Light copies of meshes and camera outlines, shared by the recording and the 3D page.

Pure functions of numpy arrays and ``trimesh`` meshes: a reconstruction simplified to a face
budget (a map of a room holds hundreds of thousands of triangles; a recording logs it many
times and a web page must stay light), and the line segments of camera frustums.
"""

from __future__ import annotations

import numpy as np
import trimesh

from naruto_gym.sensors.pinhole import PinholeCamera


def vertex_colours(mesh: trimesh.Trimesh) -> np.ndarray | None:
    """(V, 3) float RGB 0-255 of a mesh with vertex colours, else None."""
    if getattr(mesh.visual, "kind", None) != "vertex":
        return None
    return np.asarray(mesh.visual.vertex_colors, np.float64)[:, :3]


def simplify_mesh(mesh: trimesh.Trimesh, max_faces: int) -> trimesh.Trimesh:
    """The mesh with at most ``max_faces`` triangles (vertex clustering, colours averaged).

    The cluster size grows until the mesh fits; a mesh already small enough comes back as is.
    """
    if len(mesh.faces) <= max_faces:
        return mesh
    import open3d as o3d

    legacy = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(np.asarray(mesh.vertices, np.float64)),
        o3d.utility.Vector3iVector(np.asarray(mesh.faces, np.int32)),
    )
    colours = vertex_colours(mesh)
    if colours is not None:
        legacy.vertex_colors = o3d.utility.Vector3dVector(colours / 255.0)
    extent = float(np.max(mesh.bounds[1] - mesh.bounds[0]))
    # Faces scale with the inverse square of the cluster size: start from that estimate
    # (the typical edge length, from a sample of faces: all unique edges cost seconds).
    faces = np.asarray(mesh.faces)
    sample = faces[:: max(1, len(faces) // 4096)]
    vertices = np.asarray(mesh.vertices, np.float64)
    spacing = float(np.median(np.linalg.norm(vertices[sample[:, 0]] - vertices[sample[:, 1]],
                                             axis=1)))
    cluster = max(spacing * np.sqrt(len(mesh.faces) / max_faces), 1e-4)
    while True:
        simple = legacy.simplify_vertex_clustering(cluster)
        if len(simple.triangles) <= max_faces or cluster > extent:
            break
        cluster *= 1.25
    colours_out = (
        (np.asarray(simple.vertex_colors) * 255).round().astype(np.uint8)
        if simple.has_vertex_colors()
        else None
    )
    return trimesh.Trimesh(
        np.asarray(simple.vertices),
        np.asarray(simple.triangles),
        vertex_colors=colours_out,
        process=False,
    )


def frustum_segments(poses: np.ndarray, camera: PinholeCamera, depth_m: float = 0.25) -> np.ndarray:
    """(8 N, 2, 3) line segments of N camera pyramids (apex to 4 corners, then the rim).

    Args:
        poses: (N, 4, 4) camera-to-world poses (OpenCV axes).
        camera: intrinsics giving the field of view.
        depth_m: z-depth of the pyramid's base.
    """
    poses = np.asarray(poses, np.float64).reshape(-1, 4, 4)
    u = np.array([0.0, camera.width, camera.width, 0.0]) - 0.5
    v = np.array([0.0, 0.0, camera.height, camera.height]) - 0.5
    corners_camera = depth_m * np.stack(
        [(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, np.ones(4)], axis=1
    )
    corners = np.einsum("nij,kj->nki", poses[:, :3, :3], corners_camera) + poses[:, None, :3, 3]
    apex = np.repeat(poses[:, None, :3, 3], 4, axis=1)
    spokes = np.stack([apex, corners], axis=2)
    rim = np.stack([corners, np.roll(corners, -1, axis=1)], axis=2)
    return np.concatenate([spokes, rim], axis=1).reshape(-1, 2, 3)
