"""NARUTO's uncertainty-aware goal search (Feng et al., NARUTO, CVPR 2024, Sec. 3.4).

Given the planner's view of the map (an SDF volume and an uncertainty volume that is zero
except on surface voxels), find the position from which the agent would see the most
uncertainty:

1. Candidate goals lie on a grid over the volume, 0.2 m apart in x and y, at heights 1 m
   apart. A goal is *safe* when the SDF at it and at its 6 voxel neighbours is at least
   8 cm.
2. Targets are the 4000 most uncertain surface voxels, of which a seeded random subset of
   300 is used.
3. A goal *sees* a target when their distance is in (0.5 m, 2 m) and the straight line from
   the goal towards the target stays in free space (SDF > 0) at 30 samples. The target sits
   on the surface, so the SDF right at it is about 0 (and trilinear interpolation across the
   surface can dip below 0 a few centimetres in front of it): the 30 samples therefore span
   the line from the goal to ``visibility_stop_m`` (one planner voxel, 0.1 m) *before* the
   target. A target on the far side of a wall is still not seen: the wall, with its
   negative SDF, lies on the checked part of the line (for walls at least that thick, which
   is all a 0.1 m planner grid resolves anyway).
4. The score of a goal is the sum of the uncertainty of the targets it sees; the best goal
   wins, and its 10 most uncertain visible targets are the views to take there.
5. If no goal sees any target, the caller grows a goal-free RRT from the agent
   (:func:`~naruto_agent.planning.reachable_voxels`), masks the uncertainty (and here also the
   candidate goals) with the voxels within one step of that tree, and searches again
   (:func:`uncertainty_aware_goal_search` does both).

Everything is vectorised numpy. The best goals are found by branch and bound: a goal's score
is at most the summed uncertainty of the targets in its range, so goals are checked in
order of that bound and the search stops when no unchecked goal can beat the ``top_k``-th
exact score found. The answer is the same as checking every goal (ties go to the lower
candidate index).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from naruto_agent.mapping.sdf_volume import SdfVolume
from naruto_agent.planning.rrt import PlannerConfig, reachable_voxels
from naruto_gym.utils.checks import check_integer, check_number

# Comparisons of float32 volumes against float64 thresholds: a TSDF stores its truncation
# (8 cm) as float32(0.08) < 0.08, which must still count as "at least 8 cm".
_TOLERANCE_M = 1e-5

_NEIGHBOURS = np.array(
    [[0, 0, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]],
    dtype=np.float64,
)


@dataclass
class GoalSearchConfig:
    """Settings of the goal search; defaults are NARUTO's published numbers.

    Attributes:
        goal_spacing_xy_m: candidate goal spacing in x and y (0.2 m).
        goal_spacing_z_m: spacing of the candidate heights (1 m); the levels are centred in
            the volume's height.
        safe_clearance_m: SDF required at a goal and its 6 neighbours (0.08 m).
        top_uncertain: the most uncertain voxels that are target candidates (4000).
        target_subset: random subset of them used as targets (300).
        min_range_m, max_range_m: a goal sees targets at distances strictly between these
            (0.5 m, 2 m).
        visibility_samples: samples of the line of sight (30).
        visibility_stop_m: the line of sight is checked up to this distance before the
            target (0.1 m, one planner voxel; see the module docstring).
        free_sdf_m: a sample of the line of sight is free where the SDF exceeds this (0).
        num_views: views kept at the best goal (10).
        top_k: number of best goals returned, best first (the agent tries the next when the
            planner cannot reach one).
        batch_goals: goals checked per vectorised batch of the branch and bound.
        distance_discount_m: None (published) scores a goal by the uncertainty it sees
            wherever it is; a length L multiplies the score by exp(-d / L), d the straight
            distance from the agent, so that of two goals seeing about as much the nearer
            wins (the agent stops crossing the map back and forth).
        discount_by_travel: with a distance discount, d is the length of the way to the
            goal through free space (a travel-distance volume the caller passes, see
            :meth:`~naruto_agent.planning.FreeSpaceComponents.travel_distances`) instead
            of the straight distance: a goal beyond a wall, 2 m away but 15 m by the door,
            no longer counts as near. Goals the volume does not reach keep the straight
            distance.
        explore_first_share: None (published) draws the targets from the most uncertain
            voxels whatever their values. A share s searches first with targets drawn only
            from voxels at least s times as uncertain as the most uncertain one (unexplored
            space at the initial variance, surfaces nearly as uncertain), when there are at
            least ``explore_first_min_voxels`` of them, and with all targets only when no
            goal sees one of those. Without it, once the unexplored space shrinks below the
            4000 candidates, surfaces seen once or twice fill most of the 300 targets and
            the agent polishes the rooms it has seen before finishing the last ones.
        explore_first_min_voxels: see ``explore_first_share``.
    """

    goal_spacing_xy_m: float = 0.2
    goal_spacing_z_m: float = 1.0
    safe_clearance_m: float = 0.08
    top_uncertain: int = 4000
    target_subset: int = 300
    min_range_m: float = 0.5
    max_range_m: float = 2.0
    visibility_samples: int = 30
    visibility_stop_m: float = 0.1
    free_sdf_m: float = 0.0
    num_views: int = 10
    top_k: int = 3
    batch_goals: int = 64
    distance_discount_m: float | None = None
    discount_by_travel: bool = False
    explore_first_share: float | None = None
    explore_first_min_voxels: int = 30

    def __post_init__(self) -> None:
        for name in ("goal_spacing_xy_m", "goal_spacing_z_m", "max_range_m"):
            check_number(f"GoalSearchConfig.{name}", getattr(self, name), low=0.0)
        for name in (
            "top_uncertain",
            "target_subset",
            "visibility_samples",
            "num_views",
            "top_k",
            "batch_goals",
        ):
            check_integer(f"GoalSearchConfig.{name}", getattr(self, name), low=1)
        for name in ("min_range_m", "visibility_stop_m"):  # in [0, max_range_m)
            check_number(
                f"GoalSearchConfig.{name}", getattr(self, name), low=0.0, low_open=False,
                high=self.max_range_m, high_open=True,
            )
        if self.distance_discount_m is not None:
            check_number(
                "GoalSearchConfig.distance_discount_m (or None)", self.distance_discount_m, low=0.0
            )
        if self.explore_first_share is not None:
            check_number(
                "GoalSearchConfig.explore_first_share (or None)", self.explore_first_share,
                low=0.0, high=1.0,
            )


@dataclass
class GoalSearchResult:
    """Outcome of a goal search.

    Attributes:
        found: whether some safe goal sees at least one target.
        goal: (3,) best goal (world, metres), or None.
        views: (K, 3) the best goal's most uncertain visible targets, most uncertain first
            (K <= ``num_views``); target 0 is watched while moving.
        view_uncertainty: (K,) their uncertainty.
        score: summed uncertainty of the targets the best goal sees.
        goals: (top_k', 3) the best goals, best first (only those that see something).
        goal_scores: (top_k',) their scores.
        goal_views: per entry of ``goals``, its (K, 3) views.
        goal_visible: per entry of ``goals``, every target it sees ((M, 3), M >= K).
        targets: (T, 3) the targets used.
        target_uncertainty: (T,) their uncertainty.
        used_reachable_mask: whether the reachable-voxel fallback ran.
        diagnostics: counts and timings (candidates, safe, evaluated goals, tested pairs,
            time_ms, ...).
    """

    found: bool
    goal: np.ndarray | None
    views: np.ndarray
    view_uncertainty: np.ndarray
    score: float
    goals: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    goal_scores: np.ndarray = field(default_factory=lambda: np.zeros(0))
    goal_views: list[np.ndarray] = field(default_factory=list)
    goal_visible: list[np.ndarray] = field(default_factory=list)
    targets: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    target_uncertainty: np.ndarray = field(default_factory=lambda: np.zeros(0))
    used_reachable_mask: bool = False
    diagnostics: dict[str, float] = field(default_factory=dict)


def _check_same_grid(sdf: SdfVolume, uncertainty: SdfVolume) -> None:
    if (
        sdf.shape != uncertainty.shape
        or not np.allclose(sdf.origin, uncertainty.origin)
        or not math.isclose(sdf.voxel_size, uncertainty.voxel_size)
    ):
        raise ValueError(
            "the SDF and uncertainty volumes must share one grid (shape, origin, voxel size); "
            "use the pair a mapper's planner_view() returns"
        )


def _levels(low: float, high: float, spacing: float) -> np.ndarray:
    """Points ``spacing`` apart, centred in [low, high] (at least one, the centre)."""
    count = max(1, int(math.floor((high - low) / spacing + 1e-9)) + 1)
    if (count - 1) * spacing > high - low + 1e-9:
        count -= 1
    first = low + 0.5 * ((high - low) - (count - 1) * spacing)
    return first + spacing * np.arange(count, dtype=np.float64)


def candidate_goals(bounds: np.ndarray, config: GoalSearchConfig | None = None) -> np.ndarray:
    """(G, 3) candidate goals: a grid 0.2 m apart in x and y at heights 1 m apart.

    Each axis holds as many points as fit in ``bounds`` (a (2, 3) [min, max] box), centred:
    a 3.2 m tall box gets heights 0.1, 1.1, 2.1 and 3.1 m above its floor (those too close
    to the floor or ceiling then fail the safety test).
    """
    config = config or GoalSearchConfig()
    bounds = np.asarray(bounds, dtype=np.float64)
    if bounds.shape != (2, 3) or np.any(bounds[1] < bounds[0]):
        raise ValueError(f"bounds must be a (2, 3) [min, max] box, got {bounds.tolist()}")
    spacing = (config.goal_spacing_xy_m, config.goal_spacing_xy_m, config.goal_spacing_z_m)
    axes = [_levels(bounds[0, a], bounds[1, a], spacing[a]) for a in range(3)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def safe_goal_mask(
    sdf: SdfVolume, goals: np.ndarray, clearance_m: float = 0.08
) -> np.ndarray:
    """(G,) bool: the SDF at each goal and at its 6 voxel neighbours is >= ``clearance_m``.

    Points outside the volume read as occupied.
    """
    goals = np.asarray(goals, dtype=np.float64).reshape(-1, 3)
    points = goals[:, None, :] + sdf.voxel_size * _NEIGHBOURS[None, :, :]
    values = sdf.sample(points.reshape(-1, 3), outside_value=-1.0).reshape(len(goals), -1)
    return np.all(values >= clearance_m - _TOLERANCE_M, axis=1)


def select_targets(
    uncertainty: SdfVolume,
    rng: np.random.Generator,
    top_uncertain: int = 4000,
    subset: int = 300,
    mask: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The target voxels: a random subset of the most uncertain ones.

    Args:
        uncertainty: uncertainty volume (0 where there is no surface).
        rng: random generator of the subset.
        top_uncertain: how many of the most uncertain voxels are candidates (ties broken at
            random by ``rng``: many voxels share the largest value, e.g. the whole frontier of
            unexplored space, and an index order would favour one corner of the map).
        subset: how many of those are drawn (without replacement).
        mask: optional (nx, ny, nz) bool of voxels allowed as targets.

    Returns:
        ((T, 3) voxel-centre positions, (T,) uncertainty), ordered by voxel index.
    """
    values = uncertainty.values.reshape(-1).astype(np.float64)
    allowed = values > 0.0
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != uncertainty.shape:
            raise ValueError(f"mask shape {mask.shape} differs from the volume's "
                             f"{uncertainty.shape}")
        allowed &= mask.reshape(-1)
    index = np.flatnonzero(allowed)
    if len(index) > top_uncertain:
        index = rng.permutation(index)  # ties in random order (see above)
        order = np.argsort(-values[index], kind="stable")[:top_uncertain]
        index = index[order]
    if len(index) > subset:
        index = rng.choice(index, size=subset, replace=False)
    index = np.sort(index)
    voxels = np.stack(np.unravel_index(index, uncertainty.shape), axis=1)
    return uncertainty.voxel_to_world(voxels), values[index]


def visibility(
    sdf: SdfVolume,
    goals: np.ndarray,
    targets: np.ndarray,
    config: GoalSearchConfig | None = None,
) -> np.ndarray:
    """(G, T) bool: which goal sees which target (range and line of sight, see module doc).

    Safety of the goals is not checked here (see :func:`safe_goal_mask`).
    """
    config = config or GoalSearchConfig()
    goals = np.asarray(goals, dtype=np.float64).reshape(-1, 3)
    targets = np.asarray(targets, dtype=np.float64).reshape(-1, 3)
    offsets = targets[None, :, :] - goals[:, None, :]
    distance = np.linalg.norm(offsets, axis=2)
    in_range = (distance > config.min_range_m) & (distance < config.max_range_m)
    seen = np.zeros(distance.shape, dtype=bool)
    goal_index, target_index = np.nonzero(in_range)
    if len(goal_index) == 0:
        return seen
    pair_distance = distance[goal_index, target_index]
    direction = offsets[goal_index, target_index] / pair_distance[:, None]
    # Samples from the goal (fraction 0) to visibility_stop_m before the target (fraction 1).
    length = pair_distance - config.visibility_stop_m
    fractions = np.linspace(0.0, 1.0, config.visibility_samples)
    points = (
        goals[goal_index][:, None, :]
        + (length[:, None] * fractions[None, :])[:, :, None] * direction[:, None, :]
    )
    values = sdf.sample(points.reshape(-1, 3), outside_value=-1.0).reshape(len(goal_index), -1)
    seen[goal_index, target_index] = np.all(values > config.free_sdf_m, axis=1)
    return seen


def _views_of(
    seen_row: np.ndarray, targets: np.ndarray, target_uncertainty: np.ndarray, count: int
) -> tuple[np.ndarray, np.ndarray]:
    visible = np.flatnonzero(seen_row)
    order = visible[np.argsort(-target_uncertainty[visible], kind="stable")[:count]]
    return targets[order], target_uncertainty[order]


def search_goals(
    sdf: SdfVolume,
    uncertainty: SdfVolume,
    rng: np.random.Generator,
    config: GoalSearchConfig | None = None,
    goal_mask: np.ndarray | None = None,
    target_mask: np.ndarray | None = None,
    origin: np.ndarray | None = None,
    travel: np.ndarray | None = None,
) -> GoalSearchResult:
    """One goal search (no fallback): the safe goals that see the most target uncertainty.

    Args:
        sdf: the planner's SDF volume (metres, positive in free space).
        uncertainty: the uncertainty volume on the same grid (0 off the surface).
        rng: random generator of the target subset.
        config: settings (NARUTO's by default).
        goal_mask: optional (nx, ny, nz) bool: a candidate goal is kept only when the voxel
            nearest to it is True (e.g. free space connected to the agent, or reachable).
        target_mask: optional (nx, ny, nz) bool of voxels allowed as targets.
        origin: (3,) the agent's position, for ``config.distance_discount_m`` (ignored
            without it).
        travel: optional (nx, ny, nz) travel distance from the agent to each voxel, for
            ``config.discount_by_travel``.

    Returns:
        A :class:`GoalSearchResult`; ``found`` is False when no safe goal sees a target.
    """
    config = config or GoalSearchConfig()
    _check_same_grid(sdf, uncertainty)
    began = time.perf_counter()
    targets, target_uncertainty = select_targets(
        uncertainty, rng, config.top_uncertain, config.target_subset, target_mask
    )
    candidates = candidate_goals(sdf.bounds, config)
    keep = safe_goal_mask(sdf, candidates, config.safe_clearance_m)
    safe_count = int(keep.sum())
    if goal_mask is not None:
        goal_mask = np.asarray(goal_mask, dtype=bool)
        if goal_mask.shape != sdf.shape:
            raise ValueError(f"goal_mask shape {goal_mask.shape} differs from the volume's "
                             f"{sdf.shape}")
        keep &= _sample_nearest(sdf, goal_mask, candidates)
    goals = candidates[keep]
    diagnostics: dict[str, float] = {
        "candidates": float(len(candidates)),
        "safe_goals": float(safe_count),
        "searched_goals": float(len(goals)),
        "targets": float(len(targets)),
        "evaluated_goals": 0.0,
        "tested_pairs": 0.0,
    }

    def result(found: bool, best: list[tuple[float, int, np.ndarray]]) -> GoalSearchResult:
        diagnostics["time_ms"] = (time.perf_counter() - began) * 1e3
        goal_views = [
            _views_of(row, targets, target_uncertainty, config.num_views) for _, _, row in best
        ]
        return GoalSearchResult(
            found=found,
            goal=goals[best[0][1]].copy() if found else None,
            views=goal_views[0][0] if found else np.zeros((0, 3)),
            view_uncertainty=goal_views[0][1] if found else np.zeros(0),
            score=best[0][0] if found else 0.0,
            goals=goals[[index for _, index, _ in best]] if best else np.zeros((0, 3)),
            goal_scores=np.array([score for score, _, _ in best]),
            goal_views=[views for views, _ in goal_views],
            goal_visible=[targets[row] for _, _, row in best],
            targets=targets,
            target_uncertainty=target_uncertainty,
            diagnostics=diagnostics,
        )

    if len(goals) == 0 or len(targets) == 0:
        return result(False, [])
    # Branch and bound: a goal's score is at most the uncertainty of the targets in range.
    distance = np.linalg.norm(targets[None, :, :] - goals[:, None, :], axis=2)
    in_range = (distance > config.min_range_m) & (distance < config.max_range_m)
    bound = in_range.astype(np.float64) @ target_uncertainty
    discount = np.ones(len(goals))
    if config.distance_discount_m is not None and origin is not None:
        way = np.linalg.norm(goals - np.asarray(origin, np.float64).reshape(1, 3), axis=1)
        if config.discount_by_travel and travel is not None:
            if travel.shape != sdf.shape:
                raise ValueError(f"travel volume shape {travel.shape} differs from the SDF's "
                                 f"{sdf.shape}")
            by_travel = _sample_nearest(sdf, travel, goals)
            way = np.where(np.isfinite(by_travel), by_travel, way)
        discount = np.exp(-way / config.distance_discount_m)
    bound *= discount  # still an upper bound: the discount depends on the goal only
    order = np.lexsort((np.arange(len(goals)), -bound))  # bound descending, index ascending
    best: list[tuple[float, int, np.ndarray]] = []  # (score, goal index, visibility row)
    for begin in range(0, len(order), config.batch_goals):
        batch = order[begin : begin + config.batch_goals]
        kth = best[config.top_k - 1][0] if len(best) >= config.top_k else 0.0
        batch = batch[bound[batch] > 0.0]
        if len(best) >= config.top_k:
            batch = batch[bound[batch] >= kth]
        if len(batch) == 0:
            break
        seen = visibility(sdf, goals[batch], targets, config)
        diagnostics["evaluated_goals"] += len(batch)
        diagnostics["tested_pairs"] += float(in_range[batch].sum())
        scores = (seen.astype(np.float64) @ target_uncertainty) * discount[batch]
        for row, goal_index in enumerate(batch):
            if scores[row] > 0.0:
                best.append((float(scores[row]), int(goal_index), seen[row]))
        best.sort(key=lambda item: (-item[0], item[1]))
        del best[config.top_k :]
    return result(bool(best), best)


def _sample_nearest(sdf: SdfVolume, volume: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N,) values of a volume on ``sdf``'s grid at the voxels nearest to ``points``."""
    voxel = np.clip(np.rint(sdf.world_to_voxel(points)).astype(np.int64), 0,
                    np.asarray(sdf.shape) - 1)
    return volume[voxel[:, 0], voxel[:, 1], voxel[:, 2]]


def uncertainty_aware_goal_search(
    sdf: SdfVolume,
    uncertainty: SdfVolume,
    start: np.ndarray,
    rng: np.random.Generator,
    config: GoalSearchConfig | None = None,
    goal_mask: np.ndarray | None = None,
    planner_config: PlannerConfig | None = None,
    reachable_iterations: int = 2000,
    travel: np.ndarray | None = None,
) -> GoalSearchResult:
    """NARUTO's goal search with its fallback.

    With ``config.explore_first_share`` it first searches with the most uncertain tier of
    targets only (see :class:`GoalSearchConfig`). Then searches once; if no goal sees any
    target, grows a goal-free RRT from ``start`` over the whole volume
    (:func:`~naruto_agent.planning.reachable_voxels`), keeps only targets and goals within
    one step of that tree, and searches again.

    Args:
        sdf: the planner's SDF volume.
        uncertainty: the uncertainty volume on the same grid.
        start: (3,) the agent's position (root of the fallback tree).
        rng: random generator (target subsets, the tree's seed).
        config: goal search settings.
        goal_mask: optional (nx, ny, nz) bool restricting the candidate goals (first search).
        planner_config: step, clearance and limits of the fallback tree.
        reachable_iterations: extensions of the fallback tree.
        travel: optional travel distance from ``start`` per voxel
            (``config.discount_by_travel``).
    """
    config = config or GoalSearchConfig()
    if config.explore_first_share is not None:
        values = uncertainty.values
        first = values >= config.explore_first_share * float(values.max(initial=0.0))
        first &= values > 0.0
        if int(first.sum()) >= config.explore_first_min_voxels:
            found = search_goals(sdf, uncertainty, rng, config, goal_mask=goal_mask,
                                 target_mask=first, origin=start, travel=travel)
            if found.found:
                found.diagnostics["explore_first"] = 1.0
                return found
    found = search_goals(sdf, uncertainty, rng, config, goal_mask=goal_mask, origin=start,
                         travel=travel)
    if found.found:
        return found
    began = time.perf_counter()
    planner_config = planner_config or PlannerConfig()
    tree_config = PlannerConfig(**{**planner_config.__dict__,
                                   "seed": int(rng.integers(2**31 - 1))})
    reachable = reachable_voxels(sdf, start, tree_config, iterations=reachable_iterations)
    tree_ms = (time.perf_counter() - began) * 1e3
    mask = reachable if goal_mask is None else reachable & goal_mask
    retry = search_goals(sdf, uncertainty, rng, config, goal_mask=mask, target_mask=reachable,
                         origin=start, travel=travel)
    retry.used_reachable_mask = True
    retry.diagnostics["reachable_voxels"] = float(reachable.sum())
    retry.diagnostics["reachable_ms"] = tree_ms
    retry.diagnostics["time_ms"] += tree_ms + found.diagnostics["time_ms"]
    return retry
