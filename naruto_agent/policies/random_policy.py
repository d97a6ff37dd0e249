"""Random exploration that respects collisions: a seeded random walk in straight runs.

The agent picks a random direction (uniform heading, a small random climb), walks along it
with the camera looking where it goes (a random pitch per run), and picks a new random
direction when a move is blocked (``info["collided"]``: a surface, the bounds, or a move into
the open) or when the run's random length is used up. A climb the env refuses as an escape
(the top of a scan without a ceiling) sets a flight ceiling it turns back under, as the
bounds' top does. It never keeps pushing against a wall,
which is what ``action_space.sample()`` would do. All randomness comes from its own seeded
generator, so one seed gives one trajectory.

Where the observation has the depth panorama, the walk reads each move's way from it first,
as a robot reads its range sensor (``panorama_check``): a move whose sphere would touch a
surface the panorama shows, that would climb above the surfaces it shows (the open top of a
scan without a ceiling, :func:`~naruto_agent.policies.panorama_clearance.surface_top`), or
that would leave the scanned space as the env judges it
(:func:`~naruto_agent.policies.panorama_clearance.move_leaves_scan`), starts a new random run
instead of being sent. Without it about one move in sixteen was refused (17.9 per 300-step
episode on ``replica_like_room``), and on an open scan the scan's edge added its own. In a tight
spot where every redrawn run looks blocked, the walk sweeps the headings all around it for
a clear way; where none is, it turns in place for up to ``max_held_steps`` steps, then sends
the part of the move the panorama shows clear, or the move itself, and the env decides: it
never stays put for good.
"""

from __future__ import annotations

import numpy as np

from naruto_agent.policies.base import Info, Observation, Policy, clip_pose_action, pose_action
from naruto_agent.policies.panorama_clearance import (
    RefusedMoves,
    clear_part_of_move,
    first_contact,
    floor_edge_profile,
    move_leaves_scan,
    surface_top,
)
from naruto_gym.geometry.transforms import look_at_rotation, make_pose


