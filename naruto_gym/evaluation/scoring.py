"""Policy-agnostic scoring: one call that turns a reconstruction into the published metrics.

* :func:`evaluate_reconstruction` scores any mesh (a policy's own, or the reference mapper's)
  against a ground-truth :class:`~naruto_gym.scenes.mesh_scene.Scene`, culling it first by
  the trajectory's views when poses are given (the literature's protocol).
* :class:`EpisodeReconstruction` is what an env holds for ``reconstruct=True``: it fuses every
  frame of an episode with the reference :class:`TsdfFusionMapper`, remembers the poses, and
  scores the result at the end, so that even a policy with no map gets accuracy, completion
  and completion ratio for its trajectory.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
import trimesh

from naruto_gym.evaluation.background_fusion import BackgroundFusion
from naruto_gym.evaluation.culling import (
    DEFAULT_CULL_DEPTH_SCALE,
    DEFAULT_CULL_EVERY,
    DEFAULT_DEPTH_MARGIN_M,
    CullingCache,
    cull_mesh,
)
from naruto_gym.evaluation.metrics import (
    DEFAULT_NUM_SAMPLES,
    DEFAULT_REFERENCE_SAMPLES_PER_M2,
    DEFAULT_THRESHOLD_M,
    ReconstructionMetrics,
    canonical_mesh,
    reconstruction_metrics,
    trajectory_length,
)
from naruto_gym.evaluation.tsdf_mapper import TsdfFusionMapper
from naruto_gym.scenes.mesh_scene import Scene
from naruto_gym.sensors.pinhole import PinholeCamera, RgbdRenderer
from naruto_gym.utils.threads import default_thread_count

MAD_NEEDS_SDF_NOTE = "no mad_cm: it needs the map's signed distance, pass sdf=..."
NO_CULLING_NOTE = "not culled: no poses given (pass the trajectory's poses to cull)"


def _mesh_arrays(mesh: Any) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(mesh, trimesh.Trimesh | Scene):
        return np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)
    if isinstance(mesh, tuple) and len(mesh) == 2:
        return np.asarray(mesh[0], np.float64), np.asarray(mesh[1], np.int64)
    raise ValueError(
        "the reconstruction must be a trimesh.Trimesh, a Scene or a (vertices, faces) pair, "
        f"got {type(mesh).__name__}"
    )


def evaluate_reconstruction(
    recon_mesh: trimesh.Trimesh | Scene | tuple[np.ndarray, np.ndarray],
    scene: Scene,
    poses: np.ndarray | None = None,
    camera: PinholeCamera | None = None,
    cull: bool = True,
    num_samples: int = DEFAULT_NUM_SAMPLES,
    seed: int = 0,
    threshold_m: float = DEFAULT_THRESHOLD_M,
    cull_every: int = DEFAULT_CULL_EVERY,
    depth_margin_m: float = DEFAULT_DEPTH_MARGIN_M,
    cull_depth_scale: float | None = DEFAULT_CULL_DEPTH_SCALE,
    renderer: RgbdRenderer | None = None,
    progress: bool = False,
    observable_mask: Callable[[np.ndarray], np.ndarray] | None = None,
    cull_cache: CullingCache | None = None,
    reference_samples_per_m2: float | None = DEFAULT_REFERENCE_SAMPLES_PER_M2,
    sdf: Callable[[np.ndarray], np.ndarray] | None = None,
) -> ReconstructionMetrics:
    """Score a reconstructed mesh against the ground-truth scene, culled by the trajectory.

    Args:
        recon_mesh: the reconstruction (``trimesh.Trimesh``, ``Scene`` or (vertices, faces)).
        scene: the ground-truth scene.
        poses: (N, 4, 4) camera-to-world poses the reconstruction was made from. Needed for
            culling; without them the mesh is scored whole and ``note`` says so.
        camera: intrinsics of those frames (default: the 680 x 1200 published camera).
        cull: apply the literature's culling (default True; needs ``poses``).
        num_samples: area-uniform samples per mesh (200,000).
        seed: sampling seed.
        threshold_m: completion-ratio / precision threshold (5 cm).
        cull_every: cull with every n-th pose (2).
        depth_margin_m: occlusion margin of the culling (3 cm).
        cull_depth_scale: None (default) for per-vertex occlusion rays, or the resolution
            factor of rendered occlusion depth images (see :mod:`.culling`).
        renderer: an existing renderer of ``scene`` to reuse its ray-casting scene.
        progress: show a progress bar while culling.
        observable_mask: also score completion over the ground-truth samples this mask
            keeps (e.g. ``ObservableSurface.mask``: surface some free viewpoint can see).
        cull_cache: a :class:`~naruto_gym.evaluation.culling.CullingCache` shared by the
            scorings of one episode (same result, less work on a longer trajectory).
        reference_samples_per_m2: least sample density of a mesh where nearest distances
            are measured to it (2,000 per m^2; None: ``num_samples``, as published). See
            :mod:`naruto_gym.evaluation.metrics`.
        sdf: the reconstruction's signed distance function, for MAD (``mad_cm``: mean |SDF|
            at the ground-truth samples, not culled, as published).

    Returns:
        :class:`ReconstructionMetrics`, with ``faces_evaluated`` / ``faces_culled`` filled in.

    Raises:
        ValueError: an empty reconstruction, or one that culling empties completely.
    """
    vertices, faces = _mesh_arrays(recon_mesh)
    if len(faces) == 0:
        raise ValueError(
            "the reconstruction has no triangles; nothing to score (did the mapper fuse any "
            "frame with valid depth?)"
        )
    # The seeded samples then depend on the surface only, not on the order it is listed in.
    vertices, faces = canonical_mesh(vertices, faces)
    note = ""
    culled = None
    if cull and poses is not None:
        camera = camera or (renderer.camera if renderer is not None else PinholeCamera())
        before = len(faces)
        vertices, faces = cull_mesh(
            vertices,
            faces,
            poses,
            camera,
            renderer if renderer is not None else scene,
            every=cull_every,
            depth_margin_m=depth_margin_m,
            depth_scale=cull_depth_scale,
            progress=progress,
            cache=cull_cache,
        )
        culled = before - len(faces)
        if len(faces) == 0:
            raise ValueError(
                "culling removed every face: no reconstructed vertex is visible from the given "
                "poses; check that poses are camera-to-world (OpenCV axes) and in the scene's "
                "frame, or pass cull=False"
            )
    elif cull:
        note = NO_CULLING_NOTE
    else:
        note = "not culled (cull=False)"
    metrics = reconstruction_metrics(
        (vertices, faces),
        scene,
        threshold_m=threshold_m,
        num_samples=num_samples,
        seed=seed,
        observable_mask=observable_mask,
        reference_samples_per_m2=reference_samples_per_m2,
        sdf=sdf,
    )
    if sdf is None:  # say why mad_cm is None, and what gives it
        note = "; ".join(filter(None, [note, MAD_NEEDS_SDF_NOTE]))
    return ReconstructionMetrics(
        **{**metrics.as_dict(), "faces_evaluated": len(faces), "faces_culled": culled, "note": note}
    )


class EpisodeReconstruction:
    """Reference reconstruction of one episode: fuse every frame, then score.

    Args:
        camera: intrinsics of the frames that will be added.
        voxel_size_m: TSDF voxel size (2 cm).
        truncation_m: TSDF truncation (8 cm).
        max_depth_m: fusion depth range (5 m).
        device: Open3D device for fusion, ``"auto"`` by default.
        fuse_in_background: fuse on a background thread
            (:mod:`~naruto_gym.evaluation.background_fusion`), so that the episode's steps
            do not wait for it; ``None`` (default): where the process may use more than one
            thread (:func:`~naruto_gym.utils.threads.default_thread_count`). Frames are
            checked at once and fused in order, so the scores are the same either way.

    Usage (what an env does)::

        recon = EpisodeReconstruction(camera)           # at reset
        recon.add_frame(rgb, depth, camera_to_world)    # at reset and every step
        info.update(recon.evaluate(scene))              # at the end of the episode
    """

    def __init__(
        self,
        camera: PinholeCamera,
        voxel_size_m: float = 0.02,
        truncation_m: float = 0.08,
        max_depth_m: float = 5.0,
        device: str = "auto",
        fuse_in_background: bool | None = None,
    ) -> None:
        self.camera = camera
        self._mapper = TsdfFusionMapper(
            voxel_size_m=voxel_size_m,
            truncation_m=truncation_m,
            max_depth_m=max_depth_m,
            device=device,
        )
        if fuse_in_background is None:
            fuse_in_background = default_thread_count() > 1
        self._background = BackgroundFusion(self._mapper.fuse) if fuse_in_background else None
        self._fusion_seconds = 0.0
        self._poses: list[np.ndarray] = []
        # Checkpoints re-score a growing trajectory: culling reuses the earlier verdicts.
        self._cull_cache = CullingCache()

    @property
    def fuses_in_background(self) -> bool:
        """Whether frames are fused on a background thread."""
        return self._background is not None

    @property
    def mapper(self) -> TsdfFusionMapper:
        """The reference mapper, with every frame added so far fused."""
        if self._background is not None:
            self._background.wait()
        return self._mapper

    @property
    def fusion_seconds(self) -> float:
        """Seconds spent fusing frames so far, in whichever thread fused them."""
        background = self._background.busy_seconds if self._background is not None else 0.0
        return self._fusion_seconds + background

    def reset(self) -> None:
        """Start a new episode."""
        if self._background is not None:
            try:
                self._background.wait()
            except Exception:  # noqa: BLE001 - the failed episode's map is being discarded
                pass
        self._mapper.reset()
        self._poses = []
        self._cull_cache.clear()

    def close(self) -> None:
        """Fuse what is queued and stop the background thread (the object stays usable)."""
        if self._background is not None:
            self._background.close()

    def add_frame(
        self, rgb: np.ndarray | None, depth: np.ndarray, camera_to_world: np.ndarray
    ) -> None:
        """Fuse one frame and remember its pose (for culling and trajectory length).

        The frame is checked (and copied) at once, so a bad frame raises here and the
        caller may reuse its buffers; with ``fuse_in_background`` a failure of the fusion
        itself is raised at the next call.
        """
        frame = self._mapper.prepare_frame(rgb, depth, camera_to_world, self.camera)
        if self._background is not None:
            self._background.submit(frame)
        else:
            start = time.perf_counter()
            self._mapper.fuse(frame)
            self._fusion_seconds += time.perf_counter() - start
        self._poses.append(np.array(camera_to_world, dtype=np.float64))

    @property
    def poses(self) -> np.ndarray:
        """(N, 4, 4) poses added so far."""
        return np.array(self._poses).reshape(-1, 4, 4)

    @property
    def trajectory_length_m(self) -> float:
        return trajectory_length(self.poses) if self._poses else 0.0

    def mesh(self) -> trimesh.Trimesh:
        """The reference mapper's mesh so far (coloured)."""
        return self.mapper.extract_mesh()

    def evaluate(
        self,
        scene: Scene,
        cull: bool = True,
        num_samples: int = DEFAULT_NUM_SAMPLES,
        seed: int = 0,
        threshold_m: float = DEFAULT_THRESHOLD_M,
        cull_every: int = DEFAULT_CULL_EVERY,
        renderer: RgbdRenderer | None = None,
        observable_mask: Callable[[np.ndarray], np.ndarray] | None = None,
        reference_samples_per_m2: float | None = DEFAULT_REFERENCE_SAMPLES_PER_M2,
    ) -> dict[str, Any]:
        """Metrics of the fused reconstruction, as a flat dict for an env's ``info``.

        Keys: ``accuracy_cm``, ``completion_cm``, ``completion_ratio_pct``, ``precision_pct``,
        ``fscore_pct``, ``threshold_m``, sample and face counts, ``note``, ``mad_cm`` (mean
        |SDF| of the fused map at the ground-truth samples; unobserved space reads as the
        truncation distance), the ``observable_*`` scores with a mask, plus
        ``trajectory_length_m`` and ``num_frames``. When nothing could be reconstructed (no
        valid depth yet) the metric values are ``None`` and ``note`` says why, rather than
        NaN or an exception in the middle of an episode.
        """
        base = {"trajectory_length_m": self.trajectory_length_m, "num_frames": len(self._poses)}
        mesh = self.mesh()
        if len(mesh.faces) == 0:
            empty = dict.fromkeys(
                (
                    "accuracy_cm",
                    "completion_cm",
                    "completion_ratio_pct",
                    "precision_pct",
                    "fscore_pct",
                    "mad_cm",
                ),
            )
            return {**empty, **base, "note": "empty reconstruction: no valid depth was fused"}
        metrics = evaluate_reconstruction(
            mesh,
            scene,
            poses=self.poses,
            camera=self.camera,
            cull=cull,
            num_samples=num_samples,
            seed=seed,
            threshold_m=threshold_m,
            cull_every=cull_every,
            renderer=renderer,
            observable_mask=observable_mask,
            cull_cache=self._cull_cache,
            reference_samples_per_m2=reference_samples_per_m2,
            sdf=self.mapper.sdf,
        )
        return {**metrics.as_dict(), **base}
