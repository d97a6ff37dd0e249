"""A stall watchdog: notices when a policy stops getting anywhere, whatever its own rules say.

A policy's own rules can miss a stall that its designer did not foresee: a wall follower
whose circling rule never fires because it is spinning, not circling; a planner whose goal
keeps being refused one step at a time. The watchdog only watches positions, so it catches
them all. Over the last ``window_steps`` steps it calls it a stall when:

* the agent stayed within ``radius_m`` of where it is now (spinning in place, repeating one
  refused move, creeping back and forth by less than ``min_walk_m`` in all), or
* it went back and forth: it stayed within twice ``radius_m``, visited at most
  ``max_places`` places (``place_size_m`` cells, each visited twice on average over the
  default window) and ended within ``radius_m`` of where the window began (oscillating
  between two poses farther apart).

A policy with a map of its own may also hand the watchdog a measure of what it knows
(``progress``, e.g. its count of observed voxels): a stay that still adds more than
``min_progress_gain`` of it (a deliberate look-around at a new place) is then no stall,
until the agent has stayed within ``radius_m`` for ``max_stay_steps`` and is not just
leaving (a stall of kind ``"lingering"``); turning in place where nothing new shows is
one after a window.

An agent that walks at least ``min_walk_m`` over a window and still stays within
``radius_m`` (a random walk bouncing between the walls of a corner, a planner's moves among
furniture) is not standing: its own rules may still lead it away, and cutting its walk short
throws away a direction that was about to leave. It is a stall (an ``"oscillation"``) once
the stay lasts ``max_stay_steps``.

A stall triggers the policy's recovery (:meth:`~naruto_agent.policies.Policy.recover_from_stall`:
a new goal, a new direction, a height change inside the scanned space), and the watchdog then
starts a new window, so a recovery that did not help triggers the next one a window later;
the stay itself is still counted from where it began (a recovery that did not leave the spot
is a stay going on, and the next trigger comes as soon as the window allows).
Every trigger is kept as a :class:`StallEvent` (the harness and the demo write them to the
episode record; the Rerun recording shows them). The settings are :class:`StallWatchdogConfig`.
"""

from __future__ import annotations

from collections import deque
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

#: What a stall looked like: ``"refused"`` (most moves of the window were refused),
#: ``"oscillation"`` (between a few places), ``"spin"`` (in place) or ``"lingering"`` (in
#: place while still learning, for ``max_stay_steps``).
STALL_KINDS = ("refused", "oscillation", "spin", "lingering")
#: A step shorter than this is no move (a lingering agent that moved on is leaving).
_STANDING_M = 0.02


@dataclass(frozen=True)
class StallWatchdogConfig:
    """Settings of :class:`StallWatchdog`.

    Attributes:
        window_steps: steps over which net translation is judged (20: a stall is noticed
            and recovered from, at a step's 0.1 m, within 30 steps of its start).
        radius_m: staying within this of the current position over the window is a stall.
        max_places: visiting at most this many ``place_size_m`` cells over the window,
            within twice ``radius_m``, and coming back is an oscillation.
        place_size_m: size of the cells places are counted in.
        refused_share: the stall counts as ``"refused"`` when at least this share of the
            window's moves were refused by the env.
        min_progress_gain: with a ``progress`` measure, a window that raised it by at least
            this share is no stall, however little the agent moved (0.005: 0.5 %; late in
            an episode a look-around adds little) ...
        max_stay_steps: ... unless the agent stayed within ``radius_m`` for this many steps
            (24: leaving 0.5 m after it takes 5-8 steps, within the 30 steps a stay may
            last; most of a full look-around of the frontier policy, 27 steps, fits).
        min_walk_m: a window whose steps add up to at least this much is walking, not
            standing: staying within ``radius_m`` while walking is a stall only after
            ``max_stay_steps`` (1.0: ten full steps of 0.1 m, half the window's).
    """

    window_steps: int = 20
    radius_m: float = 0.5
    max_places: int = 12
    place_size_m: float = 0.1
    refused_share: float = 0.5
    min_progress_gain: float = 0.005
    max_stay_steps: int = 24
    min_walk_m: float = 1.0

    def __post_init__(self) -> None:
        if self.window_steps < 2:
            raise ValueError(
                f"StallWatchdogConfig.window_steps must be at least 2, got {self.window_steps}"
            )
        for name in ("radius_m", "place_size_m", "min_walk_m"):
            if not getattr(self, name) > 0:
                raise ValueError(
                    f"StallWatchdogConfig.{name} must be positive, got {getattr(self, name)}"
                )
        if self.max_stay_steps < self.window_steps:
            raise ValueError(
                f"StallWatchdogConfig.max_stay_steps ({self.max_stay_steps}) must be at least "
                f"window_steps ({self.window_steps})"
            )
        if self.max_places < 1:
            raise ValueError(
                f"StallWatchdogConfig.max_places must be at least 1, got {self.max_places}"
            )
        if self.min_progress_gain < 0:
            raise ValueError(
                f"StallWatchdogConfig.min_progress_gain must be >= 0, got {self.min_progress_gain}"
            )
        if not 0.0 < self.refused_share <= 1.0:
            raise ValueError(
                f"StallWatchdogConfig.refused_share must lie in (0, 1], got {self.refused_share}"
            )


