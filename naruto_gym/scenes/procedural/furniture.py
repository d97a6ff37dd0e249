"""Furniture and decorations for the procedural scenes, built from coloured primitives.

Every builder draws its sizes and colours from the generator's random stream and returns
``(width, depth, height, parts)`` in a local frame: x runs along the wall the object backs
onto, y points from that wall into the room, z up, origin at the back-left corner of the
footprint ``[0, width] x [0, depth]``. Parts are ``(kind, data, colours)`` tuples, with the
same meaning as :class:`naruto_gym.scenes.procedural.plan.Part` but in the local frame.
"""

from __future__ import annotations

import colorsys
from collections.abc import Sequence

import numpy as np

RGB = tuple[int, int, int]

WALL_PAINTS: list[RGB] = [
    (228, 220, 205), (200, 218, 232), (222, 204, 210), (208, 226, 204), (236, 228, 188),
    (198, 200, 214), (236, 236, 230), (226, 208, 186), (190, 214, 210), (230, 196, 180),
]
WOODS: list[RGB] = [
    (150, 111, 72), (118, 84, 54), (188, 152, 110), (96, 64, 40), (206, 172, 128), (140, 96, 70)
]
FABRICS: list[RGB] = [
    (70, 90, 140), (150, 60, 60), (90, 130, 90), (200, 170, 80), (120, 120, 132),
    (170, 110, 150), (60, 120, 130), (210, 120, 70), (60, 60, 70), (200, 190, 170),
]
METALS: list[RGB] = [(58, 58, 64), (170, 170, 176), (196, 184, 140), (30, 30, 34)]


# ---------------------------------------------------------------------------------------
# Colours
# ---------------------------------------------------------------------------------------
def pick(rng: np.random.Generator, palette: Sequence[RGB]) -> RGB:
    """One colour of ``palette``."""
    return palette[int(rng.integers(len(palette)))]


def jitter(rng: np.random.Generator, colour: Sequence[int], amount: int) -> RGB:
    """``colour`` with each channel moved by up to ``amount``."""
    noise = rng.integers(-amount, amount + 1, size=3)
    return tuple(int(v) for v in np.clip(np.asarray(colour) + noise, 0, 255))  # type: ignore


def hsv(hue: float, saturation: float, value: float) -> RGB:
    """RGB of a hue (wrapped to [0, 1)), saturation and value in [0, 1]."""
    r, g, b = colorsys.hsv_to_rgb(hue % 1.0, saturation, value)
    return (int(r * 255 + 0.5), int(g * 255 + 0.5), int(b * 255 + 0.5))


def bright(rng: np.random.Generator) -> RGB:
    """A random saturated colour (books, cushions, cabinet fronts)."""
    return hsv(float(rng.random()), float(rng.uniform(0.45, 0.85)), float(rng.uniform(0.5, 0.95)))


# ---------------------------------------------------------------------------------------
# Furniture: each builder returns (width, depth, height, parts) in a local frame whose
# x runs along the wall, y points from the wall into the room, origin at the back-left.
# ---------------------------------------------------------------------------------------
LocalPart = tuple[str, tuple[float, ...], tuple[RGB, ...]]


def _b(x0: float, y0: float, z0: float, x1: float, y1: float, z1: float, *rgb: RGB) -> LocalPart:
    return ("box", (x0, y0, z0, x1, y1, z1), tuple(rgb))


def _legs(x0: float, y0: float, x1: float, y1: float, height: float, size: float, rgb: RGB):
    return [
        _b(x, y, 0.0, x + size, y + size, height, rgb)
        for x in (x0, x1 - size) for y in (y0, y1 - size)
    ]


def _table(rng, ceiling: float) -> tuple[float, float, float, list[LocalPart]]:
    width, depth = float(rng.uniform(1.2, 1.7)), float(rng.uniform(0.8, 0.95))
    height, wood, fabric = 0.75, pick(rng, WOODS), pick(rng, FABRICS)
    chair_depth = 0.55
    total_depth = depth + 2 * chair_depth
    ty0 = chair_depth
    parts = [_b(0.0, ty0, height - 0.04, width, ty0 + depth, height, wood)]
    parts += _legs(0.05, ty0 + 0.05, width - 0.05, ty0 + depth - 0.05, height - 0.04, 0.06, wood)
    chairs = 2 if width < 1.45 else 3
    for k in range(chairs):
        cx = width * (k + 0.5) / chairs
        for front in (True, False):
            y0 = 0.02 if front else ty0 + depth + 0.05
            parts += _chair(cx - 0.21, y0, back_at_low_y=front, rgb=fabric, legs_rgb=wood)
    # A pendant lamp hanging over the table from the ceiling.
    cx, cy = width / 2, ty0 + depth / 2
    shade_z = ceiling - 0.95
    parts.append(("frustum", (cx, cy, shade_z + 0.28, 0.008, 0.008, ceiling - shade_z - 0.28),
                  (METALS[0],)))
    parts.append(("frustum", (cx, cy, shade_z, 0.26, 0.1, 0.28), (bright(rng),)))
    return width, total_depth, height, parts


