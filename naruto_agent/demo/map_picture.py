"""The agent's map seen from above, for the GIF: what the reconstruction holds at a step.

The env's ``rgb_array`` frame shows the ground truth from above; beside it the GIF shows the
map the agent has built so far, drawn on the same pixel grid (the env's
:class:`~naruto_gym.rendering.topdown.TopDownMap`), so the two can be compared side by side.
Pixels the map holds nothing for stay pale grey: the unexplored part of the scene.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import trimesh
from PIL import Image, ImageDraw

from naruto_agent.recording.meshes import vertex_colours

#: Colour of pixels the map holds nothing for.
UNMAPPED_RGB = (225, 225, 230)
#: The surface is splatted on a grid this many times coarser than the picture, so that the
#: vertices of a 2 cm mesh leave no holes, then scaled up.
SPLAT_FACTOR = 2


def top_down_of_mesh(mesh: trimesh.Trimesh, top_down: Any, bounds: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8: the highest surface point below the cut height in each pixel.

    Args:
        mesh: the agent's map (vertex colours used when it has them, else height shades).
        top_down: the env's top-down map (its ``width``, ``height`` and ``world_to_pixel``).
        bounds: (2, 3) scene box; the cut lies at 80 % of its height, as the env's map (the
            ceiling would hide everything).
    """
    height, width = int(top_down.height), int(top_down.width)
    small = (max(height // SPLAT_FACTOR, 1), max(width // SPLAT_FACTOR, 1))
    image = np.empty((*small, 3), np.uint8)
    image[:] = UNMAPPED_RGB
    vertices = np.asarray(mesh.vertices, np.float64)
    if len(vertices):
        low, top = float(bounds[0, 2]), float(bounds[0, 2] + 0.8 * (bounds[1, 2] - bounds[0, 2]))
        keep = vertices[:, 2] < top
        points = vertices[keep]
        colours = vertex_colours(mesh)
        relative = np.clip((points[:, 2] - low) / max(top - low, 1e-6), 0.0, 1.0)
        if colours is None:
            base = np.array([150.0, 170.0, 200.0])[None].repeat(len(points), axis=0)
        else:
            base = colours[keep]
        shaded = base * (0.65 + 0.35 * relative)[:, None]
        pixels = np.floor(top_down.world_to_pixel(points[:, :2]) / SPLAT_FACTOR).astype(int)
        inside = ((pixels[:, 0] >= 0) & (pixels[:, 0] < small[1]) & (pixels[:, 1] >= 0)
                  & (pixels[:, 1] < small[0]))
        pixels, shaded, z = pixels[inside], shaded[inside], points[inside, 2]
        flat = pixels[:, 1] * small[1] + pixels[:, 0]
        # The highest point of each pixel: sort by pixel, then height, keep each pixel's last.
        order = np.lexsort((z, flat))
        last = np.r_[flat[order][1:] != flat[order][:-1], True]
        chosen = order[last]
        image.reshape(-1, 3)[flat[chosen]] = np.clip(shaded[chosen], 0, 255).astype(np.uint8)
    return np.asarray(Image.fromarray(image).resize((width, height), Image.NEAREST))


def draw_path(picture: np.ndarray, top_down: Any, positions: np.ndarray,
              label: str = "agent's map") -> np.ndarray:
    """The picture with the trajectory so far, the current position and a label."""
    canvas = Image.fromarray(picture.copy())
    draw = ImageDraw.Draw(canvas)
    pixels = top_down.world_to_pixel(np.asarray(positions, np.float64)[:, :2])
    if len(pixels) > 1:
        draw.line([tuple(point) for point in pixels], fill=(230, 40, 40), width=2)
    if len(pixels):
        x, y = pixels[-1]
        draw.ellipse([x - 5, y - 5, x + 5, y + 5], fill=(20, 120, 255))
    draw.rectangle([0, canvas.height - 16, 8 + 6 * len(label), canvas.height], fill=(0, 0, 0))
    draw.text((4, canvas.height - 14), label, fill=(255, 255, 255))
    return np.asarray(canvas)
