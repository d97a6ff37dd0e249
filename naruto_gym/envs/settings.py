"""The scene-independent keyword arguments of ``NarutoReconEnv``, checked once.

``NarutoReconEnv`` and the batched ``NarutoReconVectorEnv`` take the same keywords; both turn
them into an :class:`EnvSettings`, so the checks, the defaults and the derived values (the
scaled camera, the rotation limit in radians) live in one place.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from naruto_gym.envs.validation import check_settings
from naruto_gym.sensors.panorama import EquirectangularCamera
from naruto_gym.sensors.pinhole import PinholeCamera
from naruto_gym.utils.threads import resolve_threads

#: How an env makes its pinhole frames by default, one env or batched: ``"auto"``, the exact
#: rasterizer wherever it is the faster (at most 4 triangles per pixel for one frame, 16 for a
#: batched env's frames drawn together), else the ray cast; the frames are the ray cast's up
#: to float rounding of the depths and exact edge ties. ``"raycast"`` is the reference
#: (docs/environment.md, "Pinhole backends").
PINHOLE_BACKEND = "auto"


@dataclass(frozen=True)
class EnvSettings:
    """What an env builds its scenes and steps its agents with (see ``NarutoReconEnv``'s
    Arguments for the meaning of each field).

    Raises:
        ValueError: for a field of the wrong type or out of range (see
            :func:`naruto_gym.envs.validation.check_settings`): an unknown ``action_mode``,
            a non-positive ``max_depth_m``, step limit or ``image_scale``, a NaN, ...
    """

    up_axis: str = "z"
    mesh_units: str = "m"
    action_mode: str = "pose"
    camera: PinholeCamera | None = None
    image_scale: float = 1.0
    max_depth_m: float = 10.0
    panorama_shape: tuple[int, int] | None = (64, 128)
    panorama_horizon_deg: float | None = None
    agent_radius_m: float = 0.05
    max_translation_m: float = 0.1
    max_rotation_deg: float = 20.0
    escape_no_hit_threshold: float | None = 0.5
    escape_rule: str = "scanned_space"
    collision_penalty: float = 0.1
    coverage_samples: int = 20_000
    coverage_range_m: float = 5.0
    observable_only: bool = True
    start_clearance_m: float = 0.3
    raycaster_backend: str = "open3d"
    pinhole_backend: str = PINHOLE_BACKEND
    threads: int | None = None

    def __post_init__(self) -> None:
        resolve_threads(self.threads)  # a bad count fails here, with what to pass
        check_settings(self)
        if self.panorama_shape is not None:
            object.__setattr__(self, "panorama_shape", tuple(int(v) for v in self.panorama_shape))

    @property
    def pinhole_camera(self) -> PinholeCamera:
        """The camera at ``image_scale`` times its resolution (the default camera if None)."""
        camera = self.camera or PinholeCamera()
        return camera.scaled(self.image_scale) if self.image_scale != 1.0 else camera

    @property
    def panorama_camera(self) -> EquirectangularCamera | None:
        """The observation panorama's camera: ``panorama_shape``, the rows cast by
        ``panorama_horizon_deg`` (None when the panorama is off)."""
        if self.panorama_shape is None:
            return None
        return EquirectangularCamera(*self.panorama_shape, horizon_deg=self.panorama_horizon_deg)

    @property
    def max_rotation_rad(self) -> float:
        """The rotation limit of one step, in radians."""
        return float(np.deg2rad(self.max_rotation_deg))
