"""Read a recording back without a viewer: which entities it holds, at which steps, and the
last map, for tests and for anyone who wants the data (Rerun's chunk API, ``rerun.chunk``)."""

from __future__ import annotations

import re
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from naruto_agent.recording.recorder import MAP_ENTITY, TIMELINE

#: Rerun escapes spaces and signs in entity paths with a backslash; names come back as logged.
_UNESCAPE = re.compile(r"\\(.)")


@dataclass
class RecordingContents:
    """What a recording holds.

    Attributes:
        steps: entity path (without the leading ``/``) -> sorted steps at which it was
            logged (empty for static entities).
        columns: entity path -> the component columns logged at it (``Archetype:field``).
        map_vertices: (V, 3) vertices of the last map logged at ``world/map`` (None if none).
        map_faces: (F, 3) its triangles.
        chunks: how many chunks the file holds (Rerun warns of an unoptimized recording
            when there are many small ones).
    """

    steps: dict[str, list[int]] = field(default_factory=dict)
    columns: dict[str, set[str]] = field(default_factory=dict)
    map_vertices: np.ndarray | None = None
    map_faces: np.ndarray | None = None
    chunks: int = 0

    @property
    def entities(self) -> list[str]:
        """Every entity path, sorted."""
        return sorted(self.steps)


def read_recording(path: str | Path) -> RecordingContents:
    """The contents of a ``.rrd`` file written by :class:`EpisodeRecorder`.

    Raises:
        FileNotFoundError: no such file.
        ImportError: ``rerun-sdk`` is missing.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no recording at {path}")
    from rerun.chunk import RrdReader

    steps: dict[str, set[int]] = defaultdict(set)
    columns: dict[str, set[str]] = defaultdict(set)
    last_map: tuple[int, np.ndarray, np.ndarray] | None = None
    chunks = 0
    for chunk in RrdReader(str(path)).store().stream():
        chunks += 1
        entity = _UNESCAPE.sub(r"\1", chunk.entity_path.lstrip("/"))
        if entity.startswith("__"):  # the recording's own properties
            continue
        batch = chunk.to_record_batch()
        names = batch.schema.names
        columns[entity].update(name for name in names if ":" in name)
        chunk_steps = batch.column(TIMELINE).to_pylist() if TIMELINE in names else []
        steps[entity].update(int(step) for step in chunk_steps if step is not None)
        if entity == MAP_ENTITY and "Mesh3D:vertex_positions" in names:
            vertices = batch.column("Mesh3D:vertex_positions").to_pylist()
            faces = batch.column("Mesh3D:triangle_indices").to_pylist()
            for step, vertex_rows, face_rows in zip(chunk_steps, vertices, faces, strict=True):
                if vertex_rows is None or (last_map is not None and step < last_map[0]):
                    continue
                last_map = (
                    int(step),
                    np.asarray(vertex_rows, np.float32).reshape(-1, 3),
                    np.asarray(face_rows or [], np.int64).reshape(-1, 3),
                )
    contents = RecordingContents(
        steps={entity: sorted(found) for entity, found in steps.items()},
        columns=dict(columns),
        chunks=chunks,
    )
    if last_map is not None:
        contents.map_vertices, contents.map_faces = last_map[1], last_map[2]
    return contents
