"""A 3D view of the episode to open in a browser and turn: ``viewer.html``.

One self-contained page (plotly.js embedded, gzip-packed and unpacked by the browser, so
nothing is fetched when it opens and the default scene's page stays under 5 MB) with

* ``reconstruction``: the episode's mesh in its own colours, simplified to at most
  ``max_faces`` triangles, cut away above 80 % of the scene's height (the ceiling);
* ``walls near the camera``: the walls between the first view's camera and the room, faded,
  so that the inside shows (a click on the legend hides or shows them);
* ``ground truth outline``: the ground-truth mesh's feature edges (creases sharper than 30
  degrees and open borders), the longest first when there are too many;
* ``trajectory``: the camera positions, coloured by step;
* ``camera frustums``: every n-th camera as a small pyramid;
* ``goals``: the goals the policy chose;
* ``camera at step``: the camera at the step a slider under the view picks.

The first view looks from inside the scene, from a high corner across the trajectory, so the
path, the cameras and the goals show at once. It needs plotly (the ``viewer`` extra:
``pip install "naruto-gym[viewer]"``); :func:`write_viewer` says so and writes nothing when it
is missing. :func:`read_viewer` reads the traces back from a page, for tests and for anyone who
wants the data without a browser. The page needs a browser with ``DecompressionStream``
(Chrome 80, Firefox 113, Safari 16.4 or later).
"""

from __future__ import annotations

import base64
import gzip
import html
import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from naruto_agent.recording.meshes import frustum_segments, simplify_mesh, vertex_colours
from naruto_gym.sensors.pinhole import PinholeCamera

__all__ = [
    "TRACE_NAMES",
    "cut_away",
    "feature_edges",
    "first_view",
    "frustum_segments",
    "plotly_available",
    "read_viewer",
    "simplify_mesh",
    "write_viewer",
]

VIEWER_EXTRA_HINT = 'pip install "naruto-gym[viewer]"'
#: Trace names of the page, in drawing order.
TRACE_NAMES = (
    "reconstruction",
    "walls near the camera",
    "ground truth outline",
    "trajectory",
    "camera frustums",
    "goals",
    "camera at step",
)
#: The reconstruction is cut away above this share of the scene's height (the ceiling).
CUT_HEIGHT = 0.8
#: Faces this close to a wall plane of the scene's box near the first camera are faded.
WALL_BAND_M = 0.3
#: Positions of the step slider at most (the last step always one of them).
SLIDER_STEPS = 60
_FIGURE_ID = "naruto-figure"
_PLOTLY_ID = "plotly-gzip"


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


def first_view(bounds: np.ndarray, positions: np.ndarray) -> dict[str, np.ndarray]:
    """Where the first view's camera stands and what it looks at, in world metres.

    The camera stands inside the scene's box, high (just under the cut height), in the
    corner farthest from the trajectory's centre, and looks at that centre a little below,
    so the path lies in front of it.

    Args:
        bounds: (2, 3) scene box.
        positions: (N, 3) camera positions of the episode.

    Returns:
        ``eye`` and ``centre`` (3,) world points, and ``corner`` (2,) the signs (-1 or +1)
        of the box corner the eye stands in, along x and y.
    """
    bounds = np.asarray(bounds, np.float64)
    middle = bounds.mean(axis=0)
    extent = bounds[1] - bounds[0]
    target = np.asarray(positions, np.float64).reshape(-1, 3).mean(axis=0) if len(positions) \
        else middle
    corners = np.array([[sx, sy] for sx in (-1.0, 1.0) for sy in (-1.0, 1.0)])
    corner_xy = middle[:2] + 0.5 * corners * extent[:2]
    corner = corners[np.argmax(np.linalg.norm(corner_xy - target[:2], axis=1))]
    eye = middle.copy()
    eye[:2] += corner * 0.5 * extent[:2] * 0.85
    eye[2] = bounds[0, 2] + (CUT_HEIGHT - 0.05) * extent[2]
    centre = target.copy()
    centre[2] = bounds[0, 2] + 0.3 * extent[2]
    return {"eye": eye, "centre": centre, "corner": corner}


