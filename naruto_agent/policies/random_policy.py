"""Random exploration that respects collisions: a seeded random walk in straight runs.

The agent picks a random direction (uniform heading, a small random climb), walks along it
with the camera looking where it goes (a random pitch per run, swinging from side to side by
``sweep_yaw_deg``), and picks a new random direction when a move is blocked
(``info["collided"]``: a surface, the bounds, or a move into the open) or when the run's
random length is used up. A climb the env refuses as an escape (the top of a scan without a
ceiling) sets a flight ceiling it turns back under, as the bounds' top does. It never keeps
pushing against a wall, which is what ``action_space.sample()`` would do. All randomness
comes from its own seeded generator, so one seed gives one trajectory.

Where the observation has the depth panorama, the shared open-scan guard
(:class:`~naruto_agent.guards.ScanGuard`) reads each move's way from it first, as a robot
reads its range sensor: a move that would touch a surface, climb above the surfaces the
panorama shows (the open top of a scan without a ceiling) or leave the scanned space starts
a new random run instead of being sent, so the walk is refused far less often. In a tight
spot where every redrawn run looks blocked, the walk sweeps the headings all around it for
a clear way; where none is, it turns in place for up to ``max_held_moves`` steps, then sends
the part of the move the panorama shows clear, or the move itself, and the env decides: it
never stays put for good. A stall all that misses (runs redrawn in one corner, one refused
move repeated) is caught by the stall watchdog (:mod:`naruto_agent.policies.watchdog`), and
the shared recovery (:mod:`naruto_agent.policies.stall_recovery`) sends a straight run to a
place past the stay that the panorama shows clear.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from naruto_agent.guards.refused_moves import RefusedMoves
from naruto_agent.guards.scan_guard import ScanGuard
from naruto_agent.policies.base import (
    EnvContext,
    Info,
    Observation,
    Policy,
    clip_pose_action,
    pose_action,
)
from naruto_agent.policies.config import RandomConfig, build_config
from naruto_agent.policies.registry import register_policy
from naruto_gym.geometry.transforms import look_at_rotation, make_pose


@register_policy("random")
class RandomPolicy(Policy):
    """Seeded random walk in straight runs, turning at random when blocked.

    Args:
        seed: seed of the policy's generator (``reset(seed=...)`` overrides it); overrides
            the config's.
        config: the settings (default :class:`RandomConfig`).
        **settings: :class:`RandomConfig` fields, and those of its ``guard``
            (:class:`~naruto_agent.guards.ScanGuardConfig`), overriding ``config``'s.

    Attributes:
        config: the settings.
        guard: the open-scan guard.
        refused: where the scan ends, learned from escape refusals.
        turns_after_block: new directions drawn because a move was blocked.
        turns_before_block: new runs drawn because the panorama showed a move's way blocked.
    """

    def __init__(
        self, seed: int | None = None, *, config: RandomConfig | None = None, **settings: Any
    ) -> None:
        super().__init__()
        if seed is not None:
            settings["seed"] = seed
        self.config = build_config(RandomConfig, config, **settings)
        self.guard = ScanGuard(self.config.guard)
        self.seed = self.config.seed
        self.rng = np.random.default_rng(self.seed)
        self.direction = np.array([1.0, 0.0, 0.0])
        self.pitch = 0.0
        self.steps_left = 0
        self._sweep_step = 0
        self.turns_after_block = 0
        self.turns_before_block = 0
        self.refused = RefusedMoves()
        self.use_stall_watchdog(enabled=self.config.stall_watchdog)

    @property
    def held_steps(self) -> int:
        """Steps in a row turned in place because every redrawn run looked blocked."""
        return self.guard.holds.count

    def bind(self, context: EnvContext) -> None:
        super().bind(context)
        self.guard.agent_radius_m = context.agent_radius_m

    def reset(self, observation: Observation, info: Info, seed: int | None = None) -> None:
        super().reset(observation, info, seed)
        if seed is not None:
            self.seed = seed
            self.rng = np.random.default_rng(seed)
        self.turns_after_block = 0
        self.turns_before_block = 0
        self._sweep_step = 0
        self.guard.reset()
        self.refused.reset()
        self._new_run(np.asarray(observation["pose"], np.float64), blocked=None)

    def _near_floor_and_top(self, z: float) -> tuple[bool, bool]:
        """Whether height ``z`` is within the height margin of the bounds' floor, and of the
        bounds' top or the flight ceiling a refused climb set."""
        bounds = self.context.bounds
        margin = self.config.height_margin_m
        near_floor = z < bounds[0, 2] + margin
        near_top = z > min(bounds[1, 2], self.refused.ceiling_z) - margin
        return near_floor, near_top

    def _new_run(self, pose: np.ndarray, blocked: np.ndarray | None) -> None:
        config = self.config
        near_floor, near_top = self._near_floor_and_top(pose[2, 3])
        cos_avoid = float(np.cos(np.deg2rad(config.avoid_blocked_deg)))
        for _ in range(100):
            heading = self.rng.uniform(-np.pi, np.pi)
            climb = self.rng.uniform(-config.max_climb, config.max_climb)
            # Turn back vertically near the floor or the ceiling.
            if near_floor:
                climb = abs(climb)
            elif near_top:
                climb = -abs(climb)
            direction = run_direction(heading, climb)
            if blocked is None or float(direction @ blocked) < cos_avoid:
                break
        self.direction = direction
        max_pitch = float(np.deg2rad(config.max_pitch_deg))
        self.pitch = self.rng.uniform(-max_pitch, max_pitch)
        self.steps_left = int(self.rng.integers(config.min_run_steps, config.max_run_steps + 1))

    def walk_out(self, position: np.ndarray, goal: np.ndarray) -> str:
        """A run straight to the way out of a stall, as long as it takes."""
        move = goal - position
        distance = float(np.linalg.norm(move))
        self.direction = move / max(distance, 1e-9)
        self.steps_left = max(1, int(np.ceil(distance / self.context.max_translation_m)))
        self.guard.holds.reset()
        return "a straight run"

    def act(self, observation: Observation, info: Info | None = None) -> np.ndarray:
        pose = np.asarray(observation["pose"], np.float64)
        panorama = self.guard.panorama(observation)
        if self.check_stall(observation, info) is not None:
            info = None  # the recovery chose the run
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
        heading = self._swept(heading)
        look = heading * np.cos(self.pitch) + np.array([0.0, 0.0, np.sin(self.pitch)])
        rotation = look_at_rotation(target, target + look)
        return clip_pose_action(pose_action(make_pose(rotation, target)), self.context.action_space)

    def _swept(self, heading: np.ndarray) -> np.ndarray:
        """The horizontal look direction: ``heading`` turned by the camera's sweep, which
        swings ``sweep_yaw_deg`` to either side over ``sweep_period_steps`` steps of a run
        (a walker that looks only ahead sees nothing new crossing a seen room)."""
        amplitude = np.deg2rad(self.config.sweep_yaw_deg)
        if amplitude == 0.0:
            return heading
        self._sweep_step += 1
        yaw = amplitude * np.sin(2.0 * np.pi * self._sweep_step / self.config.sweep_period_steps)
        cos, sin = np.cos(yaw), np.sin(yaw)
        return np.array([cos * heading[0] - sin * heading[1], sin * heading[0] + cos * heading[1],
                         0.0])

    def _checked_target(self, pose: np.ndarray, panorama: np.ndarray, target: np.ndarray
                        ) -> np.ndarray:
        """The run's next target once the guard has passed it: new runs are drawn while
        the way looks blocked; when none of ``max_redraws`` is clear a sweep of headings
        looks for one; when that finds none either the walk turns in place (its position as
        target), and after ``max_held_moves`` such steps in a row it sends the clear part of
        the move, or the move."""
        position = pose[:3, 3]
        guard = self.guard
        redraws = self.config.max_redraws
        for redraw in range(redraws + 1):
            if not guard.way_blocked(panorama, target - position):
                guard.holds.reset()
                return target
            if redraw == redraws:
                break
            self.turns_before_block += 1
            self._new_run(pose, blocked=self.direction)
            self.steps_left -= 1
            target = position + self.direction * self.context.max_translation_m
        # Every random draw looked blocked: look all around for a clear way before holding
        # (turning in place shows the panorama nothing new, so a held step only waits, and
        # a sweep that found nothing is not repeated at the same spot).
        direction = None if guard.holds.count else self._clear_direction(pose, panorama)
        if direction is not None:
            guard.holds.reset()
            self.direction = direction
            return position + direction * self.context.max_translation_m
        if guard.holds.hold():
            return position.copy()
        part = guard.clear_part(panorama, target - position)
        return target if part is None else position + part

    def _clear_direction(self, pose: np.ndarray, panorama: np.ndarray) -> np.ndarray | None:
        """The first run direction of a sweep around the agent (``sweep_headings`` headings
        from a random one, level first, then climbing and sinking within the height margins)
        whose move the panorama shows clear, or None."""
        count = self.config.sweep_headings
        if count <= 0:
            return None
        near_floor, near_top = self._near_floor_and_top(pose[2, 3])
        climbs = [0.0]
        if not near_top:
            climbs.append(self.config.max_climb)
        if not near_floor:
            climbs.append(-self.config.max_climb)
        start = self.rng.uniform(-np.pi, np.pi)
        headings = start + np.arange(count) * (2.0 * np.pi / count)
        step = self.context.max_translation_m
        for climb in climbs:
            for heading in headings:
                direction = run_direction(heading, climb)
                if not self.guard.way_blocked(panorama, direction * step):
                    return direction
        return None


def run_direction(heading: float, climb: float) -> np.ndarray:
    """The unit direction of a run: ``heading`` (radians) around the vertical, ``climb`` its
    vertical component."""
    direction = np.array([np.cos(heading), np.sin(heading), 0.0]) * np.sqrt(1 - climb**2)
    direction[2] = climb
    return direction
