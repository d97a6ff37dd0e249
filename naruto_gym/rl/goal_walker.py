"""The goal walker of the goal actions (:mod:`naruto_gym.rl.goal_actions`): turns one agent's
candidate or primitive action into one primitive move per step, walking a path planned over the
agent's own egocentric map (:mod:`naruto_gym.rl.goal_planner`) to the candidate's viewpoint,
keeping the camera level and at the walking height, turning to face the cluster and glancing
down there; with no candidate it wanders to the place farthest from its trail. A stall
watchdog's recovery walks it out of a stay (:meth:`GoalWalker.walk_out`). Its ``decision``: who
picks the goal after one is done, the walker (the nearest, "interval") or the agent ("goal").

:class:`GoalWalker` serves every agent of an :class:`EgocentricMapBuilder`; the wrappers of
:mod:`naruto_gym.rl.goal_actions` drive it, and a policy may use it without them.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from naruto_gym.motion.actions import DISCRETE_ACTIONS
from naruto_gym.rl.egocentric_map import EgocentricMapBuilder
from naruto_gym.rl.goal_candidates import (
    CANDIDATE_FEATURES,
    INTERVAL_FEATURES,
    find_candidates,
    reachable_cells,
    wander_goal,
)
from naruto_gym.rl.goal_planner import (
    MOVE_BACKWARD,
    MOVE_FORWARD,
    MOVE_LEFT,
    MOVE_RIGHT,
    REACHED,
    REPLAN,
    TRANSLATIONS,
    TURN_LEFT,
    TURN_RIGHT,
    WALK_ON_TURNS,
    WALKING,
    follow_path,
    move_is_safe,
    path_carrot,
    plan_path,
    step_direction,
    step_towards,
)
from naruto_gym.utils.checks import check_integer, check_number

__all__ = ["AWAIT_DECISION", "DECISIONS", "GoalWalker"]

MOVE_UP = DISCRETE_ACTIONS.index("move_up")
LOOK_UP = DISCRETE_ACTIONS.index("look_up")
LOOK_DOWN = DISCRETE_ACTIONS.index("look_down")
MOVE_DOWN = DISCRETE_ACTIONS.index("move_down")
#: Free space kept above or below the agent after a vertical move (radius and margin).
VERTICAL_MARGIN_M = 0.2
#: Walker phases: no goal (turning in place), walking to a viewpoint, turning to face the
#: cluster, given up on a goal the map no longer lets it reach, waiting for the agent's choice.
IDLE, WALK, FACE, GIVEN_UP, AWAIT = 0, 1, 2, 3, 4
#: Who picks the next goal once one is done: ``"interval"``, the walker (the nearest
#: candidate; the agent chooses every ``K`` steps); ``"goal"``, the agent, at every goal.
DECISIONS = ("interval", "goal")
#: The move :meth:`GoalWalker.next_moves` gives an agent waiting for its next goal.
AWAIT_DECISION = -1
#: Goals the walker may finish within one step (it then turns in place).
MAX_GOALS_PER_STEP = 3
#: Height above the floor the walker walks at, and the tolerance around it: below doorways'
#: lintels, above most furniture. The floor is the lowest surface the panorama's bottom row
#: (straight down) has hit in the episode, so walking over a table does not lift the agent
#: above the lintels.
WALK_HEIGHT_M = 1.3
WALK_HEIGHT_TOLERANCE_M = 0.25
#: Steps between two searches for candidates while the walker has none.
IDLE_SEARCH_EVERY = 4
#: Lowest camera height above what is below it that an idle walker steps down to.
IDLE_LOWEST_M = 0.6
#: Each turn in place and the turn the other way.
OPPOSITE_TURN = {TURN_LEFT: TURN_RIGHT, TURN_RIGHT: TURN_LEFT}
#: A move that took the agent less than this share of a step was refused or cut short by
#: the env (a climb clipped at the scan's top ends part of the way up).
STOPPED_SHORT = 0.75
#: The moves the env may refuse or cut short: the steps, the climb and the descent.
REFUSABLE_MOVES = frozenset({*TRANSLATIONS.tolist(), MOVE_UP, MOVE_DOWN})
#: Each step and the step that undoes it.
OPPOSITE_STEP = {
    MOVE_FORWARD: MOVE_BACKWARD,
    MOVE_BACKWARD: MOVE_FORWARD,
    MOVE_LEFT: MOVE_RIGHT,
    MOVE_RIGHT: MOVE_LEFT,
}


def _wrap(angle: float) -> float:
    return float((angle + np.pi) % (2.0 * np.pi) - np.pi)


def _heading(pose: np.ndarray) -> float:
    """The camera's optical axis' direction in the x-y plane (radians)."""
    return float(np.arctan2(pose[1, 2], pose[0, 2]))


class GoalWalker:
    """Turns candidate or primitive actions into one primitive move per step, for every agent
    of an :class:`EgocentricMapBuilder`.

    Call :meth:`refresh_candidates` after the map's update at every decision (the wrappers
    do), then :meth:`set_actions`, then :meth:`next_moves` before every env step; and
    :meth:`reset` at every episode start.

    Args:
        map_builder: the agents' maps (updated by its owner after every step).
        num_candidates: candidate slots (``N``).
        primitive_actions: actions past the candidates are the discrete moves.
        step_m: length of a move (the env's ``max_translation_m``).
        turn_rad: angle of a turn (the env's ``max_rotation_deg`` in radians).
        inflate: cells around an obstacle the planner keeps out of.
        cluster_cells: side of a target cluster in far cells.
        min_targets: fewest targets a cluster needs to be a candidate.
        view_m: farthest a viewpoint may be from its cluster's centre.
        frontier_m: the same for a cluster of free-space edges only (walked up to).
        max_path: longest path kept (a longer one is followed in parts).
        glance_steps: look-down moves at each viewpoint once the walker faces its cluster
            (then as many back up to level). A level camera at walking height sees no floor
            nearer than about 2.6 m (the default camera's half vertical field of view is 29.5
            degrees).
        decision: one of :data:`DECISIONS`. With ``"goal"``, once the agent's goal is viewed,
            given up or lost (the map's slice restarted) after a move, or a wander finds a
            candidate, :meth:`next_moves` gives :data:`AWAIT_DECISION` until :meth:`set_actions`
            (with no candidate it wanders on; a goal done before a move: the nearest next).

    Raises:
        ValueError: a count that is not a positive integer, a distance that is not positive,
            or a glance that is not a whole count.
    """

    def __init__(
        self,
        map_builder: EgocentricMapBuilder,
        num_candidates: int = 8,
        primitive_actions: bool = True,
        step_m: float = 0.1,
        turn_rad: float = float(np.deg2rad(20.0)),
        inflate: int = 1,
        cluster_cells: int = 2,
        min_targets: int = 1,
        view_m: float = 2.0,
        frontier_m: float = 0.6,
        max_path: int = 512,
        glance_steps: int = 1,
        decision: str = "interval",
    ) -> None:
        for name, count in (
            ("num_candidates", num_candidates),
            ("cluster_cells", cluster_cells),
            ("min_targets", min_targets),
        ):
            check_integer(name, count)
        check_number("view_m", view_m, low=0.0)
        check_number("frontier_m", frontier_m, low=0.0)
        check_integer("glance_steps", glance_steps, low=0)
        if decision not in DECISIONS:
            raise ValueError(f"decision must be one of {DECISIONS}, got {decision!r}")
        self.decision = decision
        self.features = CANDIDATE_FEATURES if decision == "goal" else INTERVAL_FEATURES
        self.map = map_builder
        self.num_candidates = int(num_candidates)
        self.primitive_actions = bool(primitive_actions)
        self.step_m = float(step_m)
        self.turn_rad = float(turn_rad)
        self.inflate = int(inflate)
        self.cluster_cells = int(cluster_cells)
        self.min_targets = int(min_targets)
        self.view_m = float(view_m)
        self.frontier_m = float(frontier_m)
        self.glance_steps = int(glance_steps)
        n, count = map_builder.num_envs, self.num_candidates
        half_m = map_builder.cells * map_builder.far_cell_m / 2
        self.radius = int(np.ceil(half_m * np.sqrt(2) / map_builder.cell_m)) + 1
        self.paths = np.zeros((n, max_path, 2), np.int64)
        self.lengths = np.zeros(n, np.int64)
        self.cursors = np.zeros((n, 1), np.int64)
        self.primitives = np.full(n, -1, np.int64)  # -1: walking to a candidate
        self.phases = np.full(n, IDLE, np.int64)
        self.idle_steps = np.zeros(n, np.int64)
        self.moves_without_candidate = np.zeros(n, np.int64)  # idle or wandering, since a goal
        self.floor_heights = np.full(n, np.inf)  # lowest surface seen straight down
        self.climb_ceilings = np.full(n, np.inf)  # height of a refused climb, none above it
        self.descent_floors = np.full(n, -np.inf)  # height of a refused descent, none below it
        self.glance_left = np.zeros(n, np.int64)  # look-down moves left of a glance
        self.glanced = np.zeros(n, bool)  # the goal's glance is done
        self.wandering = np.zeros(n, bool)  # walking to a place with no candidate in view
        self.leaving = np.zeros(n, bool)  # wandering out of a stay: candidates do not end it
        self.stays = np.zeros((n, 3))  # a stay left without turning: centre (x, y), radius
        self.last_moves = np.full(n, -1, np.int64)  # the walking move sent last, and from where
        self.last_positions = np.zeros((n, 3))
        self.decision_moves = np.zeros(n, np.int64)  # moves since the last set_actions
        self.slice_restarts = np.zeros(n, np.int64)  # the map's count when the goal was set
        self.targets = np.zeros((n, 2))  # world (x, y) of the cluster to face
        self.target_clusters = np.full((n, 2), -1, np.int64)
        #: Per agent: the feature table of :mod:`naruto_gym.rl.goal_candidates`, the
        #: viewpoints and cluster centres (world x, y), cluster indices, and the count.
        self.tables = np.zeros((n, count, len(self.features)), np.float32)
        self.viewpoints = np.zeros((n, count, 2))
        self.centres = np.zeros((n, count, 2))
        self.clusters = np.full((n, count, 2), -1, np.int64)
        self.counts = np.zeros(n, np.int64)
        side = -(-map_builder.coarse.shape[-1] // self.cluster_cells)
        self.done = np.zeros((n, side, side), bool)
        # Per agent: the path lengths of its last candidate search, which its wander reads
        # (an agent's wander may come after the other agents' searches).
        self.path_lengths = np.zeros((n, 2 * self.radius + 1, 2 * self.radius + 1))

    @property
    def action_space(self) -> spaces.Discrete:
        extra = len(DISCRETE_ACTIONS) if self.primitive_actions else 0
        return spaces.Discrete(self.num_candidates + extra)

    @property
    def candidate_space(self) -> spaces.Box:
        """One agent's candidate feature table (``N`` rows of :attr:`features`: every
        column of :data:`CANDIDATE_FEATURES` for the ``"goal"`` decision, the
        :data:`INTERVAL_FEATURES` for the ``"interval"`` one)."""
        return spaces.Box(-1.0, np.inf, (self.num_candidates, len(self.features)), np.float32)

    def reset(self, envs: np.ndarray | None = None) -> None:
        """New episodes for ``envs`` (default all): no goal, no cluster viewed."""
        envs = np.arange(self.map.num_envs) if envs is None else np.asarray(envs, np.int64)
        self.phases[envs] = IDLE
        for flags in (self.done, self.wandering, self.leaving, self.glanced):
            flags[envs] = False
        zeroed = (self.stays, self.lengths, self.decision_moves, self.tables, self.counts)
        for zeros in (*zeroed, self.moves_without_candidate, self.glance_left):
            zeros[envs] = 0
        self.last_moves[envs] = self.primitives[envs] = -1
        self.floor_heights[envs] = self.climb_ceilings[envs] = np.inf
        self.descent_floors[envs] = -np.inf

    def refresh_candidates(self, envs: np.ndarray | None = None) -> np.ndarray:
        """Find the candidates of ``envs`` (default all) on their maps as they are now;
        returns their feature tables ``(len(envs), N, F)``."""
        envs = np.arange(self.map.num_envs) if envs is None else np.asarray(envs, np.int64)
        for i in envs:
            self._refresh(int(i))
        return self.tables[envs].copy()

    def _refresh(self, i: int) -> None:
        self.counts[i] = find_candidates(
            self.map.grids[i],
            self.map.coarse[i],
            self.map.far_factor,
            self.map.origins[i],
            self.map.cell_m,
            self.map.poses[i],
            self.radius,
            self.inflate,
            self.cluster_cells,
            self.min_targets,
            self.view_m,
            self.frontier_m,
            self.done[i],
            self.path_lengths[i],
            self.tables[i],
            self.viewpoints[i],
            self.centres[i],
            self.clusters[i],
        )

    def set_actions(self, actions: np.ndarray, envs: np.ndarray | None = None) -> None:
        """Start the macro-step of ``actions`` (one per env of ``envs``, default all) on the
        candidates of the last :meth:`refresh_candidates`. An empty candidate slot means
        candidate 0; with no candidate at all the agent turns in place (looking around).

        Raises:
            ValueError: an action outside :attr:`action_space`.
        """
        envs = np.arange(self.map.num_envs) if envs is None else np.asarray(envs)
        actions = np.asarray(actions, np.int64).reshape(len(envs))
        bad = (actions < 0) | (actions >= self.action_space.n)
        if bad.any():
            raise ValueError(
                f"goal actions are 0..{self.action_space.n - 1} ({self.num_candidates} "
                f"candidates{' then the 10 discrete moves' if self.primitive_actions else ''}), "
                f"got {actions[bad].tolist()}"
            )
        for i, action in zip(envs, actions, strict=True):
            self.decision_moves[i] = 0
            self.phases[i] = IDLE if self.phases[i] == AWAIT else self.phases[i]
            if action < self.num_candidates:
                self.primitives[i] = -1
                self._go_to(int(i), int(action))
            else:
                self.primitives[i] = action - self.num_candidates

    def _go_to(self, i: int, slot: int) -> None:
        if slot >= self.counts[i]:
            slot = 0  # an empty slot: the nearest candidate
        self.slice_restarts[i] = self.map.slice_restarts[i]
        self.glanced[i] = False
        self.leaving[i] = False
        self.stays[i] = 0.0
        self.wandering[i] = self.counts[i] == 0
        if self.counts[i] == 0:
            self._wander(i)
            return
        self.targets[i] = self.centres[i, slot]
        self.target_clusters[i] = self.clusters[i, slot]
        self.phases[i] = WALK
        self.moves_without_candidate[i] = 0
        self._plan(i, self.viewpoints[i, slot])

    def reachable_places(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Agent ``i``'s reachable places on its map's slice (searched anew; see
        :func:`~naruto_gym.rl.goal_candidates.reachable_cells`): ``(n, 2)`` world x, y and
        their path lengths (metres), among which a stall recovery chooses its way out."""
        self._refresh(i)
        si, sj = self.map.cell_of(i, self.map.poses[i][:2, 3])
        cells, lengths = reachable_cells(
            self.path_lengths[i], self.map.coarse[i], self.map.far_factor, si, sj, self.radius
        )
        return self.map.origins[i] + (cells + 0.5) * self.map.cell_m, lengths * self.map.cell_m

    def walk_out(self, i: int, goal: np.ndarray, centre: np.ndarray, radius_m: float) -> bool:
        """Walk agent ``i`` to ``goal`` (world x, y), a stall recovery's way out of the stay of
        ``radius_m`` around ``centre`` (x, y): the goal in hand is given up (its cluster done),
        the walk steps out of the stay without turning first and keeps the goal until it is
        reached or :meth:`set_actions` replaces it. False: no path (it turns in place)."""
        self.primitives[i] = -1
        self.glance_left[i] = 0
        if self.phases[i] in (WALK, FACE):
            self._mark_done(i)
        self.targets[i] = np.asarray(goal, np.float64)[:2]
        self.stays[i] = (*np.asarray(centre, np.float64)[:2], radius_m)
        return self._walk_out_again(i)

    def _walk_out_again(self, i: int) -> bool:
        """(Re)plan the walk out of the stay to the target on the map's current slice; with no
        path, to the reachable place farthest from the trail; False: none."""
        self.slice_restarts[i] = self.map.slice_restarts[i]
        self.glanced[i], self.target_clusters[i], self.idle_steps[i] = False, -1, 0
        self.wandering[i] = self.leaving[i] = True
        self._plan(i, self.targets[i])
        if self.lengths[i] > 0:
            self.phases[i] = WALK
            return True
        self._refresh(i)
        return self._wander_away(i)

    def _wander_away(self, i: int) -> bool:
        """Wander out of a stay (on the map's current slice) to the reachable place farthest
        from the trail, not ended by a candidate found on the way; False: none is reachable
        (the walker turns in place)."""
        self.slice_restarts[i] = self.map.slice_restarts[i]
        self.wandering[i] = True
        self._wander(i)
        self.leaving[i] = self.phases[i] == WALK
        return bool(self.leaving[i])

    def _wander(self, i: int) -> None:
        """No candidate: walk to the reachable place farthest from the trail (the path
        lengths of the last search are around the current pose), or turn in place."""
        pose = self.map.poses[i]
        si, sj = self.map.cell_of(i, pose[:2, 3])
        wi, wj = wander_goal(
            self.map.grids[i], self.map.coarse[i], self.map.far_factor, self.path_lengths[i],
            si, sj, self.radius, 3,
        )  # fmt: skip
        self.target_clusters[i] = -1
        if wi < 0:
            self.phases[i] = IDLE
            self.idle_steps[i] = 0
            return
        goal = self.map.origins[i] + (np.array([wi, wj]) + 0.5) * self.map.cell_m
        self.targets[i] = goal
        self.phases[i] = WALK
        self.idle_steps[i] = 0
        self._plan(i, goal)

    def _plan(self, i: int, goal: np.ndarray) -> None:
        self.lengths[i] = plan_path(
            self.map.grids[i], self.map.origins[i], self.map.cell_m,
            self.map.poses[i][:2, 3].copy(), np.asarray(goal, np.float64), self.radius,
            self.inflate, self.paths[i],
        )  # fmt: skip
        self.cursors[i, 0] = 0

    def next_moves(self, envs: np.ndarray | None = None) -> np.ndarray:
        """The primitive move of each agent of ``envs`` (default all) for its current pose."""
        envs = np.arange(self.map.num_envs) if envs is None else np.asarray(envs)
        moves = np.empty(len(envs), np.int64)
        for row, i in enumerate(envs):
            moves[row] = self._move(int(i))
        return moves

    def _primitive(self, i: int) -> int:
        primitive = self.primitives[i]
        if primitive in (MOVE_UP, MOVE_DOWN):
            clearance = self.map.clearance_up if primitive == MOVE_UP else self.map.clearance_down
            allowed = self._may_climb(i) if primitive == MOVE_UP else self._may_descend(i)
            roomy = clearance[i] > self.step_m + VERTICAL_MARGIN_M
            return int(primitive) if roomy and allowed else TURN_LEFT
        grid, origin, cell_m = self.map.grids[i], self.map.origins[i], self.map.cell_m
        pose = self.map.poses[i]
        if move_is_safe(grid, origin, cell_m, pose, primitive, self.step_m, self.inflate):
            return int(primitive)
        return TURN_LEFT

    def _move(self, i: int) -> int:
        move = self._choose(i)
        self.decision_moves[i] += move != AWAIT_DECISION
        self.last_moves[i] = move
        self.last_positions[i] = self.map.poses[i][:3, 3]
        return move

    def _note_refusal(self, i: int) -> bool:
        """Remember a move the env refused or cut short (the agent moved less than
        :data:`STOPPED_SHORT` of a step), so that it is not sent again from where it stopped:
        a refused step marks the cell it led into blocked on the map (the planner, the safety
        check of primitive moves and the way out of a stay then go around it), a refused
        climb or descent bounds the height for the episode. The env's checks see what the map
        cannot (a hole in the floor, the top of a partial scan, a thin or fragmented
        surface), so its refusal is the evidence. Returns whether a step was refused."""
        move = int(self.last_moves[i])
        if move not in REFUSABLE_MOVES or self._moved(i) >= STOPPED_SHORT * self.step_m:
            return False
        pose = self.map.poses[i]
        z = float(pose[2, 3])
        if move == MOVE_UP:
            self.climb_ceilings[i] = min(self.climb_ceilings[i], z)
            return False
        if move == MOVE_DOWN:
            self.descent_floors[i] = max(self.descent_floors[i], z)
            return False
        direction = step_direction(pose, move)
        standing = self.map.cell_of(i, pose[:2, 3])
        reach = self.step_m
        ahead = pose[:2, 3] + reach * direction
        while self.map.cell_of(i, ahead) == standing:
            reach += 0.5 * self.map.cell_m  # a step shorter than a cell may end in this one
            ahead = pose[:2, 3] + reach * direction
        self.map.mark_blocked(i, float(ahead[0]), float(ahead[1]))
        return True

    def _may_climb(self, i: int) -> bool:
        """Whether a climb stays below every height the env refused a climb at."""
        return float(self.map.poses[i][2, 3]) + self.step_m < self.climb_ceilings[i] - 1e-6

    def _may_descend(self, i: int) -> bool:
        """Whether a descent stays above every height the env refused a descent at."""
        return float(self.map.poses[i][2, 3]) - self.step_m > self.descent_floors[i] + 1e-6

    def _choose(self, i: int) -> int:
        refused_step = self._note_refusal(i)
        if self.phases[i] == AWAIT:
            return AWAIT_DECISION
        if self.primitives[i] >= 0:
            return self._primitive(i)
        if self.glance_left[i] > 0:
            self.glance_left[i] -= 1
            return LOOK_DOWN
        pose = self.map.poses[i]
        pitch = float(np.arcsin(np.clip(pose[2, 2], -1.0, 1.0)))
        if abs(pitch) > 0.5 * self.turn_rad + 1e-6:
            # Walk with the camera level: a pitched one sees floor or ceiling only.
            return LOOK_DOWN if pitch > 0 else LOOK_UP
        # A walk out of a stay leaves first: a vertical move restarts the map's slice, which
        # empties the map the way out was planned on, and the agent turns on the spot again.
        height = -1 if self._inside_stay_left(i) else self._height_move(i)
        if height >= 0:
            return height
        if self.slice_restarts[i] != self.map.slice_restarts[i]:
            # The map restarted at a new height: the goal was found on the old slice. A walk
            # out of a stay chooses again, still out of the same stay.
            if self.stays[i, 2] > 0:
                self._walk_out_again(i)
            elif self.leaving[i]:
                self._refresh(i)
                self._wander_away(i)
            else:
                self._refresh(i)
                self._next_goal(i)
        if refused_step and self.phases[i] == WALK:
            self.phases[i] = GIVEN_UP
        for _ in range(MAX_GOALS_PER_STEP):
            if self.phases[i] == AWAIT:
                return AWAIT_DECISION
            if self.phases[i] == IDLE:
                self.idle_steps[i] += 1
                if self.idle_steps[i] % IDLE_SEARCH_EVERY:
                    return self._idle_move(i)
                if self.stays[i, 2] > 0:
                    # A walk out of a stay that found nothing reachable (the map had just
                    # restarted) tries again out of the same stay, not to the nearest goal.
                    self._walk_out_again(i)
                else:
                    self._refresh(i)
                    self._next_goal(i)
                if self.phases[i] in (IDLE, AWAIT):
                    return self._idle_move(i) if self.phases[i] == IDLE else AWAIT_DECISION
            if self.phases[i] == GIVEN_UP:
                self._finish(i)
                continue
            if self.phases[i] == WALK and self.wandering[i]:
                self.idle_steps[i] += 1
                if self.idle_steps[i] % IDLE_SEARCH_EVERY == 0:
                    # A candidate found on the way ends the wander (not one out of a stay).
                    self._refresh(i)
                    if self.counts[i] > 0 and not self.leaving[i]:
                        self._next_goal(i)
                    if self.phases[i] == AWAIT:
                        return AWAIT_DECISION
                if self.wandering[i]:
                    self.moves_without_candidate[i] += 1
                    if self._descends(i):
                        return MOVE_DOWN
            if self.phases[i] == WALK:
                move = self._leave_move(i) if self.stays[i, 2] > 0 else -1
                if move < 0:
                    move = self._walk(i)
                if move >= 0:
                    return move
            if self.phases[i] == FACE:
                error = _wrap(
                    np.arctan2(self.targets[i, 1] - pose[1, 3], self.targets[i, 0] - pose[0, 3])
                    - _heading(pose)
                )
                if abs(error) > 0.5 * self.turn_rad + 1e-6:
                    return TURN_LEFT if error > 0 else TURN_RIGHT
                if (
                    self.glance_steps > 0
                    and not self.glanced[i]
                    and self.target_clusters[i, 0] >= 0
                ):
                    # Facing the cluster: a glance down at the floor before it
                    # (the camera then levels again, see above).
                    self.glanced[i] = True
                    self.glance_left[i] = self.glance_steps - 1
                    return LOOK_DOWN
            # Viewed (or given up): the cluster is done; on to the nearest candidate now.
            self._finish(i)
        return TURN_LEFT

    def _idle_move(self, i: int) -> int:
        """Turning in place with nothing in reach; after a full turn, a step down where the
        space below allows: an agent standing over furniture walks its slice of the map
        above the doorways' lintels, where every room looks closed (the slice restarts
        lower on the way down)."""
        self.moves_without_candidate[i] += 1
        return MOVE_DOWN if self._descends(i) else TURN_LEFT

    def _descends(self, i: int) -> bool:
        """Whether to step down now: a full turn's worth of moves with nothing in reach, and
        room below."""
        below = self.map.clearance_down[i]
        roomy = below > max(IDLE_LOWEST_M, self.step_m + VERTICAL_MARGIN_M)
        return self._idle_descent(i) and roomy and self._may_descend(i)

    def _height_move(self, i: int) -> int:
        """A vertical move towards the walking height above the floor, or -1 (at it, or
        nothing seen below yet). It never comes nearer than one step and the vertical margin
        to the surface below, nor climbs while an idle walker steps down, nor where the env
        refused a climb this episode."""
        below, above = self.map.clearance_down[i], self.map.clearance_up[i]
        if below <= 0:
            return -1
        z = float(self.map.poses[i][2, 3])
        self.floor_heights[i] = min(self.floor_heights[i], z - below)
        height = z - self.floor_heights[i]
        least = self.step_m + VERTICAL_MARGIN_M
        too_high = height > WALK_HEIGHT_M + WALK_HEIGHT_TOLERANCE_M
        if too_high and below - self.step_m > least and self._may_descend(i):
            return MOVE_DOWN
        # Nothing measured above (an open scan's sky) is room to climb, up to where the env
        # refused a climb: without it an agent that starts low on an open scan walks its
        # whole episode there, below the furniture that fences its map's slice.
        room_above = self._may_climb(i) and (above > least or self.map.open_above[i])
        if (
            (height < WALK_HEIGHT_M - WALK_HEIGHT_TOLERANCE_M or below < least)
            and room_above
            and not self._idle_descent(i)
        ):
            return MOVE_UP
        return -1

    def _idle_descent(self, i: int) -> bool:
        """Whether the walker has spent a full turn's worth of moves with nothing in reach,
        turning in place or wandering (it then steps down, see :meth:`_descends`, until a
        goal shows): over furniture, the floor it keeps its height above may be the
        furniture's top, never having seen the floor. A walk out of a stay (:meth:`walk_out`)
        has a place to reach and does not count."""
        full_turn = int(np.ceil(2.0 * np.pi / max(self.turn_rad, 1e-6)))
        nothing_in_reach = self.phases[i] == IDLE or (
            self.phases[i] == WALK and self.wandering[i] and not self.leaving[i]
        )
        return nothing_in_reach and self.moves_without_candidate[i] > full_turn

    def _moved(self, i: int) -> float:
        """How far agent ``i`` moved since the move sent last (metres)."""
        return float(np.linalg.norm(self.map.poses[i][:3, 3] - self.last_positions[i]))

    def _stood_still(self, i: int) -> bool:
        """Whether the move sent last (a step or a climb) left agent ``i`` where it was (the
        env refused it)."""
        return self._moved(i) <= 0.25 * self.step_m

    def _inside_stay_left(self, i: int) -> bool:
        """Whether agent ``i`` is walking out of a stay (:meth:`walk_out`) and still inside it."""
        if self.phases[i] != WALK or self.stays[i, 2] <= 0:
            return False
        return bool(np.hypot(*(self.map.poses[i][:2, 3] - self.stays[i, :2])) <= self.stays[i, 2])

    def _leave_move(self, i: int) -> int:
        """A step out of the stay along the path without turning first (whichever step
        brings the agent nearest to the path's carrot, never the one undoing the last; turning
        to face a path behind takes up to half a turn's steps); where none does, a turn
        towards it while it lies more than the walk-on angle off; -1: out of the stay, the
        last step refused, or facing the carrot (the path is followed as usual)."""
        pose = self.map.poses[i]
        refused = self.last_moves[i] in TRANSLATIONS and self._stood_still(i)
        if not self._inside_stay_left(i) or refused:
            self.stays[i] = 0.0
            return -1
        grid, origin, cell_m = self.map.grids[i], self.map.origins[i], self.map.cell_m
        carrot, status = path_carrot(
            grid, origin, cell_m, pose, self.paths[i], self.lengths[i], self.cursors[i],
            self.inflate,
        )  # fmt: skip
        if status != WALKING:
            return -1
        x, y = origin + (self.paths[i, carrot] + 0.5) * cell_m
        # Never the step that undoes the last one: the carrot moves with the agent, and a
        # carrot between two places a step apart would send it right and left between them.
        undo = OPPOSITE_STEP.get(int(self.last_moves[i]), -1)
        move = step_towards(
            grid, origin, cell_m, pose, x, y, self.step_m, self.inflate,
            TRANSLATIONS[TRANSLATIONS != undo],
        )  # fmt: skip
        if move < 0:
            error = _wrap(np.arctan2(y - pose[1, 3], x - pose[0, 3]) - _heading(pose))
            if abs(error) > WALK_ON_TURNS * self.turn_rad + 1e-6:
                return TURN_LEFT if error > 0 else TURN_RIGHT
            self.stays[i] = 0.0
        return int(move)

    def _walk(self, i: int) -> int:
        """The walking move, or -1 once at the viewpoint (phase FACE) or given up."""
        grid, origin, cell_m = self.map.grids[i], self.map.origins[i], self.map.cell_m
        pose = self.map.poses[i]

        def follow() -> tuple[int, int]:
            return follow_path(
                grid, origin, cell_m, pose, self.paths[i], self.lengths[i], self.cursors[i],
                self.step_m, self.turn_rad, self.inflate,
            )  # fmt: skip

        move, status = follow()
        if status == REPLAN:
            # The path ran into a newly seen obstacle: plan again to its end, once.
            last = self.paths[i, max(self.lengths[i] - 1, 0)]
            goal = self.map.origins[i] + (last + 0.5) * self.map.cell_m
            self._plan(i, goal)
            move, status = follow()
            if status == REPLAN:
                self.phases[i] = GIVEN_UP
                return -1
        if status == REACHED:
            self.lengths[i] = 0
            self.phases[i] = FACE
            return -1
        if (
            move in OPPOSITE_TURN
            and self.last_moves[i] == OPPOSITE_TURN[move]
            and move_is_safe(grid, origin, cell_m, pose, MOVE_FORWARD, self.step_m, self.inflate)
        ):
            # Turning back the way it turned last: the carrot lies between two headings a
            # turn apart, each a hair beyond half a turn off it. Walk on instead.
            return MOVE_FORWARD
        return int(move)

    def _mark_done(self, i: int) -> None:
        """The cluster agent ``i`` was sent to is done for the episode (none: nothing)."""
        a, b = self.target_clusters[i]
        if 0 <= a < self.done.shape[1] and 0 <= b < self.done.shape[2]:
            self.done[i, a, b] = True

    def _finish(self, i: int) -> None:
        self._mark_done(i)
        self._refresh(i)
        self._next_goal(i)

    def _next_goal(self, i: int) -> None:
        """After a refresh, the goal after one done, given up or lost: the agent's choice
        (``decision="goal"``, after a move, a candidate in reach), else the nearest one."""
        if self.decision == "goal" and self.decision_moves[i] > 0 and self.counts[i] > 0:
            self.phases[i] = AWAIT
            self.wandering[i] = False
            return
        self._go_to(i, 0)
