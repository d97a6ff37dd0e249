"""The frames the harness's reference map is fused from: the leaderboard's camera at every
pose of the episode, whatever camera the policy sees.

The reference TSDF map (:class:`naruto_gym.evaluation.EpisodeReconstruction`) scores every
policy the same way, but a map fused from coarser frames misses surface (at 68 x 120 a 2 cm
voxel a few metres away is hit by no ray), so its completion ratio would fall with the
policy's camera for the same walk. A leaderboard row must not move with the camera a policy
is run at, so :class:`ReferenceFusion` fuses, at each pose the policy reached, a frame of the
*reference camera* (the leaderboard's 680 x 1200 camera at ``reference_image_scale``, 0.25:
170 x 300) with the leaderboard's sensor range: the observation itself when the env's camera
and range are those, else a frame rendered for the map alone (same scene, same renderer
backend). What the policy sees (its own map, its coverage) still follows its own camera.
"""

from __future__ import annotations

from typing import Any

from naruto_agent.episode_loop import FrameFusion
from naruto_gym.envs.settings import EnvSettings
from naruto_gym.sensors.pinhole import PinholeCamera, RgbdRenderer

LEADERBOARD_IMAGE_SCALE = 0.25
"""The camera resolution factor the leaderboard's reference maps are fused at (170 x 300)."""


def reference_camera(image_scale: float = LEADERBOARD_IMAGE_SCALE) -> PinholeCamera:
    """The published 680 x 1200 camera at ``image_scale`` (the reference map's camera)."""
    camera = PinholeCamera()
    return camera.scaled(image_scale) if image_scale != 1.0 else camera


def reference_max_depth_m() -> float:
    """The sensor range of the reference frames: the env's default ``max_depth_m``."""
    return float(EnvSettings().max_depth_m)


class ReferenceFrames:
    """What :class:`ReferenceFusion` hands its frames to: it adds each frame to the reference
    map, or, with a ``renderer``, the renderer's frame at the same pose instead."""

    def __init__(self, reconstruction: Any) -> None:
        self.reconstruction = reconstruction
        self.renderer: RgbdRenderer | None = None

    def add_frame(self, rgb: Any, depth: Any, camera_to_world: Any) -> None:
        """Add the frame at ``camera_to_world`` (rendered anew with a renderer)."""
        if self.renderer is not None:
            rgb, depth = self.renderer.render(camera_to_world)
        self.reconstruction.add_frame(rgb, depth, camera_to_world)


class ReferenceFusion(FrameFusion):
    """Fuses a frame of the reference camera at every pose of the episode (the reset's
    included) into ``reconstruction``, under the ``mapping`` phase.

    Args:
        reconstruction: the reference map (its ``camera`` must be the reference camera).

    :meth:`before_reset` decides, from the env, whether the observations are the reference
    frames (same camera and range: no extra work) or frames must be rendered for the map.
    """

    def __init__(self, reconstruction: Any) -> None:
        self.frames = ReferenceFrames(reconstruction)
        super().__init__(self.frames)

    def before_reset(self, env: Any, policy: Any) -> None:
        base = env.unwrapped
        camera = self.frames.reconstruction.camera
        max_depth_m = reference_max_depth_m()
        same = base.camera == camera and float(base.settings.max_depth_m) == max_depth_m
        self.frames.renderer = (
            None
            if same
            else RgbdRenderer(
                base.scene,
                camera,
                max_depth_m=max_depth_m,
                raycaster=base.raycaster,
                backend=base.renderer.backend,
                threads=base.renderer.threads,
            )
        )

    @property
    def renders_own_frames(self) -> bool:
        """Whether the map's frames are rendered apart from the observations."""
        return self.frames.renderer is not None