def _chair(x0: float, y0: float, back_at_low_y: bool, rgb: RGB, legs_rgb: RGB) -> list[LocalPart]:
    size, seat = 0.42, 0.45
    parts = [_b(x0, y0, seat - 0.05, x0 + size, y0 + size, seat, rgb)]
    parts += _legs(x0, y0, x0 + size, y0 + size, seat - 0.05, 0.04, legs_rgb)
    by0 = y0 if back_at_low_y else y0 + size - 0.05
    parts.append(_b(x0, by0, seat, x0 + size, by0 + 0.05, 0.92, rgb))
    return parts


def _coffee_table(rng, ceiling: float):
    width, depth, height = float(rng.uniform(0.9, 1.2)), float(rng.uniform(0.5, 0.65)), 0.42
    wood = pick(rng, WOODS)
    parts = [_b(0.0, 0.0, height - 0.05, width, depth, height, wood),
             _b(0.05, 0.05, 0.12, width - 0.05, depth - 0.05, 0.15, pick(rng, WOODS))]
    parts += _legs(0.0, 0.0, width, depth, height - 0.05, 0.05, wood)
    parts.append(("sphere", (width * 0.3, depth * 0.5, height + 0.09, 0.09), (bright(rng),)))
    return width, depth, height, parts


def _sofa(rng, ceiling: float):
    width, depth = float(rng.uniform(1.6, 2.3)), float(rng.uniform(0.85, 0.95))
    fabric, cushion = pick(rng, FABRICS), bright(rng)
    arm = 0.18
    parts = [
        _b(0.0, 0.0, 0.0, width, depth, 0.42, fabric),
        _b(0.0, 0.0, 0.42, width, 0.22, 0.85, fabric),
        _b(0.0, 0.22, 0.42, arm, depth, 0.62, fabric),
        _b(width - arm, 0.22, 0.42, width, depth, 0.62, fabric),
    ]
    seats = 2 if width < 1.9 else 3
    span = (width - 2 * arm) / seats
    for k in range(seats):
        x0 = arm + k * span + 0.02
        parts.append(_b(x0, 0.24, 0.42, x0 + span - 0.04, depth - 0.04, 0.52,
                        jitter(rng, fabric, 18)))
        parts.append(_b(x0 + 0.08, 0.22, 0.52, x0 + span - 0.12, 0.36, 0.8, cushion))
    return width, depth, 0.85, parts


def _bed(rng, ceiling: float):
    width, depth = float(rng.choice([1.4, 1.6, 1.8])), float(rng.uniform(1.95, 2.1))
    wood, sheet, blanket = pick(rng, WOODS), (236, 236, 240), bright(rng)
    parts = [
        _b(0.0, 0.0, 0.0, width, depth, 0.3, wood),
        _b(0.0, 0.0, 0.0, width, 0.08, 1.05, wood),
        _b(0.04, 0.08, 0.3, width - 0.04, depth - 0.02, 0.5, sheet),
        _b(0.02, depth * 0.38, 0.3, width - 0.02, depth, 0.54, blanket),
    ]
    pillows = 2 if width > 1.2 else 1
    pw = (width - 0.2) / pillows
    for k in range(pillows):
        x0 = 0.1 + k * pw
        parts.append(_b(x0 + 0.03, 0.12, 0.5, x0 + pw - 0.03, 0.5, 0.62, (250, 250, 246)))
    return width, depth, 1.05, parts


