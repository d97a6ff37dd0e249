"""What a policy can show of its thinking: named layers of points, line strips, boxes, scalars.

A policy returns them from :meth:`~naruto_agent.policies.Policy.view_layers` (the default
returns none). A recorder (:mod:`naruto_agent.recording`) draws 3D layers in the world at
``world/policy/<name>`` and plots scalars over the steps at ``policy/<name>``; this module
knows nothing of any viewer, so a policy that shows layers needs no viewer installed.

Layers hold world coordinates (metres, z up) and RGB colours as 0-255 integers.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from naruto_gym.utils.checks import check_integer, check_number

#: A layer name: letters, digits, spaces and ``-_().%``, with ``/`` between sub-layers.
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9 _\-().%]*(/[A-Za-z0-9][A-Za-z0-9 _\-().%]*)*")


def _check_name(name: str) -> str:
    if not isinstance(name, str) or not _NAME.fullmatch(name) or name != name.strip():
        raise ValueError(
            f"a layer name holds letters, digits, spaces and -_().%, with '/' between "
            f"sub-layers (e.g. 'goals' or 'frontier/near'); got {name!r}"
        )
    return name


def _points(values: object, what: str) -> np.ndarray:
    array = np.asarray(values, dtype=np.float64)
    if array.size == 0:
        return np.zeros((0, 3))
    if array.ndim != 2 or array.shape[1] != 3 or not np.all(np.isfinite(array)):
        raise ValueError(
            f"{what} must be a finite (N, 3) array of world points, got shape {array.shape}"
        )
    return array


def _colour(value: tuple[int, int, int], what: str) -> tuple[int, int, int]:
    try:
        channels = tuple(value)
    except TypeError:
        channels = ()
    if len(channels) != 3:
        raise ValueError(f"{what} is three integers 0-255 (R, G, B), got {value!r}")
    colour = tuple(
        check_integer(f"{what} {band}", channel, low=0, high=255)
        for band, channel in zip(("red", "green", "blue"), channels, strict=True)
    )
    return colour  # type: ignore[return-value]


@dataclass(frozen=True)
class PointsLayer:
    """Points in the world, e.g. a frontier or the targets of a goal.

    Attributes:
        name: the layer's name (see :func:`layer_names`).
        points: (N, 3) world positions.
        colour: RGB of every point.
        colours: (N, 3) uint8 RGB per point instead of ``colour``, or None.
        radius_m: the points' radius.
    """

    name: str
    points: np.ndarray
    colour: tuple[int, int, int] = (255, 200, 0)
    colours: np.ndarray | None = None
    radius_m: float = 0.03

    def __post_init__(self) -> None:
        _check_name(self.name)
        object.__setattr__(self, "points", _points(self.points, f"layer {self.name!r} points"))
        object.__setattr__(self, "colour", _colour(self.colour, f"layer {self.name!r} colour"))
        check_number(f"layer {self.name!r} radius_m", self.radius_m, low=0.0)
        if self.colours is not None:
            colours = np.asarray(self.colours)
            if colours.shape != (len(self.points), 3):
                raise ValueError(
                    f"layer {self.name!r}: colours must be (N, 3) for N points, "
                    f"got {colours.shape} for {len(self.points)}"
                )
            object.__setattr__(self, "colours", np.clip(colours, 0, 255).astype(np.uint8))


@dataclass(frozen=True)
class LinesLayer:
    """Polylines in the world, e.g. a planned path.

    Attributes:
        name: the layer's name.
        strips: each a (K, 3) array of world points joined in order.
        colour: RGB of the lines.
        width_m: the lines' width.
    """

    name: str
    strips: tuple[np.ndarray, ...] = field(default_factory=tuple)
    colour: tuple[int, int, int] = (0, 200, 255)
    width_m: float = 0.02

    def __post_init__(self) -> None:
        _check_name(self.name)
        strips = tuple(_points(strip, f"layer {self.name!r} strip") for strip in self.strips)
        object.__setattr__(self, "strips", strips)
        object.__setattr__(self, "colour", _colour(self.colour, f"layer {self.name!r} colour"))
        check_number(f"layer {self.name!r} width_m", self.width_m, low=0.0)


@dataclass(frozen=True)
class BoxesLayer:
    """Axis-aligned boxes in the world, e.g. space a policy learned to avoid.

    Attributes:
        name: the layer's name.
        centres: (N, 3) box centres.
        half_sizes: (N, 3) half extents (or (3,) for all boxes).
        colour: RGB of the boxes.
    """

    name: str
    centres: np.ndarray
    half_sizes: np.ndarray
    colour: tuple[int, int, int] = (255, 60, 60)

    def __post_init__(self) -> None:
        _check_name(self.name)
        centres = _points(self.centres, f"layer {self.name!r} centres")
        half = np.broadcast_to(np.asarray(self.half_sizes, np.float64), centres.shape).copy()
        if np.any(half < 0):
            raise ValueError(f"layer {self.name!r}: half sizes must be >= 0")
        object.__setattr__(self, "centres", centres)
        object.__setattr__(self, "half_sizes", half)
        object.__setattr__(self, "colour", _colour(self.colour, f"layer {self.name!r} colour"))


@dataclass(frozen=True)
class ScalarLayer:
    """One number at the current step, plotted over the episode (e.g. a goal's score).

    Attributes:
        name: the layer's name.
        value: the number.
    """

    name: str
    value: float

    def __post_init__(self) -> None:
        _check_name(self.name)
        object.__setattr__(self, "value", float(self.value))


Layer = PointsLayer | LinesLayer | BoxesLayer | ScalarLayer


def layer_names(layers: list[Layer]) -> list[str]:
    """The names of ``layers`` in order; raises ValueError when two share a name."""
    names = [layer.name for layer in layers]
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise ValueError(f"layer names must be unique within a step; repeated: {repeated}")
    return names


def subsample(points: np.ndarray, limit: int) -> np.ndarray:
    """At most ``limit`` of ``points``, evenly spread through the array (deterministic), so
    that a large frontier stays light to record."""
    points = np.asarray(points)
    if len(points) <= limit:
        return points
    return points[np.linspace(0, len(points) - 1, limit).round().astype(int)]
