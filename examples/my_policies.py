"""A walker that goes straight ahead and turns where its way is blocked."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from naruto_agent.guards import ScanGuard, ScanGuardConfig
from naruto_agent.policies import EnvContext, Policy, register_policy
from naruto_agent.policies.base import Info, Observation, clip_pose_action, pose_action
from naruto_agent.policies.config import build_config
from naruto_gym.geometry.transforms import look_at_rotation, make_pose


@dataclass
class TurnerConfig:
    """Settings of :class:`TurnerPolicy`.

    Attributes:
        turn_deg: how far it turns left when its way is blocked.
        guard: the open-scan guard that reads each move off the depth panorama; its edge
            probe is skipped where scanned floor lies all around below (70 degrees).
    """

    turn_deg: float = 60.0
    guard: ScanGuardConfig = field(
        default_factory=lambda: ScanGuardConfig(full_floor_polar_deg=70.0)
    )

    def __post_init__(self) -> None:
        if not 0.0 < self.turn_deg <= 180.0:
            raise ValueError(f"turn_deg must be in (0, 180], got {self.turn_deg}")


@register_policy("turner")
class TurnerPolicy(Policy):
    """Walks straight ahead at its height; turns left where the way is blocked."""

    action_modes = ("pose",)
    required_observations = ("pose",)

    def __init__(self, *, config: TurnerConfig | None = None, **settings: Any) -> None:
        super().__init__()
        self.config = build_config(TurnerConfig, config, **settings)
        self.guard = ScanGuard(self.config.guard)
        self.heading = 0.0

    def bind(self, context: EnvContext) -> None:
        super().bind(context)
        self.guard.agent_radius_m = context.agent_radius_m

    def reset(self, observation: Observation, info: Info, seed: int | None = None) -> None:
        super().reset(observation, info, seed)
        self.guard.reset()
        forward = np.asarray(observation["pose"], np.float64)[:3, 2]
        self.heading = float(np.arctan2(forward[1], forward[0]))

    def act(self, observation: Observation, info: Info | None = None) -> np.ndarray:
        turn = float(np.deg2rad(self.config.turn_deg))
        if info and info.get("collided"):  # the env refused the last move
            if info.get("collision_reason") == "escape":
                self.guard.note_escape()
            self.heading += turn
        position = np.asarray(observation["pose"], np.float64)[:3, 3]
        panorama = self.guard.panorama(observation)  # None without one, or with the check off
        step = self.context.max_translation_m
        for _ in range(int(np.ceil(2.0 * np.pi / turn))):
            move = step * np.array([np.cos(self.heading), np.sin(self.heading), 0.0])
            if panorama is None or not self.guard.way_blocked(panorama, move):
                break
            self.heading += turn  # blocked: try further left (after a full turn, the env decides)
        target = position + move
        rotation = look_at_rotation(target, target + move)
        return clip_pose_action(pose_action(make_pose(rotation, target)), self.context.action_space)