def _bookshelf(rng, ceiling: float):
    width, depth = float(rng.uniform(0.8, 1.3)), float(rng.uniform(0.3, 0.38))
    height = float(min(rng.uniform(1.6, 2.1), ceiling - 0.4))
    wood, side = pick(rng, WOODS), 0.03
    parts = [
        _b(0.0, 0.0, 0.0, side, depth, height, wood),
        _b(width - side, 0.0, 0.0, width, depth, height, wood),
        _b(side, 0.0, 0.0, width - side, 0.02, height - side, jitter(rng, wood, 20)),
        _b(side, 0.0, height - side, width - side, depth, height, wood),
    ]
    levels = int(rng.integers(4, 6))
    pitch = (height - side) / levels
    for k in range(levels):
        z = k * pitch
        parts.append(_b(side, 0.02, z, width - side, depth, z + side, wood))
        x = side + 0.02
        while x < width - side - 0.08:
            book_w = float(rng.uniform(0.03, 0.07))
            if rng.random() < 0.15:  # leave gaps so the shelves are not solid walls of books
                x += book_w * 2
                continue
            book_h = float(rng.uniform(0.55, 0.85)) * (pitch - side)
            book_d = float(rng.uniform(0.6, 0.9)) * (depth - 0.03)
            parts.append(_b(x, 0.02, z + side, x + book_w, 0.02 + book_d, z + side + book_h,
                            bright(rng)))
            x += book_w + 0.004
    return width, depth, height, parts


def _cabinet(rng, ceiling: float, tall: bool | None = None):
    tall = bool(rng.random() < 0.5) if tall is None else tall
    width = float(rng.uniform(0.8, 1.6))
    depth = float(rng.uniform(0.5, 0.62)) if tall else float(rng.uniform(0.4, 0.5))
    height = float(min(rng.uniform(1.8, 2.2), ceiling - 0.4)) if tall else float(
        rng.uniform(0.7, 0.95)
    )
    body, front, handle = pick(rng, WOODS), bright(rng), pick(rng, METALS)
    parts = [_b(0.0, 0.0, 0.0, width, depth - 0.02, height, body)]
    doors = max(1, int(round(width / 0.5)))
    door_w = (width - 0.04) / doors
    for k in range(doors):
        x0 = 0.02 + k * door_w
        parts.append(_b(x0 + 0.01, depth - 0.02, 0.06, x0 + door_w - 0.01, depth, height - 0.03,
                        front))
        hx = x0 + (door_w - 0.06 if k % 2 == 0 else 0.03)
        parts.append(_b(hx, depth, height * 0.5 - 0.08, hx + 0.025, depth + 0.025,
                        height * 0.5 + 0.08, handle))
    if not tall:  # something standing on a low cabinet
        parts.append(("frustum", (width * 0.25, depth * 0.5, height, 0.08, 0.06, 0.25),
                      (bright(rng),)))
        parts.append(("sphere", (width * 0.7, depth * 0.5, height + 0.1, 0.1), (bright(rng),)))
    return width, depth + 0.025, height, parts


def _tv_unit(rng, ceiling: float):
    width, depth, height = float(rng.uniform(1.4, 2.0)), 0.45, 0.5
    wood = pick(rng, WOODS)
    parts = [_b(0.0, 0.0, 0.0, width, depth - 0.01, height, wood),
             _b(0.05, depth - 0.01, 0.08, width / 2 - 0.02, depth, height - 0.06, bright(rng)),
             _b(width / 2 + 0.02, depth - 0.01, 0.08, width - 0.05, depth, height - 0.06,
                bright(rng))]
    screen_w = min(width - 0.2, 1.4)
    x0 = (width - screen_w) / 2
    parts.append(_b(width / 2 - 0.15, 0.1, height, width / 2 + 0.15, 0.3, height + 0.05,
                    METALS[3]))
    parts.append(_b(width / 2 - 0.03, 0.18, height, width / 2 + 0.03, 0.22, height + 0.2,
                    METALS[3]))
    parts.append(_b(x0, 0.16, height + 0.2, x0 + screen_w, 0.22, height + 0.2 + screen_w * 0.56,
                    METALS[3], METALS[3], METALS[3], (20, 24, 36), METALS[3], METALS[3]))
    return width, depth, height + 0.2 + screen_w * 0.56, parts


