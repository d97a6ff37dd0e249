"""A 3D view of the episode to open in a browser and turn: ``viewer.html``.

One self-contained HTML page (plotly.js embedded, nothing fetched when it opens) with

* ``reconstruction``: the episode's mesh in its own colours, simplified to at most
  ``max_faces`` triangles so the page stays light;
* ``ground truth outline``: the ground-truth mesh's feature edges (creases sharper than 30
  degrees and open borders), the longest first when there are too many;
* ``trajectory``: the camera positions, coloured by step;
* ``camera frustums``: every n-th camera as a small pyramid;
* ``goals``: the goals the policy chose.

It needs plotly (the ``viewer`` extra: ``pip install "naruto-gym[viewer]"``);
:func:`write_viewer` says so and writes nothing when it is missing. :func:`read_viewer` reads
the traces back from a page, for tests and for anyone who wants the data without a browser.
"""

from __future__ import annotations

import base64
import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from naruto_gym.sensors.pinhole import PinholeCamera

VIEWER_EXTRA_HINT = 'pip install "naruto-gym[viewer]"'
#: Trace names of the page, in drawing order.
TRACE_NAMES = ("reconstruction", "ground truth outline", "trajectory", "camera frustums", "goals")


def plotly_available() -> bool:
    """Whether the optional plotly dependency (the ``viewer`` extra) is installed."""
    try:
        import plotly  # noqa: F401
    except ImportError:
        return False
    return True


# -- geometry (pure functions) -------------------------------------------------------------
def feature_edges(
    vertices: np.ndarray, faces: np.ndarray, angle_deg: float = 30.0, max_edges: int = 20_000
) -> np.ndarray:
    """(E, 2, 3) edges of a mesh where it folds by more than ``angle_deg`` or is open.

    Args:
        vertices: (V, 3) vertex positions.
        faces: (F, 3) triangle indices.
        angle_deg: smallest angle between adjacent face normals that makes a crease.
        max_edges: keep at most this many, the longest first (a dense scan has many short
            creases; the long ones draw the room).
    """
    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
    creases = mesh.face_adjacency_edges[mesh.face_adjacency_angles > np.deg2rad(angle_deg)]
    # An edge used by one face only is a border of the mesh (an opening of a scan).
    edges = np.sort(mesh.edges, axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    indices = np.concatenate([creases.reshape(-1, 2), unique[counts == 1]], axis=0)
    segments = np.asarray(vertices, np.float64)[indices]
    if len(segments) > max_edges:
        lengths = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1)
        segments = segments[np.argsort(-lengths, kind="stable")[:max_edges]]
    return segments


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
    colours = _vertex_colours(mesh)
    if colours is not None:
        legacy.vertex_colors = o3d.utility.Vector3dVector(colours / 255.0)
    extent = float(np.max(mesh.bounds[1] - mesh.bounds[0]))
    # Faces scale with the inverse square of the cluster size: start from that estimate.
    spacing = float(np.median(mesh.edges_unique_length)) if len(mesh.faces) else extent
    cluster = max(spacing * np.sqrt(len(mesh.faces) / max_faces), 1e-4)
    while True:
        simple = legacy.simplify_vertex_clustering(cluster)
        if len(simple.triangles) <= max_faces or cluster > extent:
            break
        cluster *= 1.25
    vertex_colors = (
        (np.asarray(simple.vertex_colors) * 255).round().astype(np.uint8)
        if simple.has_vertex_colors()
        else None
    )
    return trimesh.Trimesh(
        np.asarray(simple.vertices),
        np.asarray(simple.triangles),
        vertex_colors=vertex_colors,
        process=False,
    )


def _vertex_colours(mesh: trimesh.Trimesh) -> np.ndarray | None:
    if getattr(mesh.visual, "kind", None) != "vertex":
        return None
    return np.asarray(mesh.visual.vertex_colors, np.float64)[:, :3]


def _segments_trace(go: Any, segments: np.ndarray, name: str, colour: str) -> Any:
    """A plotly line trace of (E, 2, 3) segments: plain lists, None between segments (plotly's
    line breaks), coordinates rounded to mm."""
    coordinates: tuple[list, list, list] = ([], [], [])
    for start, end in np.round(np.asarray(segments, np.float64), 3):
        for axis in range(3):
            coordinates[axis].extend((float(start[axis]), float(end[axis]), None))
    x, y, z = coordinates
    line = {"color": colour, "width": 2}
    return go.Scatter3d(x=x, y=y, z=z, mode="lines", name=name, line=line, hoverinfo="skip")


