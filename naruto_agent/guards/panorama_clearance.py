"""Free distance in a world direction, read from the env's equirectangular depth panorama.

The panorama observation is world-aligned (see ``naruto_gym.sensors.panorama``): it is what a
360-degree depth sensor on the agent reports, so reading obstacles from it is fair for a
policy. Scripted and reactive policies use it to check the way ahead before they move.
"""

from __future__ import annotations

import functools

import numpy as np

from naruto_gym.motion.scanned_space import ScannedSpaceConfig, support_directions
from naruto_gym.sensors.panorama import EquirectangularCamera
from naruto_gym.sensors.pinhole import PinholeCamera


class PanoramaClearance:
    """Clearance queries on panoramas of one size.

    Args:
        cone_half_angle_deg: a direction's clearance is the nearest hit within this angle of
            it (the agent's body sweeps a cone-shaped neighbourhood of its heading).
    """

    def __init__(self, cone_half_angle_deg: float = 25.0) -> None:
        self.cos_half_angle = float(np.cos(np.deg2rad(cone_half_angle_deg)))

    @staticmethod
    def _directions_for(panorama: np.ndarray) -> np.ndarray:
        shape = tuple(panorama.shape)
        if len(shape) != 2:
            raise ValueError(f"panorama must be (H, W), got shape {shape}")
        return _panorama_rays(*shape)

    def clearance(self, panorama: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Nearest hit distance within the cone around each direction (inf when none).

        Args:
            panorama: (H, W) radial distances, 0 where nothing was hit.
            directions: (K, 3) or (3,) world directions (need not be unit).

        Returns:
            (K,) clearances in metres.
        """
        directions = np.atleast_2d(np.asarray(directions, np.float64))
        norms = np.linalg.norm(directions, axis=1, keepdims=True)
        directions = directions / np.maximum(norms, 1e-12)
        rays = self._directions_for(panorama)
        distance = np.asarray(panorama, np.float64).reshape(-1)
        distance = np.where(distance > 0.0, distance, np.inf)
        inside = directions @ rays.T >= self.cos_half_angle
        return np.where(inside, distance[None, :], np.inf).min(axis=1)


def horizontal_profile(
    panorama: np.ndarray,
    max_height_offset_m: float = 0.3,
    max_elevation_deg: float = 20.0,
    height_m: float = 0.0,
) -> np.ndarray:
    """Horizontal free distance per panorama column (azimuth) around a height.

    Pixels within ``max_elevation_deg`` of the horizon whose hit lies within
    ``max_height_offset_m`` of ``height_m`` above the agent (0: its own height) count; the
    result is, per column, the smallest horizontal distance of those (inf when none).
    Column ``u`` looks at azimuth ``-pi + 2 pi (u + 0.5) / W``.
    """
    panorama = np.asarray(panorama, np.float64)
    height, width = panorama.shape
    elevation = np.pi / 2.0 - np.pi * (np.arange(height) + 0.5) / height
    rows = np.abs(elevation) <= np.deg2rad(max_elevation_deg)
    distance = np.where(panorama[rows] > 0.0, panorama[rows], np.inf)
    horizontal = distance * np.cos(elevation[rows])[:, None]
    offset = np.abs(distance * np.sin(elevation[rows])[:, None] - height_m)
    horizontal = np.where(offset <= max_height_offset_m, horizontal, np.inf)
    return horizontal.min(axis=0)


def floor_edge_profile(panorama: np.ndarray, max_polar_deg: float = 60.0) -> np.ndarray:
    """Horizontal distance per panorama column (azimuth) to where the scan below ends.

    Walking a column's pixels from straight down towards the horizon (down to
    ``max_polar_deg`` from straight down, the env's support cone), the first pixel that hits
    nothing after the first that hits marks the edge of the scanned floor in that direction
    (past a missing wall, the rim of a floor hole); the result is the horizontal distance of
    the last hit before it, inf when no pixel after the first hit misses, 0 when no pixel of
    the column hits. Misses straight below the agent (it stands over a floor hole, or past
    the scan's edge) do not count: the way back onto the floor stays open. Inside a closed
    scan every pixel below hits, so the profile is inf everywhere.
    """
    panorama = np.asarray(panorama, np.float64)
    height, width = panorama.shape
    elevation = np.pi / 2.0 - np.pi * (np.arange(height) + 0.5) / height
    rows = np.flatnonzero(elevation <= -np.pi / 2.0 + np.deg2rad(max_polar_deg))[::-1]
    below = panorama[rows]  # straight down first
    horizontal = below * np.cos(elevation[rows])[:, None]
    miss = below <= 0.0
    hits = ~miss
    first_hit = np.where(hits.any(axis=0), hits.argmax(axis=0), len(rows))
    after_floor = miss & (np.arange(len(rows))[:, None] > first_hit[None, :])
    first_miss = np.where(after_floor.any(axis=0), after_floor.argmax(axis=0), -1)
    edge = np.full(width, np.inf)
    columns = np.flatnonzero(first_miss >= 0)
    edge[columns] = horizontal[first_miss[columns] - 1, columns]
    edge[first_hit >= len(rows)] = 0.0
    return edge


def profile_clearance(profile: np.ndarray, yaw: float, half_width_rad: float) -> float:
    """Smallest profile distance within ``half_width_rad`` of azimuth ``yaw``."""
    inside = azimuth_window(len(profile), yaw, half_width_rad)
    return float(profile[inside].min()) if inside.any() else float("inf")


def azimuth_window(width: int, yaw: float, half_width_rad: float) -> np.ndarray:
    """Which of a profile's (or panorama's) ``width`` columns look within ``half_width_rad``
    of azimuth ``yaw``, (W,) bool."""
    azimuth = -np.pi + 2.0 * np.pi * (np.arange(width) + 0.5) / width
    return np.abs(np.angle(np.exp(1j * (azimuth - yaw)))) <= half_width_rad


def vertical_clearance(panorama: np.ndarray) -> tuple[float, float]:
    """The nearest hit straight above and straight below the agent (the rows within about
    11 degrees of the poles: a sixteenth of the panorama's rows at each end, at least one),
    metres; inf where those rows hit nothing."""
    panorama = np.asarray(panorama, np.float64)
    rows = max(1, len(panorama) // 16)
    hits = np.where(panorama > 0.0, panorama, np.inf)
    return float(hits[:rows].min()), float(hits[-rows:].min())


@functools.lru_cache(maxsize=8)
def _panorama_rays(height: int, width: int) -> np.ndarray:
    """(H * W, 3) world directions of a panorama's pixels (read-only, kept per shape)."""
    rays = EquirectangularCamera(height, width).ray_directions.astype(np.float64)
    rays.flags.writeable = False
    return rays


def _surface_points(panorama: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) the surface points a panorama shows (relative to its centre), one per hit
    pixel, and their (N,) distances."""
    distance = np.asarray(panorama, np.float64).reshape(-1)
    hit = distance > 0.0
    return _panorama_rays(*panorama.shape)[hit] * distance[hit, None], distance[hit]


def surface_top(panorama: np.ndarray, quantile: float = 0.99) -> float:
    """Height (relative to the panorama's centre) under which ``quantile`` of the surface
    area the panorama shows lies; -inf when it shows none. Each hit pixel stands for the
    patch it sees (its solid angle times its distance squared). Indoors that is the ceiling;
    without one, the wall tops: the env refuses a climb above the scan's own such height
    (:mod:`naruto_gym.motion.scanned_space`), which small stray fragments high above a scan
    do not raise, nor do they raise this one."""
    points, distance = _surface_points(panorama)
    if len(points) == 0:
        return float("-inf")
    # An equirectangular pixel's solid angle goes with the cosine of its elevation.
    horizontal = np.hypot(points[:, 0], points[:, 1]) / np.maximum(distance, 1e-9)
    area = distance * distance * horizontal
    order = np.argsort(points[:, 2])
    cumulative = np.cumsum(area[order])
    index = int(np.searchsorted(cumulative, quantile * cumulative[-1]))
    return float(points[order[min(index, len(order) - 1)], 2])


def first_contact(panorama: np.ndarray, move: np.ndarray, radius_m: float) -> np.ndarray | None:
    """The surface point the panorama shows in a move's way, or None when the way is clear.

    A sphere of ``radius_m`` around the panorama's centre moves by ``move`` (world metres);
    every hit pixel is a surface point, and one that the sphere's path comes closer to than
    ``radius_m`` blocks the move. As in the env's own sweep, an agent already closer than that
    to a surface may move as long as it gets no closer than it is.

    Args:
        panorama: (H, W) radial distances from the agent, 0 where nothing was hit.
        move: (3,) displacement of the move.
        radius_m: the clearance the move must keep.

    Returns:
        (3,) the blocking point relative to the agent (the first along the move), or None.
    """
    move = np.asarray(move, np.float64)
    length = float(np.linalg.norm(move))
    points, distance = _surface_points(panorama)
    if length < 1e-9 or len(distance) == 0:
        return None
    threshold = min(radius_m, float(distance.min()) - 1e-3)
    near = distance < length + radius_m
    if threshold <= 0.0 or not near.any():
        return None
    points = points[near]
    direction = move / length
    along = np.clip(points @ direction, 0.0, length)
    gap = np.linalg.norm(points - along[:, None] * direction, axis=1)
    touching = gap < threshold
    if not touching.any():
        return None
    return points[int(np.argmin(np.where(touching, along, np.inf)))]


def clear_part_of_move(
    panorama: np.ndarray, move: np.ndarray, radius_m: float, min_length_m: float = 0.01
) -> np.ndarray | None:
    """The part of a blocked move the panorama shows clear, or None when none is worth sending.

    Two candidates: the move slid along the surface it would touch (its component towards
    the surface removed, as a robot slides along a wall), and the move cut short a
    centimetre before the contact. Of those clear (:func:`first_contact`) and at least
    ``min_length_m`` long, the one that goes furthest along the move.

    Args:
        panorama: (H, W) radial distances from the agent, 0 where nothing was hit.
        move: (3,) displacement of the move.
        radius_m: the clearance the move must keep.
        min_length_m: shortest part worth sending.

    Returns:
        (3,) the clear displacement (the move itself when it is clear), or None.
    """
    move = np.asarray(move, np.float64)
    contact = first_contact(panorama, move, radius_m)
    if contact is None:
        return move
    length = float(np.linalg.norm(move))
    direction = move / length
    # How far the sphere goes before it first touches a surface point the panorama shows.
    points, distance = _surface_points(panorama)
    threshold = min(radius_m, float(distance.min()) - 1e-3)
    along = points @ direction
    gap = np.linalg.norm(points - along[:, None] * direction, axis=1)
    touching = (gap < threshold) & (along > 0.0)
    reach = along[touching] - np.sqrt(threshold * threshold - gap[touching] ** 2)
    touch = max(float(reach.min()), 0.0) if len(reach) else length
    # The surface's normal there: towards the surface point nearest the sphere's centre.
    centre = touch * direction
    nearest = points[int(np.argmin(np.linalg.norm(points - centre, axis=1)))] - centre
    normal = nearest / max(float(np.linalg.norm(nearest)), 1e-9)
    slide = move - max(float(move @ normal), 0.0) * normal
    short = direction * min(max(touch - 0.01, 0.0), length)
    clear = [part for part in (slide, short)
             if np.linalg.norm(part) >= min_length_m
             and first_contact(panorama, part, radius_m) is None]
    if not clear:
        return None
    return max(clear, key=lambda part: float(part @ direction))  # the most progress


def cone_supported(panorama: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The env's scanned-space test (:mod:`naruto_gym.motion.scanned_space`) below each point,
    read from the panorama's surface points instead of rays cast in the mesh.

    Each of the env's support rays from a point (:func:`support_directions`: 8 azimuth
    sectors of a 60-degree downward cone) counts as a hit when a surface point the panorama
    shows lies within the panorama's own spacing of it (its pixels are 2.8 degrees apart at
    64 x 128: a point ``d`` from the agent stands for a patch about ``0.05 d`` wide); the
    point is supported when every sector has a hit. The few centimetres between the agent
    and the point hide little: what the agent sees around it stands in for what rays from
    there would meet.

    Args:
        panorama: (H, W) radial distances from the agent, 0 where nothing was hit.
        points: (K, 3) query points relative to the agent.

    Returns:
        (K,) bool.
    """
    points = np.atleast_2d(np.asarray(points, np.float64))
    surface, distance = _surface_points(panorama)
    # Half the larger pixel pitch, as a width per metre from the agent.
    pitch = 0.5 * max(np.pi / panorama.shape[0], 2.0 * np.pi / panorama.shape[1])
    patch = pitch * distance
    directions, sectors = _support_rays()
    count = int(sectors.max()) + 1
    slope = float(np.tan(np.arccos(-float(directions[:, 2].max())) + 2.0 * pitch))
    supported = np.zeros(len(points), bool)
    for index, point in enumerate(points):
        offset = surface - point
        # Only points inside the cone (and a pitch around it) can meet a ray.
        inside = np.hypot(offset[:, 0], offset[:, 1]) <= -offset[:, 2] * slope
        offset = offset[inside]
        if len(offset) == 0:
            continue
        length = np.linalg.norm(offset, axis=1)
        cos_tolerance = np.cos(np.minimum(np.arctan2(patch[inside], length), 4.0 * pitch))
        along = directions @ (offset / length[:, None]).T
        rays_hit = (along >= cos_tolerance[None, :]).any(axis=1)
        supported[index] = len(np.unique(sectors[rays_hit])) == count
    return supported


def move_leaves_scan(
    panorama: np.ndarray, move: np.ndarray, radius_m: float, margin_start_passes: bool = False
) -> bool:
    """Whether a move from the panorama's centre leaves the scanned space as the env judges
    it (:func:`cone_supported`).

    The env judges a point by the lattice corners within its clearance, a few centimetres
    around it on every side, so the move is probed at its end, a point ``radius_m`` further
    on along it and horizontally, and the corners of the cube ``radius_m`` around the end:
    beside a floor hole's rim or a wall's opening a corner to the side of the move can fall
    outside while the end itself is supported. The move leaves when the start is supported
    and one of the first three is not, or when the end's cube has unsupported corners and
    at least as many as the start's own cube: along the edge in the margin the env refuses,
    while a move that takes the agent further in (up from low over a floor hole, where the
    cube's lower corners sink into it) passes. A cube counts only when its corners lie
    within the free ball around its point (the panorama's nearest surface point is farther),
    as the env counts only lattice corners within the agent's clearance: next to a wall the
    far corners lie behind it, where nothing below them is in view, and the walls of a room
    would read as its edge. From an unsupported start any move passes:
    the agent has to get back in; with ``margin_start_passes`` so does any move from a start
    whose own cube is not wholly supported (the env then decides: for a caller that gives
    its goal up at every refusal, where holding moves back in the margin can leave none)."""
    move = np.asarray(move, np.float64)
    probes = [np.zeros(3), move]
    for way in (move, np.array([move[0], move[1], 0.0])):
        length = float(np.linalg.norm(way))
        if length > 1e-9:
            probes.append(move + radius_m * way / length)
    corners = len(_CUBE_CORNERS)
    probes.extend(move + radius_m * _CUBE_CORNERS)
    probes.extend(radius_m * _CUBE_CORNERS)
    supported = cone_supported(panorama, np.array(probes))
    if not supported[0]:
        return False
    # As the env, only corners within the free ball around a point count: next to a wall the
    # cube's far corners lie behind it, where the panorama sees nothing below them.
    clearance = _clearances(panorama, np.array([move, np.zeros(3)]))
    reach = radius_m * float(np.sqrt(3.0))
    end_outside = int(np.count_nonzero(~supported[-2 * corners : -corners]))
    end_outside *= int(clearance[0] > reach)
    start_outside = int(np.count_nonzero(~supported[-corners:])) * int(clearance[1] > reach)
    if margin_start_passes and start_outside:
        return False
    if not supported[1 : len(supported) - 2 * corners].all():
        return True
    return end_outside > 0 and end_outside >= start_outside


def _clearances(panorama: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(K,) distance from each of (K, 3) points (relative to the panorama's centre) to the
    nearest surface point the panorama shows (inf when it shows none)."""
    surface, _ = _surface_points(panorama)
    if len(surface) == 0:
        return np.full(len(points), np.inf)
    return np.array([float(np.min(np.linalg.norm(surface - point, axis=1))) for point in points])


_CUBE_CORNERS = np.array(
    [[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)]
)


@functools.lru_cache(maxsize=1)
def _support_rays() -> tuple[np.ndarray, np.ndarray]:
    """The env's support rays (directions, sectors), read-only."""
    directions, sectors = support_directions(ScannedSpaceConfig())
    directions.flags.writeable = False
    sectors.flags.writeable = False
    return directions, sectors


@functools.lru_cache(maxsize=8)
def _subsampled_rays(camera: PinholeCamera, stride: int) -> tuple[np.ndarray, np.ndarray]:
    """(h, w, 3) camera-frame rays (z = 1) of every ``stride``-th pixel, and their lengths;
    the same for every frame of a camera, so kept (read-only)."""
    v, u = np.mgrid[0 : camera.height : stride, 0 : camera.width : stride]
    rays = np.stack(
        [(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, np.ones(u.shape)], axis=-1
    )
    norms = np.linalg.norm(rays, axis=-1)
    rays.flags.writeable = False
    norms.flags.writeable = False
    return rays, norms


def steep_miss_share(
    depth: np.ndarray, pose: np.ndarray, camera: PinholeCamera, min_elevation_deg: float = 35.0,
    stride: int = 4,
) -> float:
    """Share of a depth frame's pixels looking at least ``min_elevation_deg`` up or down
    (every ``stride``-th pixel) that hit nothing within the sensor's range; 0 when none looks
    that steeply. Indoors such a ray meets a ceiling or a floor within a few metres, so misses
    there mean a scan without a ceiling or with a hole in its floor."""
    depth = np.asarray(depth)[::stride, ::stride]
    rays, norms = _subsampled_rays(camera, stride)
    up = rays @ np.asarray(pose, np.float64)[:3, :3][2]  # world z of each camera-frame ray
    steep = np.abs(up) >= np.sin(np.deg2rad(min_elevation_deg)) * norms
    if not steep.any():
        return 0.0
    return float(np.mean(depth[steep] <= 0.0))


def sees_all_around_below(
    panorama: np.ndarray, max_polar_deg: float = 45.0, sectors: int = 8, min_share: float = 0.75
) -> bool:
    """True when, in every azimuth sector of the panorama's downward cone (within
    ``max_polar_deg`` of straight down), at least ``min_share`` of the pixels hit something:
    scanned surface all around below, so not at the edge of the scanned floor nor over a
    hole (a few hits through a hole do not count)."""
    panorama = np.asarray(panorama, np.float64)
    height, width = panorama.shape
    elevation = np.pi / 2.0 - np.pi * (np.arange(height) + 0.5) / height
    rows = elevation <= -np.pi / 2.0 + np.deg2rad(max_polar_deg)
    hits = panorama[rows] > 0.0
    sector = (np.arange(width) * sectors) // width
    return bool(all(hits[:, sector == k].mean() >= min_share for k in range(sectors)))
