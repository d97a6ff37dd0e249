"""Checks of the keyword arguments the envs take, each with an error that says what to pass.

``EnvSettings`` (the keywords ``NarutoReconEnv`` and ``NarutoReconVectorEnv`` share) and the
vector env's own keywords are checked here, with the helpers of :mod:`naruto_gym.utils.checks`,
before anything is built, so that a wrong type, a NaN or a value out of range fails at
construction with one ``ValueError`` naming the keyword, rather than deep inside a renderer or
a Gymnasium space.
"""

from __future__ import annotations

from typing import Any

from naruto_gym.motion.actions import ACTION_MODES
from naruto_gym.motion.collision import ESCAPE_RULES
from naruto_gym.scenes.mesh_scene import UP_AXES
from naruto_gym.scenes.units import MESH_UNITS
from naruto_gym.sensors.panorama import EquirectangularCamera
from naruto_gym.sensors.pinhole import PINHOLE_BACKENDS, PinholeCamera
from naruto_gym.sensors.raycaster import RAYCASTER_BACKENDS
from naruto_gym.utils.checks import (
    check_bool,
    check_choice,
    check_integer,
    check_number,
    is_integer,
)

#: The most pixels along either side of the pinhole image (``camera`` times ``image_scale``).
MAX_IMAGE_SIDE = 16_384
#: The most pixels along either side of the panorama.
MAX_PANORAMA_SIDE = 8_192
#: The largest length in metres a setting takes (a thousand kilometres: far past any scene,
#: and inside float32, in which depth images and observation bounds are stored).
MAX_LENGTH_M = 1e6
#: The most coverage samples (each costs a projection per step).
MAX_COVERAGE_SAMPLES = 10_000_000
#: Keywords of the envs renamed so that one concept has one name: old name -> new name. An
#: old name is refused with an error naming the new one (0.x: no aliases).
RENAMED_KEYWORDS: dict[str, str] = {"step_budget": "max_episode_steps"}


def check_panorama_shape(value: Any) -> tuple[int, int] | None:
    """``panorama_shape``: None, or two positive integers (height, width)."""
    if value is None:
        return None
    try:
        height, width = value
    except (TypeError, ValueError):
        raise ValueError(f"panorama_shape must be None or (height, width), got {value!r}") from None
    for side, name in ((height, "height"), (width, "width")):
        check_integer(f"panorama_shape {name}", side, low=1, high=MAX_PANORAMA_SIDE)
    return int(height), int(width)


def check_keyword_names(given: Any, accepted: Any, owner: str, hint: str = "") -> None:
    """Refuse keyword names ``owner`` does not take, with the names it does take.

    Raises:
        ValueError: an old name of :data:`RENAMED_KEYWORDS` (the message names the new one),
            or an unknown keyword (the message lists the accepted ones and ``hint``).
    """
    for old, new in RENAMED_KEYWORDS.items():
        if old in given and new in accepted:
            value = f"={given[old]!r}" if isinstance(given, dict) else ""
            raise ValueError(f"{owner}'s keyword {old!r} was renamed: pass {new}{value} instead")
    unknown = sorted(set(given) - set(accepted))
    if unknown:
        raise ValueError(
            f"{owner} got unknown keyword(s) {', '.join(map(repr, unknown))}; it takes "
            f"{', '.join(sorted(accepted))}{'. ' + hint if hint else ''}"
        )