class RandomPolicy(Policy):
    """Seeded random walk in straight runs, turning at random when blocked.

    Args:
        seed: seed of the policy's generator (``reset(seed=...)`` overrides it).
        min_run_steps: shortest run in steps (a run's length is uniform in the range).
        max_run_steps: longest run in steps.
        max_climb: largest vertical component of a run's (unit) direction.
        max_pitch_deg: the camera's pitch is drawn uniformly within +-this per run.
        height_margin_m: runs turn back vertically within this distance of the bounds'
            floor and ceiling.
        avoid_blocked_deg: a new direction after a block is at least this far from the
            blocked one.
        panorama_check: read each move's way from the observation's depth panorama (when
            it has one) and start a new run instead of a move that would bump or leave the
            scan (see above).
        panorama_margin_m: clearance kept beyond the env's agent radius in that check.
        scan_edge_margin_m: the scan's edge is probed
            (:func:`~naruto_agent.policies.panorama_clearance.move_leaves_scan`) at the agent
            radius and again at the radius plus this: the panorama's pixels place an edge
            below to a few centimetres, and a walk has no goal that a wider berth would cost.
        max_redraws: new runs drawn at one step for ``panorama_check`` before the walk
            gives the step up (a tight spot where every way looks blocked).
        sweep_headings: when all of them look blocked the walk sweeps this many headings
            around it (level, then climbing and sinking) for a clear way before it holds
            (0: no sweep).
        max_held_steps: steps in a row the walk turns in place in such a spot before it sends
            the clear part of the move (slid along or cut short of the surface it would
            touch), or the move itself, and the env decides.
    """

    def __init__(
        self,
        seed: int | None = None,
        min_run_steps: int = 5,
        max_run_steps: int = 40,
        max_climb: float = 0.3,
        max_pitch_deg: float = 30.0,
        height_margin_m: float = 0.3,
        avoid_blocked_deg: float = 60.0,
        panorama_check: bool = True,
        panorama_margin_m: float = 0.01,
        scan_edge_margin_m: float = 0.05,
        max_redraws: int = 8,
        sweep_headings: int = 16,
        max_held_steps: int = 3,
    ) -> None:
        super().__init__()
        if not 1 <= min_run_steps <= max_run_steps:
            raise ValueError(
                f"need 1 <= min_run_steps <= max_run_steps, got {min_run_steps}, {max_run_steps}"
            )
        self.seed = seed
        self.min_run_steps = min_run_steps
        self.max_run_steps = max_run_steps
        self.max_climb = max_climb
        self.max_pitch_rad = float(np.deg2rad(max_pitch_deg))
        self.height_margin_m = height_margin_m
        self.cos_avoid = float(np.cos(np.deg2rad(avoid_blocked_deg)))
        self.panorama_check = panorama_check
        self.panorama_margin_m = panorama_margin_m
        self.scan_edge_margin_m = scan_edge_margin_m
        self.max_redraws = max_redraws
        self.sweep_headings = sweep_headings
        self.max_held_steps = max_held_steps
        self.rng = np.random.default_rng(seed)
        self.direction = np.array([1.0, 0.0, 0.0])
        self.pitch = 0.0
        self.steps_left = 0
        #: Number of new directions drawn because a move was blocked (for tests and logs).
        self.turns_after_block = 0
        #: Number of new runs drawn because the panorama showed a move's way blocked.
        self.turns_before_block = 0
        #: Steps in a row turned in place because every redrawn run looked blocked.
        self.held_steps = 0
        self.refused = RefusedMoves()

    def reset(self, observation: Observation, info: Info, seed: int | None = None) -> None:
        super().reset(observation, info, seed)
        if seed is not None:
            self.seed = seed
            self.rng = np.random.default_rng(seed)
        self.turns_after_block = 0
        self.turns_before_block = 0
        self.held_steps = 0
        self.refused.reset()
        self._new_run(np.asarray(observation["pose"], np.float64), blocked=None)

    def _near_floor_and_top(self, z: float) -> tuple[bool, bool]:
        """Whether height ``z`` is within the height margin of the bounds' floor, and of the
        bounds' top or the flight ceiling a refused climb set."""
        bounds = self.context.bounds
        near_floor = z < bounds[0, 2] + self.height_margin_m
        near_top = z > min(bounds[1, 2], self.refused.ceiling_z) - self.height_margin_m
        return near_floor, near_top

    def _new_run(self, pose: np.ndarray, blocked: np.ndarray | None) -> None:
        near_floor, near_top = self._near_floor_and_top(pose[2, 3])
        for _ in range(100):
            heading = self.rng.uniform(-np.pi, np.pi)
            climb = self.rng.uniform(-self.max_climb, self.max_climb)
            # Turn back vertically near the floor or the ceiling.
            if near_floor:
                climb = abs(climb)
            elif near_top:
                climb = -abs(climb)
            direction = run_direction(heading, climb)
            if blocked is None or float(direction @ blocked) < self.cos_avoid:
                break
        self.direction = direction
        self.pitch = self.rng.uniform(-self.max_pitch_rad, self.max_pitch_rad)
        self.steps_left = int(self.rng.integers(self.min_run_steps, self.max_run_steps + 1))

    def act(self, observation: Observation, info: Info | None = None) -> np.ndarray:
        pose = np.asarray(observation["pose"], np.float64)
        panorama = observation.get("panorama") if self.panorama_check else None
        if info is not None and info.get("collided", False):
            if info.get("collision_reason") == "escape":
                # The panorama tells a refused climb at the open top from the floor's edge.
                self.refused.record(pose[:3, 3], pose[:3, 3] + self.direction, panorama)
            self.turns_after_block += 1
            self._new_run(pose, blocked=self.direction)
        elif self.steps_left <= 0:
            self._new_run(pose, blocked=None)
        self.steps_left -= 1
        position = pose[:3, 3]
        target = position + self.direction * self.context.max_translation_m
        if panorama is not None:
            target = self._checked_target(pose, panorama, target)
        heading = np.array([self.direction[0], self.direction[1], 0.0])
        heading /= max(np.linalg.norm(heading), 1e-9)
        look = heading * np.cos(self.pitch) + np.array([0.0, 0.0, np.sin(self.pitch)])
        rotation = look_at_rotation(target, target + look)
        return clip_pose_action(pose_action(make_pose(rotation, target)), self.context.action_space)

    def _checked_target(self, pose: np.ndarray, panorama: np.ndarray, target: np.ndarray
                        ) -> np.ndarray:
        """The run's next target once the panorama has passed it: new runs are drawn while
        the way looks blocked; when none of ``max_redraws`` is clear a sweep of headings
        looks for one; when that finds none either the walk turns in place (its position as
        target), and after ``max_held_steps`` such steps in a row it sends the clear part of
        the move, or the move."""
        position = pose[:3, 3]
        for redraw in range(self.max_redraws + 1):
            if not self._way_blocked(panorama, target - position):
                self.held_steps = 0
                return target
            if redraw == self.max_redraws:
                break
            self.turns_before_block += 1
            self._new_run(pose, blocked=self.direction)
            self.steps_left -= 1
            target = position + self.direction * self.context.max_translation_m
        # Every random draw looked blocked: look all around for a clear way before holding
        # (turning in place shows the panorama nothing new, so a held step only waits, and
        # a sweep that found nothing is not repeated at the same spot).
        direction = None if self.held_steps else self._clear_direction(pose, panorama)
        if direction is not None:
            self.held_steps = 0
            self.direction = direction
            return position + direction * self.context.max_translation_m
        if self.held_steps < self.max_held_steps:
            self.held_steps += 1
            return position.copy()
        self.held_steps = 0
        part = clear_part_of_move(panorama, target - position,
                                  self.context.agent_radius_m + self.panorama_margin_m)
        return target if part is None else position + part

    def _clear_direction(self, pose: np.ndarray, panorama: np.ndarray) -> np.ndarray | None:
        """The first run direction of a sweep around the agent (``sweep_headings`` headings
        from a random one, level first, then climbing and sinking within the height margins)
        whose move the panorama shows clear, or None."""
        if self.sweep_headings <= 0:
            return None
        near_floor, near_top = self._near_floor_and_top(pose[2, 3])
        climbs = [0.0]
        if not near_top:
            climbs.append(self.max_climb)
        if not near_floor:
            climbs.append(-self.max_climb)
        start = self.rng.uniform(-np.pi, np.pi)
        headings = start + np.arange(self.sweep_headings) * (2.0 * np.pi / self.sweep_headings)
        step = self.context.max_translation_m
        for climb in climbs:
            for heading in headings:
                direction = run_direction(heading, climb)
                if not self._way_blocked(panorama, direction * step):
                    return direction
        return None

    def _way_blocked(self, panorama: np.ndarray, move: np.ndarray) -> bool:
        """Whether the panorama shows the move bumping into a surface, climbing above the
        surfaces it shows (the open top of a scan without a ceiling), or leaving the scan."""
        radius = self.context.agent_radius_m
        if first_contact(panorama, move, radius + self.panorama_margin_m) is not None:
            return True
        if move[2] > 0.0 and move[2] > surface_top(panorama):
            return True
        # The full test is costly (tens of ms); where the panorama shows scanned surface all
        # around below, out to 70 degrees from straight down, no move of a step can leave.
        if not np.isfinite(floor_edge_profile(panorama, max_polar_deg=70.0)).any():
            return False
        # Strict in the scan's margin too: a walk has no goal to give up, only a new run to
        # draw (a move from the margin back in still passes).
        # Both radii: the wider one sees an edge a pixel off, but its cube test drops out
        # nearer a wall (the cube's corners must lie within the free ball).
        return any(move_leaves_scan(panorama, move, probe)
                   for probe in (radius, radius + self.scan_edge_margin_m))


def run_direction(heading: float, climb: float) -> np.ndarray:
    """The unit direction of a run: ``heading`` (radians) around the vertical, ``climb`` its
    vertical component."""
    direction = np.array([np.cos(heading), np.sin(heading), 0.0]) * np.sqrt(1 - climb**2)
    direction[2] = climb
    return direction
