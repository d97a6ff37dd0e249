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

from naruto_gym.sensors.panorama import EquirectangularCamera
from naruto_gym.sensors.raycaster import RayCaster

_PROBE = EquirectangularCamera(16, 32)


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
    directions = _PROBE.ray_directions
    hits = raycaster.cast(np.asarray(position, np.float32), directions)
    hit = hits.hit_mask
    if 1.0 - hit.mean() > max_no_hit_share:
        return False
    facing = np.einsum("ij,ij->i", face_normals[hits.triangle_ids[hit]], directions[hit]) < 0
    return bool(facing.mean() >= min_front_facing_share)


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
) -> np.ndarray:
    """Up to ``count`` positions inside the scene, at least ``clearance_m`` from any surface.

    Candidates are drawn uniformly in the bounds (shrunk by the clearance) in batches; fewer
    than ``count`` come back when ``max_candidates`` draws do not find enough. ``is_inside``
    decides which clear candidates lie inside the scene (default: :func:`is_inside_free_space`
    with ``max_no_hit_share``; the env passes its escape rule's test). The candidates drawn
    do not depend on it, so two tests that agree give the same positions.
    """
    if is_inside is None:
        def is_inside(position: np.ndarray) -> bool:
            return is_inside_free_space(raycaster, face_normals, position, max_no_hit_share)

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
        clear = raycaster.unsigned_distance(candidates) >= clearance_m
        for position in candidates[clear]:
            if is_inside(position):
                found.append(position)
                if len(found) == count:
                    break
    return np.array(found).reshape(-1, 3)


def visible_from_any(
    raycaster: RayCaster,
    points: np.ndarray,
    viewpoints: np.ndarray,
    max_range_m: float | None = None,
    tolerance_m: float = 0.02,
) -> np.ndarray:
    """Boolean mask of the points with an unoccluded line of sight to some viewpoint.

    Points already seen are not cast again, so the cost falls quickly with each viewpoint.
    """
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
        )
        if len(self.viewpoints) == 0:
            raise ValueError(
                "found no free viewpoint inside the scene to define its observable surface; "
                "check the mesh (closed room, normals facing the free space) or switch "
                "observable-only scoring off"
            )

    def mask(self, points: np.ndarray) -> np.ndarray:
        """Boolean mask of the observable points among ``points`` ((N, 3))."""
        return visible_from_any(self.raycaster, points, self.viewpoints, self.max_range_m)
