"""Which surface an agent can ever observe, and where in a scene it can stand.

Scene meshes hold surface nothing inside can see: the outer faces of solid walls, the underside
of a floor slab, the top of a ceiling, the bottoms of furniture standing on the floor. Counting
it would cap coverage and completion far below 100 % (about 60 % on the shipped scenes). A
surface sample is *observable* when an unoccluded line of sight within range joins it to at
least one of a few hundred free viewpoints spread over the scene's interior.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from naruto_gym.observability_kernels import absorb_hits, emit_rays
from naruto_gym.sensors.panorama import EquirectangularCamera
from naruto_gym.sensors.raycaster import RayCaster

_PROBE = EquirectangularCamera(16, 32)
# Points whose visibility state (remembered blockers, next viewpoint, ray) is held at once.
_POINTS_PER_CHUNK = 262_144


def is_inside_free_space(
    raycaster: RayCaster,
    face_normals: np.ndarray,
    position: np.ndarray,
    max_no_hit_share: float = 0.5,
    min_front_facing_share: float = 0.9,
) -> bool:
    """True when ``position`` is inside the scene and not inside a solid.

    Inside the scene: at most ``max_no_hit_share`` of the rays around it hit nothing (a scan
    without a ceiling sees the sky upwards). Not inside a solid: the surfaces it sees face it.
    """
    return bool(
        inside_free_space_many(
            raycaster, face_normals, np.asarray(position, np.float64).reshape(1, 3),
            max_no_hit_share, min_front_facing_share,
        )[0]
    )


def inside_free_space_many(
    raycaster: RayCaster,
    face_normals: np.ndarray,
    positions: np.ndarray,
    max_no_hit_share: float = 0.5,
    min_front_facing_share: float = 0.9,
    chunk: int = 1024,
) -> np.ndarray:
    """:func:`is_inside_free_space` of (N, 3) points, ``chunk`` points' rays per cast ((N,)
    bool)."""
    positions = np.asarray(positions, np.float64).reshape(-1, 3)
    inside = np.zeros(len(positions), dtype=bool)
    directions = _PROBE.ray_directions
    rays = len(directions)
    for start in range(0, len(positions), chunk):
        part = positions[start : start + chunk]
        count = len(part)
        hits = raycaster.cast(
            np.repeat(part.astype(np.float32), rays, axis=0), np.tile(directions, (count, 1))
        )
        hit = hits.hit_mask
        hit_count = hit.reshape(count, rays).sum(axis=1)
        open_enough = 1.0 - hit_count / rays <= max_no_hit_share
        # The same products, in the same einsum, as one point's test.
        facing = np.einsum(
            "ij,ij->i", face_normals[hits.triangle_ids[hit]], np.tile(directions, (count, 1))[hit]
        ) < 0
        facing_count = np.bincount(np.repeat(np.arange(count), rays)[hit], facing, count)
        # A point that sees nothing fails: no surface to face it.
        facing_share = facing_count / np.maximum(hit_count, 1)
        inside[start : start + count] = (
            open_enough & (hit_count > 0) & (facing_share >= min_front_facing_share)
        )
    return inside


def sample_free_positions(
    raycaster: RayCaster,
    face_normals: np.ndarray,
    bounds: np.ndarray,
    count: int,
    clearance_m: float,
    rng: np.random.Generator,
    max_no_hit_share: float = 0.5,
    max_candidates: int = 200_000,
    is_inside: Callable[[np.ndarray], bool] | None = None,
    is_inside_many: Callable[[np.ndarray], np.ndarray] | None = None,
) -> np.ndarray:
    """Up to ``count`` positions inside the scene, at least ``clearance_m`` from any surface.

    Candidates are drawn uniformly in the bounds (shrunk by the clearance) in batches; fewer
    than ``count`` come back when ``max_candidates`` draws do not find enough. ``is_inside``
    decides which clear candidates lie inside the scene (default: :func:`is_inside_free_space`
    with ``max_no_hit_share``; the env passes its escape rule's test). The candidates drawn
    do not depend on it, so two tests that agree give the same positions.
    ``is_inside_many``, the same test of (K, 3) candidates at once ((K,) bool), is used
    instead when given (by default the free-space test is batched): the first ``count``
    clear candidates it accepts are the same, and are found with far fewer calls.
    """
    if is_inside_many is None and is_inside is None:
        def is_inside_many(positions: np.ndarray) -> np.ndarray:
            return inside_free_space_many(raycaster, face_normals, positions, max_no_hit_share)

    low = np.asarray(bounds[0], np.float64) + clearance_m
    high = np.asarray(bounds[1], np.float64) - clearance_m
    if np.any(high <= low):
        return np.zeros((0, 3))
    found: list[np.ndarray] = []
    drawn = 0
    batch = max(4 * count, 256)
    while len(found) < count and drawn < max_candidates:
        candidates = rng.uniform(low, high, size=(batch, 3))
        drawn += batch
        clear = candidates[raycaster.unsigned_distance(candidates) >= clearance_m]
        if is_inside_many is None:
            for position in clear:
                if is_inside(position):  # type: ignore[misc]
                    found.append(position)
                    if len(found) == count:
                        break
            continue
        start = 0
        while start < len(clear) and len(found) < count:
            # A little more than the positions still missing: most clear candidates pass.
            missing = count - len(found)
            chunk = clear[start : start + missing + missing // 8 + 8]
            start += len(chunk)
            accepted = chunk[np.asarray(is_inside_many(chunk), bool)]
            found.extend(accepted[: count - len(found)])
    return np.array(found).reshape(-1, 3)


def visible_from_any(
    raycaster: RayCaster,
    points: np.ndarray,
    viewpoints: np.ndarray,
    max_range_m: float | None = None,
    tolerance_m: float = 0.02,
    blocker_slots: int = 8,
    ball_size: int = 16,
) -> np.ndarray:
    """Boolean mask of the points with an unoccluded line of sight to some viewpoint.

    A point is visible from a viewpoint when the ray from the viewpoint towards it hits
    nothing closer than ``tolerance_m`` short of it (and it lies within ``max_range_m``), the
    test of :func:`visible_from_any_per_viewpoint`, which this returns the same mask as. Most
    pairs need no ray: each point remembers the ``blocker_slots`` triangles that last blocked
    it, and a segment that provably crosses one is blocked; viewpoints are grouped in balls of
    ``ball_size`` neighbours, and one blocker may hide a whole ball at once (see
    :mod:`naruto_gym.observability_kernels`). On the generated apartments about 1 ray in 25
    of the per-viewpoint loop's is left.
    """
    points = np.ascontiguousarray(np.asarray(points, np.float64).reshape(-1, 3))
    viewpoints = np.ascontiguousarray(np.asarray(viewpoints, np.float64).reshape(-1, 3))
    if blocker_slots < 1 or ball_size < 1:
        raise ValueError(
            f"blocker_slots and ball_size must be >= 1, got {blocker_slots} and {ball_size}"
        )
    count = len(points)
    visible = np.zeros(count, dtype=bool)
    if count == 0 or len(viewpoints) == 0:
        return visible
    triangles = raycaster.vertices.astype(np.float64)[raycaster.faces]
    plane_normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    plane_normals /= np.maximum(np.linalg.norm(plane_normals, axis=1, keepdims=True), 1e-300)
    plane_offsets = np.einsum("ij,ij->i", plane_normals, triangles[:, 0])
    viewpoints, ball_of, ball_end, balls = _balls_of_neighbours(viewpoints, ball_size)
    max_range = np.inf if max_range_m is None else float(max_range_m)
    # Points are independent: bounded chunks bound the per-point state (dense evaluation
    # samples of a large scene run to millions).
    for start in range(0, count, _POINTS_PER_CHUNK):
        stop = min(start + _POINTS_PER_CHUNK, count)
        part = points[start:stop]
        size = len(part)
        blockers = np.full((size, blocker_slots), -1, np.int32)
        cursor = np.zeros(size, np.int64)
        forward = np.zeros(size, dtype=bool)
        pending = np.arange(size, dtype=np.int64)
        rays = np.empty((size, 6), np.float32)
        ray_point = np.empty(size, np.int64)
        ray_reach = np.empty(size, np.float64)
        part_visible = visible[start:stop]
        pending_count = size
        while pending_count > 0:
            rays_count, pending_count = emit_rays(
                part, pending, pending_count, viewpoints, float(tolerance_m), max_range,
                triangles, plane_normals, plane_offsets, ball_of, ball_end, balls, blockers,
                cursor, forward, part_visible, rays, ray_point, ray_reach,
            )
            if rays_count == 0:
                break
            hits = raycaster.cast_packed(rays[:rays_count])
            absorb_hits(
                ray_point, ray_reach, rays_count, hits.distance, hits.triangle_ids, blockers,
                cursor, forward, part_visible,
            )
    return visible


def _balls_of_neighbours(
    viewpoints: np.ndarray, size: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Viewpoints reordered into balls of at most ``size`` neighbours (median splits along
    the widest axis), after one viewpoint of each: the reordered (V, 3) viewpoints, each
    one's ball (V,), one past each ball's last viewpoint (B,) and each ball's centre and
    radius (B, 4)."""
    groups: list[np.ndarray] = []
    stack = [np.arange(len(viewpoints))]
    while stack:
        index = stack.pop()
        if len(index) <= size:
            groups.append(index)
            continue
        spread = np.ptp(viewpoints[index], axis=0)
        index = index[np.argsort(viewpoints[index, int(np.argmax(spread))], kind="stable")]
        half = len(index) // 2
        stack += [index[half:], index[:half]]
    # One viewpoint of every ball first, each alone: spread over the scene, they see most
    # points early (consecutive neighbours would all look at the same corner).
    groups = [group[:1] for group in groups] + [group[1:] for group in groups if len(group) > 1]
    order = np.concatenate(groups)
    ball_of = np.repeat(np.arange(len(groups)), [len(g) for g in groups])
    ball_end = np.cumsum([len(g) for g in groups]).astype(np.int64)
    balls = np.zeros((len(groups), 4))
    for ball, members in enumerate(groups):
        centre = viewpoints[members].mean(axis=0)
        balls[ball, :3] = centre
        balls[ball, 3] = np.linalg.norm(viewpoints[members] - centre, axis=1).max()
    return np.ascontiguousarray(viewpoints[order]), ball_of.astype(np.int64), ball_end, balls


def visible_from_any_per_viewpoint(
    raycaster: RayCaster,
    points: np.ndarray,
    viewpoints: np.ndarray,
    max_range_m: float | None = None,
    tolerance_m: float = 0.02,
) -> np.ndarray:
    """:func:`visible_from_any` as one ray cast per viewpoint over the points not seen yet
    (the reference it is tested and timed against; every unobservable point costs a ray per
    viewpoint here)."""
    points = np.asarray(points, np.float64)
    visible = np.zeros(len(points), dtype=bool)
    for viewpoint in viewpoints:
        pending = np.flatnonzero(~visible)
        if len(pending) == 0:
            break
        offsets = points[pending] - viewpoint
        distance = np.linalg.norm(offsets, axis=1)
        usable = distance > 1e-6
        if max_range_m is not None:
            usable &= distance <= max_range_m
        if not usable.any():
            continue
        index = pending[usable]
        directions = offsets[usable] / distance[usable, None]
        hit_distance = raycaster.cast_distance(np.asarray(viewpoint, np.float32), directions)
        visible[index[hit_distance >= distance[usable] - tolerance_m]] = True
    return visible


class ObservableSurface:
    """The part of a scene's surface that some free viewpoint can see.

    Args:
        raycaster: the scene.
        face_normals: (F, 3) triangle normals (orientation tells solids from free space).
        bounds: (2, 3) scene bounds.
        num_viewpoints: free viewpoints to look from (256).
        clearance_m: their minimum distance to any surface (0.1 m, so that they reach under
            tables and between furniture).
        max_range_m: longest line of sight that counts (None: unlimited).
        max_no_hit_share: how open a viewpoint may be (0.5, as the published escape check).
        seed: seed of the viewpoints (fixed per scene, not per episode).
        is_inside: which clear points count as inside the scene (default: the whole-sphere
            test with ``max_no_hit_share``; the env passes its escape rule's test, so that
            open scans get viewpoints where the agent may go).
        is_inside_many: the same test of (K, 3) points at once, used instead when given
            (see :func:`sample_free_positions`).
    """

    def __init__(
        self,
        raycaster: RayCaster,
        face_normals: np.ndarray,
        bounds: np.ndarray,
        num_viewpoints: int = 256,
        clearance_m: float = 0.1,
        max_range_m: float | None = None,
        max_no_hit_share: float = 0.5,
        seed: int = 0,
        is_inside: Callable[[np.ndarray], bool] | None = None,
        is_inside_many: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> None:
        self.raycaster = raycaster
        self.max_range_m = max_range_m
        self.viewpoints = sample_free_positions(
            raycaster,
            face_normals,
            bounds,
            num_viewpoints,
            clearance_m,
            np.random.default_rng(seed),
            max_no_hit_share,
            is_inside=is_inside,
            is_inside_many=is_inside_many,
        )
        if len(self.viewpoints) == 0:
            raise ValueError(
                "found no free viewpoint inside the scene to define its observable surface "
                f"(no point has {clearance_m} m of free space inside the scanned space: the "
                "scene is too small for the agent, or not a room); check the mesh (its units "
                "are metres, normals face the free space) or switch observable-only scoring "
                "off (observable_only=False)"
            )

    def mask(self, points: np.ndarray) -> np.ndarray:
        """Boolean mask of the observable points among ``points`` ((N, 3))."""
        return visible_from_any(self.raycaster, points, self.viewpoints, self.max_range_m)