def cut_away(mesh: trimesh.Trimesh, bounds: np.ndarray,
             corner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(F,) bool masks of the faces to show and of those to fade.

    Faces wholly above :data:`CUT_HEIGHT` of the box's height are dropped (the ceiling);
    upright faces within :data:`WALL_BAND_M` of the two wall planes of the box that meet in
    ``corner`` (the first camera's corner) are faded; the rest are shown.

    Args:
        mesh: the reconstruction.
        bounds: (2, 3) scene box.
        corner: (2,) signs of the camera's corner along x and y (see :func:`first_view`).
    """
    bounds = np.asarray(bounds, np.float64)
    faces = np.asarray(mesh.faces)
    if not len(faces):
        return np.zeros(0, bool), np.zeros(0, bool)
    triangles = np.asarray(mesh.vertices, np.float64)[faces]
    top = bounds[0, 2] + CUT_HEIGHT * (bounds[1, 2] - bounds[0, 2])
    kept = triangles[:, :, 2].min(axis=1) <= top
    centres = triangles.mean(axis=1)
    upright = np.abs(np.asarray(mesh.face_normals)[:, 2]) < 0.5
    near_wall = np.zeros(len(faces), bool)
    for axis in (0, 1):
        plane = bounds[1 if corner[axis] > 0 else 0, axis]
        near_wall |= np.abs(centres[:, axis] - plane) < WALL_BAND_M
    faded = kept & upright & near_wall
    return kept & ~faded, faded


def _mesh_trace(go: Any, mesh: trimesh.Trimesh, mask: np.ndarray, name: str,
                opacity: float) -> Any:
    """A plotly Mesh3d of the faces of ``mask``: float32 vertices, uint16 indices where they
    fit, 12-bit hex vertex colours (compact in the page)."""
    faces = np.asarray(mesh.faces)[mask]
    used, inverse = np.unique(faces.reshape(-1), return_inverse=True)
    faces = inverse.reshape(-1, 3)
    vertices = np.asarray(mesh.vertices, np.float32)[used]
    index_type = np.uint16 if len(used) < 65536 else np.uint32
    colours = vertex_colours(mesh)
    style: dict[str, Any] = {"color": "lightsteelblue"}
    if colours is not None:
        nibbles = np.clip(np.round(colours[used] / 17.0), 0, 15).astype(int)
        style = {"vertexcolor": [f"#{r:x}{g:x}{b:x}" for r, g, b in nibbles]}
    return go.Mesh3d(
        x=vertices[:, 0], y=vertices[:, 1], z=vertices[:, 2],
        i=faces[:, 0].astype(index_type), j=faces[:, 1].astype(index_type),
        k=faces[:, 2].astype(index_type),
        name=name, showlegend=True, opacity=opacity, flatshading=False,
        lighting={"ambient": 0.6, "diffuse": 0.6, "specular": 0.05}, hoverinfo="skip",
        **style,
    )


def _segments_trace(go: Any, segments: np.ndarray, name: str, colour: str,
                    width: int = 2) -> Any:
    """A plotly line trace of (E, 2, 3) segments: plain lists, None between segments (plotly's
    line breaks), coordinates rounded to cm."""
    coordinates: tuple[list, list, list] = ([], [], [])
    for start, end in np.round(np.asarray(segments, np.float64), 2):
        for axis in range(3):
            coordinates[axis].extend((float(start[axis]), float(end[axis]), None))
    x, y, z = coordinates
    line = {"color": colour, "width": width}
    return go.Scatter3d(x=x, y=y, z=z, mode="lines", name=name, line=line, hoverinfo="skip")


def _normalised(point: np.ndarray, bounds: np.ndarray) -> dict[str, float]:
    """A world point in plotly's scene coordinates (the box's centre at 0, its longest side
    1 long, as the manual aspect ratio of :func:`write_viewer` sets)."""
    middle = bounds.mean(axis=0)
    scale = float(np.max(bounds[1] - bounds[0]))
    x, y, z = (np.asarray(point, np.float64) - middle) / scale
    return {"x": float(x), "y": float(y), "z": float(z)}


# -- the page ---------------------------------------------------------------------------------
def write_viewer(
    path: str | Path,
    mesh: trimesh.Trimesh,
    scene: Any,
    poses: np.ndarray,
    camera: PinholeCamera,
    goals: np.ndarray | None = None,
    title: str = "",
    max_faces: int = 40_000,
    frustums: int = 40,
    quiet: bool = False,
) -> Path | None:
    """Write the self-contained 3D page; None (with a message) when plotly is missing.

    Args:
        path: the HTML file to write.
        mesh: the reconstruction.
        scene: the ground truth (anything with ``vertices``, ``faces`` and ``bounds``).
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
    positions = poses[:, :3, 3]
    bounds = np.asarray(getattr(scene, "bounds", None) if hasattr(scene, "bounds") else
                        [np.min(scene.vertices, 0), np.max(scene.vertices, 0)], np.float64)
    view = first_view(bounds, positions)
    shown = simplify_mesh(mesh, max_faces)
    solid, faded = cut_away(shown, bounds, view["corner"])
    traces = [
        _mesh_trace(go, shown, solid, "reconstruction", 1.0),
        _mesh_trace(go, shown, faded, "walls near the camera", 0.15),
    ]
    outline = feature_edges(scene.vertices, scene.faces, max_edges=3000)
    traces.append(_segments_trace(go, outline, "ground truth outline", "rgba(40,40,40,0.45)"))
    rounded = np.round(positions, 3)
    traces.append(
        go.Scatter3d(
            x=rounded[:, 0].tolist(), y=rounded[:, 1].tolist(), z=rounded[:, 2].tolist(),
            mode="lines", name="trajectory",
            line={"color": list(range(len(rounded))), "colorscale": "Plasma", "width": 6},
            text=[f"step {step}" for step in range(len(rounded))], hoverinfo="text",
        )
    )
    chosen = np.unique(np.linspace(0, len(poses) - 1, max(frustums, 1)).round().astype(int))
    traces.append(_segments_trace(go, frustum_segments(poses[chosen], camera),
                                  "camera frustums", "royalblue"))
    goals = np.asarray(goals if goals is not None else np.zeros((0, 3)), np.float64)
    goals = np.round(goals.reshape(-1, 3), 3)
    traces.append(
        go.Scatter3d(
            x=goals[:, 0].tolist(), y=goals[:, 1].tolist(), z=goals[:, 2].tolist(),
            mode="markers", name="goals",
            marker={"symbol": "diamond", "size": 6, "color": "gold",
                    "line": {"color": "black", "width": 1}},
            text=[f"goal {index + 1}" for index in range(len(goals))], hoverinfo="text",
        )
    )
    steps = np.unique(np.linspace(0, len(poses) - 1, min(SLIDER_STEPS, len(poses)))
                      .round().astype(int))
    current = len(traces)
    traces.append(_step_trace(go, poses, camera, int(steps[-1])))
    frames = [go.Frame(name=str(step), data=[_step_trace(go, poses, camera, int(step))],
                       traces=[current]) for step in steps]
    figure = go.Figure(traces, frames=frames)
    extent = bounds[1] - bounds[0]
    ratio = extent / float(np.max(extent))
    axis = {"showbackground": False, "showgrid": False, "zeroline": False}
    figure.update_layout(
        title=title,
        margin={"l": 0, "r": 0, "t": 40, "b": 0},
        paper_bgcolor="white",
        scene={
            "aspectmode": "manual",
            "aspectratio": {"x": float(ratio[0]), "y": float(ratio[1]), "z": float(ratio[2])},
            "xaxis": {**axis, "range": [float(bounds[0, 0]), float(bounds[1, 0])],
                      "title": "x (m)"},
            "yaxis": {**axis, "range": [float(bounds[0, 1]), float(bounds[1, 1])],
                      "title": "y (m)"},
            "zaxis": {**axis, "range": [float(bounds[0, 2]), float(bounds[1, 2])],
                      "title": "z (m)"},
            "camera": {
                "eye": _normalised(view["eye"], bounds),
                "center": _normalised(view["centre"], bounds),
                "up": {"x": 0.0, "y": 0.0, "z": 1.0},
                "projection": {"type": "perspective"},
            },
        },
        legend={"itemclick": "toggle", "x": 0.0, "y": 0.98, "bgcolor": "rgba(255,255,255,0.7)"},
        sliders=[{
            "active": len(steps) - 1,
            "currentvalue": {"prefix": "camera at step "},
            "pad": {"t": 10, "b": 10},
            "steps": [
                {"label": str(step), "method": "animate",
                 "args": [[str(step)], {"mode": "immediate", "frame": {"duration": 0,
                                                                       "redraw": True},
                                        "transition": {"duration": 0}}]}
                for step in steps
            ],
        }],
    )
    path = Path(path)
    path.write_text(_page(figure, title), encoding="utf-8")
    return path


def _step_trace(go: Any, poses: np.ndarray, camera: PinholeCamera, step: int) -> Any:
    """The camera of one step: a larger frustum, for the slider."""
    segments = frustum_segments(poses[step][None], camera, depth_m=0.4)
    trace = _segments_trace(go, segments, "camera at step", "crimson", width=6)
    trace.update(text=[f"step {step}"] * len(trace.x), hoverinfo="text")
    return trace


def _plotly_js() -> str:
    """plotly.js as shipped with plotly.py, gzip-compressed and base64-encoded."""
    import plotly

    source = Path(os.path.dirname(plotly.__file__), "package_data", "plotly.min.js")
    return base64.b64encode(gzip.compress(source.read_bytes(), 9, mtime=0)).decode("ascii")


_LOADER = """
(async function () {
  var status = document.getElementById("status");
  try {
    var packed = document.getElementById("%(plotly)s").textContent.trim();
    var bytes = Uint8Array.from(atob(packed), function (c) { return c.charCodeAt(0); });
    var stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream("gzip"));
    var source = await new Response(stream).text();
    var script = document.createElement("script");
    script.textContent = source;
    document.head.appendChild(script);
    var figure = JSON.parse(document.getElementById("%(figure)s").textContent);
    figure.config = {responsive: true, displaylogo: false};
    await Plotly.newPlot("view", figure);
    status.remove();
    document.body.setAttribute("data-rendered", "yes");
  } catch (error) {
    status.textContent = "The 3D view could not be shown (" + error + "). It needs a browser " +
      "with DecompressionStream: Chrome 80, Firefox 113, Safari 16.4 or later.";
  }
})();
"""


def _page(figure: Any, title: str) -> str:
    """The HTML page: the figure as JSON, plotly.js packed, and the loader that joins them."""
    import plotly.io as pio

    data = pio.to_json(figure, validate=False, engine="json").replace("</", "<\\/")
    loader = _LOADER % {"plotly": _PLOTLY_ID, "figure": _FIGURE_ID}
    return (
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\">"
        f"<title>{html.escape(title or 'naruto-gym episode')}</title>"
        "<style>html,body{margin:0;height:100%;font-family:sans-serif}"
        "#view{width:100%;height:100%}#status{position:absolute;top:12px;left:12px}</style>"
        "</head><body><div id=\"status\">Loading the 3D view...</div><div id=\"view\"></div>\n"
        f"<script type=\"application/json\" id=\"{_FIGURE_ID}\">{data}</script>\n"
        f"<script type=\"application/octet-stream\" id=\"{_PLOTLY_ID}\">{_plotly_js()}</script>\n"
        f"<script>{loader}</script>\n</body></html>\n"
    )


def read_viewer(path: str | Path) -> dict[str, dict[str, Any]]:
    """The traces of a page written by :func:`write_viewer`, by name, arrays as numpy.

    Numeric arrays plotly stored base64-encoded (``{"dtype", "bdata"}``) come back decoded;
    line coordinates with breaks (None) come back as float arrays with NaN at the breaks.
    The slider's frames come back under the key ``"frames"`` (a list of ``(name, traces)``).

    Raises:
        ValueError: the file holds no figure of this module.
    """
    figure = read_figure(path)
    traces = {trace.get("name", str(index)): _decode(trace)
              for index, trace in enumerate(figure.get("data", []))}
    return traces


def read_figure(path: str | Path) -> dict[str, Any]:
    """The whole figure of a page (``data``, ``layout``, ``frames``) as plotly JSON.

    Raises:
        ValueError: the file holds no figure of this module.
    """
    text = Path(path).read_text(encoding="utf-8")
    marker = f'id="{_FIGURE_ID}">'
    start = text.find(marker)
    if start < 0:
        raise ValueError(f"{path} holds no plotly figure (no {_FIGURE_ID} block)")
    start += len(marker)
    end = text.find("</script>", start)
    return json.loads(text[start:end])


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