# -- the page ---------------------------------------------------------------------------------
def write_viewer(
    path: str | Path,
    mesh: trimesh.Trimesh,
    scene: Any,
    poses: np.ndarray,
    camera: PinholeCamera,
    goals: np.ndarray | None = None,
    title: str = "",
    max_faces: int = 120_000,
    frustums: int = 40,
    quiet: bool = False,
) -> Path | None:
    """Write the self-contained 3D page; None (with a message) when plotly is missing.

    Args:
        path: the HTML file to write.
        mesh: the reconstruction.
        scene: the ground truth (anything with ``vertices`` and ``faces``).
        poses: (N, 4, 4) camera-to-world poses of the episode.
        camera: the frames' intrinsics (for the frustums).
        goals: (G, 3) goals the policy chose.
        title: the page's title.
        max_faces: the reconstruction is simplified to at most this many triangles.
        frustums: how many cameras to draw, evenly over the episode (the last included).
        quiet: do not print the message when plotly is missing.
    """
    if not plotly_available():
        if not quiet:
            print(f"3D view skipped: plotly is not installed ({VIEWER_EXTRA_HINT})")
        return None
    import plotly.graph_objects as go

    poses = np.asarray(poses, np.float64).reshape(-1, 4, 4)
    traces = []
    shown = simplify_mesh(mesh, max_faces)
    if len(shown.faces):
        colours = _vertex_colours(shown)
        vertices = np.asarray(shown.vertices, np.float32)
        faces = np.asarray(shown.faces, np.int32)
        mesh_style: dict[str, Any] = (
            {"vertexcolor": [f"rgb({r},{g},{b})" for r, g, b in colours.astype(int)]}
            if colours is not None
            else {"color": "lightsteelblue"}
        )
        traces.append(
            go.Mesh3d(
                x=vertices[:, 0],
                y=vertices[:, 1],
                z=vertices[:, 2],
                i=faces[:, 0],
                j=faces[:, 1],
                k=faces[:, 2],
                name="reconstruction",
                showlegend=True,
                flatshading=False,
                lighting={"ambient": 0.6, "diffuse": 0.6, "specular": 0.05},
                hoverinfo="skip",
                **mesh_style,
            )
        )
    outline = feature_edges(scene.vertices, scene.faces)
    traces.append(_segments_trace(go, outline, "ground truth outline", "rgba(40,40,40,0.55)"))
    positions = np.round(poses[:, :3, 3], 4)
    traces.append(
        go.Scatter3d(
            x=positions[:, 0].tolist(),
            y=positions[:, 1].tolist(),
            z=positions[:, 2].tolist(),
            mode="lines",
            name="trajectory",
            line={"color": list(range(len(positions))), "colorscale": "Plasma", "width": 5},
            text=[f"step {step}" for step in range(len(positions))],
            hoverinfo="text",
        )
    )
    chosen = np.unique(np.linspace(0, len(poses) - 1, max(frustums, 1)).round().astype(int))
    cameras = frustum_segments(poses[chosen], camera)
    traces.append(_segments_trace(go, cameras, "camera frustums", "royalblue"))
    goals = np.asarray(goals if goals is not None else np.zeros((0, 3)), np.float64)
    goals = np.round(goals.reshape(-1, 3), 4)
    traces.append(
        go.Scatter3d(
            x=goals[:, 0].tolist(),
            y=goals[:, 1].tolist(),
            z=goals[:, 2].tolist(),
            mode="markers",
            name="goals",
            marker={"symbol": "diamond", "size": 5, "color": "gold"},
            text=[f"goal {index + 1}" for index in range(len(goals))],
            hoverinfo="text",
        )
    )
    figure = go.Figure(traces)
    figure.update_layout(
        title=title,
        margin={"l": 0, "r": 0, "t": 40, "b": 0},
        scene={
            "aspectmode": "data",
            "xaxis_title": "x (m)",
            "yaxis_title": "y (m)",
            "zaxis_title": "z (m)",
        },
        legend={"itemclick": "toggle"},
    )
    path = Path(path)
    # Plotly.js embedded, MathJax left out: the page opens without a network.
    figure.write_html(path, include_plotlyjs=True, include_mathjax=False, full_html=True)
    return path


def read_viewer(path: str | Path) -> dict[str, dict[str, Any]]:
    """The traces of a page written by :func:`write_viewer`, by name, arrays as numpy.

    Numeric arrays plotly stored base64-encoded (``{"dtype", "bdata"}``) come back decoded;
    line coordinates with breaks (None) come back as float arrays with NaN at the breaks.

    Raises:
        ValueError: the file holds no plotly figure.
    """
    text = Path(path).read_text(encoding="utf-8")
    match = re.search(r"Plotly\.newPlot\(\s*", text)
    if match is None:
        raise ValueError(f"{path} holds no plotly figure (no Plotly.newPlot call)")
    decoder = json.JSONDecoder()
    _, end = decoder.raw_decode(text, match.end())  # the div's id
    comma = re.compile(r"\s*,\s*").match(text, end)
    if comma is None:
        raise ValueError(f"{path}: unexpected text after the figure's div id")
    data, _ = decoder.raw_decode(text, comma.end())
    return {trace.get("name", str(index)): _decode(trace) for index, trace in enumerate(data)}


_DTYPES = {
    "f8": np.float64,
    "f4": np.float32,
    "i4": np.int32,
    "u4": np.uint32,
    "i2": np.int16,
    "u2": np.uint16,
    "i1": np.int8,
    "u1": np.uint8,
}


def _decode(value: Any) -> Any:
    if isinstance(value, dict) and "bdata" in value and "dtype" in value:
        array = np.frombuffer(base64.b64decode(value["bdata"]), dtype=_DTYPES[value["dtype"]])
        shape = value.get("shape")
        if shape:
            array = array.reshape([int(size) for size in str(shape).split(",")])
        return array
    if isinstance(value, dict):
        return {key: _decode(item) for key, item in value.items()}
    if (
        isinstance(value, list)
        and value
        and all(
            item is None or (isinstance(item, (int, float)) and not isinstance(item, bool))
            for item in value
        )
    ):
        return np.array([np.nan if item is None else item for item in value], np.float64)
    return value
