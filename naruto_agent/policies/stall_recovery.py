"""One way out of a stall for every policy: a reachable place past the stay, away from the trail.

The stall watchdog (:mod:`naruto_agent.policies.watchdog`) notices that an agent stays; what it
does then is the same for every policy, whatever it plans with:

1. the policy's own map names the places it can reach from where it stands
   (:class:`ReachablePlaces`, through the hook
   :meth:`~naruto_agent.policies.Policy.reachable_places`; a policy without a map gets them
   from its depth panorama, :func:`panorama_places`);
2. :class:`StallRecovery` keeps those past the stay (farther than the stay radius and a step
   from every position of the stall's window), not near a way out that failed before, and
   takes the one farthest across the floor from the agent's trail (the shorter path among
   equals): the stay is left, and for space the agent has not been in yet;
3. the policy walks there with its own motion (the hook
   :meth:`~naruto_agent.policies.Policy.walk_out`).

A way out fails when, before the agent is past the stay, the env refuses a move on it or the
agent gets no nearer to it for ``max_idle_steps`` steps (a move its own checks held, or its
own rules took over), or when the next stall comes first. A failed way out is not chosen
again in the episode, and the policy is sent at once to the next way out of the same stay
(:attr:`StallRecovery.walk_failed`): the steps a stay may last are not spent on the
policy's own rules, which are what kept it there.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from naruto_agent.guards.panorama_clearance import (
    floor_edge_profile,
    horizontal_profile,
    profile_clearance,
    vertical_clearance,
)


@dataclass(frozen=True)
class ReachablePlaces:
    """Places a policy's map says it can reach from where it stands.

    Attributes:
        points: (n, 3) the places, metres, world frame.
        path_m: (n,) the length of the way to each, metres (the straight distance for a
            straight walk).
    """

    points: np.ndarray
    path_m: np.ndarray

    def __post_init__(self) -> None:
        points = np.asarray(self.points, np.float64).reshape(-1, 3)
        path_m = np.asarray(self.path_m, np.float64).reshape(-1)
        if len(points) != len(path_m):
            raise ValueError(
                f"ReachablePlaces needs one path length per place, got {len(points)} places "
                f"and {len(path_m)} path lengths"
            )
        object.__setattr__(self, "points", points)
        object.__setattr__(self, "path_m", path_m)

    def __len__(self) -> int:
        return len(self.points)


@dataclass(frozen=True)
class StallRecoveryConfig:
    """Settings of :class:`StallRecovery`.

    Attributes:
        max_path_m: places farther than this along their way are not considered (3.0: a
            recovery leaves the stay for the next room at most, it is not a plan of its own).
        trail_points: how many of the agent's last positions count as its trail.
        failed_radius_m: places this close to a way out that failed are not chosen again.
        arrival_m: the way out is reached within this of it (a step and a half).
        max_idle_steps: a way out the agent got no nearer to (by ``min_progress_m``) for this
            many steps in a row failed (2: one held move and the step after it; leaving a
            stay of 0.6 m takes 6 steps, and a stay is noticed 20-24 steps in).
        min_progress_m: the least a step must bring the agent nearer to the way out to count.
        max_failed_ways_out: ways out of one stay that may fail before the policy's own
            recovery takes over (:meth:`~naruto_agent.policies.Policy.no_way_out`): each
            failure costs a step, and several in a row say the map's places are not reachable.
        max_declined: places in a row a policy may decline to walk to
            (:meth:`~naruto_agent.policies.Policy.walk_out` returns None) before the next
            source of places is asked.
    """

    max_path_m: float = 3.0
    trail_points: int = 300
    failed_radius_m: float = 0.5
    arrival_m: float = 0.15
    max_idle_steps: int = 2
    min_progress_m: float = 0.01
    max_failed_ways_out: int = 3
    max_declined: int = 5

    def __post_init__(self) -> None:
        for name in ("max_path_m", "failed_radius_m", "arrival_m", "min_progress_m"):
            if not getattr(self, name) > 0:
                raise ValueError(
                    f"StallRecoveryConfig.{name} must be positive, got {getattr(self, name)}"
                )
        for name in ("trail_points", "max_idle_steps", "max_failed_ways_out", "max_declined"):
            if getattr(self, name) < 1:
                raise ValueError(
                    f"StallRecoveryConfig.{name} must be at least 1, got {getattr(self, name)}"
                )


class StallRecovery:
    """Chooses the way out of a stay (see the module docstring) and remembers the trail and
    the ways out that failed.

    Args:
        config: the settings (default :class:`StallRecoveryConfig`).

    Attributes:
        config: the settings.
        goal: the way out being walked (None when none is).
        walk_failed: the way out walked last failed before the agent got there (refused, held
            or idle) and no other has been chosen since: the next way out of the same stay is
            due (:meth:`~naruto_agent.policies.Policy.check_stall` sends the policy there).
    """

    def __init__(self, config: StallRecoveryConfig | None = None) -> None:
        self.config = config or StallRecoveryConfig()
        self.reset()

    def reset(self) -> None:
        """Forget the episode (call at every ``reset``)."""
        self._trail: deque[np.ndarray] = deque(maxlen=self.config.trail_points)
        self._failed: list[np.ndarray] = []
        self.goal: np.ndarray | None = None
        self._stay = (np.zeros((0, 3)), 0.0)  # the spots and radius of the stay being left
        self.walk_failed = False
        self._closest = np.inf
        self._idle_steps = 0

    def record(self, position: np.ndarray, refused: bool = False) -> None:
        """One step: the agent's position and whether the env refused its last move. A way
        out is done once the agent is within ``arrival_m`` of it. One the env refused, or
        one the agent got no nearer to for ``max_idle_steps`` steps, failed while the agent
        is still in the stay, and ends (the policy's own rules go on) past it."""
        position = np.asarray(position, np.float64).reshape(3).copy()
        self._trail.append(position)
        if self.goal is None:
            return
        distance = float(np.linalg.norm(position - self.goal))
        if distance <= self.config.arrival_m:
            self.goal = None
            return
        if distance < self._closest - self.config.min_progress_m:
            self._closest, self._idle_steps = distance, 0
        else:
            self._idle_steps += 1
        if refused or self._idle_steps >= self.config.max_idle_steps:
            self.fail()

    def fail(self) -> None:
        """The way out being walked failed (refused, held or idle): still in the stay, it is
        not chosen again in the episode and the next one is due (:attr:`walk_failed`); past
        the stay it has done its work and just ends."""
        if self.goal is None:
            return
        spots, radius_m = self._stay
        if self._trail and np.linalg.norm(spots - self._trail[-1], axis=1).min() > radius_m:
            self.goal = None
            return
        self.decline()
        self.walk_failed = True

    def decline(self) -> None:
        """The way out just chosen is given up without a step walked on it (the policy cannot
        walk there, or a new stall came first): it is not chosen again in the episode."""
        if self.goal is not None:
            self._failed.append(self.goal)
            self.goal = None

    def way_out(self, places: ReachablePlaces, spots: np.ndarray, radius_m: float) -> int | None:
        """The index of the place to walk to out of the stay at ``spots`` (``(n, 3)``
        positions) of radius ``radius_m``, or None when no place is past it; the chosen
        place becomes :attr:`goal`."""
        self.decline()  # still walked at the next stall: it did not get the agent out
        self.walk_failed = False
        index = self.choose(places, spots, radius_m)
        if index is not None:
            self.goal = places.points[index].copy()
            self._stay = (np.asarray(spots, np.float64).reshape(-1, 3), float(radius_m))
            start = self._trail[-1] if self._trail else spots.reshape(-1, 3)[-1]
            self._closest, self._idle_steps = float(np.linalg.norm(start - self.goal)), 0
        return index

    def choose(self, places: ReachablePlaces, spots: np.ndarray, radius_m: float) -> int | None:
        """:meth:`way_out`'s choice, without remembering it."""
        if len(places) == 0:
            return None
        points, path_m = places.points, places.path_m
        spots = np.asarray(spots, np.float64).reshape(-1, 3)
        from_stay = np.linalg.norm(points[:, None, :] - spots[None, :, :], axis=2).min(axis=1)
        keep = (from_stay > radius_m) & np.isfinite(path_m) & (path_m <= self.config.max_path_m)
        for failed in self._failed:
            keep &= np.linalg.norm(points - failed, axis=1) > self.config.failed_radius_m
        candidates = np.flatnonzero(keep)
        if len(candidates) == 0:
            return None
        trail = np.asarray(self._trail) if self._trail else spots
        novelty = np.full(len(candidates), np.inf)
        for chunk in np.array_split(trail, max(1, len(trail) // 64)):
            across = points[candidates, None, :2] - chunk[None, :, :2]
            novelty = np.minimum(novelty, np.linalg.norm(across, axis=2).min(axis=1))
        # Farthest from the trail (to a centimetre); the shorter way among equals.
        order = np.lexsort((path_m[candidates], -np.round(novelty, 2)))
        return int(candidates[order[0]])


def panorama_places(
    panorama: np.ndarray,
    position: np.ndarray,
    step_m: float,
    max_path_m: float = 3.0,
    margin_m: float = 0.25,
    headings: int = 24,
    heights_m: tuple[float, ...] = (0.0, 0.25, -0.25, 0.5, -0.5),
    bounds: np.ndarray | None = None,
) -> ReachablePlaces:
    """Places a straight walk reaches, read from a depth panorama: a climb or descent by one
    of ``heights_m`` that the panorama shows clear straight above or below (with
    ``margin_m``), then along each of ``headings`` level headings, every 3 steps up to the
    wall or the scanned floor's edge less ``margin_m`` and a step (the way a policy without
    a map of its own sees out; at a height where every way is blocked, another height's).

    Args:
        panorama: (H, W) the env's world-aligned depth panorama at ``position``.
        position: (3,) the agent's position.
        step_m: the agent's step.
        max_path_m: the farthest place considered (the height change included).
        margin_m: the clearance kept from what the panorama shows.
        headings: how many headings around the agent are read.
        heights_m: the height changes considered.
        bounds: (2, 3) the box places must lie in, ``margin_m`` inside its sides (the env's
            bounds: past an open scan's edge the panorama shows no wall); None: anywhere.
    """
    panorama = np.asarray(panorama, np.float64)
    position = np.asarray(position, np.float64).reshape(3)
    above, below = vertical_clearance(panorama)
    floor_edge = floor_edge_profile(panorama)
    half_width = np.pi / headings
    spacing = 3.0 * step_m
    points, path_m = [], []
    for change in heights_m:
        height = position[2] + change
        room = above if change > 0 else below
        if change and not abs(change) + margin_m < room:
            continue
        if bounds is not None and not bounds[0, 2] <= height <= bounds[1, 2]:
            continue
        profile = np.minimum(
            horizontal_profile(panorama, max_elevation_deg=50.0 if change else 20.0,
                               height_m=change),
            floor_edge,
        )
        for yaw in 2.0 * np.pi * np.arange(headings) / headings:
            clear = profile_clearance(profile, yaw, half_width) - margin_m - step_m
            reach = np.arange(spacing, min(clear, max_path_m - abs(change)) + 1e-9, spacing)
            direction = np.array([np.cos(yaw), np.sin(yaw), 0.0])
            points.extend(position + [0.0, 0.0, change] + np.outer(reach, direction))
            path_m.extend(abs(change) + reach)
    points, path_m = np.asarray(points).reshape(-1, 3), np.asarray(path_m)
    if bounds is not None:
        inside = np.all((points[:, :2] >= bounds[0, :2] + margin_m)
                        & (points[:, :2] <= bounds[1, :2] - margin_m), axis=1)
        points, path_m = points[inside], path_m[inside]
    return ReachablePlaces(points, path_m)
