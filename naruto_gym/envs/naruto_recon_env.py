"""``NarutoReconEnv``: a camera-carrying agent explores an indoor mesh to reconstruct it."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from naruto_gym.coverage import CoverageTracker
from naruto_gym.envs.scene_runtime import SceneRuntime
from naruto_gym.envs.settings import PINHOLE_BACKEND, EnvSettings
from naruto_gym.envs.validation import (
    check_env_keywords,
    check_keyword_names,
    check_reset_options,
    check_seed,
)
from naruto_gym.evaluation.scoring import EpisodeReconstruction
from naruto_gym.geometry.transforms import make_pose, validate_pose
from naruto_gym.motion.actions import (
    delta_target_from_action,
    discrete_target_from_action,
    limit_pose_step,
    pose_target_from_action,
)
from naruto_gym.motion.collision import CollisionChecker
from naruto_gym.observability import ObservableSurface
from naruto_gym.rendering.topdown import TopDownMap, compose_frame
from naruto_gym.scenes.mesh_scene import Scene
from naruto_gym.sensors.panorama import EquirectangularCamera, no_hit_share, render_panorama
from naruto_gym.sensors.pinhole import PinholeCamera, RgbdRenderer
from naruto_gym.sensors.raycaster import RayCaster

#: Every keyword ``NarutoReconEnv`` takes: its settings' and its own.
ENV_KEYWORDS = frozenset(
    {item.name for item in dataclasses.fields(EnvSettings)}
    | {"scene", "reconstruct", "max_episode_steps", "render_mode"}
)


class NarutoReconEnv(gym.Env):
    """Active 3D reconstruction of an indoor scene by a camera-carrying agent.

    ## Description
    The agent is a sphere (radius ``agent_radius_m``) carrying a pinhole RGB-D camera through a
    triangle mesh of an indoor scene. Every step it moves (with collision checking against the
    ground-truth mesh), renders a new frame by Embree ray casting, and is rewarded for the
    share of the scene's surface it sees for the first time. The task follows NARUTO (Feng et
    al., CVPR 2024): explore so that a map built from the frames is as complete and accurate as
    possible.

    World frame: metres, z up. Poses are camera-to-world 4x4 matrices with OpenCV camera axes
    (x right, y down, z forward). Quaternions are (x, y, z, w).

    ## Action Space
    Chosen by ``action_mode``:

    * ``"pose"`` (default): ``Box(7,)`` float32, an absolute target pose
      ``(x, y, z, qx, qy, qz, qw)``; position within the scene bounds, the quaternion is
      normalised (must not be zero). The camera moves towards it by at most
      ``max_translation_m`` along the straight line and at most ``max_rotation_deg`` along the
      rotation geodesic (SLERP). This is what the NARUTO agent uses.
    * ``"delta"``: ``Box(-1, 1, (6,))`` float32, increments in the camera frame:
      ``(tx, ty, tz)`` scaled by ``max_translation_m`` and a rotation vector ``(rx, ry, rz)``
      scaled by ``max_rotation_deg`` (each 3-vector clipped to norm 1).
    * ``"discrete"``: ``Discrete(10)``: 0 move forward, 1 move backward, 2 move left, 3 move
      right (horizontal, relative to the camera heading), 4 move up, 5 move down (world z), all
      by ``max_translation_m``; 6 turn left, 7 turn right (yaw about world z), 8 look up, 9 look
      down (pitch, kept within +-80 degrees), all by ``max_rotation_deg``.

    Actions that are NaN/inf, of the wrong shape, or outside the space raise ``ValueError`` and
    leave the env unchanged.

    ## Observation Space
    A flat ``Dict``:

    * ``rgb``: ``Box(0, 255, (H, W, 3), uint8)``.
    * ``depth``: ``Box(0, max_depth_m, (H, W), float32)``, z-depth in metres, 0 for no hit or
      beyond ``max_depth_m``.
    * ``pose``: ``Box(-inf, inf, (4, 4), float32)``, camera-to-world.
    * ``panorama`` (when ``panorama_shape`` is not None): ``Box(0, inf, (h, w), float32)``,
      world-aligned equirectangular radial distance, 0 for no hit.

    The info of every reset and step holds ``coverage`` (0..1), ``coverage_gain``,
    ``collided``, ``collision_reason`` ("", "surface", "bounds", "escape"),
    ``path_length_m``, ``intrinsics`` (dict of width, height, fx, fy, cx, cy), ``step``, and
    ``panorama_no_hit_share`` when the panorama is on.

    ## Rewards
    ``100 * (coverage_t - coverage_{t-1}) - collision_penalty * collided``: the coverage gain in
    percentage points of the ground-truth surface, minus a penalty for a blocked move.
    Coverage counts area-uniform surface samples that have been inside the frustum, within
    ``coverage_range_m`` and not occluded, out of the observable ones (see
    ``observable_only``).

    Reconstruction quality is scored apart from the reward: ``env.unwrapped.evaluate(mesh)``
    scores a policy's own mesh against the ground truth, culled to what the episode's frames
    saw, and with ``reconstruct=True`` ``env.unwrapped.reconstruction_metrics()`` scores the
    env's reference map (see ``reconstruct`` and ``max_episode_steps``).

    ## Starting State
    ``reset(seed=...)`` draws a position in free space at least ``start_clearance_m`` from every
    surface and inside the scanned space (as the escape rule judges it, exactly at that point),
    looking horizontally in a random direction. ``reset(options={"pose": c2w})`` starts
    exactly at a 4x4 pose (not collision-checked, so recorded trajectories replay exactly; it
    must lie inside the bounds; if it lies outside the scanned space, moves that go no
    further out are still allowed).

    ## Episode End
    The env never terminates. ``gymnasium.make`` adds a ``TimeLimit`` (2000 steps for the
    default ids, the published Replica budget), which truncates. Given ``max_episode_steps``,
    the env also truncates by itself on the step that reaches it.

    ## Arguments
    * ``scene``: a catalogue name (see ``naruto_gym.scenes.available_scenes()``), a mesh path
      (PLY/OBJ/GLB/glTF) or a ``Scene``. Default: the shipped ``"replica_like_room"``.
    * ``up_axis``: the up axis of a mesh file (``"z"``, ``"y"``, ``"-y"``, ``"x"``, ``"-x"``,
      ``"-z"``), rotated to +z; ``"auto"`` reads it from a recognised dataset layout (ScanNet
      ``*_vh_clean_2.ply``, Replica ``mesh.ply`` beside ``textures/``) and raises otherwise.
    * ``mesh_units``: the length unit of a mesh file, ``"m"`` (default), ``"cm"`` or ``"mm"``;
      it is rescaled to metres. A file whose size says it is not in these units (a room in
      millimetres read as metres: thousands of metres across with coarse triangles) raises
      ``ValueError`` naming the likely unit (see :mod:`naruto_gym.scenes.units`).
    * ``action_mode``: ``"pose"``, ``"delta"`` or ``"discrete"``.
    * ``camera``: ``PinholeCamera`` intrinsics (default 680 x 1200, fx = fy = 600).
    * ``image_scale``: resolution factor applied to ``camera`` (0.25 gives 170 x 300).
    * ``max_depth_m``: sensor range (10 m).
    * ``panorama_shape``: ``(h, w)`` of the panorama observation, None to switch it off.
    * ``panorama_horizon_deg``: cast only the panorama rows within this many degrees of
      elevation of the horizon, for a user that reads only those (such as a top-down map at
      the agent's height; a third of the rays at 30 degrees); the other rows read 0 and
      ``panorama_no_hit_share`` counts the rows cast. None (default): every row.
    * ``agent_radius_m``, ``max_translation_m``, ``max_rotation_deg``: body and step limits
      (0.05 m, 0.1 m, 20 degrees).
    * ``escape_rule``: how a move that would leave the scanned space is told apart
      (``collision_reason == "escape"``; see ``naruto_gym.motion.collision``):
      ``"scanned_space"`` (default) refuses a move whose end does not see scanned surface
      below it in every direction (each 45-degree sector of a 60-degree downward cone of
      rays must hit something) or is above the scan (above the height under which 99 % of
      its area lies, plus 0.1 m). It needs no ceiling and no walls around, so real scans (no
      ceiling, holes, missing walls) stay explorable, while walking off the edge of the
      scanned floor, out of a wall hole or down a floor hole is refused. It is answered from
      a 5 cm lattice filled lazily where the agent goes: no extra ray cast per step once the
      lattice around a place is known.
      ``"published"``: NARUTO's rule, refuse a move whose end sees more than
      ``escape_no_hit_threshold`` no-hit pixels on a whole-sphere panorama (right for closed
      meshes; it refuses moves anywhere in a room without a ceiling). ``"off"``: no check.
      Start poses and the observable surface's viewpoints use the same rule.
    * ``escape_no_hit_threshold``: the published rule's share (0.5); None switches every
      escape check off.
    * ``collision_penalty``: reward subtracted for a blocked move (0.1).
    * ``coverage_samples``, ``coverage_range_m``: surface samples for coverage (20,000) and the
      range within which a sample counts as seen (5 m, the mapping range).
    * ``observable_only``: count coverage over the observable surface only (default True):
      samples that some free viewpoint inside the scene can see. Solid walls, floor slabs and
      furniture bottoms otherwise hold surface nobody can see, so coverage could never reach
      100 %. Scoring reports completion over it beside the standard metrics.
    * ``start_clearance_m``: free space around a random start (0.3 m).
    * ``raycaster_backend``: ``"open3d"`` (default) or ``"embreex"``.
    * ``pinhole_backend``: how the pinhole frame is made: ``"raycast"`` (default, Embree ray
      casting, the reference), ``"raster"`` (the rasterizer, several times faster: the same
      triangles and colours up to exact edge ties, depths up to float rounding) or ``"auto"``
      (the rasterizer unless the mesh has more than 4 triangles per pixel). The panorama,
      collisions and coverage always ray-cast. ``renderer.frame_backend`` says which method
      the frames use.
    * ``threads``: threads of the rasterizer and the colour lookup (None: the
      ``NARUTO_GYM_THREADS`` environment variable, else every CPU the process may run on,
      one in the worker of an ``AsyncVectorEnv`` or a Ray actor; see
      :func:`naruto_gym.utils.threads.default_thread_count`).
    * ``reconstruct``: fuse every frame into a reference TSDF map (2 cm voxels) so that any
      policy gets accuracy / completion / completion ratio:
      ``env.unwrapped.reconstruction_metrics()`` gives them at any time, and the info of the
      step that reaches ``max_episode_steps`` carries them under ``"reconstruction"``.
    * ``max_episode_steps``: the episode's length in steps, when the env itself should know
      it (None: it does not). The env truncates on the step that reaches it and, with
      ``reconstruct=True``, puts the final metrics into that step's info, so that no wrapper
      is needed. ``gymnasium.make(..., max_episode_steps=N)`` takes the keyword for its own
      ``TimeLimit`` and does not pass it on (Gymnasium keeps the budget on that wrapper; the
      made env's ``unwrapped.spec.max_episode_steps`` is None), so the env made so does not
      know its end: wrap it in ``naruto_gym.wrappers.FinalReconstructionMetrics`` for the
      metrics there (Gymnasium refuses registered wrappers together with the vector entry
      point, so the ids cannot add it).
    * ``render_mode``: None or ``"rgb_array"``.

    ## Version History
    * v0: initial release.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        scene: str | Path | Scene | None = None,
        up_axis: str = "z",
        mesh_units: str = "m",
        action_mode: str = "pose",
        camera: PinholeCamera | None = None,
        image_scale: float = 1.0,
        max_depth_m: float = 10.0,
        panorama_shape: tuple[int, int] | None = (64, 128),
        panorama_horizon_deg: float | None = None,
        agent_radius_m: float = 0.05,
        max_translation_m: float = 0.1,
        max_rotation_deg: float = 20.0,
        escape_no_hit_threshold: float | None = 0.5,
        escape_rule: str = "scanned_space",
        collision_penalty: float = 0.1,
        coverage_samples: int = 20_000,
        coverage_range_m: float = 5.0,
        observable_only: bool = True,
        start_clearance_m: float = 0.3,
        raycaster_backend: str = "open3d",
        pinhole_backend: str = PINHOLE_BACKEND,
        threads: int | None = None,
        reconstruct: bool = False,
        max_episode_steps: int | None = None,
        render_mode: str | None = None,
        **unknown: Any,
    ) -> None:
        if unknown:  # a misspelt or renamed keyword: refused by name, with what it takes
            check_keyword_names(unknown, ENV_KEYWORDS, type(self).__name__)
        settings = EnvSettings(
            up_axis=up_axis,
            mesh_units=mesh_units,
            action_mode=action_mode,
            camera=camera,
            image_scale=image_scale,
            max_depth_m=max_depth_m,
            panorama_shape=panorama_shape,
            panorama_horizon_deg=panorama_horizon_deg,
            agent_radius_m=agent_radius_m,
            max_translation_m=max_translation_m,
            max_rotation_deg=max_rotation_deg,
            escape_no_hit_threshold=escape_no_hit_threshold,
            escape_rule=escape_rule,
            collision_penalty=collision_penalty,
            coverage_samples=coverage_samples,
            coverage_range_m=coverage_range_m,
            observable_only=observable_only,
            start_clearance_m=start_clearance_m,
            raycaster_backend=raycaster_backend,
            pinhole_backend=pinhole_backend,
            threads=threads,
        )
        check_env_keywords(
            render_mode, self.metadata["render_modes"], reconstruct, max_episode_steps
        )
        # The native ray-casting scene, the coverage samples and the observable surface are
        # built lazily (first reset), after any fork.
        self.runtime = SceneRuntime.load(scene, settings)
        self.render_mode = render_mode
        self.max_episode_steps = None if max_episode_steps is None else int(max_episode_steps)
        self._intrinsics = self.camera.as_dict()
        self.reconstruction: EpisodeReconstruction | None = (
            EpisodeReconstruction(self.camera) if reconstruct else None
        )
        self.observation_space = self.runtime.observation_space()
        self.action_space = self.runtime.action_space()

        self._pose = np.eye(4)
        self._positions: list[np.ndarray] = []
        self._poses: list[np.ndarray] = []
        self._rgb: np.ndarray | None = None
        self._depth: np.ndarray | None = None
        self._panorama: np.ndarray | None = None
        self._path_length_m = 0.0
        self._step_count = 0

    # -- what the env is made of (each owned by its settings or its scene's runtime) ------
    @property
    def settings(self) -> EnvSettings:
        """The env's settings: every keyword but ``scene``, ``reconstruct``,
        ``max_episode_steps`` and ``render_mode`` (``env.settings.max_translation_m``, ...)."""
        return self.runtime.settings

    @property
    def scene(self) -> Scene:
        """The scene explored."""
        return self.runtime.scene

    @property
    def camera(self) -> PinholeCamera:
        """The pinhole camera (``settings.camera`` at ``settings.image_scale``)."""
        return self.runtime.camera

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) the scene's axis-aligned box."""
        return self.runtime.bounds

    @property
    def raycaster(self) -> RayCaster:
        """The scene's ray caster."""
        return self.runtime.raycaster

    @property
    def renderer(self) -> RgbdRenderer:
        """The pinhole RGB-D renderer."""
        return self.runtime.renderer

    @property
    def panorama_camera(self) -> EquirectangularCamera | None:
        """The observation panorama's camera (None when ``panorama_shape`` is None)."""
        return self.runtime.panorama_camera

    @property
    def collision(self) -> CollisionChecker:
        """The collision checker, with the settings' escape rule."""
        return self.runtime.collision

    # -- public helpers ------------------------------------------------------------------
    @property
    def coverage(self) -> CoverageTracker:
        """The coverage tracker over the (observable) ground-truth surface samples."""
        return self.runtime.coverage

    @property
    def observable_surface(self) -> ObservableSurface:
        """The surface some free viewpoint inside the scene can see (fixed per scene)."""
        return self.runtime.observable_surface

    @property
    def top_down_map(self) -> TopDownMap:
        """The scene's top-down map, on which ``render`` draws the trajectory (built on first
        use)."""
        return self.runtime.top_down_map

    @property
    def pose(self) -> np.ndarray:
        """Current camera-to-world pose (a copy)."""
        return self._pose.copy()

    @property
    def trajectory(self) -> np.ndarray:
        """(K, 3) positions visited this episode, start included."""
        return np.array(self._positions)

    @property
    def poses(self) -> np.ndarray:
        """(K, 4, 4) camera-to-world poses of every frame this episode, start included."""
        return np.array(self._poses).reshape(-1, 4, 4)

    def evaluate(self, mesh: Any, cull: bool = True, **kwargs: Any) -> dict[str, Any]:
        """Score a policy's own reconstruction against the ground truth.

        Accuracy / completion (cm), completion ratio, precision and F-score (%) at 5 cm from
        200,000 area-uniform samples per mesh; the mesh is first culled to what this episode's
        frames saw (see ``naruto_gym.evaluation``).

        Args:
            mesh: a ``trimesh.Trimesh`` (or ``(vertices, faces)``) in world coordinates.
            cull: cull by this episode's poses (default True).
            **kwargs: passed to ``naruto_gym.evaluation.evaluate_reconstruction``
                (``num_samples``, ``threshold_m``, ``seed``, ...).
        """
        if not self._poses:
            raise RuntimeError("call reset() and run an episode before evaluate()")
        metrics = self.runtime.evaluate(mesh, self.poses, cull=cull, **kwargs)
        return {**metrics, "trajectory_length_m": self._path_length_m}

    def reconstruction_metrics(self, **kwargs: Any) -> dict[str, Any]:
        """Metrics of the reference TSDF reconstruction of this episode (``reconstruct=True``)."""
        if self.reconstruction is None:
            raise RuntimeError("make the env with reconstruct=True to fuse a reference map")
        return self.runtime.reconstruction_metrics(self.reconstruction, **kwargs)

    # -- gymnasium API -------------------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        super().reset(seed=check_seed(seed))
        options = check_reset_options(options, ("pose",))
        unknown = set(options) - {"pose"}
        if unknown:
            raise ValueError(f"unknown reset options {sorted(unknown)}; supported: ['pose']")
        if "pose" in options:
            pose = validate_pose(options["pose"], "options['pose']")
            self.runtime.check_start_pose(pose)
        else:
            pose = self.runtime.sample_start_pose(self.np_random)
        self._pose = pose
        self._positions = [pose[:3, 3].copy()]
        self._poses = [pose.copy()]
        if self.reconstruction is not None:
            self.reconstruction.reset()
        self._path_length_m = 0.0
        self._step_count = 0
        self.coverage.reset()
        self._observe()
        gain = self.coverage.update(self._pose, self._depth)
        return self._observation(), self._info(gain, False, "")

    def step(self, action: Any) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        if self._rgb is None:
            raise RuntimeError("call reset() before step()")
        target = self._target_pose(self._validated_action(action))
        settings = self.settings
        limited = limit_pose_step(
            self._pose, target, settings.max_translation_m, settings.max_rotation_rad
        )
        move = self.collision.move(self._pose[:3, 3], limited[:3, 3])
        self._path_length_m += float(np.linalg.norm(move.position - self._pose[:3, 3]))
        self._pose = make_pose(limited[:3, :3], move.position)
        self._positions.append(move.position.copy())
        self._poses.append(self._pose.copy())
        self._step_count += 1
        self._observe()
        gain = self.coverage.update(self._pose, self._depth)
        reward = 100.0 * gain - (settings.collision_penalty if move.collided else 0.0)
        info = self._info(gain, move.collided, move.reason)
        truncated = (
            self.max_episode_steps is not None and self._step_count >= self.max_episode_steps
        )
        if truncated and self.reconstruction is not None:
            info["reconstruction"] = self.reconstruction_metrics()
        return self._observation(), float(reward), False, truncated, info

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        if self._rgb is None:
            raise RuntimeError("call reset() before render()")
        top_down = self.top_down_map.draw(self.trajectory, self._pose)
        return compose_frame(top_down, self._rgb, self._depth, self.settings.max_depth_m)

    # -- internals -----------------------------------------------------------------------
    def close(self) -> None:
        """Stop the reference reconstruction's background fusion (``reconstruct=True``)."""
        if self.reconstruction is not None:
            self.reconstruction.close()
        super().close()

    def _validated_action(self, action: Any) -> Any:
        action_mode = self.settings.action_mode
        if action_mode == "discrete":
            if (
                isinstance(action, (int, np.integer))
                and not isinstance(action, (bool, np.bool_))
                and 0 <= action < self.action_space.n
            ):
                return int(action)  # the common case, without the array checks below
            if isinstance(action, (bool, np.bool_)) or not np.issubdtype(
                np.asarray(action).dtype, np.integer
            ):
                raise ValueError(
                    f"discrete action must be an integer in [0, {self.action_space.n}), "
                    f"got {action!r}"
                )
            if np.asarray(action).shape not in ((), (1,)) or not self.action_space.contains(
                int(np.asarray(action).reshape(-1)[0])
            ):
                raise ValueError(
                    f"discrete action must be an integer in [0, {self.action_space.n}), "
                    f"got {action!r}"
                )
            return int(np.asarray(action).reshape(-1)[0])
        try:
            array = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError) as error:
            raise ValueError(f"action must be a numeric array, got {action!r}") from error
        expected = self.action_space.shape
        if array.shape != expected:
            raise ValueError(f"{action_mode} action must have shape {expected}, got {array.shape}")
        if not np.all(np.isfinite(array)):
            raise ValueError(f"action contains NaN or inf: {array.tolist()}")
        tolerance = 1e-5
        low, high = self.action_space.low, self.action_space.high
        if np.any(array < low - tolerance) or np.any(array > high + tolerance):
            raise ValueError(
                f"{action_mode} action {np.round(array, 4).tolist()} is outside the action "
                f"space [{low.tolist()}, {high.tolist()}]"
            )
        return array

    def _target_pose(self, action: Any) -> np.ndarray:
        settings = self.settings
        if settings.action_mode == "pose":
            return pose_target_from_action(action)
        if settings.action_mode == "delta":
            return delta_target_from_action(
                self._pose, action, settings.max_translation_m, settings.max_rotation_rad
            )
        return discrete_target_from_action(
            self._pose, action, settings.max_translation_m, settings.max_rotation_rad
        )

    def _observe(self) -> None:
        self._rgb, self._depth = self.renderer.render(self._pose)
        if self.panorama_camera is not None:
            position = self._pose[:3, 3]
            self._panorama = render_panorama(self.raycaster, self.panorama_camera, position)
        if self.reconstruction is not None:
            self.reconstruction.add_frame(self._rgb, self._depth, self._pose)

    def _observation(self) -> dict[str, np.ndarray]:
        observation = {
            "rgb": self._rgb.copy(),
            "depth": self._depth.copy(),
            "pose": self._pose.astype(np.float32),
        }
        if self._panorama is not None:
            observation["panorama"] = self._panorama.copy()
        return observation

    def _info(self, gain: float, collided: bool, reason: str) -> dict[str, Any]:
        info: dict[str, Any] = {
            "coverage": self.coverage.coverage,
            "coverage_gain": float(gain),
            "collided": bool(collided),
            "collision_reason": reason,
            "path_length_m": float(self._path_length_m),
            "intrinsics": dict(self._intrinsics),
            "step": self._step_count,
        }
        if self._panorama is not None:
            start, stop = self.panorama_camera.cast_rows  # the rows not cast say nothing
            info["panorama_no_hit_share"] = no_hit_share(self._panorama[start:stop])
        return info
