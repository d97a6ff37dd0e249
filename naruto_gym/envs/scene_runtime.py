"""``SceneRuntime``: what an env builds once per scene and every episode in it reuses.

The ray caster, the pinhole and panorama cameras, the collision checker (with its escape
test), the coverage samples over the observable surface, the start-pose sampler and the
top-down map depend on the scene and the env's settings only, never on an episode. The single
env holds one runtime; the batched env holds one per scene and shares it between every agent
in that scene, so both build and use them the same way.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces

from naruto_gym.coverage import CoverageTracker
from naruto_gym.envs.settings import EnvSettings
from naruto_gym.evaluation.scoring import EpisodeReconstruction, evaluate_reconstruction
from naruto_gym.geometry.transforms import look_at_rotation, make_pose
from naruto_gym.motion.actions import DISCRETE_ACTIONS
from naruto_gym.motion.collision import CollisionChecker
from naruto_gym.observability import ObservableSurface, sample_free_positions
from naruto_gym.rendering.topdown import TopDownMap
from naruto_gym.scenes.mesh_scene import Scene, check_mesh_area
from naruto_gym.sensors.pinhole import RgbdRenderer
from naruto_gym.sensors.raycaster import RayCaster

#: Candidate positions drawn (in one batch) when looking for a random start.
START_CANDIDATES = 2048


def observation_space(settings: EnvSettings) -> spaces.Dict:
    """The observation space of one agent of an env with ``settings`` (see
    ``NarutoReconEnv``): it depends on the cameras only, never on the scene."""
    camera = settings.pinhole_camera
    observation_spaces: dict[str, spaces.Space] = {
        "rgb": spaces.Box(0, 255, (camera.height, camera.width, 3), np.uint8),
        "depth": spaces.Box(
            0.0, float(settings.max_depth_m), (camera.height, camera.width), np.float32
        ),
        "pose": spaces.Box(-np.inf, np.inf, (4, 4), np.float32),
    }
    panorama = settings.panorama_camera
    if panorama is not None:
        observation_spaces["panorama"] = spaces.Box(
            0.0, np.inf, (panorama.height, panorama.width), np.float32
        )
    return spaces.Dict(observation_spaces)


class SceneRuntime:
    """The per-scene building blocks of an env.

    Building one casts no ray: the native ray-casting scene, the observable surface and the
    coverage samples are made on first use (after any fork of a worker process).

    Args:
        scene: the scene.
        settings: the env's settings.
        auto_max_triangles_per_pixel: the most triangles per pixel at which the ``"auto"``
            pinhole backend rasterizes; None keeps the renderer's single-frame default.

    Attributes:
        scene, settings: as given.
        camera: the pinhole camera (scaled by ``settings.image_scale``).
        bounds: (2, 3) the scene's axis-aligned box.
        raycaster: the scene's ray caster (Embree).
        renderer: the pinhole RGB-D renderer.
        panorama_camera: the observation panorama's camera, None when it is off.
        collision: the collision checker, with the escape rule of ``settings``.
    """

    def __init__(
        self,
        scene: Scene,
        settings: EnvSettings,
        auto_max_triangles_per_pixel: float | None = None,
    ) -> None:
        check_mesh_area(scene.vertices, scene.faces, f"scene {scene.name!r}")
        self.scene = scene
        self.settings = settings
        self.camera = settings.pinhole_camera
        self.bounds = scene.bounds
        self.raycaster = RayCaster(scene.vertices, scene.faces, settings.raycaster_backend)
        self.renderer = RgbdRenderer(
            scene,
            self.camera,
            float(settings.max_depth_m),
            self.raycaster,
            backend=settings.pinhole_backend,
            threads=settings.threads,
        )
        if auto_max_triangles_per_pixel is not None:
            self.renderer.auto_max_triangles_per_pixel = auto_max_triangles_per_pixel
        self.panorama_camera = settings.panorama_camera
        self.collision = CollisionChecker(
            self.raycaster,
            self.bounds,
            float(settings.agent_radius_m),
            settings.escape_no_hit_threshold,
            escape_rule=settings.escape_rule,
            face_normals=scene.face_normals,
        )
        self._coverage: CoverageTracker | None = None
        self._observable: ObservableSurface | None = None
        self._top_down: TopDownMap | None = None

    @classmethod
    def load(
        cls,
        scene: str | Path | Scene | None,
        settings: EnvSettings,
        auto_max_triangles_per_pixel: float | None = None,
    ) -> SceneRuntime:
        """The runtime of a scene given as ``NarutoReconEnv`` takes it: a catalogue name, a
        mesh path (read with ``settings.up_axis`` and ``settings.mesh_units``), a ``Scene``,
        or None for the default."""
        from naruto_gym.scenes.catalogue import DEFAULT_SCENE, resolve_scene

        resolved = resolve_scene(
            scene if scene is not None else DEFAULT_SCENE, settings.up_axis, settings.mesh_units
        )
        return cls(resolved, settings, auto_max_triangles_per_pixel)

    # -- built on first use ------------------------------------------------------------------
    @property
    def coverage(self) -> CoverageTracker:
        """The coverage tracker over the (observable) ground-truth surface samples."""
        if self._coverage is None:
            samples = self.scene.sample_surface(int(self.settings.coverage_samples), seed=0)
            if self.settings.observable_only:
                samples = samples[self.observable_surface.mask(samples)]
            self._coverage = CoverageTracker(
                samples, self.camera, float(self.settings.coverage_range_m)
            )
        return self._coverage

    @property
    def observable_surface(self) -> ObservableSurface:
        """The surface some free viewpoint inside the scene can see."""
        if self._observable is None:
            self._observable = ObservableSurface(
                self.raycaster,
                self.scene.face_normals,
                self.bounds,
                max_no_hit_share=self.collision.max_no_hit_share,
                is_inside=self.collision.start_test(),
                is_inside_many=self.collision.start_test_many(),
            )
        return self._observable

    @property
    def top_down_map(self) -> TopDownMap:
        """The scene's top-down map (what ``render`` draws the trajectory on)."""
        if self._top_down is None:
            self._top_down = TopDownMap(self.scene, self.raycaster)
        return self._top_down

    # -- spaces ------------------------------------------------------------------------------
    def observation_space(self) -> spaces.Dict:
        """The observation space of one agent (see ``NarutoReconEnv``)."""
        return observation_space(self.settings)

    def action_space(self) -> spaces.Space:
        """The action space of one agent: pose actions are bounded by this scene's box."""
        mode = self.settings.action_mode
        if mode == "pose":
            low = np.concatenate([self.bounds[0], -np.ones(4)]).astype(np.float32)
            high = np.concatenate([self.bounds[1], np.ones(4)]).astype(np.float32)
            return spaces.Box(low, high, dtype=np.float32)
        if mode == "delta":
            return spaces.Box(-1.0, 1.0, (6,), np.float32)
        return spaces.Discrete(len(DISCRETE_ACTIONS))

    # -- episodes ----------------------------------------------------------------------------
    def sample_start_pose(self, rng: np.random.Generator) -> np.ndarray:
        """A random start: a position in free space at least ``start_clearance_m`` from every
        surface and inside the scanned space (the escape rule's own test), looking
        horizontally in a random direction; ``rng`` draws it.

        Raises:
            RuntimeError: when no candidate position qualifies.
        """
        clearance = float(self.settings.start_clearance_m)
        found = sample_free_positions(
            self.raycaster,
            self.scene.face_normals,
            self.bounds,
            1,
            clearance,
            rng,
            self.collision.max_no_hit_share,
            max_candidates=START_CANDIDATES,
            is_inside=self.collision.start_test(),
            is_inside_many=self.collision.start_test_many(),
        )
        if len(found) == 0:
            raise RuntimeError(
                f"found no free start position in scene {self.scene.name!r} with "
                f"start_clearance_m={clearance}; lower it or pass "
                "reset(options={'pose': c2w})"
            )
        position = found[0]
        yaw = rng.uniform(-np.pi, np.pi)
        target = position + np.array([np.cos(yaw), np.sin(yaw), 0.0])
        return make_pose(look_at_rotation(position, target), position)

    def check_start_pose(self, pose: np.ndarray) -> None:
        """Raise ``ValueError`` when a given start pose (4x4) lies outside the scene's box."""
        if not np.all((pose[:3, 3] >= self.bounds[0]) & (pose[:3, 3] <= self.bounds[1])):
            raise ValueError(
                f"options['pose'] position {pose[:3, 3].tolist()} lies outside the scene "
                f"bounds {self.bounds.tolist()}"
            )

    # -- scoring -----------------------------------------------------------------------------
    def reconstruction_metrics(
        self, reconstruction: EpisodeReconstruction, **kwargs: Any
    ) -> dict[str, Any]:
        """Metrics of an episode's reference TSDF reconstruction in this scene.

        Args:
            reconstruction: the episode's fused map.
            **kwargs: passed to ``EpisodeReconstruction.evaluate`` (completion is also
                reported over the observable surface unless ``observable_mask`` is given).
        """
        kwargs.setdefault("observable_mask", self.observable_surface.mask)
        return reconstruction.evaluate(self.scene, renderer=self.renderer, **kwargs)

    def evaluate(
        self, mesh: Any, poses: np.ndarray, cull: bool = True, **kwargs: Any
    ) -> dict[str, Any]:
        """Score a reconstruction of this scene, culled to what the frames at ``poses`` saw.

        Args:
            mesh: a ``trimesh.Trimesh`` (or ``(vertices, faces)``) in world coordinates.
            poses: (K, 4, 4) camera-to-world poses of the episode's frames.
            cull: cull by ``poses``.
            **kwargs: passed to ``naruto_gym.evaluation.evaluate_reconstruction``.
        """
        kwargs.setdefault("observable_mask", self.observable_surface.mask)
        metrics = evaluate_reconstruction(
            mesh,
            self.scene,
            poses=poses,
            camera=self.camera,
            cull=cull,
            renderer=self.renderer,
            **kwargs,
        )
        return metrics.as_dict()