def check_settings(settings: Any) -> None:
    """Check every field of an ``EnvSettings`` (see ``NarutoReconEnv``'s Arguments).

    Raises:
        ValueError: the first field that is of the wrong type or out of range, by name.
    """
    check_choice("up_axis", settings.up_axis, UP_AXES)
    check_choice("mesh_units", settings.mesh_units, tuple(MESH_UNITS))
    check_choice("action_mode", settings.action_mode, ACTION_MODES)
    if settings.camera is not None and not isinstance(settings.camera, PinholeCamera):
        raise ValueError(
            f"camera must be a naruto_gym.sensors.PinholeCamera or None, got "
            f"{type(settings.camera).__name__}"
        )
    check_number("image_scale", settings.image_scale, low=0.0)
    camera = settings.camera or PinholeCamera()
    scaled = camera.width * float(settings.image_scale), camera.height * float(settings.image_scale)
    if max(scaled) > MAX_IMAGE_SIDE:
        raise ValueError(
            f"image_scale={settings.image_scale!r} makes a {scaled[0]:.0f} x {scaled[1]:.0f} "
            f"image from a {camera.width} x {camera.height} camera; the most is "
            f"{MAX_IMAGE_SIDE} pixels a side"
        )
    check_number("max_depth_m", settings.max_depth_m, low=0.0, high=MAX_LENGTH_M)
    check_panorama_shape(settings.panorama_shape)
    if settings.panorama_horizon_deg is not None:
        if settings.panorama_shape is None:
            raise ValueError(
                "panorama_horizon_deg limits the rows of the panorama, which panorama_shape=None "
                "switches off: pass a panorama_shape or panorama_horizon_deg=None"
            )
        check_number("panorama_horizon_deg", settings.panorama_horizon_deg, low=0.0, high=90.0)
        try:
            EquirectangularCamera(*settings.panorama_shape, settings.panorama_horizon_deg)
        except ValueError as error:
            raise ValueError(
                f"panorama_horizon_deg with panorama_shape={settings.panorama_shape}: {error}"
            ) from None
    check_number("agent_radius_m", settings.agent_radius_m, low=0.0, high=MAX_LENGTH_M)
    check_number("max_translation_m", settings.max_translation_m, low=0.0, high=MAX_LENGTH_M)
    check_number("max_rotation_deg", settings.max_rotation_deg, low=0.0, high=180.0)
    if settings.escape_no_hit_threshold is not None:
        check_number(
            "escape_no_hit_threshold",
            settings.escape_no_hit_threshold,
            low=0.0,
            high=1.0,
            low_open=False,
        )
    check_choice("escape_rule", settings.escape_rule, ESCAPE_RULES)
    check_number("collision_penalty", settings.collision_penalty, low=-1e12, high=1e12)
    check_integer("coverage_samples", settings.coverage_samples, low=1, high=MAX_COVERAGE_SAMPLES)
    check_number("coverage_range_m", settings.coverage_range_m, low=0.0, high=MAX_LENGTH_M)
    check_bool("observable_only", settings.observable_only)
    check_number(
        "start_clearance_m", settings.start_clearance_m, low=0.0, high=MAX_LENGTH_M, low_open=False
    )
    check_choice("raycaster_backend", settings.raycaster_backend, RAYCASTER_BACKENDS)
    check_choice("pinhole_backend", settings.pinhole_backend, PINHOLE_BACKENDS)


def check_seed(seed: Any) -> int | None:
    """A reset seed as Gymnasium takes it: None, or a non-negative Python int (NumPy
    integers of any width are converted), else a ``ValueError`` saying what to pass."""
    if seed is None:
        return None
    if not is_integer(seed) or seed < 0:
        raise ValueError(f"seed must be None or a non-negative integer, got {seed!r}")
    return int(seed)


def check_reset_options(options: Any, supported: tuple[str, ...]) -> dict[str, Any]:
    """Reset ``options`` as a dict (None gives an empty one), else a ``ValueError``."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise ValueError(
            f"reset options must be None or a dict with keys among {list(supported)}, got "
            f"{type(options).__name__}"
        )
    return options


def check_env_keywords(
    render_mode: Any, render_modes: list[str], reconstruct: Any, max_episode_steps: Any
) -> None:
    """Check the single env's own keywords (the rest are ``EnvSettings``')."""
    if render_mode is not None and (
        not isinstance(render_mode, str) or render_mode not in render_modes
    ):
        raise ValueError(f"render_mode must be None or one of {render_modes}, got {render_mode!r}")
    check_bool("reconstruct", reconstruct)
    if max_episode_steps is not None:
        check_integer("max_episode_steps", max_episode_steps, low=1)


def check_vector_keywords(max_episode_steps: Any, scene_cache_size: Any) -> None:
    """Check the batched vector env's own keywords (the rest are ``EnvSettings``')."""
    if max_episode_steps is not None:
        check_integer("max_episode_steps", max_episode_steps, low=1)
    check_integer("scene_cache_size", scene_cache_size, low=0)