def _desk(rng, ceiling: float):
    width, depth, height = float(rng.uniform(1.1, 1.5)), float(rng.uniform(0.6, 0.7)), 0.75
    wood, fabric = pick(rng, WOODS), pick(rng, FABRICS)
    parts = [_b(0.0, 0.0, height - 0.04, width, depth, height, wood),
             _b(0.0, 0.0, 0.0, 0.04, depth, height - 0.04, wood),
             _b(width - 0.45, 0.0, 0.0, width, depth, height - 0.04, jitter(rng, wood, 20)),
             _b(width - 0.43, depth, 0.3, width - 0.02, depth + 0.02, 0.36, METALS[1])]
    parts.append(_b(width * 0.3, 0.05, height, width * 0.3 + 0.5, 0.1, height + 0.32,
                    METALS[3], METALS[3], METALS[3], (30, 50, 80), METALS[3], METALS[3]))
    parts.append(("frustum", (width - 0.15, 0.15, height, 0.07, 0.07, 0.02), (METALS[0],)))
    parts.append(("frustum", (width - 0.15, 0.15, height + 0.02, 0.012, 0.012, 0.35),
                  (METALS[0],)))
    parts.append(("frustum", (width - 0.15, 0.15, height + 0.3, 0.1, 0.05, 0.14),
                  (bright(rng),)))
    parts += _chair(width * 0.3, depth + 0.12, back_at_low_y=False, rgb=fabric, legs_rgb=METALS[0])
    return width, depth + 0.12 + 0.42, height + 0.37, parts


def _floor_lamp(rng, ceiling: float):
    metal, shade = pick(rng, METALS), bright(rng)
    height = float(rng.uniform(1.4, 1.75))
    r = 0.2
    parts = [("frustum", (r, r, 0.0, 0.15, 0.15, 0.03), (metal,)),
             ("frustum", (r, r, 0.03, 0.015, 0.015, height - 0.3), (metal,)),
             ("frustum", (r, r, height - 0.32, 0.2, 0.14, 0.32), (shade,))]
    return 2 * r, 2 * r, height, parts


def _plant(rng, ceiling: float):
    pot = pick(rng, [(180, 90, 60), (60, 60, 70), (220, 220, 215), (150, 120, 90)])
    green = hsv(float(rng.uniform(0.22, 0.4)), float(rng.uniform(0.5, 0.8)),
                 float(rng.uniform(0.35, 0.6)))
    r_pot = float(rng.uniform(0.14, 0.22))
    pot_h = float(rng.uniform(0.3, 0.45))
    leaves = float(rng.uniform(0.25, 0.4))
    r = max(r_pot, leaves)
    parts = [("frustum", (r, r, 0.0, r_pot * 0.75, r_pot, pot_h), (pot,)),
             ("frustum", (r, r, pot_h, 0.02, 0.02, 0.3), ((90, 70, 40),)),
             ("sphere", (r, r, pot_h + 0.2 + leaves, leaves), (green,))]
    return 2 * r, 2 * r, pot_h + 0.2 + 2 * leaves, parts


def _column(rng, ceiling: float):
    radius = float(rng.uniform(0.15, 0.25))
    colour = pick(rng, [(230, 228, 220), (200, 196, 188), (170, 160, 150)])
    c = radius + 0.04
    parts = [("frustum", (c, c, 0.0, radius, radius, ceiling), (colour,)),
             ("frustum", (c, c, 0.0, c, c, 0.12), (colour,))]
    return 2 * (radius + 0.04), 2 * (radius + 0.04), ceiling, parts


def _counter(rng, ceiling: float):
    width, depth, height = float(rng.uniform(1.6, 2.6)), 0.62, 0.9
    body, top = bright(rng), pick(rng, [(230, 230, 226), (60, 60, 64), (190, 180, 160)])
    parts = [_b(0.0, 0.0, 0.0, width, depth - 0.04, height - 0.04, body),
             _b(0.0, 0.0, height - 0.04, width, depth, height, top),
             _b(0.0, 0.0, height, width, 0.02, height + 0.6, (240, 240, 240))]
    units = max(1, int(round(width / 0.6)))
    for k in range(units):
        x0 = k * width / units
        parts.append(_b(x0 + 0.2, depth - 0.04, height - 0.18, x0 + width / units - 0.2,
                        depth - 0.02, height - 0.15, METALS[1]))
    parts.append(("frustum", (width * 0.7, depth * 0.5, height, 0.1, 0.1, 0.2), (bright(rng),)))
    return width, depth, height + 0.6, parts


def _fridge(rng, ceiling: float):
    width, depth, height = 0.7, 0.68, float(min(1.85, ceiling - 0.4))
    body = pick(rng, [(232, 232, 232), (180, 182, 186), (40, 40, 44)])
    parts = [_b(0.0, 0.0, 0.0, width, depth - 0.02, height, body),
             _b(0.02, depth - 0.02, 0.02, width - 0.02, depth, height * 0.62, body),
             _b(0.02, depth - 0.02, height * 0.64, width - 0.02, depth, height - 0.02, body),
             _b(width - 0.1, depth, height * 0.4, width - 0.07, depth + 0.03, height * 0.58,
                METALS[0])]
    return width, depth + 0.03, height, parts


