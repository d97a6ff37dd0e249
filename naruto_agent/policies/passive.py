"""The "human scan" baseline: replay a recorded trajectory, or walk a scripted scan loop.

* With a trajectory (e.g. Replica's ``traj.txt``, 2000 camera-to-world poses) the episode
  starts exactly at its first pose and every step targets the next one. When the step budget
  is smaller than the trajectory, the poses are subsampled uniformly to fit the budget
  (``fit_to_budget``), so the whole scan is walked, faster; a pose the env refuses to reach
  (blocked by the agent's body) is skipped after a few tries.
* Without one, a scripted scan: loops around the middle of the scene (ellipses at several
  sizes inside the bounding box) at about head height, the camera turned outwards to the walls
  (or, every other loop, inwards across the room) and sweeping up, down and sideways, as a
  person scanning a room would. The way ahead is checked on the depth panorama before each
  move; blocked stretches of the loop are walked around or skipped. Only the bounds and the
  observations are used, never the mesh.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from naruto_agent.policies.base import Info, Observation, Policy, clip_pose_action, pose_action
from naruto_agent.policies.panorama_clearance import PanoramaClearance
from naruto_gym.geometry.transforms import look_at_rotation, make_pose, validate_pose


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


def subsample_poses(poses: np.ndarray, step_budget: int) -> np.ndarray:
    """The poses to replay in ``step_budget`` steps: all of them when they fit, else
    ``step_budget + 1`` uniformly spaced ones (first and last kept)."""
    if step_budget < 1:
        raise ValueError(f"step_budget must be at least 1, got {step_budget}")
    if len(poses) <= step_budget + 1:
        return poses
    index = np.round(np.linspace(0, len(poses) - 1, step_budget + 1)).astype(np.int64)
    return poses[index]


class PassivePolicy(Policy):
    """Replays a pose sequence, or follows a scripted scan loop when none is given.

    Args:
        trajectory: (N, 4, 4) poses or a path to a ``traj.txt``-style file; None for the
            scripted loop.
        fit_to_budget: subsample a longer trajectory uniformly to the episode's step budget.
        position_tolerance_m, rotation_tolerance_deg: a replayed pose counts as reached within
            these.
        max_blocked_steps: skip a replayed pose after this many steps without reaching it.
        loop_fractions: sizes of the scripted loops as fractions of the half-extents of the
            bounding box (cycled, one loop each).
        loop_facings: for each loop, ``"out"`` (camera towards the walls) or ``"in"``
            (towards the middle of the room: furniture, the opposite walls, the floor).
        scan_height_fraction: scripted scan height as a fraction of the bounds' height.
        sweep_yaw_deg, sweep_pitch_deg: amplitudes of the scripted camera sweeps.
        sweep_period_steps: period of the yaw sweep (the pitch sweep uses 1.6 times it).
        safety_distance_m: the scripted scan keeps this clearance ahead (panorama).
    """

    def __init__(
        self,
        trajectory: np.ndarray | str | Path | None = None,
        fit_to_budget: bool = True,
        position_tolerance_m: float = 1e-3,
        rotation_tolerance_deg: float = 0.5,
        max_blocked_steps: int = 3,
        loop_fractions: tuple[float, ...] = (0.55, 0.8, 0.3),
        loop_facings: tuple[str, ...] = ("out", "in", "out"),
        scan_height_fraction: float = 0.45,
        sweep_yaw_deg: float = 50.0,
        sweep_pitch_deg: float = 30.0,
        sweep_period_steps: int = 40,
        safety_distance_m: float = 0.3,
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
        if not loop_fractions or not all(0.0 < f < 1.0 for f in loop_fractions):
            raise ValueError(f"loop_fractions must lie in (0, 1), got {loop_fractions}")
        if len(loop_facings) != len(loop_fractions) or not set(loop_facings) <= {"in", "out"}:
            raise ValueError(
                f"loop_facings must give 'in' or 'out' for each of the {len(loop_fractions)} "
                f"loops, got {loop_facings}"
            )
        self.loop_facings = tuple(loop_facings)
        self.fit_to_budget = fit_to_budget
        self.position_tolerance_m = position_tolerance_m
        self.rotation_tolerance_rad = float(np.deg2rad(rotation_tolerance_deg))
        self.max_blocked_steps = max_blocked_steps
        self.loop_fractions = tuple(loop_fractions)
        self.scan_height_fraction = scan_height_fraction
        self.sweep_yaw_rad = float(np.deg2rad(sweep_yaw_deg))
        self.sweep_pitch_rad = float(np.deg2rad(sweep_pitch_deg))
        self.sweep_period_steps = sweep_period_steps
        self.safety_distance_m = safety_distance_m
        self.required_observations = ("pose",) if self.poses is not None else ("pose", "panorama")
        self._clearance = PanoramaClearance()
        self._replay: np.ndarray | None = None
        self._index = 0
        self._last_sent = -1
        self._last_pose: np.ndarray | None = None
        self._blocked = 0
        self._step = 0
        self._phase = 0.0
        self._loop = 0
        self._stalled = 0

    @property
    def replays(self) -> bool:
        """True when replaying a trajectory (False: scripted scan loop)."""
        return self.poses is not None

    def replay_poses(self) -> np.ndarray:
        """The poses this episode replays (after fitting to the budget)."""
        if self.poses is None:
            raise ValueError("this PassivePolicy has no trajectory; it follows a scripted loop")
        budget = self.context.step_budget if self._context is not None else None
        if self.fit_to_budget and budget is not None:
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
        self._stalled = 0
        self._loop = 0
        if self.poses is not None:
            self._replay = self.replay_poses()
            self._index = 1
            self._last_sent = -1
            self._last_pose = None
            return
        position = np.asarray(observation["pose"], np.float64)[:3, 3]
        offset = self._normalised(position)
        self._phase = float(np.arctan2(offset[1], offset[0]))

    # -- replay ------------------------------------------------------------------------
    def _reached(self, pose: np.ndarray, target: np.ndarray) -> bool:
        if np.linalg.norm(pose[:3, 3] - target[:3, 3]) > self.position_tolerance_m:
            return False
        relative = Rotation.from_matrix(pose[:3, :3].T @ target[:3, :3])
        return relative.magnitude() <= self.rotation_tolerance_rad

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
            if self._blocked > self.max_blocked_steps:
                self._index += 1
                self._blocked = 0
        self._last_sent = self._index
        self._last_pose = pose
        target = self._replay[min(self._index, len(self._replay) - 1)]
        return clip_pose_action(pose_action(target), self.context.action_space)

    # -- scripted loop -------------------------------------------------------------------
    def _centre_and_radii(self) -> tuple[np.ndarray, np.ndarray]:
        bounds = self.context.bounds
        return (bounds[0, :2] + bounds[1, :2]) / 2.0, (bounds[1, :2] - bounds[0, :2]) / 2.0

    def _normalised(self, position: np.ndarray) -> np.ndarray:
        centre, radii = self._centre_and_radii()
        return (position[:2] - centre) / np.maximum(radii, 1e-6)

    def _loop_point(self, phase: float) -> np.ndarray:
        centre, radii = self._centre_and_radii()
        fraction = self.loop_fractions[self._loop % len(self.loop_fractions)]
        bounds = self.context.bounds
        height = bounds[0, 2] + self.scan_height_fraction * (bounds[1, 2] - bounds[0, 2])
        xy = centre + fraction * radii * np.array([np.cos(phase), np.sin(phase)])
        return np.array([xy[0], xy[1], height])

    def _phase_step(self) -> float:
        """Loop angle that advances about one step's length along the current ellipse."""
        _, radii = self._centre_and_radii()
        fraction = self.loop_fractions[self._loop % len(self.loop_fractions)]
        mean_radius = float(np.mean(fraction * radii))
        return self.context.max_translation_m / max(mean_radius, 0.1)

    def _free_direction(self, panorama: np.ndarray, wanted: np.ndarray) -> np.ndarray | None:
        """``wanted`` if its way is clear, else the nearest clear horizontal deviation."""
        need = self.safety_distance_m + self.context.max_translation_m
        horizontal = np.array([wanted[0], wanted[1], 0.0])
        if np.linalg.norm(horizontal) < 1e-9:
            candidates = [wanted]
        else:
            candidates = [wanted]
            for angle in np.deg2rad([20, -20, 40, -40, 60, -60, 80, -80, 100, -100, 120, -120]):
                turn = Rotation.from_rotvec([0.0, 0.0, angle]).as_matrix()
                candidates.append(turn @ horizontal)
        clearances = self._clearance.clearance(panorama, np.array(candidates))
        for candidate, clearance in zip(candidates, clearances, strict=True):
            if clearance >= need:
                return candidate / np.linalg.norm(candidate)
        return None

    def _act_scripted(self, observation: Observation, info: Info | None) -> np.ndarray:
        pose = np.asarray(observation["pose"], np.float64)
        position = pose[:3, 3]
        self._step += 1
        target = self._loop_point(self._phase)
        # Advance the loop target once the agent is near it (pure pursuit along the ellipse).
        if np.linalg.norm(target - position) < 2.0 * self.context.max_translation_m:
            self._phase += self._phase_step()
            self._stalled = 0
        else:
            self._stalled += 1
        collided = bool(info.get("collided", False)) if info else False
        if self._stalled > 25 or (collided and self._stalled > 5):
            # This stretch of the loop is out of reach (furniture, another room): skip ahead.
            self._phase += 8.0 * self._phase_step()
            self._stalled = 0
        if self._phase >= 2.0 * np.pi:
            self._phase -= 2.0 * np.pi
            self._loop += 1
        target = self._loop_point(self._phase)
        wanted = target - position
        distance = float(np.linalg.norm(wanted))
        next_position = position
        if distance > 1e-6:
            direction = self._free_direction(observation["panorama"], wanted)
            if direction is not None:
                next_position = position + direction * min(distance, self.context.max_translation_m)
        # Look outwards at the walls (or inwards across the room), sweeping sideways and
        # up/down.
        centre, _ = self._centre_and_radii()
        outward = next_position[:2] - centre
        base_yaw = (
            float(np.arctan2(outward[1], outward[0]))
            if np.linalg.norm(outward) > 0.05
            else self._phase
        )
        if self.loop_facings[self._loop % len(self.loop_facings)] == "in":
            base_yaw += np.pi
        yaw = base_yaw + self.sweep_yaw_rad * np.sin(
            2.0 * np.pi * self._step / self.sweep_period_steps
        )
        pitch = self.sweep_pitch_rad * np.sin(
            2.0 * np.pi * self._step / (1.6 * self.sweep_period_steps)
        )
        look = np.array([np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch)])
        rotation = look_at_rotation(next_position, next_position + look)
        action = pose_action(make_pose(rotation, next_position))
        return clip_pose_action(action, self.context.action_space)

    def act(self, observation: Observation, info: Info | None = None) -> np.ndarray:
        if self.poses is not None:
            return self._act_replay(observation)
        return self._act_scripted(observation, info)
