"""A Rerun recording of one episode, to scrub through step by step (``episode.rrd``).

Entity paths (timeline ``step``; ``rerun FILE.rrd`` opens the file):

* ``world/camera``: the camera's pose and frustum (a pinhole), with ``world/camera/rgb``
  (JPEG) and ``world/camera/depth`` (millimetres) under it;
* ``world/trajectory``: the positions so far;
* ``world/map``: the map the agent holds, every few steps (simplified to a face budget);
* ``world/ground_truth``: the scene, once (static), when given;
* ``world/policy/<name>``: the 3D layers the policy shows of its thinking
  (:meth:`~naruto_agent.policies.Policy.view_layers`: targets, goals, planned paths);
* ``events/stalls``: every trigger of the policy's stall watchdog (step, kind, recovery),
  as a text log, and ``world/stalls``: where they happened;
* ``metrics/coverage (%)``, ``metrics/completion ratio (%)``,
  ``metrics/observable completion ratio (%)`` and ``policy/<name>``: time series.

Recording never changes the episode: it reads observations, infos, meshes and layers.
Needs ``rerun-sdk`` (the ``viewer`` extra).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from naruto_agent.policies.layers import (
    BoxesLayer,
    Layer,
    LinesLayer,
    PointsLayer,
    ScalarLayer,
    layer_names,
)
from naruto_agent.recording.live import RERUN_EXTRA_HINT, reach_viewer, rerun_available
from naruto_agent.recording.meshes import simplify_mesh, vertex_colours
from naruto_gym.sensors.pinhole import PinholeCamera

#: The timeline every entity is logged on.
TIMELINE = "step"
MAP_ENTITY = "world/map"
CAMERA_ENTITY = "world/camera"
COVERAGE_ENTITY = "metrics/coverage (%)"
COMPLETION_ENTITIES = {
    "completion_ratio_pct": "metrics/completion ratio (%)",
    "observable_completion_ratio_pct": "metrics/observable completion ratio (%)",
}


def entity_path(text: str) -> str:
    """A Rerun entity path of a ``/``-separated name whose parts may hold spaces and signs
    (each part escaped, so ``coverage (%)`` shows as written)."""
    from rerun import escape_entity_path_part

    return "/".join(escape_entity_path_part(part) for part in text.split("/"))


class EpisodeRecorder:
    """Writes one episode into a Rerun recording file and, optionally, a live viewer.

    Call :meth:`log_step` after reset (step 0) and after every step; :meth:`log_map`,
    :meth:`log_layers` and :meth:`log_scores` when there is something to show;
    :meth:`close` at the end.

    Args:
        path: the ``.rrd`` file to write (None: live only).
        camera: intrinsics of the frames.
        title: the recording's name in the viewer.
        live: ``"spawn"`` (start a local viewer), a viewer's address, or None.
        map_faces: a logged map is simplified to at most this many triangles.
        depth_every: log the depth image every this many steps (the RGB every step).
        jpeg_quality: quality of the RGB frames.

    Raises:
        ImportError: ``rerun-sdk`` is missing (the message says how to install it).
        naruto_agent.recording.LiveViewerError: ``live`` was asked and no viewer answers.
    """

    def __init__(
        self,
        path: str | Path | None,
        camera: PinholeCamera,
        title: str = "naruto-gym episode",
        live: str | None = None,
        map_faces: int = 30_000,
        depth_every: int = 5,
        jpeg_quality: int = 80,
    ) -> None:
        if not rerun_available():
            raise ImportError(f"recording an episode needs rerun-sdk: {RERUN_EXTRA_HINT}")
        if path is None and not live:
            raise ValueError("give a recording file, a live viewer, or both")
        if depth_every < 1 or map_faces < 1:
            raise ValueError("depth_every and map_faces must be at least 1")
        import rerun as rr

        self._rr = rr
        sinks = []
        url = reach_viewer(live) if live else None
        self.path = None if path is None else Path(path)
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            sinks.append(rr.FileSink(str(self.path)))
        if url is not None:
            sinks.append(rr.GrpcSink(url))
        self.stream = rr.RecordingStream("naruto-gym", send_properties=False)
        self.stream.set_sinks(*sinks)
        self.stream.send_recording_name(title)
        self.camera = camera
        self.map_faces = map_faces
        self.depth_every = depth_every
        self.jpeg_quality = jpeg_quality
        self.positions: list[np.ndarray] = []
        self.steps_logged = 0
        self._shown_layers: set[str] = set()
        self._stalls_logged = 0
        self.stream.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)

    def _at(self, step: int) -> None:
        self.stream.set_time(TIMELINE, sequence=int(step))

    def log_scene(self, scene: Any, max_faces: int = 60_000) -> None:
        """The ground truth (anything with ``vertices`` and ``faces``), once (static), pale
        grey, simplified to ``max_faces`` triangles."""
        mesh = trimesh.Trimesh(np.asarray(scene.vertices), np.asarray(scene.faces), process=False)
        simple = simplify_mesh(mesh, max_faces)
        self.stream.log(
            "world/ground_truth",
            self._rr.Mesh3D(
                vertex_positions=np.asarray(simple.vertices, np.float32),
                triangle_indices=np.asarray(simple.faces, np.uint32),
                albedo_factor=[0.75, 0.75, 0.78, 0.35],
            ),
            static=True,
        )

    def log_step(self, step: int, observation: dict[str, Any], info: dict[str, Any]) -> None:
        """The camera (pose, frustum, frames), the trajectory and the coverage at ``step``."""
        rr = self._rr
        self._at(step)
        pose = np.asarray(observation["pose"], np.float64)
        camera = self.camera
        self.stream.log(
            CAMERA_ENTITY,
            rr.Transform3D(translation=pose[:3, 3], mat3x3=pose[:3, :3]),
            rr.Pinhole(
                focal_length=[camera.fx, camera.fy],
                principal_point=[camera.cx, camera.cy],
                resolution=[camera.width, camera.height],
                camera_xyz=rr.ViewCoordinates.RDF,
                image_plane_distance=0.25,
            ),
        )
        if "rgb" in observation:
            image = rr.Image(np.asarray(observation["rgb"], np.uint8))
            self.stream.log(f"{CAMERA_ENTITY}/rgb", image.compress(jpeg_quality=self.jpeg_quality))
        if "depth" in observation and step % self.depth_every == 0:
            millimetres = np.clip(np.asarray(observation["depth"]) * 1000.0, 0, 65535)
            self.stream.log(
                f"{CAMERA_ENTITY}/depth",
                rr.DepthImage(millimetres.astype(np.uint16), meter=1000.0),
            )
        self.positions.append(pose[:3, 3].astype(np.float32))
        if len(self.positions) > 1:
            self.stream.log(
                "world/trajectory",
                rr.LineStrips3D([np.stack(self.positions)], colors=[[230, 40, 40]], radii=0.01),
            )
        if "coverage" in info:
            coverage = 100.0 * float(info["coverage"])
            self.stream.log(entity_path(COVERAGE_ENTITY), rr.Scalars(coverage))
        self.steps_logged += 1

    def log_map(self, step: int, mesh: trimesh.Trimesh) -> None:
        """The agent's map at ``step`` (simplified to :attr:`map_faces` triangles)."""
        self._at(step)
        if len(mesh.faces) == 0:
            self.stream.log(MAP_ENTITY, self._rr.Clear(recursive=False))
            return
        simple = simplify_mesh(mesh, self.map_faces)
        colours = vertex_colours(simple)
        self.stream.log(
            MAP_ENTITY,
            self._rr.Mesh3D(
                vertex_positions=np.asarray(simple.vertices, np.float32),
                triangle_indices=np.asarray(simple.faces, np.uint32),
                vertex_colors=None if colours is None else colours.astype(np.uint8),
            ),
        )

    def log_layers(self, step: int, layers: list[Layer]) -> None:
        """A policy's layers at ``step``; a layer it showed before and not now is cleared."""
        rr = self._rr
        self._at(step)
        names = set(layer_names(layers))
        for name in sorted(self._shown_layers - names):
            self.stream.log(entity_path(f"world/policy/{name}"), rr.Clear(recursive=False))
        for layer in layers:
            if isinstance(layer, ScalarLayer):
                self.stream.log(entity_path(f"policy/{layer.name}"), rr.Scalars(layer.value))
                names.discard(layer.name)
                continue
            entity = entity_path(f"world/policy/{layer.name}")
            if isinstance(layer, PointsLayer):
                colours = layer.colours if layer.colours is not None else [layer.colour]
                self.stream.log(entity, rr.Points3D(layer.points, colors=colours,
                                                    radii=layer.radius_m))
            elif isinstance(layer, LinesLayer):
                strips = [strip for strip in layer.strips if len(strip) > 1]
                self.stream.log(entity, rr.LineStrips3D(strips, colors=[layer.colour],
                                                        radii=layer.width_m / 2))
            elif isinstance(layer, BoxesLayer):
                self.stream.log(entity, rr.Boxes3D(centers=layer.centres,
                                                   half_sizes=layer.half_sizes,
                                                   colors=[layer.colour]))
            else:
                raise TypeError(f"not a layer of naruto_agent.policies.layers: {layer!r}")
        self._shown_layers = names

    def log_policy(self, step: int, policy: Any) -> None:
        """:meth:`log_layers` of what ``policy.view_layers()`` returns (nothing when the
        policy has no such method)."""
        view_layers: Callable[[], list[Layer]] | None = getattr(policy, "view_layers", None)
        if callable(view_layers):
            self.log_layers(step, list(view_layers()))

    def log_stalls(self, step: int, policy: Any) -> None:
        """The stall watchdog's triggers ``policy.stall_events`` holds that are not logged
        yet: a text line each, and their places (nothing when the policy has none)."""
        events = list(getattr(policy, "stall_events", []) or [])
        if len(events) < self._stalls_logged:
            self._stalls_logged = 0  # a new episode
        if len(events) == self._stalls_logged:
            return
        rr = self._rr
        self._at(step)
        for event in events[self._stalls_logged:]:
            self.stream.log("events/stalls", rr.TextLog(
                f"step {event.step}: stall ({event.kind}) -> {event.recovery}", level="WARN"))
        places = np.array([event.position for event in events], np.float32)
        self.stream.log("world/stalls", rr.Points3D(places, colors=[[255, 140, 0]], radii=0.06))
        self._stalls_logged = len(events)

    def observe(self, step: int, observation: dict[str, Any], info: dict[str, Any],
                policy: Any = None, map_mesh: Callable[[], trimesh.Trimesh] | None = None,
                map_every: int = 50, last: bool = False) -> None:
        """One step in full: :meth:`log_step`, the policy's layers, and the map from
        ``map_mesh()`` every ``map_every`` steps and at the ``last``."""
        self.log_step(step, observation, info)
        if policy is not None:
            self.log_policy(step, policy)
            self.log_stalls(step, policy)
        if map_mesh is not None and (last or (map_every > 0 and step % map_every == 0)):
            self.log_map(step, map_mesh())

    def log_scores(self, step: int, scores: dict[str, Any] | None) -> None:
        """The completion ratios of a checkpoint's scores (those that are not None)."""
        self._at(step)
        for key, entity in COMPLETION_ENTITIES.items():
            value = (scores or {}).get(key)
            if value is not None:
                self.stream.log(entity_path(entity), self._rr.Scalars(float(value)))

    def close(self) -> None:
        """Flush everything to the file and the viewer and close the recording."""
        self.stream.flush()
        self.stream.disconnect()
