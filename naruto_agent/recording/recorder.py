"""A Rerun recording of one episode, to scrub through step by step (``episode.rrd``).

Entity paths (timeline ``step``; ``rerun FILE.rrd`` opens the file):

* ``world/camera``: the camera's pose and frustum (a pinhole), with ``world/camera/rgb``
  (JPEG) and ``world/camera/depth`` (millimetres, a lossless 16-bit PNG) under it;
* ``world/trajectory``: the positions so far, every few steps and at the end;
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

A recording is kept compact: a file-only recording is batched into large chunks (Rerun's
micro-batching, flushed by size rather than every few hundred milliseconds), a policy layer
is logged again only when it changed (the viewer shows the latest one), the depth frames are
PNG-encoded, and the trajectory is logged every few steps rather than growing at each.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
from collections.abc import Callable
from datetime import timedelta
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from PIL import Image

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
#: Micro-batching of a file-only recording: a chunk per entity per 4 MiB logged, not one per
#: 200 ms (Rerun's default), so a 1000-step episode is a few hundred chunks, not thousands.
FILE_FLUSH_BYTES = 4 * 2**20
FILE_FLUSH_TICK = timedelta(seconds=60)
COMPLETION_ENTITIES = {
    "completion_ratio_pct": "metrics/completion ratio (%)",
    "observable_completion_ratio_pct": "metrics/observable completion ratio (%)",
}


def entity_path(text: str) -> str:
    """A Rerun entity path of a ``/``-separated name whose parts may hold spaces and signs
    (each part escaped, so ``coverage (%)`` shows as written)."""
    from rerun import escape_entity_path_part

    return "/".join(escape_entity_path_part(part) for part in text.split("/"))


def depth_png(depth: np.ndarray) -> Any:
    """A depth frame in metres as a Rerun encoded depth image: millimetres in a 16-bit PNG
    (lossless, about a fifth of the raw frame's size)."""
    from rerun import EncodedDepthImage

    millimetres = np.clip(np.asarray(depth, np.float64) * 1000.0, 0, 65535).astype(np.uint16)
    buffer = io.BytesIO()
    Image.fromarray(millimetres).save(buffer, format="PNG")
    # No ``meter``: the viewer reads integer depth as millimetres.
    return EncodedDepthImage(buffer.getvalue(), media_type="image/png")


def layer_digest(layer: Layer) -> str:
    """A digest of everything a layer draws (name, kind, arrays, colours, sizes)."""
    hasher = hashlib.sha1(type(layer).__name__.encode())
    for value in (getattr(layer, item.name) for item in dataclasses.fields(layer)):
        if isinstance(value, (list, tuple)) and value and isinstance(value[0], np.ndarray):
            for array in value:
                hasher.update(np.ascontiguousarray(array).tobytes())
                hasher.update(str(np.shape(array)).encode())
        elif isinstance(value, np.ndarray):
            hasher.update(np.ascontiguousarray(value).tobytes())
            hasher.update(str(value.shape).encode())
        else:
            hasher.update(repr(value).encode())
    return hasher.hexdigest()


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
        trajectory_every: log the trajectory so far every this many steps (and at
            :meth:`close`); each log holds every position, so logging it at every step
            would grow the file with the square of the episode's length.
        layers_every: :meth:`log_policy` logs the policy's 3D layers every this many steps
            and at the last (its scalars every step); a frontier of a few thousand points
            logged at every step would be most of the file.

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
        map_faces: int = 15_000,
        depth_every: int = 10,
        jpeg_quality: int = 60,
        trajectory_every: int = 10,
        layers_every: int = 10,
    ) -> None:
        if not rerun_available():
            raise ImportError(f"recording an episode needs rerun-sdk: {RERUN_EXTRA_HINT}")
        if path is None and not live:
            raise ValueError("give a recording file, a live viewer, or both")
        if min(depth_every, map_faces, trajectory_every, layers_every) < 1:
            raise ValueError(
                "depth_every, map_faces, trajectory_every and layers_every must be at least 1"
            )
        if not 1 <= jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be in 1..100, got {jpeg_quality}")
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
        # Streaming to a viewer keeps Rerun's low-latency batching; a file alone is batched
        # by size, which is what makes it compact.
        batcher = None
        if url is None:
            batcher = rr.ChunkBatcherConfig(
                flush_tick=FILE_FLUSH_TICK, flush_num_bytes=FILE_FLUSH_BYTES
            )
        self.stream = rr.RecordingStream(
            "naruto-gym", send_properties=False, batcher_config=batcher
        )
        self.stream.set_sinks(*sinks)
        self.stream.send_recording_name(title)
        self.camera = camera
        self.map_faces = map_faces
        self.depth_every = depth_every
        self.jpeg_quality = jpeg_quality
        self.trajectory_every = trajectory_every
        self.layers_every = layers_every
        self.positions: list[np.ndarray] = []
        self.steps_logged = 0
        self._shown_layers: set[str] = set()
        self._layer_digests: dict[str, str] = {}
        self._trajectory_logged = 0
        self._last_step = 0
        self._stalls_logged = 0
        self.stream.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        # The intrinsics do not change over the episode: the frustum is logged once.
        self.stream.log(
            CAMERA_ENTITY,
            rr.Pinhole(
                focal_length=[camera.fx, camera.fy],
                principal_point=[camera.cx, camera.cy],
                resolution=[camera.width, camera.height],
                camera_xyz=rr.ViewCoordinates.RDF,
                image_plane_distance=0.25,
            ),
            static=True,
        )

    def _at(self, step: int) -> None:
        self._last_step = max(self._last_step, int(step))
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
        self.stream.log(CAMERA_ENTITY, rr.Transform3D(translation=pose[:3, 3], mat3x3=pose[:3, :3]))
        if "rgb" in observation:
            image = rr.Image(np.asarray(observation["rgb"], np.uint8))
            self.stream.log(f"{CAMERA_ENTITY}/rgb", image.compress(jpeg_quality=self.jpeg_quality))
        if "depth" in observation and step % self.depth_every == 0:
            self.stream.log(f"{CAMERA_ENTITY}/depth", depth_png(observation["depth"]))
        self.positions.append(pose[:3, 3].astype(np.float32))
        if step % self.trajectory_every == 0:
            self._log_trajectory()
        if "coverage" in info:
            coverage = 100.0 * float(info["coverage"])
            self.stream.log(entity_path(COVERAGE_ENTITY), rr.Scalars(coverage))
        self.steps_logged += 1

    def _log_trajectory(self) -> None:
        """The positions so far as one line (nothing before there are two)."""
        if len(self.positions) > 1 and len(self.positions) != self._trajectory_logged:
            self.stream.log(
                "world/trajectory",
                self._rr.LineStrips3D(
                    [np.stack(self.positions)], colors=[[230, 40, 40]], radii=0.01
                ),
            )
            self._trajectory_logged = len(self.positions)

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
            self._layer_digests.pop(name, None)
        for layer in layers:
            if not isinstance(layer, ScalarLayer):
                # The viewer shows the latest logged value: an unchanged layer is not logged.
                digest = layer_digest(layer)
                if self._layer_digests.get(layer.name) == digest:
                    continue
                self._layer_digests[layer.name] = digest
            if isinstance(layer, ScalarLayer):
                self.stream.log(entity_path(f"policy/{layer.name}"), rr.Scalars(layer.value))
                names.discard(layer.name)
                continue
            entity = entity_path(f"world/policy/{layer.name}")
            if isinstance(layer, PointsLayer):
                colours = layer.colours if layer.colours is not None else [layer.colour]
                self.stream.log(
                    entity, rr.Points3D(layer.points, colors=colours, radii=layer.radius_m)
                )
            elif isinstance(layer, LinesLayer):
                strips = [strip for strip in layer.strips if len(strip) > 1]
                self.stream.log(
                    entity, rr.LineStrips3D(strips, colors=[layer.colour], radii=layer.width_m / 2)
                )
            elif isinstance(layer, BoxesLayer):
                self.stream.log(
                    entity,
                    rr.Boxes3D(
                        centers=layer.centres, half_sizes=layer.half_sizes, colors=[layer.colour]
                    ),
                )
            else:
                raise TypeError(f"not a layer of naruto_agent.policies.layers: {layer!r}")
        self._shown_layers = names

    def log_policy(self, step: int, policy: Any, last: bool = False) -> None:
        """:meth:`log_layers` of what ``policy.view_layers()`` returns (nothing when the
        policy has no such method) every :attr:`layers_every` steps and at the ``last``;
        between them only its scalar layers."""
        view_layers: Callable[[], list[Layer]] | None = getattr(policy, "view_layers", None)
        if not callable(view_layers):
            return
        layers = list(view_layers())
        if last or step % self.layers_every == 0:
            self.log_layers(step, layers)
            return
        self._at(step)
        for layer in layers:
            if isinstance(layer, ScalarLayer):
                self.stream.log(entity_path(f"policy/{layer.name}"), self._rr.Scalars(layer.value))

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

    def observe(
        self,
        step: int,
        observation: dict[str, Any],
        info: dict[str, Any],
        policy: Any = None,
        map_mesh: Callable[[], trimesh.Trimesh] | None = None,
        map_every: int = 50,
        last: bool = False,
    ) -> None:
        """One step in full: :meth:`log_step`, the policy's layers, and the map from
        ``map_mesh()`` every ``map_every`` steps and at the ``last``."""
        self.log_step(step, observation, info)
        if policy is not None:
            self.log_policy(step, policy, last)
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
        """Log the whole trajectory at the last step, flush everything to the file and the
        viewer and close the recording."""
        self._at(self._last_step)
        self._log_trajectory()
        self.stream.flush()
        self.stream.disconnect()