@dataclass
class StallEvent:
    """One trigger of the watchdog.

    Attributes:
        step: the episode step (1 = the first ``act`` after ``reset``) it fired at.
        position: (3,) where the agent was, metres.
        kind: one of :data:`STALL_KINDS`.
        recovery: what the policy did about it (its own words; empty until it recovered).
        window: (n, 3) the positions the stall was judged on (the last ``window_steps``), so
            that a recovery can leave the whole spot; not written to records.
    """

    step: int
    position: np.ndarray
    kind: str
    recovery: str = ""
    window: np.ndarray | None = field(default=None, repr=False)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (for episode records)."""
        record = asdict(self)
        record.pop("window")
        record["position"] = [round(float(v), 3) for v in self.position]
        return record


class StallWatchdog:
    """Watches an agent's positions for stalls (see the module docstring).

    Args:
        config: the settings (default :class:`StallWatchdogConfig`).

    Attributes:
        config: the settings.
        events: the triggers of this episode, in order.
        stalled_steps: steps of this episode at which the last ``window_steps`` positions
            made a stall, recovered from or not (a stall the watchdog noticed at once counts
            once; one its recoveries could not end keeps counting).
    """

    def __init__(self, config: StallWatchdogConfig | None = None) -> None:
        self.config = config or StallWatchdogConfig()
        self.reset()

    def reset(self) -> None:
        """Forget the episode (call at every ``reset``)."""
        window = self.config.window_steps
        self._positions: deque[np.ndarray] = deque(maxlen=window)
        self._refused: deque[bool] = deque(maxlen=window)
        self._trailing: deque[np.ndarray] = deque(maxlen=window)
        self._progress: deque[float] = deque(maxlen=window)
        self._trailing_progress: deque[float] = deque(maxlen=window)
        self.events: list[StallEvent] = []
        self.stalled_steps = 0
        self.step = 0
        self._stay: list[np.ndarray] = []  # positions since the agent last left radius_m

    def observe(
        self, position: np.ndarray, refused: bool = False, progress: float | None = None
    ) -> StallEvent | None:
        """One step: the agent's position, whether the env refused its last move and,
        optionally, the policy's measure of what it knows; the stall noticed now, or None.
        After a stall the window starts again; the stay goes on until the agent leaves."""
        position = np.asarray(position, np.float64).reshape(3).copy()
        progress = float("nan") if progress is None else float(progress)
        self.step += 1
        self._positions.append(position)
        self._refused.append(bool(refused))
        self._progress.append(progress)
        self._trailing.append(position)
        self._trailing_progress.append(progress)
        self._stay.append(position)
        while np.linalg.norm(self._stay[0] - position) > self.config.radius_m:
            self._stay.pop(0)
        window = self.config.window_steps
        if len(self._trailing) == window and self._kind(self._trailing, self._trailing_progress):
            self.stalled_steps += 1
        if len(self._positions) < window:
            return None
        kind = self._kind(self._positions, self._progress)
        if kind is None and len(self._stay) >= self.config.max_stay_steps:
            departing = np.linalg.norm(position - self._positions[-2]) > _STANDING_M
            if self._walked(self._stay) >= self.config.min_walk_m:
                kind = "oscillation"  # walking about, and still here
            elif not departing:
                kind = "lingering"
        if kind is None:
            return None
        event = StallEvent(self.step, position, kind, window=np.asarray(self._positions))
        self.events.append(event)
        self._positions.clear()
        self._refused.clear()
        self._progress.clear()
        return event

    def _kind(self, window: deque[np.ndarray], progress: deque[float]) -> str | None:
        """The stall the window of positions (and progress) shows, or None."""
        config = self.config
        first, last = progress[0], progress[-1]
        if (
            np.isfinite(first)
            and np.isfinite(last)
            and (last - first > config.min_progress_gain * max(abs(first), 1e-12))
        ):
            return None  # it stayed, but learned: a look-around, not a stall
        points = np.asarray(window)
        newest = points[-1]
        if np.linalg.norm(points - newest, axis=1).max() <= config.radius_m:
            if self._walked(points) >= config.min_walk_m:
                return None  # walking about: a stall only once the stay lasts
            refused = np.mean(self._refused) if self._refused else 0.0
            return "refused" if refused >= config.refused_share else "spin"
        if np.linalg.norm(points - newest, axis=1).max() > 2.0 * config.radius_m:
            return None
        places = np.unique(np.floor(points / config.place_size_m).astype(np.int64), axis=0)
        if len(places) <= config.max_places and np.linalg.norm(newest - points[0]) <= (
            config.radius_m
        ):
            return "oscillation"
        return None

    @staticmethod
    def _walked(positions: Any) -> float:
        """Metres walked along consecutive ``positions``."""
        points = np.asarray(positions)
        return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def longest_stay(
    positions: np.ndarray, coverage: np.ndarray, radius_m: float = 0.5, covered: float = 0.9
) -> int:
    """What the watchdog keeps short, measured after the fact: the most steps in a row an
    agent stayed within ``radius_m`` of where it ended them, counted while coverage was
    below ``covered`` (a stay ends once coverage reaches it).

    Args:
        positions: (T, 3) positions, one per step.
        coverage: (T,) the env's coverage (0..1) at the same steps.
        radius_m: the stay radius.
        covered: coverage from which on staying is no stall.
    """
    positions = np.asarray(positions, np.float64).reshape(-1, 3)
    coverage = np.asarray(coverage, np.float64).reshape(-1)
    if len(positions) != len(coverage):
        raise ValueError(
            f"longest_stay needs one coverage per position, got {len(positions)} "
            f"positions and {len(coverage)} coverages"
        )
    longest, start = 0, 0
    for end in range(len(positions)):
        if coverage[end] >= covered:
            start = end
            continue
        while np.linalg.norm(positions[start : end + 1] - positions[end], axis=1).max() > radius_m:
            start += 1
        longest = max(longest, end - start)
    return longest
