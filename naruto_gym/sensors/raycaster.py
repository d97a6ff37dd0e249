"""Where every ray is cast: one small interface over Embree.

Two backends implement :class:`RayCaster`:

* ``"open3d"`` (default): Open3D's ``RaycastingScene`` (Embree inside); it casts a full
  680 x 1200 frame about twice as fast as embreex (docs/benchmarks/rendering.md), so it is
  the default.
* ``"embreex"``: the embreex binding, kept behind the same interface for comparison
  (``pip install naruto-gym[embreex]``).

Distances returned by :meth:`RayCaster.cast` are in units of the direction vector's length:
pass unit directions for metres, or camera-frame directions with ``z = 1`` for z-depth.

Both backends hold native objects that cannot be pickled or shared across ``fork``; the
caster pickles itself as its triangles and rebuilds the native scene on unpickling, so an
env can be sent to a ``spawn`` worker.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Literal

import numpy as np

from naruto_gym.geometry.sweep_kernels import first_blocked_sample, sweep_step_count
from naruto_gym.utils.fork_safety import enter_native_code
from naruto_gym.utils.threads import default_thread_count

RayCasterBackend = Literal["open3d", "embreex"]
#: The ray-casting backends ``RayCaster`` takes.
RAYCASTER_BACKENDS: tuple[str, ...] = ("open3d", "embreex")


@dataclass(frozen=True)
class RayHits:
    """Result of casting N rays.

    Attributes:
        distance: (N,) float32 ray parameter of the first hit, ``inf`` where nothing was hit.
        triangle_ids: (N,) int32 index of the hit triangle, -1 where nothing was hit.
        barycentric_uv: (N, 2) float32 barycentric coordinates (u, v) of the hit inside its
            triangle: point = (1 - u - v) * v0 + u * v1 + v * v2.
    """

    distance: np.ndarray
    triangle_ids: np.ndarray
    barycentric_uv: np.ndarray

    @property
    def hit_mask(self) -> np.ndarray:
        return np.isfinite(self.distance)


def _as_rays(origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    origins = np.asarray(origins, dtype=np.float32)
    directions = np.asarray(directions, dtype=np.float32)
    if directions.ndim != 2 or directions.shape[1] != 3:
        raise ValueError(f"directions must have shape (N, 3), got {directions.shape}")
    if origins.shape != directions.shape:
        origins = np.broadcast_to(origins.reshape(-1, 3), directions.shape)
    return origins, directions


class RayCaster:
    """Casts rays against a fixed triangle mesh.

    Args:
        vertices: (V, 3) vertex positions in metres.
        faces: (F, 3) triangle vertex indices.
        backend: ``"open3d"`` (default, fastest here) or ``"embreex"``.
    """

    def __init__(
        self, vertices: np.ndarray, faces: np.ndarray, backend: RayCasterBackend = "open3d"
    ) -> None:
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float32)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3:
            raise ValueError(f"vertices must have shape (V, 3), got {self.vertices.shape}")
        if self.faces.ndim != 2 or self.faces.shape[1] != 3 or len(self.faces) == 0:
            raise ValueError(f"faces must have shape (F, 3) with F > 0, got {self.faces.shape}")
        if backend not in RAYCASTER_BACKENDS:
            raise ValueError(f"unknown ray-casting backend {backend!r}; use 'open3d' or 'embreex'")
        self.backend: RayCasterBackend = backend
        self._scene = None
        self._distance_scene = None
        self._distance_pid: int | None = None
        self._built_in_pid: int | None = None

    # -- native scene ------------------------------------------------------------------
    @property
    def native_scene(self):
        """The backend's scene, built on first use and rebuilt in a forked child.

        Building lazily keeps Embree's worker threads out of a parent process that forks
        (gymnasium's async vector env creates one env in the parent before forking).
        """
        enter_native_code()
        if self._scene is None or self._built_in_pid != os.getpid():
            self._build()
        return self._scene

    def _build(self) -> None:
        self._built_in_pid = os.getpid()
        if self.backend == "open3d":
            import open3d as o3d

            self._o3d = o3d
            self._scene = o3d.t.geometry.RaycastingScene()
            self._scene.add_triangles(
                o3d.core.Tensor(self.vertices), o3d.core.Tensor(self.faces.astype(np.uint32))
            )
        else:
            try:
                import embreex.rtcore_scene as rtcs
                from embreex.mesh_construction import TriangleMesh
            except ImportError as error:  # pragma: no cover - depends on the install
                raise ImportError(
                    "backend='embreex' needs the embreex package: pip install 'naruto-gym[embreex]'"
                ) from error
            self._scene = rtcs.EmbreeScene()
            TriangleMesh(self._scene, self.vertices[self.faces])

    def __getstate__(self) -> dict:
        return {"vertices": self.vertices, "faces": self.faces, "backend": self.backend}

    def __setstate__(self, state: dict) -> None:
        self.vertices = state["vertices"]
        self.faces = state["faces"]
        self.backend = state["backend"]
        self._scene = None
        self._distance_scene = None
        self._distance_pid: int | None = None
        self._built_in_pid = None

    # -- queries -----------------------------------------------------------------------
    def cast(self, origins: np.ndarray, directions: np.ndarray) -> RayHits:
        """First hit of each ray (origins may be a single (3,) point shared by all rays)."""
        origins, directions = _as_rays(origins, directions)
        return self.cast_packed(np.concatenate([origins, directions], axis=1))

    def cast_packed(self, rays: np.ndarray) -> RayHits:
        """First hit of each ray given as one (N, 6) float32 array [origin, direction].

        The fast path for renderers that keep a preallocated ray buffer: the open3d backend
        wraps the buffer without copying it.
        """
        rays = np.ascontiguousarray(rays, dtype=np.float32)
        if self.backend == "open3d":
            result = self.native_scene.cast_rays(
                self._o3d.core.Tensor.from_numpy(rays), nthreads=default_thread_count()
            )
            distance = result["t_hit"].numpy()
            triangle_ids = result["primitive_ids"].numpy().view(np.int32)
            uv = result["primitive_uvs"].numpy()
            # Open3D marks a miss with id 2**32 - 1, which reads as -1 as int32.
            return RayHits(distance, triangle_ids, uv)
        result = self.native_scene.run(
            np.ascontiguousarray(rays[:, :3]), np.ascontiguousarray(rays[:, 3:]), output=1
        )
        triangle_ids = result["primID"].astype(np.int32)
        hit = triangle_ids >= 0
        distance = np.where(hit, result["tfar"], np.inf).astype(np.float32)
        uv = np.stack([result["u"], result["v"]], axis=1).astype(np.float32)
        return RayHits(distance, triangle_ids, uv)

    def hits_any_packed(self, rays: np.ndarray) -> np.ndarray:
        """Whether each ray of (N, 6) float32 ``rays`` hits the mesh at all, (N,) bool: the
        ``hit_mask`` of :meth:`cast_packed`, about twice as fast with Open3D (an occlusion
        query stops at the first triangle found, not the nearest)."""
        rays = np.ascontiguousarray(rays, dtype=np.float32)
        if self.backend == "open3d":
            scene = self.native_scene  # built first: it imports Open3D
            return (
                scene.test_occlusions(
                    self._o3d.core.Tensor.from_numpy(rays), nthreads=default_thread_count()
                )
                .numpy()
                .astype(bool)
            )
        return self.cast_packed(rays).hit_mask

    def cast_distance(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Only the first-hit distance of each ray ((N,) float32, ``inf`` for no hit)."""
        return self.cast(origins, directions).distance

    def unsigned_distance(self, points: np.ndarray) -> np.ndarray:
        """Distance from each point to the closest surface point, (N,) float32 metres."""
        points = np.ascontiguousarray(np.asarray(points, dtype=np.float32).reshape(-1, 3))
        # embreex has no closest-point query: both backends answer it with Open3D.
        return (
            self._open3d_scene()
            .compute_distance(self._o3d.core.Tensor(points), nthreads=default_thread_count())
            .numpy()
        )

    def _open3d_scene(self):
        if self.backend == "open3d":
            return self.native_scene
        enter_native_code()
        if self._distance_scene is None or self._distance_pid != os.getpid():
            import open3d as o3d

            self._distance_pid = os.getpid()
            self._o3d = o3d
            self._distance_scene = o3d.t.geometry.RaycastingScene()
            self._distance_scene.add_triangles(
                o3d.core.Tensor(self.vertices), o3d.core.Tensor(self.faces.astype(np.uint32))
            )
        return self._distance_scene

    def segment_is_free(self, start: np.ndarray, end: np.ndarray, clearance: float) -> bool:
        """True when a sphere of radius ``clearance`` can sweep from start to end untouched.

        Exact for the sphere: the segment's distance to the mesh is checked by sampling it
        every ``clearance / 2`` and requiring each sample to be at least ``clearance`` from
        every triangle, plus a ray cast along the segment so that no sample step can jump a
        thin wall.
        """
        start = np.asarray(start, dtype=np.float64)
        end = np.asarray(end, dtype=np.float64)
        return self.free_fraction_of_segment(start, end, clearance) >= 1.0

    def free_fraction_of_segment(
        self, start: np.ndarray, end: np.ndarray, clearance: float
    ) -> float:
        """Largest fraction t in [0, 1] such that the sphere can move from start to
        start + t (end - start) while staying ``clearance`` away from every surface.

        Returns 0.0 when even the start violates the clearance.
        """
        return self.sweep(start, end, clearance)[0]

    def sweep(self, start: np.ndarray, end: np.ndarray, clearance: float) -> tuple[float, float]:
        """:meth:`free_fraction_of_segment`, and the distance to the surface where the sweep
        stops (one of its samples, so it comes free; nan when it cannot leave the start)."""
        start = np.asarray(start, dtype=np.float64)
        end = np.asarray(end, dtype=np.float64)
        fractions, samples, length = segment_samples(start, end, clearance)
        surface_distance = self.unsigned_distance(samples)
        wall = np.inf
        if length > 0:
            # A ray along the segment catches a wall thinner than the sampling step.
            wall = float(self.cast_distance(start[None], ((end - start) / length)[None])[0])
        return sweep_stop_from_distances(fractions, length, surface_distance, wall, clearance)


def segment_samples(
    start: np.ndarray, end: np.ndarray, clearance: float
) -> tuple[np.ndarray, np.ndarray, float]:
    """Where a sphere's sweep from ``start`` to ``end`` is checked (pure).

    Returns the fractions along the segment (every ``clearance / 4``, at least 1 mm apart,
    both ends included), the (K, 3) points at those fractions and the segment's length.
    """
    delta = end - start
    dx, dy, dz = (float(value) for value in delta)
    # Summed axis by axis, as the batched env's compiled kernel does, so both agree to the
    # bit: np.linalg.norm goes through BLAS, whose rounding differs between CPUs.
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    fractions = np.linspace(0.0, 1.0, sweep_step_count(length, clearance) + 1)
    samples = start[None, :] + fractions[:, None] * delta[None, :]
    return fractions, samples, length


def sweep_stop_from_distances(
    fractions: np.ndarray,
    length: float,
    surface_distance: np.ndarray,
    wall_distance: float,
    clearance: float,
) -> tuple[float, float]:
    """:func:`free_fraction_from_distances`, and the surface distance of the sample where the
    sweep stops (the stop is one of the samples; nan when the sweep cannot leave the start)."""
    fraction = free_fraction_from_distances(
        fractions, length, surface_distance, wall_distance, clearance
    )
    if fraction <= 0.0:
        return fraction, float("nan")
    return fraction, float(surface_distance[np.searchsorted(fractions, fraction)])


def free_fraction_from_distances(
    fractions: np.ndarray,
    length: float,
    surface_distance: np.ndarray,
    wall_distance: float,
    clearance: float,
) -> float:
    """The free fraction of a sweep from the queries at :func:`segment_samples` (pure).

    Args:
        fractions: the sample fractions along the segment.
        length: the segment's length.
        surface_distance: distance from each sample to the nearest surface.
        wall_distance: first hit of the ray along the segment (``inf`` for none; ignored for a
            zero-length segment).
        clearance: the sphere's radius.
    """
    distance = np.asarray(surface_distance)
    if not np.issubdtype(distance.dtype, np.floating):
        distance = distance.astype(np.float64)
    first_blocked = first_blocked_sample(
        np.asarray(fractions, np.float64),
        float(length),
        distance,
        float(wall_distance),
        float(clearance),
        distance.dtype.type(clearance),
    )
    if first_blocked < 0:
        return 1.0
    if first_blocked == 0:
        return 0.0
    return float(fractions[first_blocked - 1])