def rug(
    rng: np.random.Generator, room_width: float, room_depth: float
) -> tuple[float, float, float, list[LocalPart]]:
    """A two-tone rug at most the room's size less 1 m."""
    width = float(min(rng.uniform(1.4, 2.6), room_width - 1.0))
    depth = float(min(rng.uniform(1.0, 2.0), room_depth - 1.0))
    outer, inner = bright(rng), bright(rng)
    return width, depth, 0.012, [
        _b(0.0, 0.0, 0.0, width, depth, 0.01, outer),
        _b(0.15, 0.15, 0.0, width - 0.15, depth - 0.15, 0.012, inner),
    ]


def _wardrobe(rng, ceiling: float):
    return _cabinet(rng, ceiling, tall=True)


def _low_cabinet(rng, ceiling: float):
    return _cabinet(rng, ceiling, tall=False)


# (builder, placement, probability) per room kind; placement "wall" puts the back flush
# against a wall, "free" keeps the object clear of every wall.
FURNITURE: dict[str, list[tuple]] = {
    "living_room": [
        (_sofa, "wall", 1.0), (_tv_unit, "wall", 0.9), (_bookshelf, "wall", 0.9),
        (_coffee_table, "free", 0.9), (_table, "free", 0.6), (_cabinet, "wall", 0.7),
        (_plant, "free", 0.9), (_floor_lamp, "free", 0.8), (_bookshelf, "wall", 0.4),
        (_plant, "free", 0.5), (_column, "free", 0.25),
    ],
    "bedroom": [
        (_bed, "wall", 1.0), (_wardrobe, "wall", 0.9),
        (_low_cabinet, "wall", 0.8), (_desk, "wall", 0.5),
        (_plant, "free", 0.6), (_floor_lamp, "free", 0.6),
    ],
    "kitchen": [
        (_counter, "wall", 1.0), (_fridge, "wall", 0.9), (_counter, "wall", 0.6),
        (_table, "free", 0.6), (_plant, "free", 0.5),
    ],
    "office": [
        (_desk, "wall", 1.0), (_bookshelf, "wall", 1.0), (_bookshelf, "wall", 0.7),
        (_low_cabinet, "wall", 0.7), (_plant, "free", 0.7),
        (_floor_lamp, "free", 0.6), (_column, "free", 0.2),
    ],
    "dining_room": [
        (_table, "free", 1.0), (_low_cabinet, "wall", 0.9),
        (_bookshelf, "wall", 0.5), (_plant, "free", 0.8), (_floor_lamp, "free", 0.4),
    ],
    "bathroom": [
        (_low_cabinet, "wall", 1.0),
        (_wardrobe, "wall", 0.6), (_plant, "free", 0.6),
    ],
    # Hallways of the corridor plans: narrow, so only wall-standing pieces.
    "corridor": [
        (_low_cabinet, "wall", 0.5), (_bookshelf, "wall", 0.3), (_plant, "wall", 0.4),
    ],
}
ROOM_KIND_ORDER = ["bedroom", "kitchen", "office", "dining_room", "bedroom", "office", "bedroom"]


def painting(rng: np.random.Generator, width: float, height: float, z0: float) -> list[LocalPart]:
    """A framed canvas of coloured blocks (abstract art), so walls carry colour detail."""
    frame_rgb = pick(rng, [(40, 36, 32), (200, 170, 90), (236, 236, 236), (110, 80, 50)])
    parts = [_b(0.0, 0.0, z0, width, 0.03, z0 + height, frame_rgb)]
    columns, rows = int(rng.integers(2, 5)), int(rng.integers(2, 4))
    border = 0.04
    cell_w, cell_h = (width - 2 * border) / columns, (height - 2 * border) / rows
    hue = float(rng.random())
    for i in range(columns):
        for j in range(rows):
            colour = hsv(hue + float(rng.uniform(-0.18, 0.18)), float(rng.uniform(0.3, 0.9)),
                          float(rng.uniform(0.4, 0.98)))
            x0, z = border + i * cell_w, z0 + border + j * cell_h
            parts.append(_b(x0, 0.03, z, x0 + cell_w, 0.035, z + cell_h, colour))
    return parts
