"""Clutter: the small things lived-in houses hold beside their furniture.

Real multi-room scans (Matterport3D, HM3D) are full of small objects that occlude and must be
looked around: moving boxes, a stray chair, stools, laundry baskets, side tables, shoe racks.
The builders here follow the convention of :mod:`naruto_gym.scenes.procedural.furniture`
(``(width, depth, height, parts)`` in a local frame, x along the wall, y into the room) and
:data:`CLUTTER` lists them with their placement and probability, as ``FURNITURE`` does per
room kind. The furnishing step places them after a room's furniture when a layout asks for
clutter, with the same gaps, so they never block a doorway or close off part of a room.
"""

from __future__ import annotations

import numpy as np

from naruto_gym.scenes.procedural.furniture import (
    FABRICS,
    METALS,
    WOODS,
    LocalPart,
    bright,
    jitter,
    pick,
)

_CARDBOARD = [(176, 138, 96), (160, 124, 84), (196, 160, 116), (140, 112, 80)]


def _box(x0: float, y0: float, z0: float, x1: float, y1: float, z1: float, rgb) -> LocalPart:
    return ("box", (x0, y0, z0, x1, y1, z1), (rgb,))


def _moving_boxes(rng: np.random.Generator, ceiling: float):
    """A stack of one to three cardboard boxes, each a little smaller and shifted."""
    width, depth = float(rng.uniform(0.4, 0.65)), float(rng.uniform(0.35, 0.55))
    parts: list[LocalPart] = []
    z = 0.0
    for level in range(int(rng.integers(1, 4))):
        shrink = 0.06 * level
        shift = float(rng.uniform(-0.03, 0.03))
        x0, y0 = shrink + abs(shift), shrink
        x1, y1 = width - shrink - abs(shift), depth - shrink
        box_height = float(rng.uniform(0.25, 0.45))
        colour = jitter(rng, pick(rng, _CARDBOARD), 10)
        parts.append(_box(x0, y0, z, x1, y1, z + box_height, colour))
        # The tape across the lid.
        mid = 0.5 * (x0 + x1)
        parts.append(_box(mid - 0.025, y0, z + box_height, mid + 0.025, y1, z + box_height + 0.004,
                          (210, 200, 170)))
        z += box_height + 0.004
    return width, depth, z, parts


def _stray_chair(rng: np.random.Generator, ceiling: float):
    """One chair standing on its own."""
    size, seat = 0.44, float(rng.uniform(0.43, 0.48))
    wood, fabric = pick(rng, WOODS), pick(rng, FABRICS)
    parts = [_box(0.0, 0.0, seat - 0.05, size, size, seat, fabric)]
    leg = 0.04
    for x in (0.0, size - leg):
        for y in (0.0, size - leg):
            parts.append(_box(x, y, 0.0, x + leg, y + leg, seat - 0.05, wood))
    parts.append(_box(0.0, 0.0, seat, size, 0.05, float(rng.uniform(0.85, 0.98)), wood))
    return size, size, 0.98, parts


def _stool(rng: np.random.Generator, ceiling: float):
    """A round stool."""
    radius, height = float(rng.uniform(0.16, 0.22)), float(rng.uniform(0.42, 0.7))
    metal, top = pick(rng, METALS), bright(rng)
    c = radius
    parts: list[LocalPart] = [
        ("frustum", (c, c, 0.0, radius * 0.9, radius * 0.9, 0.03), (metal,)),
        ("frustum", (c, c, 0.03, 0.025, 0.025, height - 0.08), (metal,)),
        ("frustum", (c, c, height - 0.05, radius, radius, 0.05), (top,)),
    ]
    return 2 * radius, 2 * radius, height, parts


def _laundry_basket(rng: np.random.Generator, ceiling: float):
    """A basket with clothes heaped in it."""
    radius, height = float(rng.uniform(0.2, 0.28)), float(rng.uniform(0.35, 0.55))
    wicker = pick(rng, [(190, 160, 110), (230, 230, 230), (90, 120, 160)])
    c = radius
    parts: list[LocalPart] = [
        ("frustum", (c, c, 0.0, radius * 0.85, radius, height), (wicker,)),
        ("sphere", (c * 0.8, c, height - 0.02, radius * 0.45), (pick(rng, FABRICS),)),
        ("sphere", (c * 1.2, c * 1.1, height, radius * 0.4), (bright(rng),)),
    ]
    return 2 * radius, 2 * radius, height + radius * 0.4, parts


def _side_table(rng: np.random.Generator, ceiling: float):
    """A small table with a lamp and a pile of books."""
    width, depth, height = float(rng.uniform(0.4, 0.6)), float(rng.uniform(0.35, 0.5)), 0.6
    wood = pick(rng, WOODS)
    parts = [_box(0.0, 0.0, height - 0.03, width, depth, height, wood)]
    leg = 0.035
    for x in (0.0, width - leg):
        for y in (0.0, depth - leg):
            parts.append(_box(x, y, 0.0, x + leg, y + leg, height - 0.03, wood))
    parts.append(("frustum", (0.3 * width, 0.5 * depth, height, 0.06, 0.05, 0.25), (METALS[1],)))
    parts.append(("frustum", (0.3 * width, 0.5 * depth, height + 0.25, 0.14, 0.09, 0.16),
                  (bright(rng),)))
    z = height
    for _ in range(int(rng.integers(1, 4))):
        thick = float(rng.uniform(0.025, 0.05))
        parts.append(_box(0.6 * width, 0.15 * depth, z, 0.95 * width, 0.8 * depth, z + thick,
                          bright(rng)))
        z += thick
    return width, depth, height + 0.41, parts


def _shoe_rack(rng: np.random.Generator, ceiling: float):
    """A low rack with two rows of shoes."""
    width, depth, height = float(rng.uniform(0.6, 1.0)), 0.32, 0.5
    wood = pick(rng, WOODS)
    parts = [_box(0.0, 0.0, 0.0, 0.03, depth, height, wood),
             _box(width - 0.03, 0.0, 0.0, width, depth, height, wood)]
    for z in (0.05, 0.28):
        parts.append(_box(0.03, 0.0, z, width - 0.03, depth, z + 0.02, wood))
        x = 0.06
        while x < width - 0.16:
            colour = pick(rng, [(30, 30, 34), (120, 80, 50), (200, 200, 200), bright(rng)])
            parts.append(_box(x, 0.03, z + 0.02, x + 0.09, depth - 0.02, z + 0.1, colour))
            x += float(rng.uniform(0.11, 0.16))
    return width, depth, height, parts


# (builder, placement, probability), as ``FURNITURE`` lists a room kind's furniture: tried
# in every room of a cluttered layout, each probability scaled by the layout's clutter.
CLUTTER: list[tuple] = [
    (_moving_boxes, "wall", 0.55), (_moving_boxes, "free", 0.35), (_stray_chair, "free", 0.45),
    (_stool, "free", 0.35), (_laundry_basket, "free", 0.35), (_side_table, "wall", 0.45),
    (_shoe_rack, "wall", 0.3),
]
