"""Classic frontier-based exploration (Yamauchi, 1997) on a voxel occupancy map from depth.

The policy builds its own :class:`~naruto_agent.mapping.occupancy.OccupancyGrid` from the
depth and pose observations (never the ground-truth mesh), looks around, then goes from one
nearest reachable frontier cluster (free voxels next to unknown ones) to the next and looks
around at each, until no frontier is left. On an open scan it keeps its frontier, goals and
paths to where the env's scanned-space test passes on its map, and learns the scan's edge
from the moves the env refuses; before every move the shared open-scan guard
(:class:`~naruto_agent.guards.ScanGuard`) reads the move's way from the depth panorama. The
loop, and why each rule is there, is in docs/policies.md; the settings are
:class:`~naruto_agent.policies.config.FrontierConfig`. A stall the loop's own rules miss
(turning on the spot with no frontier it can reach, a goal refused one step at a time) is
caught by the stall watchdog (:mod:`naruto_agent.policies.watchdog`): the policy gives the
spot up and walks to the reachable place past the stay that the shared recovery
(:mod:`naruto_agent.policies.stall_recovery`) chose from its map, and plans from there.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np
from scipy import ndimage

from naruto_agent.guards.refused_moves import RefusedMoves
from naruto_agent.guards.scan_guard import ScanGuard
from naruto_agent.mapping.occupancy import OccupancyGrid
from naruto_agent.policies.base import (
    EnvContext,
    Info,
    Observation,
    Policy,
    clip_pose_action,
    pose_action,
)
from naruto_agent.policies.config import FrontierConfig, build_config
from naruto_agent.policies.layers import Layer, LinesLayer, PointsLayer, subsample
from naruto_agent.policies.registry import register_policy
from naruto_agent.policies.stall_recovery import ReachablePlaces
from naruto_agent.policies.watchdog import StallEvent, StallWatchdogConfig
from naruto_gym.geometry.transforms import look_at_rotation, make_pose, rotation_angle_between

_ALL_NEIGHBOURS = np.ones((3, 3, 3), bool)


#: The frontier policy's stall watchdog: a stay that still learns (a look-around at a goal,
#: 27 steps in full) is cut after 22 steps (24 by default): its walk away from a stay climbs or
#: sinks as it goes and needs up to 8 steps to get 0.5 m away, within the 30 a stay may last
#: (docs/policies.md).
STALL_WATCHDOG = StallWatchdogConfig(max_stay_steps=22)


@register_policy("frontier")
class FrontierPolicy(Policy):
    """Nearest-frontier exploration with a depth-built voxel occupancy map.

    Args:
        config: the settings (default :class:`FrontierConfig`).
        **settings: :class:`FrontierConfig` fields, and those of its ``guard``
            (:class:`~naruto_agent.guards.ScanGuardConfig`), overriding ``config``'s.

    Attributes:
        config: the settings.
        guard: the open-scan guard.
        grid: the occupancy map of the episode (after ``reset``).
        refused: where the scan ends, learned from escape refusals.
        state: ``"look"``, ``"plan"``, ``"move"`` or ``"done"``.
        visited_goals: goals reached or given up on this episode (world positions).
        plans: planning requests this episode.
    """

    required_observations = ("depth", "pose")

    def __init__(self, *, config: FrontierConfig | None = None, **settings: Any) -> None:
        super().__init__()
        self.config = build_config(FrontierConfig, config, **settings)
        self.guard = ScanGuard(self.config.guard)
        self._closed_scan_held_done = False  # see _release_closed_scan
        self.grid: OccupancyGrid | None = None
        self.state = "look"
        self.visited_goals: list[np.ndarray] = []
        self.plans = 0
        self._views: deque[np.ndarray] = deque()
        self._path: np.ndarray = np.zeros((0, 3))
        self._goal_cell: np.ndarray | None = None
        self._goal_focus: np.ndarray | None = None
        self._visited: np.ndarray | None = None
        self._blocked: np.ndarray | None = None
        self._steps_since_plan = 0
        self._last_position: np.ndarray | None = None
        self._stuck = 0
        self._pitch_index = 0
        self._traversable_cache: np.ndarray | None = None
        self.refused = RefusedMoves()
        self._last_target: np.ndarray | None = None
        self._wandering = False  # on a stall recovery's walk: the env, not the probes, decides
        self._way_out_plan: tuple[Any, np.ndarray] | None = None  # reachable_places' plan
        self.use_stall_watchdog(STALL_WATCHDOG, enabled=self.config.stall_watchdog)

    @property
    def wandering(self) -> bool:
        """On a stall recovery's walk to a reachable place away from the stall."""
        return self._wandering

    @property
    def scan_open(self) -> bool:
        """The scan is known to be open (an escape refusal, or a depth frame saw the sky)."""
        return self.guard.scan_open

    @scan_open.setter
    def scan_open(self, value: bool) -> None:
        self.guard.scan_open = value

    def bind(self, context: EnvContext) -> None:
        super().bind(context)
        self.guard.agent_radius_m = context.agent_radius_m

    # -- episode -------------------------------------------------------------------------
    def reset(self, observation: Observation, info: Info, seed: int | None = None) -> None:
        super().reset(observation, info, seed)
        context = self.context
        self.grid = OccupancyGrid(
            context.bounds,
            voxel_size_m=self.config.voxel_size_m,
            max_range_m=min(self.config.max_range_m, context.max_depth_m),
            pixel_stride=self.config.pixel_stride,
        )
        self._visited = np.zeros(self.grid.shape, bool)
        # Cells beyond the scan's edge, learned from escape refusals; kept apart from the
        # occupancy map, whose free-space updates would erase them (nothing is there to see).
        self._blocked = np.zeros(self.grid.shape, bool)
        self.visited_goals = []
        self.plans = 0
        self._path = np.zeros((0, 3))
        self._goal_cell = None
        self._goal_focus = None
        self._steps_since_plan = 0
        self._last_position = None
        self._stuck = 0
        self._pitch_index = 0
        self.refused.reset()
        self._last_target = None
        self._wandering = False
        self._way_out_plan = None
        self.guard.reset()
        self._closed_scan_held_done = False
        pose = np.asarray(observation["pose"], np.float64)
        self._integrate(observation["depth"], pose)
        self._start_look_around(pose, focus=None)

    def view_layers(self) -> list[Layer]:
        """The frontier not yet visited, the goal the policy heads for with the rest of its
        path, and the goals it reached (see :meth:`Policy.view_layers`)."""
        if self.grid is None or self._visited is None:
            return []
        frontier = self.grid.cell_to_world(np.argwhere(self.grid.frontier() & ~self._visited))
        layers: list[Layer] = [
            PointsLayer("frontier", subsample(frontier, 3000), colour=(80, 220, 120)),
            PointsLayer("goals chosen", np.reshape(self.visited_goals, (-1, 3)),
                        colour=(255, 255, 255), radius_m=0.04),
        ]
        if self._goal_cell is not None and self.state == "move":
            goal = self.grid.cell_to_world(np.reshape(self._goal_cell, (1, 3)))
            layers.append(PointsLayer("goal", goal, colour=(255, 200, 0), radius_m=0.08))
            layers.append(LinesLayer("planned path", (self._path,), colour=(0, 200, 255)))
        return layers

    # -- helpers -------------------------------------------------------------------------
    def _integrate(self, depth: np.ndarray, pose: np.ndarray) -> None:
        assert self.grid is not None
        self.grid.integrate(depth, pose, self.context.camera)
        self.guard.observe_depth(depth, pose, self.context.camera)

    @property
    def _held_to_scan(self) -> bool:
        if not self.config.scanned_space_support:
            return False
        return self.scan_open or (
            self.config.support_on_closed_scans and not self._closed_scan_held_done
        )

    def _release_closed_scan(self) -> bool:
        """On a closed scan held to the test, once no frontier it keeps can be reached, let
        the rest go (the unknown above the measured top there is a ceiling still to see, and
        chasing it finishes the map): True when that changed the policy's hold."""
        if self.scan_open or not self._held_to_scan:
            return False
        self._closed_scan_held_done = True
        return True

    @property
    def _probes_edges(self) -> bool:
        # Only once the scan is known open: a closed scan has no edge to probe for, and the
        # probes' false alarms (a coarse panorama) gave goals up for nothing.
        return self.config.scanned_space_support and self.scan_open

    def _z_band(self, position: np.ndarray) -> tuple[float, float]:
        """Heights paths and goals keep to: ``height_margin_m`` inside the bounds, below the
        flight ceiling refused climbs have taught, and on an open scan
        ``scan_top_margin_m`` below the measured surfaces' top, though never below the agent
        itself (early on, the measured top may be a table)."""
        assert self.grid is not None
        config = self.config
        bounds = self.context.bounds
        low = bounds[0, 2] + config.height_margin_m
        high = min(bounds[1, 2] - config.height_margin_m,
                   self.refused.ceiling_z - config.voxel_size_m)
        if self._held_to_scan:
            top = self.grid.occupied_top_z(config.scan_top_quantile) - config.scan_top_margin_m
            high = min(high, max(top, float(position[2])))
        if high <= low:  # a very flat scene: use its middle
            middle = (bounds[0, 2] + bounds[1, 2]) / 2.0
            return middle - config.voxel_size_m, middle + config.voxel_size_m
        return low, high

    def _start_look_around(self, pose: np.ndarray, focus: np.ndarray | None) -> None:
        """Queue the views of a look-around: a full turn without a focus; with one, the
        focus itself, then headings ``look_focus_sweep_deg`` to either side of it."""
        position = pose[:3, 3]
        self._views.clear()
        to_focus = None if focus is None else focus - position
        if to_focus is not None and np.linalg.norm(to_focus[:2]) > 1e-3:
            yaw = float(np.arctan2(to_focus[1], to_focus[0]))
            pitch = float(np.arctan2(to_focus[2], np.linalg.norm(to_focus[:2])))
            limit = float(np.deg2rad(self.config.max_focus_pitch_deg))
            pitch = float(np.clip(pitch, -limit, limit))
            sweep = float(np.deg2rad(self.config.look_focus_sweep_deg))
            views = [(yaw, pitch), (yaw + sweep, pitch), (yaw - sweep, pitch)]
        else:
            forward = pose[:3, 2]
            start_yaw = float(np.arctan2(forward[1], forward[0]))
            views = []
            pitches = [float(np.deg2rad(p)) for p in self.config.look_pitches_deg]
            headings = self.config.look_around_headings
            for k in range(headings):
                pitch = pitches[self._pitch_index % len(pitches)]
                self._pitch_index += 1
                views.append((start_yaw + 2.0 * np.pi * k / headings, pitch))
        for yaw, pitch in views:
            look = np.array(
                [np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch)]
            )
            self._views.append(look_at_rotation(position, position + look))
        self.state = "look"

    def _mark_visited(self, position: np.ndarray) -> None:
        assert self.grid is not None and self._visited is not None
        self.visited_goals.append(position.copy())
        radius = int(np.ceil(self.config.visited_radius_m / self.config.voxel_size_m))
        centre = self.grid.world_to_cell(position[None])[0]
        low = np.maximum(centre - radius, 0)
        high = np.minimum(centre + radius + 1, np.array(self.grid.shape))
        if np.any(high <= low):
            return
        axes = [np.arange(low[i], high[i]) for i in range(3)]
        cells = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        near = np.linalg.norm(self.grid.cell_to_world(cells) - position, axis=1)
        cells = cells[near <= self.config.visited_radius_m]
        self._visited[tuple(cells.T)] = True

    def _frontier_clusters(self, position: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(labels, kept) of frontier clusters big enough and not yet visited; with
        ``scanned_space_support``, of frontier inside the scan (see docs/policies.md)."""
        assert self.grid is not None and self._visited is not None
        if not self._held_to_scan:
            return self._clusters(self.grid.frontier() & ~self._visited)
        # Unknown above the measured top (though never below the agent: early on the top may
        # be the floor) is the open sky: no view resolves it.
        top = max(self.grid.occupied_top_z(self.config.scan_top_quantile), float(position[2]))
        frontier = self.grid.frontier(unknown_below_z=top) & ~self._visited
        labels, kept = self._clusters(self._inside_scan(frontier, position))
        if kept.any():
            return labels, kept
        # Little measured yet (a floor, nothing around): frontier over measured surface.
        frontier &= self.grid.levels_within(self._z_band(position))[None, None, :]
        frontier &= self.grid.supported_below(self.config.support_below_m,
                                              self.config.support_reach_m)
        return self._clusters(frontier)

    def _clusters(self, frontier: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        labels, _ = ndimage.label(frontier, structure=_ALL_NEIGHBOURS)
        sizes = np.bincount(labels.reshape(-1))
        big = sizes >= self.config.min_cluster_voxels
        big[0] = False
        return labels, big[labels]

    def _traversable(
        self, position: np.ndarray, inflation_voxels: int, inside_scan: bool
    ) -> np.ndarray:
        assert self.grid is not None
        traversable = self.grid.traversable(inflation_voxels, self._z_band(position))
        if inside_scan:
            traversable = self._inside_scan(traversable, position)
        # The agent may always leave its own neighbourhood (it may start close to a wall).
        centre = self.grid.world_to_cell(position[None])[0]
        low = np.maximum(centre - 1, 0)
        high = np.minimum(centre + 2, np.array(self.grid.shape))
        block = (slice(low[0], high[0]), slice(low[1], high[1]), slice(low[2], high[2]))
        traversable[block] |= ~self.grid.occupied[block]
        traversable &= ~self._blocked  # but never past an edge the env refused
        return traversable

    def _inside_scan(self, candidates: np.ndarray, position: np.ndarray) -> np.ndarray:
        """Of the ``candidates`` voxels, those the env's scanned-space test would accept on
        this policy's map: inside the height band and with measured surface in every sector
        of the downward cone."""
        assert self.grid is not None
        cells = np.argwhere(candidates)
        cells = cells[self.grid.levels_within(self._z_band(position))[cells[:, 2]]]
        inside = np.zeros_like(candidates)
        supported = self.guard.inside_scan(self.grid, self.grid.cell_to_world(cells))
        inside[tuple(cells[supported].T)] = True
        return inside

    def _plan(self, position: np.ndarray) -> bool:
        """Choose the nearest reachable frontier cluster; set the path. False: none left.

        On an open scan paths keep to voxels that pass the env's test on this map.
        When no cluster can be reached that way, the agent may be boxed in by its own
        inflation (it went low under furniture, and later frames closed the way it came in)
        or by floor it has not measured below it: it then plans once more without inflation,
        and then once more without the test (goals still pass it). On a closed scan, when
        nothing is left that way, the test is let go for the rest of the episode
        (:meth:`_release_closed_scan`)."""
        assert self.grid is not None
        self.plans += 1
        self._steps_since_plan = 0
        self._wandering = False
        labels, kept = self._frontier_clusters(position)
        if not kept.any():
            return self._release_closed_scan() and self._plan(position)
        held = self._held_to_scan
        inflation = self.config.inflation_voxels
        attempts = [(inflation, held), (0, held), (inflation, False)]
        for inflation, inside_scan in dict.fromkeys(attempts):
            if self._plan_through(position, labels, kept, inflation, inside_scan):
                return True
        return self._release_closed_scan() and self._plan(position)

    def _plan_through(
        self, position: np.ndarray, labels: np.ndarray, kept: np.ndarray, inflation: int,
        inside_scan: bool,
    ) -> bool:
        assert self.grid is not None
        traversable = self._traversable(position, inflation, inside_scan)
        start = self.grid.world_to_cell(position[None])[0]
        start = np.clip(start, 0, np.array(self.grid.shape) - 1)
        plan = self.grid.plan_from(start, traversable)
        reachable = np.isfinite(plan.costs) & traversable
        distance, nearest = ndimage.distance_transform_edt(~kept, return_indices=True)
        candidates = reachable & (distance <= self.config.goal_radius_voxels)
        if self._held_to_scan and not inside_scan:
            candidates = self._inside_scan(candidates, position)
        # Do not count the start as a goal: it was just looked around from.
        candidates[tuple(start)] = False
        index = np.flatnonzero(candidates)
        if len(index) == 0:
            return False
        path_cost = plan.costs.reshape(-1)[index]
        if np.any(path_cost >= self.config.min_goal_distance_m):
            index = index[path_cost >= self.config.min_goal_distance_m]
        voxel = self.config.voxel_size_m
        score = plan.costs.reshape(-1)[index] + distance.reshape(-1)[index] * voxel
        best = index[int(np.argmin(score))]
        goal = np.array(np.unravel_index(best, self.grid.shape))
        focus_cell = np.array([n.reshape(-1)[best] for n in nearest])
        cluster = labels == labels[tuple(focus_cell)]
        self._goal_focus = self.grid.cell_to_world(np.argwhere(cluster)).mean(axis=0)
        self._goal_cell = goal
        cells = self.grid.trace_path(plan, goal)
        self._path = self.grid.cell_to_world(cells)
        self._path[0] = position  # start exactly where the agent is
        self._traversable_cache = traversable
        self.state = "move"
        return True

    def _goal_still_frontier(self, position: np.ndarray) -> bool:
        if self._goal_cell is None:
            return False
        _, kept = self._frontier_clusters(position)
        radius = int(np.ceil(self.config.goal_radius_voxels))
        low = np.maximum(self._goal_cell - radius, 0)
        high = self._goal_cell + radius + 1
        return bool(kept[low[0] : high[0], low[1] : high[1], low[2] : high[2]].any())

    # -- stall recovery --------------------------------------------------------------------
    def reachable_places(self, position: np.ndarray) -> ReachablePlaces | None:
        """The free voxels the map connects to ``position``, a few voxels away and more, with
        their path lengths (the shared stall recovery's choice): those the planner's
        inflation keeps clear of surfaces, or without inflation when none is."""
        assert self.grid is not None
        self._release_closed_scan()
        start = np.clip(self.grid.world_to_cell(position[None])[0], 0,
                        np.array(self.grid.shape) - 1)
        for inflation in dict.fromkeys((self.config.inflation_voxels, 0)):
            traversable = self._traversable(position, inflation, self._held_to_scan)
            traversable[tuple(start)] = True  # the way out starts where the agent stands
            plan = self.grid.plan_from(start, traversable)
            cells = np.argwhere(traversable & np.isfinite(plan.costs)
                                & (plan.costs >= 3.0 * self.config.voxel_size_m))
            if len(cells):
                break
        self._way_out_plan = (plan, traversable)
        return ReachablePlaces(self.grid.cell_to_world(cells), plan.costs[tuple(cells.T)])

    def walk_out(self, position: np.ndarray, goal: np.ndarray) -> str:
        """Give the stalled spot and the goal up and walk to ``goal``: along the map's path
        when the map reaches it, else straight; arrived, it looks on ahead and plans."""
        assert self.grid is not None
        self._give_up_spot(position)
        cell = self.grid.world_to_cell(goal[None])[0]
        plan, traversable = self._way_out_plan or (None, None)
        if (plan is not None and self.grid.in_grid(cell[None])[0]
                and np.isfinite(plan.costs[tuple(cell)])):
            self._path = self.grid.cell_to_world(self.grid.trace_path(plan, cell))
            self._traversable_cache = traversable
            how = "along the map's path"
        else:
            steps = max(1, int(np.ceil(np.linalg.norm(goal - position) / 0.1)))
            self._path = position + np.outer(np.arange(steps + 1) / steps, goal - position)
            self._traversable_cache = ~self.grid.occupied
            how = "straight"
        self._path[0] = position
        self._goal_cell = cell
        # Arrived, it looks on ahead (a short look, not a full turn: that stalled).
        self._goal_focus = goal + np.append(goal[:2] - position[:2], 0.0)
        self._steps_since_plan = 0
        self.state = "move"
        self._wandering = True
        return how

    def no_way_out(self, event: StallEvent) -> str:
        """No reachable place past the stay: give the spot up and plan anew."""
        position = np.asarray(event.position, np.float64)
        self._give_up_spot(position)
        if self._plan(position):
            return "no way out: new frontier goal"
        self.state = "done"
        return "no way out: look around"

    def _give_up_spot(self, position: np.ndarray) -> None:
        """The stalled spot and the goal count as visited; the look-around is dropped."""
        assert self.grid is not None
        if self._goal_cell is not None:
            self._mark_visited(self.grid.cell_to_world(self._goal_cell[None])[0])
        self._mark_visited(position)
        self._views.clear()
        self._stuck = 0

    # -- acting --------------------------------------------------------------------------
    def _look_action(self, pose: np.ndarray) -> np.ndarray | None:
        while self._views:
            if rotation_angle_between(pose[:3, :3], self._views[0]) > np.deg2rad(2.0):
                return pose_action(make_pose(self._views[0], pose[:3, 3]))
            self._views.popleft()
        return None

    def _learn_edge(self, position: np.ndarray, panorama: np.ndarray | None) -> None:
        """Learn from an escape refusal (see docs/policies.md)."""
        assert self.grid is not None
        if self._last_target is None:
            return
        ceiling = self.refused.ceiling_z
        edge = self.refused.record(position, self._last_target, panorama, across_half_width_m=0)
        if self.refused.ceiling_z < ceiling:
            return  # the top of the scan: the height band now ends below it
        # Block the voxels the refused move headed into and the edge joined through earlier
        # refusals nearby, from 0.3 m below to 0.3 m above, but only ahead of the agent and
        # never its own voxel (paths start there, and the edge often runs through it):
        # blocking behind it could box it in where edges meet (a floor hole's corner).
        move = self._last_target - position
        direction = move / max(float(np.linalg.norm(move)), 1e-9)
        ahead = position + np.outer([1.0, 1.5, 2.0], direction) * self.config.voxel_size_m
        points = np.concatenate([ahead, edge])
        if len(edge):
            heights = np.arange(-0.3, 0.3 + 1e-9, self.config.voxel_size_m)
            layers = np.repeat(edge, len(heights), axis=0)
            layers[:, 2] += np.tile(heights, len(edge))
            points = np.concatenate([ahead, layers])
        points = points[(points - position) @ direction > 0.0]
        cells = self.grid.world_to_cell(points)
        own = self.grid.world_to_cell(position[None])[0]
        cells = cells[self.grid.in_grid(cells) & np.any(cells != own, axis=1)]
        self._blocked[tuple(cells.T)] = True

    def _panorama_shows_surface(
        self, position: np.ndarray, target: np.ndarray, panorama: np.ndarray | None
    ) -> bool:
        """Whether the guard holds the move back for a surface the panorama taken where the
        agent stands shows in its way; the surface point is then marked occupied (the 0.1 m
        grid misses thin or small surfaces by a few centimetres)."""
        assert self.grid is not None
        contact = self.guard.hold_for_surface(panorama, target - position)
        if contact is None:
            return False
        self.grid.mark_occupied((position + contact)[None])
        return True

    def _probe_refuses(
        self, position: np.ndarray, target: np.ndarray, panorama: np.ndarray | None
    ) -> bool:
        """On an open scan, whether the move towards ``target`` would leave the scanned
        space: on the policy's own map, or on the depth panorama taken where it stands
        (the guard's edge probes; once they held ``max_held_moves`` moves at one spot, or
        from a start in the scan's margin, the panorama's word is dropped and the env
        decides: low over a floor hole every move can look like leaving)."""
        assert self.grid is not None
        if self.guard.map_leaves_scan(self.grid, position, target):
            return True
        return self.guard.hold_for_edge(panorama, target - position)

    def _move_action(self, pose: np.ndarray, panorama: np.ndarray | None) -> np.ndarray | None:
        assert self.grid is not None
        position = pose[:3, 3]
        # Drop the path points already passed.
        distances = np.linalg.norm(self._path - position, axis=1)
        closest = int(np.argmin(distances))
        self._path = self._path[closest:]
        if len(self._path) <= 1 and np.linalg.norm(self._path[-1] - position) < 0.02:
            return None
        target = self._path[min(1, len(self._path) - 1)]
        for index in range(min(self.config.lookahead_voxels, len(self._path) - 1), 1, -1):
            if self.grid.segment_is_traversable(
                position, self._path[index], self._traversable_cache
            ):
                target = self._path[index]
                break
        step = target - position
        heading = np.array([step[0], step[1], 0.0])
        if np.linalg.norm(heading) < 1e-6:
            rotation = pose[:3, :3]
        else:
            rotation = look_at_rotation(position, position + heading)
        length = float(np.linalg.norm(step))
        if length > self.context.max_translation_m:
            target = position + step * (self.context.max_translation_m / length)
        self._last_target = np.asarray(target, np.float64).copy()
        if not self._wandering and self._panorama_shows_surface(
                position, self._last_target, panorama):
            self.state = "plan"  # the goal stays; the marked surface reroutes the path
            return None
        if self.guard.surface_holds_spent(panorama):
            # Held at this spot too often: send what the panorama shows clear of the move
            # (slid along the surface, or cut short), else the move itself; the env decides.
            part = self.guard.clear_part(panorama, self._last_target - position)
            if part is not None:
                self._last_target = position + part
                target = self._last_target
        if self._wandering:
            return pose_action(make_pose(rotation, target))
        if self._probes_edges and self._probe_refuses(position, self._last_target, panorama):
            # Refused as the env would: learn the edge; close to the goal, arrive here (the
            # caller looks around), else give the goal up and plan.
            self._learn_edge(position, None)
            waypoints = np.concatenate([position[None], self._path])
            remaining = float(np.linalg.norm(np.diff(waypoints, axis=0), axis=1).sum())
            if remaining <= self.config.edge_arrival_m:
                self._path = position[None].copy()
                return None
            if self._goal_cell is not None:
                self._mark_visited(self.grid.cell_to_world(self._goal_cell[None])[0])
            self.state = "plan"
            return None
        return pose_action(make_pose(rotation, target))

    def act(self, observation: Observation, info: Info | None = None) -> np.ndarray:
        if self.grid is None:
            raise RuntimeError("call reset() before act()")
        pose = np.asarray(observation["pose"], np.float64)
        position = pose[:3, 3]
        self._integrate(observation["depth"], pose)
        known = float(np.count_nonzero(self.grid.observed))
        if self.check_stall(observation, info, progress=known) is not None:
            self._last_position = position.copy()
            info = {}  # the recovery has dealt with this step's refusal
        self._steps_since_plan += 1
        collided = bool(info.get("collided", False)) if info else False

        if self.state == "move":
            moved = (
                self._last_position is None or np.linalg.norm(position - self._last_position) > 1e-3
            )
            self._stuck = 0 if moved else self._stuck + 1
            if moved:
                self.guard.moved()
            if collided and info.get("collision_reason") == "escape":
                self.guard.note_escape()
                self._learn_edge(position, observation.get("panorama"))
            elif collided and self._last_target is not None:
                # A bump: the map missed an obstacle in the refused move's way; remember it
                # and plan again (the env may have moved the agent part of the way, so the
                # same path would bump again).
                ahead = self._last_target - position
                norm = np.linalg.norm(ahead)
                if norm > 1e-6:
                    bump = position + ahead / norm * (
                        self.context.agent_radius_m + 0.5 * self.config.voxel_size_m
                    )
                    self.grid.mark_occupied(bump[None])
            if self._wandering and collided:
                self.state = "plan"  # a stall recovery's walk refused (it is not chosen again)
            elif self._stuck >= 3 or (collided and self._stuck >= 1):
                self._mark_visited(self.grid.cell_to_world(self._goal_cell[None])[0])
                self._stuck = 0
                self.state = "plan"
            elif collided:
                self.state = "plan"
            elif self._steps_since_plan >= self.config.replan_every and not self._wandering:
                self._steps_since_plan = 0
                if not self._goal_still_frontier(position):
                    self.state = "plan"
        elif self.state == "done" and self._steps_since_plan >= 3 * self.config.replan_every:
            self.state = "plan"  # turning on the spot may have revealed new frontiers
        self._last_position = position.copy()

        for _ in range(3):
            if self.state == "look":
                action = self._look_action(pose)
                if action is not None:
                    return clip_pose_action(action, self.context.action_space)
                self.state = "plan"
            if self.state == "plan":
                if not self._plan(position):
                    self.state = "done"
                    break
            if self.state == "move":
                action = self._move_action(pose, observation.get("panorama"))
                if action is not None:
                    return clip_pose_action(action, self.context.action_space)
                if self.state == "plan":
                    continue  # the move would have left the scan
                # Arrived: look around here, towards the cluster first.
                self._mark_visited(position)
                self._start_look_around(pose, self._goal_focus)
        # Nothing left to explore (or no decision this step): keep turning on the spot.
        if not self._views:
            self._start_look_around(pose, focus=None)
            self.state = "done" if self.state == "done" else "look"
        action = self._look_action(pose)
        if action is None:
            action = pose_action(pose)
        return clip_pose_action(action, self.context.action_space)
