"""Observations shaped for learning: single-env wrappers of the transforms of
:mod:`naruto_gym.wrappers.observation`, and :func:`for_learning`, the usual chain on a single
env or a batched one (with :mod:`naruto_gym.wrappers.vector`)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from naruto_gym.wrappers.observation import (
    DepthTransform,
    DropKeys,
    MapTransform,
    ObservationTransform,
    PoseTransform,
    ResizeTransform,
)
from naruto_gym.wrappers.vector import VectorTransformObservation

__all__ = ["EgocentricMap", "FlatPose", "NormalizeDepth", "ResizeFrames", "for_learning"]


class _TransformObservation(gym.Wrapper):
    """Applies one :class:`~naruto_gym.wrappers.observation.ObservationTransform` to a single
    env."""

    def __init__(self, env: gym.Env, transform: ObservationTransform) -> None:
        super().__init__(env)
        self.transform = transform
        self.observation_space = transform.space(env.observation_space)
        transform.bind(getattr(env.unwrapped, "camera", None), 1)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        observation, info = self.env.reset(seed=seed, options=options)
        self.transform.reset_envs([getattr(self.env.unwrapped, "bounds", None)], [0])
        return self._apply(observation), info

    def step(self, action: Any):
        observation, reward, terminated, truncated, info = self.env.step(action)
        return self._apply(observation), reward, terminated, truncated, info

    def _apply(self, observation: dict[str, Any]) -> dict[str, Any]:
        batch = {key: value[None] for key, value in observation.items()}
        return {key: value[0] for key, value in self.transform.apply(batch).items()}


class ResizeFrames(_TransformObservation, gym.utils.RecordConstructorArgs):
    """``rgb`` and ``depth`` resized to ``size x size`` pixels (nearest pixel).

    Args:
        env: the env (its observation a ``Dict`` with ``rgb`` and ``depth``).
        size: output side in pixels, e.g. 64 or 128.
    """

    def __init__(self, env: gym.Env, size: int = 64) -> None:

        gym.utils.RecordConstructorArgs.__init__(self, size=size)
        super().__init__(env, ResizeTransform(size))


class NormalizeDepth(_TransformObservation, gym.utils.RecordConstructorArgs):
    """``depth`` in metres -> ``(H, W, 1)`` in [0, 1] of the sensor range: uint8 (0..255, an
    image for CNN policies) or float32. 0 stays "no hit".

    Args:
        env: the env.
        dtype: ``"uint8"`` (default) or ``"float"``.
        max_depth_m: the depth mapped to 1 (default: the depth space's upper bound).
    """

    def __init__(self, env: gym.Env, dtype: str = "uint8", max_depth_m: float | None = None):

        gym.utils.RecordConstructorArgs.__init__(self, dtype=dtype, max_depth_m=max_depth_m)
        super().__init__(env, DepthTransform(max_depth_m, dtype))  # type: ignore[arg-type]


class FlatPose(_TransformObservation, gym.utils.RecordConstructorArgs):
    """``pose`` 4x4 -> ``(9,)`` float32: position and the 6D rotation (first two columns)."""

    def __init__(self, env: gym.Env) -> None:

        gym.utils.RecordConstructorArgs.__init__(self)
        super().__init__(env, PoseTransform())


class EgocentricMap(_TransformObservation, gym.utils.RecordConstructorArgs):
    """Adds ``"map"``, an egocentric top-down map (``cells x cells x 2`` uint8) of what the
    episode has seen (channel 0) and of what is occupied (channel 1), from the observations
    alone. Wrap it before ``ResizeFrames``, ``NormalizeDepth`` and ``FlatPose``.

    Args:
        env: the env.
        cells: map side in cells.
        cell_m: cell side in metres.
        stride: every ``stride``-th pixel of the depth frame is projected.
        obstacle_m: height above the floor estimate from which a hit is an obstacle.
    """

    def __init__(
        self,
        env: gym.Env,
        cells: int = 32,
        cell_m: float = 0.15,
        stride: int = 2,
        obstacle_m: float = 0.15,
    ) -> None:

        gym.utils.RecordConstructorArgs.__init__(
            self, cells=cells, cell_m=cell_m, stride=stride, obstacle_m=obstacle_m
        )
        super().__init__(env, MapTransform(cells, cell_m, stride, obstacle_m))


def for_learning(
    env: Any,
    size: int = 64,
    depth: str = "uint8",
    flat_pose: bool = True,
    top_down_map: bool = False,
    keep_panorama: bool = False,
) -> Any:
    """The usual learning chain on a single env or on a batched env:
    (egocentric map), frames resized to ``size``, depth normalised, pose flattened; the
    panorama dropped unless ``keep_panorama``.

    Args:
        env: a ``NarutoReconEnv`` (wrapped or not) or a batched env
            (``naruto_gym.vector.make_vector_env``).
        size: square frame side (pixels).
        depth: ``"uint8"`` or ``"float"``.
        flat_pose: pose as position + 6D rotation.
        top_down_map: add the egocentric top-down map.
        keep_panorama: keep the ``panorama`` observation.
    """
    transforms: list[Any] = []
    if top_down_map:
        transforms.append(MapTransform())
    transforms += [ResizeTransform(size), DepthTransform(None, depth)]  # type: ignore[arg-type]
    if flat_pose:
        transforms.append(PoseTransform())
    if not keep_panorama:
        transforms.append(DropKeys(("panorama",)))
    if isinstance(env, gym.vector.VectorEnv):
        for transform in transforms:
            env = VectorTransformObservation(env, transform)
        return env
    if top_down_map:
        env = EgocentricMap(env)
    env = NormalizeDepth(ResizeFrames(env, size), dtype=depth)
    if flat_pose:
        env = FlatPose(env)
    if not keep_panorama and "panorama" in env.observation_space.spaces:
        keys = [key for key in env.observation_space.spaces if key != "panorama"]
        env = gym.wrappers.FilterObservation(env, keys)
    return env
