"""Scenes of the benchmark suite's three size classes, each drawn from one seed.

Each class draws its footprint area, aspect, height and room count from the seed, then calls
:func:`~naruto_gym.scenes.procedural.generators.generate_layout`:

=========  ===============  ===========  =======  ==========================================
kind       suite class      floor area   rooms    plan
=========  ===============  ===========  =======  ==========================================
``small``  small            40-60 m²     2-3      rooms opening into each other
``flat``   flat             100-120 m²   6-8      rooms opening into each other, or onto a
                                                  hallway (every other seed)
``house``  house            200-350 m²   12-20    hallway spine, a branch corridor from 15
                                                  rooms on, clutter in every room
=========  ===============  ===========  =======  ==========================================

Each suite class is named as its kind. The apartment-sized kind is ``flat`` because
``"apartment"`` already names the older 4-9 room scenes of
:func:`~naruto_gym.scenes.procedural.generators.make_random_scene`, whose seeds must keep
giving the same scenes. Floor area is the free footprint (width x depth);
corridors are not counted as rooms.
"""

from __future__ import annotations

import math

import numpy as np

from naruto_gym.scenes.mesh_scene import Scene
from naruto_gym.scenes.procedural.generators import generate_layout
from naruto_gym.scenes.procedural.layout import SceneLayout

#: The scene kinds of the suite's size classes, smallest first.
SIZE_CLASS_KINDS = ("small", "flat", "house")

#: Bumped whenever a seed of a size class starts giving another scene (a test pins one scene
#: per class): it names the cache folder of their meshes, so a stale file is never reused,
#: and the benchmark suite's version follows it.
SIZE_CLASSES_VERSION = 1

# Salt of the size draw's stream ([seed, salt]), apart from the layout's own stream.
_SIZE_SALT = {"small": 21, "flat": 22, "house": 23}


def _footprint(
    rng: np.random.Generator, area: tuple[float, float], aspect: tuple[float, float]
) -> tuple[float, float, float]:
    """(width, depth, area) of a footprint of random area and aspect (width >= depth)."""
    drawn = float(rng.uniform(*area))
    ratio = float(rng.uniform(*aspect))
    width = round(math.sqrt(drawn * ratio), 2)
    depth = round(drawn / width, 2)
    return width, depth, width * depth


def size_class_layout(kind: str, seed: int) -> SceneLayout:
    """The layout of scene ``seed`` of a size class (see the module's table).

    Args:
        kind: ``"small"``, ``"flat"`` or ``"house"``.
        seed: non-negative integer; the same seed always gives the same layout.

    Raises:
        ValueError: an unknown kind or a negative seed.
    """
    if kind not in SIZE_CLASS_KINDS:
        raise ValueError(
            f"size-class kind must be one of {', '.join(SIZE_CLASS_KINDS)}, got {kind!r}"
        )
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    rng = np.random.default_rng([int(seed), _SIZE_SALT[kind]])
    if kind == "small":
        width, depth, _ = _footprint(rng, (40.0, 60.0), (1.2, 1.8))
        height = round(float(rng.uniform(2.5, 2.8)), 2)
        num_rooms = int(rng.integers(2, 4))
        options: list[dict] = [{}]
    elif kind == "flat":
        width, depth, _ = _footprint(rng, (100.0, 120.0), (1.2, 1.6))
        height = round(float(rng.uniform(2.5, 2.8)), 2)
        num_rooms = int(rng.integers(6, 9))
        hallway = {"corridor_width": round(float(rng.uniform(1.2, 1.5)), 2), "clutter": 0.4}
        open_plan = {"clutter": 0.4}
        # Every other seed has a hallway; if the drawn plan does not fit, the other plan.
        options = [hallway, open_plan] if seed % 2 else [open_plan, hallway]
    else:
        width, depth, area = _footprint(rng, (200.0, 350.0), (1.15, 1.7))
        height = round(float(rng.uniform(2.6, 3.0)), 2)
        most = int(np.clip(area / 16.0, 12, 20))
        num_rooms = int(rng.integers(12, most + 1))
        corridor = round(float(rng.uniform(1.3, 1.6)), 2)
        house = {
            "corridor_width": corridor,
            "corridor_branch": num_rooms >= 15,
            "clutter": 1.0,
            "furniture_density": 1.2,
        }
        options = [house, {**house, "corridor_branch": not house["corridor_branch"]}]
    least = {"small": 2, "flat": 6, "house": 12}[kind]
    error: ValueError | None = None
    # A drawn partition may leave no cell large enough to split again: then the other plan,
    # then fewer rooms, never below the class's least.
    for rooms in range(num_rooms, least - 1, -1):
        for option in options:
            try:
                return generate_layout(seed, (width, depth, height), rooms, **option)
            except ValueError as failure:
                error = failure
    assert error is not None
    raise error


def size_class_scene(kind: str, seed: int) -> Scene:
    """The mesh of :func:`size_class_layout`, named ``"<kind>_<seed>"``."""
    return size_class_layout(kind, seed).to_scene(f"{kind}_{seed}")
