"""The "human scan" baseline: replay a recorded trajectory, or walk a scripted scan loop.

* With a trajectory (e.g. Replica's ``traj.txt``, 2000 camera-to-world poses) the episode
  starts exactly at its first pose and every step targets the next one. When the step budget
  is smaller than the trajectory, the poses are subsampled uniformly to fit the budget
  (``fit_to_budget``), so the whole scan is walked, faster; a pose the env refuses to reach
  (blocked by the agent's body) is skipped after a few tries.
* Without one, a scripted scan: a loop around the room along the walls, as a person scanning
  a room walks it. The agent keeps to about head height, goes straight until it meets a wall,
  then follows the walls on its right at ``wall_distance_m`` (a right-hand wall follower,
  which also leads through doorways into the next rooms), the camera sweeping between the
  wall beside it and the room ahead and across, and up and down. Walls are read from the
  depth panorama around the agent's height; on an open scan the edge of the scanned floor
  (past a missing wall, the rim of a floor hole) shows nothing there, so the follower also
  reads where the panorama's downward rays stop hitting (``floor_edge_profile``) as a wall,
  and a move the env still refuses as an escape leaves a virtual wall that the follower
  follows from then on. A wall followed all the way round without adding coverage (an island
  of furniture, a room circled again and again, the low edge of a partial scan) is left:
  the agent crosses the room towards its most open side until it meets another wall, and
  follows that one. A stall the follower's own rules miss (spinning in a small cluttered
  room, a refused sink repeated) is caught by the stall watchdog
  (:mod:`naruto_agent.policies.watchdog`): the follower then walks, without steering and
  with a smaller clearance, to the place past the stay that the shared recovery
  (:mod:`naruto_agent.policies.stall_recovery`) chose. Only the bounds, the observations and
  the step info are used, never the mesh.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from naruto_agent.guards.panorama_clearance import (
    azimuth_window,
    floor_edge_profile,
    horizontal_profile,
    profile_clearance,
    vertical_clearance,
)
from naruto_agent.guards.refused_moves import RefusedMoves
from naruto_agent.policies.base import Info, Observation, Policy, clip_pose_action, pose_action
from naruto_agent.policies.config import PassiveConfig, build_config
from naruto_agent.policies.registry import register_policy
from naruto_agent.policies.watchdog import StallEvent
from naruto_gym.geometry.transforms import look_at_rotation, make_pose, validate_pose
from naruto_gym.utils.checks import check_integer

HOLD_HEIGHT_STEPS = 20
"""Steps the wall follower keeps its height after a refused move that changed it."""
FLOOR_CLEARANCE_M = 0.3
"""Height the follower keeps above the surface straight below it (its wall clearance and a
step's worth)."""
FORCED_CLEARANCE_M = 0.0
"""Clearance ahead a stall recovery's walk needs, the agent's radius and a step (the
follower's own is 0.25 m + a step)."""


def load_trajectory(path: str | Path) -> np.ndarray:
    """(N, 4, 4) camera-to-world poses from a text file of one row-major 4x4 matrix per line.

    Raises:
        ValueError: the file is missing or its rows are not 16 numbers forming rigid poses.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"trajectory file {str(path)!r} does not exist")
    values = np.loadtxt(path, dtype=np.float64, ndmin=2)
    if values.shape[1] != 16 or len(values) == 0:
        raise ValueError(
            f"{path}: expected one row-major 4x4 camera-to-world matrix (16 numbers) per line, "
            f"got rows of {values.shape[1]}"
        )
    poses = values.reshape(-1, 4, 4)
    for index in (0, len(poses) // 2, len(poses) - 1):
        validate_pose(poses[index], f"{path} pose {index}")
    return poses


def subsample_poses(poses: np.ndarray, max_episode_steps: int) -> np.ndarray:
    """The poses to replay in ``max_episode_steps`` steps: all of them when they fit, else
    ``max_episode_steps + 1`` uniformly spaced ones (first and last kept)."""
    steps = check_integer("max_episode_steps", max_episode_steps, low=1)
    if len(poses) <= steps + 1:
        return poses
    index = np.round(np.linspace(0, len(poses) - 1, steps + 1)).astype(np.int64)
    return poses[index]


@register_policy("passive")
class PassivePolicy(Policy):
    """Replays a pose sequence, or follows a scripted wall-following scan when none is given.

    Args:
        trajectory: (N, 4, 4) poses or a path to a ``traj.txt``-style file; None for the
            scripted scan.
        config: the settings (default :class:`PassiveConfig`).
        **settings: :class:`PassiveConfig` fields, overriding ``config``'s.

    Attributes:
        config: the settings.
        poses: the trajectory's poses, or None (scripted scan).
    """

    def __init__(
        self,
        trajectory: np.ndarray | str | Path | None = None,
        *,
        config: PassiveConfig | None = None,
        **settings: Any,
    ) -> None:
        super().__init__()
        if trajectory is None:
            self.poses: np.ndarray | None = None
        elif isinstance(trajectory, (str, Path)):
            self.poses = load_trajectory(trajectory)
        else:
            self.poses = np.asarray(trajectory, np.float64)
            if self.poses.ndim != 3 or self.poses.shape[1:] != (4, 4) or len(self.poses) == 0:
                raise ValueError(
                    f"trajectory must be (N, 4, 4) camera-to-world poses, got {self.poses.shape}"
                )
        self.config = build_config(PassiveConfig, config, **settings)
        self.required_observations = ("pose",) if self.poses is not None else ("pose", "panorama")
        self._replay: np.ndarray | None = None
        self._index = 0
        self._last_sent = -1
        self._last_pose: np.ndarray | None = None
        self._blocked = 0
        self._step = 0
        self._heading = 0.0
        self._found_wall = False
        self._recent: list[np.ndarray] = []
        self._position = np.zeros(3)
        self._refused = RefusedMoves()
        self._last_target: np.ndarray | None = None
        self._visits: list[tuple[np.ndarray, float]] = []
        self._profile: np.ndarray | None = None
        self._forced_steps = 0
        self._height_offset = 0.0
        self._refused_spot: np.ndarray | None = None
        self._refused_headings: list[float] = []
        self.use_stall_watchdog(enabled=self.config.stall_watchdog)

    @property
    def replays(self) -> bool:
        """True when replaying a trajectory (False: scripted scan)."""
        return self.poses is not None

    def replay_poses(self) -> np.ndarray:
        """The poses this episode replays (after fitting to the budget)."""
        if self.poses is None:
            raise ValueError("this PassivePolicy has no trajectory; it follows a scripted scan")
        budget = self.context.max_episode_steps if self._context is not None else None
        if self.config.fit_to_budget and budget is not None:
            return subsample_poses(self.poses, budget)
        return self.poses

    def reset_options(self) -> dict | None:
        if self.poses is None:
            return None
        return {"pose": self.replay_poses()[0].copy()}

    def reset(self, observation: Observation, info: Info, seed: int | None = None) -> None:
        super().reset(observation, info, seed)
        self._step = 0
        self._blocked = 0
        self._last_sent = -1
        self._last_pose = None
        if self.poses is not None:
            self._replay = self.replay_poses()
            self._index = 1
            return
        forward = np.asarray(observation["pose"], np.float64)[:3, 2]
        self._heading = float(np.arctan2(forward[1], forward[0]))
        self._found_wall = False
        self._recent = []
        self._refused.reset()
        self._last_target = None
        self._visits = []
        self._hold_height = 0
        self._profile = None
        self._forced_steps = 0
        self._height_offset = 0.0
        self._refused_spot = None
        self._refused_headings = []

    # -- replay ------------------------------------------------------------------------
    def _reached(self, pose: np.ndarray, target: np.ndarray) -> bool:
        if np.linalg.norm(pose[:3, 3] - target[:3, 3]) > self.config.position_tolerance_m:
            return False
        relative = Rotation.from_matrix(pose[:3, :3].T @ target[:3, :3])
        return relative.magnitude() <= float(np.deg2rad(self.config.rotation_tolerance_deg))

    def _act_replay(self, observation: Observation) -> np.ndarray:
        assert self._replay is not None
        pose = np.asarray(observation["pose"], np.float64)
        if self._index < len(self._replay) and self._reached(pose, self._replay[self._index]):
            self._index += 1
            self._blocked = 0
        elif (
            self._index < len(self._replay)
            and self._last_sent == self._index
            and self._last_pose is not None
            and np.allclose(pose, self._last_pose, atol=1e-5)
        ):
            # The last step aimed here and made no progress: the body is blocked.
            self._blocked += 1
            if self._blocked > self.config.max_blocked_steps:
                self._index += 1
                self._blocked = 0
        self._last_sent = self._index
        self._last_pose = pose
        target = self._replay[min(self._index, len(self._replay) - 1)]
        return clip_pose_action(pose_action(target), self.context.action_space)

    # -- scripted wall-following scan ----------------------------------------------------
    def _steer(self, profile: np.ndarray, collided: bool) -> None:
        """Update the walking heading (right-hand wall following)."""
        cone = np.deg2rad(25.0)
        front = profile_clearance(profile, self._heading, cone)
        right = profile_clearance(profile, self._heading - np.pi / 2.0, np.deg2rad(30.0))
        if not self._found_wall:
            if front < self.config.wall_distance_m + 0.2 or collided:
                self._found_wall = True
            else:
                return
        if front < self.config.front_clearance_m or collided:
            self._heading += np.deg2rad(30.0)  # wall ahead: turn left, keeping it on the right
        elif right > self.config.lost_wall_m:
            self._heading -= np.deg2rad(15.0)  # around a corner or into a doorway
        else:
            error = right - self.config.wall_distance_m
            self._heading -= float(np.clip(0.5 * error, -np.deg2rad(15.0), np.deg2rad(15.0)))
        # Going in circles without progress (an island, a dead end): break away to the left.
        self._recent.append(np.array(self._position[:2]))
        if len(self._recent) > 60:
            self._recent.pop(0)
            if np.linalg.norm(np.ptp(np.array(self._recent), axis=0)) < 0.4:
                self._heading += np.pi / 2.0
                self._recent.clear()

    def _loop_without_news(self, position: np.ndarray, coverage: float | None) -> bool:
        """Whether the follower just closed a loop along its wall that added less than
        ``loop_min_gain`` coverage (False while no coverage is reported)."""
        if coverage is None or not self._found_wall:
            return False
        config = self.config
        self._visits.append((np.array(position[:2]), float(coverage)))
        earlier = len(self._visits) - config.loop_min_steps
        if earlier <= 0:
            return False
        points = np.array([point for point, _ in self._visits[:earlier]])
        close = np.flatnonzero(np.linalg.norm(points - position[:2], axis=1) < config.loop_close_m)
        if len(close) == 0:
            return False
        return coverage - self._visits[close[-1]][1] < config.loop_min_gain

    def _leave_the_wall(self, profile: np.ndarray) -> None:
        """Head across the room: the most open direction on the side away from the wall
        (between 30 and 150 degrees left of the walking direction), until another wall."""
        candidates = self._heading + np.deg2rad(np.arange(30.0, 151.0, 15.0))
        clearance = [profile_clearance(profile, yaw, np.deg2rad(10.0)) for yaw in candidates]
        self._heading = float(candidates[int(np.argmax(clearance))])
        self._found_wall = False
        self._visits = []
        self._recent = []

    def recover_from_stall(self, event: StallEvent) -> str:
        """Replaying: skip to the next pose. Scripted: the shared recovery
        (:meth:`~naruto_agent.policies.Policy.recover_from_stall`)."""
        if self.poses is not None:
            self._index += 1
            self._blocked = 0
            return "skipped to the next pose"
        return super().recover_from_stall(event)

    def walk_out(self, position: np.ndarray, goal: np.ndarray) -> str:
        """Leave the wall and walk straight to the way out of a stall, without steering,
        after changing height to the way out's (which stays the scan height from then on:
        every way was blocked at the old one)."""
        move = goal[:2] - position[:2]
        self._heading = float(np.arctan2(move[1], move[0]))
        self._found_wall = False
        self._visits = []
        self._recent = []
        step = self.context.max_translation_m
        climb = float(goal[2] - position[2])
        self._forced_steps = max(1, int(np.ceil(float(np.linalg.norm(move)) / step)))
        self._forced_steps += int(np.ceil(abs(climb) / step - 1e-9))
        self._height_offset = float(goal[2] - self._scan_height(0.0))
        self._hold_height = 0
        return (f"walk towards heading {np.rad2deg(self._heading) % 360.0:.0f} deg"
                + (f" after a height change of {climb:+.2f} m" if abs(climb) > 1e-6 else ""))

    @staticmethod
    def _lowest_height(panorama: np.ndarray, position: np.ndarray) -> float:
        """The lowest height the follower scans at here: :data:`FLOOR_CLEARANCE_M` above the
        surface the panorama shows straight below (a sloped or stepped floor, a cabinet's
        top), where a horizontal move still clears it; -inf where nothing is below."""
        _, below = vertical_clearance(panorama)
        return float(position[2] - below + FLOOR_CLEARANCE_M)

    def _scan_height(self, offset: float | None = None) -> float:
        """The height the follower scans at: ``scan_height_fraction`` of the bounds' height,
        moved by ``offset`` (default: the height a stall recovery last chose), within the
        bounds."""
        bounds = self.context.bounds
        height = bounds[0, 2] + self.config.scan_height_fraction * (bounds[1, 2] - bounds[0, 2])
        offset = self._height_offset if offset is None else offset
        return float(np.clip(height + offset, bounds[0, 2], bounds[1, 2]))

    def _without_refused_headings(self, profile: np.ndarray, position: np.ndarray,
                                  collided: bool) -> np.ndarray:
        """``profile`` with no room along a heading the env refused a move on from where the
        agent stands (a fragment or clutter the panorama's band around its height missed):
        a refused move is never sent again from the same spot; moving on forgets them."""
        if self._refused_spot is None or np.linalg.norm(position - self._refused_spot) > 0.02:
            self._refused_spot, self._refused_headings = position.copy(), []
        if collided and self._last_target is not None:
            move = self._last_target[:2] - position[:2]
            if np.linalg.norm(move) > 1e-6:
                self._refused_headings.append(float(np.arctan2(move[1], move[0])))
        if not self._refused_headings:
            return profile
        profile = profile.copy()
        for heading in self._refused_headings:
            profile[azimuth_window(len(profile), heading, np.deg2rad(20.0))] = 0.0
        return profile

    def _act_scripted(self, observation: Observation, info: Info | None) -> np.ndarray:
        pose = np.asarray(observation["pose"], np.float64)
        position = pose[:3, 3]
        self._position = position
        self._step += 1
        collided = bool(info.get("collided", False)) if info else False
        if collided and info.get("collision_reason") == "escape" and self._last_target is not None:
            self._refused.record(position, self._last_target)
        # Walls around the agent's height, and the scan's floor edge as a wall of its own.
        panorama = observation["panorama"]
        profile = np.minimum(horizontal_profile(panorama), floor_edge_profile(panorama))
        profile = self._refused.overlay(profile, position)
        profile = self._without_refused_headings(profile, position, collided)
        self._profile = profile
        coverage = info.get("coverage") if info else None
        if collided:
            self._forced_steps = 0
        if self._forced_steps > 0:
            self._forced_steps -= 1  # a stall recovery's walk: no steering
        else:
            if self._loop_without_news(position, coverage):
                self._leave_the_wall(profile)
            self._steer(profile, collided)
        height = max(self._scan_height(), self._lowest_height(panorama, position))
        step = self.context.max_translation_m
        direction = np.array([np.cos(self._heading), np.sin(self._heading)])
        next_position = position.copy()
        # Move only when the way is clear (the turn above may need a few steps).
        # A stall recovery's walk goes on while the panorama shows any room ahead; the env
        # refuses a move that touches a surface, and a refusal ends the walk.
        needed = FORCED_CLEARANCE_M if self._forced_steps > 0 else 0.25 + step
        if self._forced_steps > 0 and abs(height - position[2]) > 0.02 and not collided:
            pass  # a stall recovery's walk changes height first, then walks
        elif profile_clearance(profile, self._heading, np.deg2rad(20.0)) > needed:
            next_position[:2] += direction * step
        # A refused move that also climbed or sank (onto a tall cabinet's top, under a
        # shelf) is tried again at the height the agent has, until it walks clear.
        if (
            collided
            and self._last_target is not None
            and abs(self._last_target[2] - position[2]) > 1e-6
        ):
            self._hold_height = HOLD_HEIGHT_STEPS
        if self._hold_height > 0:
            self._hold_height -= 1
        else:
            next_position[2] += float(np.clip(height - position[2], -step, step))
        # Camera: sweep between the wall on the right and across the room, and up and down.
        phase = 2.0 * np.pi * self._step / self.config.sweep_period_steps
        sweep_yaw = float(np.deg2rad(self.config.sweep_yaw_deg))
        offset = -sweep_yaw + (np.deg2rad(150.0)) * (0.5 - 0.5 * np.cos(phase))
        yaw = self._heading + offset
        pitch = float(np.deg2rad(self.config.sweep_pitch_deg)) * np.sin(phase / 1.6)
        look = np.array([np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch)])
        rotation = look_at_rotation(next_position, next_position + look)
        self._last_target = next_position
        action = pose_action(make_pose(rotation, next_position))
        return clip_pose_action(action, self.context.action_space)

    def act(self, observation: Observation, info: Info | None = None) -> np.ndarray:
        self.check_stall(observation, info)
        if self.poses is not None:
            return self._act_replay(observation)
        return self._act_scripted(observation, info)
