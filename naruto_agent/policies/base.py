"""The policy interface every exploration policy implements, and what it may know of the env.

A policy is bound once to an :class:`EnvContext` (what a real robot knows before it starts:
the action mode and space, the scene's bounding box, the camera intrinsics, its step limits
and the episode's length), then, for every episode, ``reset`` with the first observation
and info, then ``act`` on each observation. It never sees the ground-truth mesh: geometry comes
only from the observations (RGB-D, pose, panorama) and the info of the last step.

The loop a runner drives::

    policy.bind(EnvContext.from_env(env, max_episode_steps=500))
    obs, info = env.reset(seed=seed, options=policy.reset_options())
    policy.reset(obs, info, seed=seed)
    for _ in range(500):
        obs, reward, terminated, truncated, info = env.step(policy.act(obs, info))
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import gymnasium as gym
import numpy as np

from naruto_agent.policies.layers import Layer
from naruto_agent.policies.stall_recovery import ReachablePlaces, StallRecovery, panorama_places
from naruto_agent.policies.watchdog import StallEvent, StallWatchdog, StallWatchdogConfig
from naruto_gym.envs.validation import check_keyword_names
from naruto_gym.geometry.transforms import quaternion_from_pose
from naruto_gym.sensors.pinhole import PinholeCamera

Observation = dict[str, np.ndarray]
Info = dict[str, Any]


@dataclass(frozen=True)
class EnvContext:
    """What a policy may know about the env before it starts (no ground-truth geometry).

    Attributes:
        action_mode: ``"pose"``, ``"delta"`` or ``"discrete"``.
        action_space: the env's action space.
        bounds: (2, 3) scene bounding box (min, max), metres, world z-up.
        camera: intrinsics of the ``rgb``/``depth`` observations.
        max_translation_m: longest move of one step.
        max_rotation_rad: largest rotation of one step.
        agent_radius_m: radius of the agent's collision sphere.
        max_depth_m: sensor range; depth is 0 beyond it.
        max_episode_steps: steps the episode will last, when known.
    """

    action_mode: str
    action_space: gym.Space
    bounds: np.ndarray
    camera: PinholeCamera
    max_translation_m: float = 0.1
    max_rotation_rad: float = float(np.deg2rad(20.0))
    agent_radius_m: float = 0.05
    max_depth_m: float = 10.0
    max_episode_steps: int | None = None

    @classmethod
    def from_env(
        cls, env: gym.Env, max_episode_steps: int | None = None, **unknown: Any
    ) -> EnvContext:
        """Context of a (possibly wrapped) ``NarutoReconEnv``.

        Args:
            env: the env, wrapped or not.
            max_episode_steps: the episode's length in steps; defaults to the ``TimeLimit``
                of the env's spec when there is one, else to the unwrapped env's own
                ``max_episode_steps``.

        Raises:
            ValueError: a keyword other than these (a renamed one names its new name).
        """
        if unknown:
            check_keyword_names(unknown, {"env", "max_episode_steps"}, "EnvContext.from_env")
        base = env.unwrapped
        for name in ("bounds", "camera", "settings"):
            if not hasattr(base, name):
                raise ValueError(
                    f"EnvContext.from_env needs a NarutoReconEnv-like env with `{name}`; got "
                    f"{type(base).__name__}. Build the EnvContext yourself for other envs."
                )
        if max_episode_steps is None and env.spec is not None:
            max_episode_steps = env.spec.max_episode_steps
        if max_episode_steps is None:
            max_episode_steps = getattr(base, "max_episode_steps", None)
        settings = base.settings
        return cls(
            action_mode=settings.action_mode,
            action_space=base.action_space,
            bounds=np.array(base.bounds, dtype=np.float64),
            camera=base.camera,
            max_translation_m=float(settings.max_translation_m),
            max_rotation_rad=float(settings.max_rotation_rad),
            agent_radius_m=float(settings.agent_radius_m),
            max_depth_m=float(settings.max_depth_m),
            max_episode_steps=max_episode_steps,
        )


class OwnReconstruction(NamedTuple):
    """A policy's own map of the scene, to be scored beside the env's reference map.

    Attributes:
        mesh: its surface (a ``trimesh.Trimesh`` in world coordinates).
        sdf: its signed distance function ((N, 3) metres -> (N,) metres), for MAD, or None.
    """

    mesh: Any
    sdf: Callable[[np.ndarray], np.ndarray] | None = None


class Policy(ABC):
    """Base class of exploration policies.

    Subclasses set :attr:`action_modes` (the env action modes they can act in, preferred
    first) and implement :meth:`act`; they override :meth:`reset` to clear per-episode state
    and :meth:`reset_options` to ask for a start pose.

    A stall watchdog (:mod:`naruto_agent.policies.watchdog`) is opt-in: a policy calls
    :meth:`use_stall_watchdog` (every shipped policy does), calls :meth:`check_stall` at the
    start of its ``act``, and implements :meth:`walk_out`. On a stall the one shared recovery
    (:mod:`naruto_agent.policies.stall_recovery`) chooses a reachable place past the stay,
    away from the trail, among those :meth:`reachable_places` names (the policy's own map;
    by default its depth panorama), and :meth:`walk_out` walks there; a way out that fails
    before the agent gets there (refused, held, idle) is followed at once by the next one.

    Attributes:
        stall_watchdog: the watchdog in use, or None (off, the default).
        stall_recovery: the shared recovery in use with the watchdog, or None.
    """

    #: Action modes this policy can act in; the first is the one a runner builds the env with.
    action_modes: ClassVar[tuple[str, ...]] = ("pose",)
    #: Observation keys the policy reads; a runner checks the env provides them.
    required_observations: ClassVar[tuple[str, ...]] = ()

    def __init__(self) -> None:
        self._context: EnvContext | None = None
        self.stall_watchdog: StallWatchdog | None = None
        self.stall_recovery: StallRecovery | None = None
        self._stall_panorama: np.ndarray | None = None
        self._stay_event: StallEvent | None = None  # the stall whose way out is walked
        self._failed_ways_out = 0  # ways out of that stall that failed

    @property
    def context(self) -> EnvContext:
        """The env context given to :meth:`bind` (raises if not bound yet)."""
        if self._context is None:
            raise RuntimeError(
                f"{type(self).__name__} is not bound to an env: call "
                "policy.bind(EnvContext.from_env(env)) before reset()"
            )
        return self._context

    @property
    def preferred_action_mode(self) -> str:
        return self.action_modes[0]

    def bind(self, context: EnvContext) -> None:
        """Attach the policy to an env; checks the action mode is supported."""
        if context.action_mode not in self.action_modes:
            raise ValueError(
                f"{type(self).__name__} acts in action modes {self.action_modes}, but the env "
                f"uses {context.action_mode!r}; make the env with "
                f"action_mode={self.preferred_action_mode!r}"
            )
        self._context = context

    def check_observation(self, observation: Observation) -> None:
        """Raise a ValueError when an observation lacks a key the policy needs."""
        missing = [key for key in self.required_observations if key not in observation]
        if missing:
            raise ValueError(
                f"{type(self).__name__} needs observation keys {missing}, which the env does "
                f"not provide (it gives {sorted(observation)}); e.g. keep the env's panorama on"
            )

    def reset_options(self) -> dict[str, Any] | None:
        """Options for ``env.reset`` (e.g. ``{"pose": c2w}`` for a fixed start), or None."""
        return None

    def reset(self, observation: Observation, info: Info, seed: int | None = None) -> None:
        """Start an episode from its first observation and info.

        Args:
            observation: the env's first observation.
            info: the env's reset info.
            seed: reseeds the policy's own randomness when given.
        """
        self.check_observation(observation)
        if self.stall_watchdog is not None:
            self.stall_watchdog.reset()
        if self.stall_recovery is not None:
            self.stall_recovery.reset()
        self._stall_panorama = None
        self._stay_event, self._failed_ways_out = None, 0

    # -- stall watchdog (opt-in) -----------------------------------------------------------
    def use_stall_watchdog(
        self, config: StallWatchdogConfig | None = None, enabled: bool = True
    ) -> None:
        """Watch this policy for stalls from now on (``enabled=False``: stop watching).

        Args:
            config: the watchdog's settings (default :class:`StallWatchdogConfig`).
            enabled: False turns the watchdog off.
        """
        own = type(self)
        if enabled and (own.walk_out is Policy.walk_out
                        and own.recover_from_stall is Policy.recover_from_stall):
            raise NotImplementedError(
                f"{own.__name__} uses a stall watchdog but does not implement "
                "walk_out(position, goal) (how it walks to the way out the shared recovery "
                "chooses) or recover_from_stall(event); implement one, or call "
                "use_stall_watchdog(enabled=False)"
            )
        self.stall_watchdog = StallWatchdog(config) if enabled else None
        self.stall_recovery = StallRecovery() if enabled else None

    def check_stall(
        self, observation: Observation, info: Info | None, progress: float | None = None
    ) -> StallEvent | None:
        """Feed the watchdog this step's position and refusal (and ``progress``, a measure
        of what the policy knows, e.g. its observed voxels, when it has one); on a stall, run
        :meth:`recover_from_stall` and return the event (with what the recovery did), else
        None. Call it at the start of ``act``; it does nothing without a watchdog. A way out
        that failed since the last step (:attr:`StallRecovery.walk_failed`) is followed by the
        next way out of the same stay, noted in that stall's record."""
        if self.stall_watchdog is None:
            return None
        position = np.asarray(observation["pose"], np.float64)[:3, 3]
        refused = bool(info.get("collided", False)) if info else False
        self._stall_panorama = observation.get("panorama")
        if self.stall_recovery is not None:
            self.stall_recovery.record(position, refused)
        event = self.stall_watchdog.observe(position, refused, progress)
        if event is not None:
            event.recovery = self.recover_from_stall(event)
        elif (self.stall_recovery is not None and self.stall_recovery.walk_failed
              and self._stay_event is not None):
            stay, self.stall_recovery.walk_failed = self._stay_event, False
            self._failed_ways_out += 1
            if self._failed_ways_out > self.stall_recovery.config.max_failed_ways_out:
                self._stay_event = None
                done = self.no_way_out(stay)
            else:
                done = self.leave_stay(stay, position)
            stay.recovery += f"; failed at step {self.stall_watchdog.step}, then {done}"
        return event

    def stay_of(self, event: StallEvent) -> tuple[np.ndarray, float]:
        """Where ``event``'s stay was, ``(n, 3)`` positions (the window the stall was judged
        on, or its position alone), and how far a recovery must get from every one of them
        to have left it: the stay radius and one step more."""
        assert self.stall_watchdog is not None
        spots = np.asarray(event.position if event.window is None else event.window, np.float64)
        radius = self.stall_watchdog.config.radius_m + self.context.max_translation_m
        return spots.reshape(-1, 3), radius

    @property
    def walking_out(self) -> bool:
        """Whether a way out of a stall is being walked (until the agent is there, the env
        refuses a move, or the next stall)."""
        return self.stall_recovery is not None and self.stall_recovery.goal is not None

    def recover_from_stall(self, event: StallEvent) -> str:
        """The shared recovery: :meth:`leave_stay` from where the stall was noticed. Returns
        what it did, in a few words, for the record."""
        self._stay_event, self._failed_ways_out = event, 0
        return self.leave_stay(event, np.asarray(event.position, np.float64))

    def leave_stay(self, event: StallEvent, position: np.ndarray) -> str:
        """Walk from ``position`` out of ``event``'s stay: to the reachable place past it
        farthest from the trail, among :meth:`reachable_places` (then the panorama's,
        :func:`panorama_places`, when the map has none past the stay), walked to by
        :meth:`walk_out` (a place it declines, the next); with none, :meth:`no_way_out`.
        Returns what it did."""
        recovery = self.stall_recovery
        assert recovery is not None
        spots, radius = self.stay_of(event)
        position = np.asarray(position, np.float64)
        offers = (self.reachable_places, self.panorama_places)  # the panorama's only if needed
        for places in (offer(position) for offer in offers):
            if places is None:
                continue
            for _ in range(recovery.config.max_declined):
                if recovery.way_out(places, spots, radius) is None:
                    break
                goal = recovery.goal
                how = self.walk_out(position.copy(), goal.copy())
                if how is not None:
                    return f"walk out to ({goal[0]:.2f}, {goal[1]:.2f}, {goal[2]:.2f}): {how}"
                recovery.decline()
        return self.no_way_out(event)

    def reachable_places(self, position: np.ndarray) -> ReachablePlaces | None:
        """The places the policy's own map says it can reach from ``position`` (a hook of the
        shared stall recovery); by default None: the depth panorama's
        (:meth:`panorama_places`) stand in."""
        return None

    def panorama_places(self, position: np.ndarray) -> ReachablePlaces | None:
        """The places a straight, level walk reaches as the last panorama shows them
        (:func:`~naruto_agent.policies.stall_recovery.panorama_places`); None without one."""
        if self._stall_panorama is None:
            return None
        return panorama_places(self._stall_panorama, position, self.context.max_translation_m,
                               bounds=np.asarray(self.context.bounds, np.float64))

    def walk_out(self, position: np.ndarray, goal: np.ndarray) -> str | None:
        """Walk from ``position`` to ``goal`` (3,), the way out of a stall the shared recovery
        chose, with the policy's own motion; returns how, in a few words, or None when the
        policy cannot walk there (no path, or its own reading shows the way blocked: the
        recovery offers the next place, no step spent). Policies that use a watchdog must
        implement it (:attr:`walking_out` says whether the walk is still on)."""
        raise NotImplementedError(
            f"{type(self).__name__} uses a stall watchdog but does not implement "
            "walk_out(position, goal); implement it, or call use_stall_watchdog(enabled=False)"
        )

    def no_way_out(self, event: StallEvent) -> str:
        """What to do when no reachable place lies past the stay (a hook); by default
        nothing: the policy's own rules go on, and the next stall tries again."""
        return "no reachable place past the stay"

    @property
    def stall_events(self) -> list[StallEvent]:
        """The watchdog's triggers this episode (none without a watchdog)."""
        return [] if self.stall_watchdog is None else list(self.stall_watchdog.events)

    @property
    def stalled_steps(self) -> int:
        """Steps of this episode spent in a stall (0 without a watchdog)."""
        return 0 if self.stall_watchdog is None else self.stall_watchdog.stalled_steps

    @abstractmethod
    def act(self, observation: Observation, info: Info | None = None) -> Any:
        """The action for the current observation (and the info of the step that produced it)."""

    def reconstruction(self) -> OwnReconstruction | None:
        """The policy's own map, scored by the benchmark harness beside the reference map;
        None (the default) for policies that build none."""
        return None

    def view_layers(self) -> list[Layer]:
        """What the policy wants shown of its thinking now, as named layers (points, line
        strips, boxes, scalars of :mod:`naruto_agent.policies.layers`); none by default.

        A recorder (``naruto-demo``, ``naruto-benchmark --record``) calls it after ``act``
        every few steps and draws the layers beside the camera and the map, so a policy of
        one's own shows its targets and plans too. It must only read the policy's state
        (calling it must not change what the policy does) and stay cheap.
        """
        return []

    def close(self) -> None:  # noqa: B027 (optional hook, empty by default)
        """Free resources (optional)."""


def pose_action(pose: np.ndarray) -> np.ndarray:
    """A ``"pose"`` action (x, y, z, qx, qy, qz, qw) float32 from a 4x4 camera-to-world pose."""
    pose = np.asarray(pose, dtype=np.float64)
    return np.concatenate([pose[:3, 3], quaternion_from_pose(pose)]).astype(np.float32)


def clip_pose_action(action: np.ndarray, space: gym.spaces.Box) -> np.ndarray:
    """Clip a pose action's position into the action space (the quaternion is left alone)."""
    action = np.array(action, dtype=np.float32)
    action[:3] = np.clip(action[:3], space.low[:3], space.high[:3])
    return action
