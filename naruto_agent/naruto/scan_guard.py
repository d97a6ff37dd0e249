"""NARUTO's guard of the scanned space: the panorama move check and the open scan's edges.

A robot checks its range sensor before it moves; this agent checks every move against the
env's depth panorama taken where it stands (when the observation has one): the 0.1 m map's
distance field misses a surface by a few centimetres here and there, the panorama does not.

On an *open* scan (no ceiling, a missing wall, a floor hole) the env refuses moves that
leave the scanned space. The scan counts as open once the env refused a move for that reason
or a depth frame saw the sky (:func:`~naruto_agent.guards.panorama_clearance.
steep_miss_share`); closed scenes give neither sign, and there only the panorama's surface
check runs. On an open scan a move must also

* end below the scan's top (the measured surfaces' top, or the flight ceiling a refused climb
  taught);
* keep to the scanned space as the panorama shows it (the env's support-cone test on the
  panorama's points, :func:`~naruto_agent.guards.panorama_clearance.move_leaves_scan`);
* not cross the scan's edge as the agent's own grid shows it (a probe ``edge_probe_m`` past
  the move's end).

A move held back by the panorama is counted; after ``max_held_moves`` holds in a row at one
spot the next goes to the env (its refusal teaches the map as any other), or, at an open
scan's edge, the agent climbs out of the margin first (``margin_climb_m``).

:class:`ScanGuard`'s public API:

* :meth:`ScanGuard.observe_frame`, :meth:`ScanGuard.observe_panorama`: what each frame shows.
* :attr:`ScanGuard.scan_open`, :meth:`ScanGuard.mark_open`: whether the scan is known open.
* :meth:`ScanGuard.check_move`: every check of one move (its parts are public too).
* :meth:`ScanGuard.inside_scan`: which points lie inside the scan (for goals).
* :meth:`ScanGuard.refused_climb`: whether an escape refusal came at the scan's top.
* :meth:`ScanGuard.take_climb`: the climb out of the margin planned by the last check.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from naruto_agent.guards.panorama_clearance import (
    clear_part_of_move,
    first_contact,
    move_leaves_scan,
    steep_miss_share,
)
from naruto_agent.guards.refused_moves import refused_at_top
from naruto_agent.naruto.agent_map import AgentMap
from naruto_agent.naruto.config import NarutoConfig
from naruto_agent.policies.base import EnvContext

#: A climb out of an open scan's margin shorter than this is not worth it (metres).
MIN_CLIMB_M = 0.02
#: A panorama or a held count belongs to a spot within this distance (metres).
_SAME_SPOT_M = 1e-3


def _no_goal_failed() -> None:
    """What a guard without a goal to fail does when a check fails the goal: nothing."""


class ScanGuard:
    """Checks moves against the panorama and, on an open scan, against the scan's edges.

    Args:
        config: the agent's settings.
        context: the env's context (the agent's radius, the camera).
        agent_map: the agent's map; checks that fail block space in it.
        fail_goal: called when a check fails the current plan's goal (a move that would
            cross the scan's edge as the agent's grid shows it).
    """

    def __init__(self, config: NarutoConfig, context: EnvContext, agent_map: AgentMap,
                 fail_goal: Callable[[], None] = _no_goal_failed) -> None:
        self.config = config
        self.context = context
        self.agent_map = agent_map
        self._fail_goal = fail_goal
        self._open = False
        self._panorama: tuple[np.ndarray, np.ndarray] | None = None  # (panorama, where)
        self._held: tuple[np.ndarray, int] | None = None  # where moves were held, how many
        self._climb: np.ndarray | None = None  # a climb out of an open scan's margin, next

    # -- what the frames show ----------------------------------------------------------------
    @property
    def scan_open(self) -> bool:
        """Whether the scan is known to be open (an escape refusal, or the sky)."""
        return self._open

    def mark_open(self) -> None:
        """The scan is open (the env refused a move for leaving it)."""
        self._open = True

    def observe_frame(self, depth: np.ndarray, pose: np.ndarray) -> None:
        """A depth frame: the scan is open once ``open_sky_share`` of its steep pixels miss."""
        if not self._open and self.config.open_sky_share is not None:
            miss = steep_miss_share(depth, pose, self.context.camera)
            self._open = miss >= self.config.open_sky_share

    def observe_panorama(self, panorama: np.ndarray | None, position: np.ndarray) -> None:
        """The newest depth panorama (None: the observation has none) and where it was taken."""
        self._panorama = (None if panorama is None
                          else (np.asarray(panorama), np.asarray(position, np.float64).copy()))

    # -- move checks -------------------------------------------------------------------------
    def check_move(self, start: np.ndarray, end: np.ndarray) -> bool:
        """Every check of the move from ``start`` to ``end``: the panorama shows the way
        clear, and on an open scan (``sector_support_after_escape``) the move stays below the
        top, keeps to the scan on the panorama and stays in the scan on the agent's grid."""
        if not self.panorama_shows_way_clear(start, end):
            return False
        if self._open and self.config.sector_support_after_escape:
            return (self.stays_below_top(start, end) and self.panorama_keeps_to_scan(start, end)
                    and self.stays_in_scan(start, end))
        return True

    def panorama_from(self, start: np.ndarray) -> np.ndarray | None:
        """The newest panorama when it was taken at ``start`` and the panorama checks are on
        (``check_moves_on_panorama``); None otherwise."""
        if not self.config.check_moves_on_panorama or self._panorama is None:
            return None
        panorama, centre = self._panorama
        return panorama if np.linalg.norm(start - centre) <= _SAME_SPOT_M else None

    def panorama_shows_way_clear(self, start: np.ndarray, end: np.ndarray) -> bool:
        """The move checked against the panorama taken where it starts: a move that comes
        within the agent's radius plus ``panorama_margin_m`` of a surface is held and the
        surface point blocked in the map (the goal stays), unless the holds ran out
        (:meth:`hold_here`)."""
        panorama = self.panorama_from(start)
        if panorama is None:
            return True
        radius = self.context.agent_radius_m + self.config.panorama_margin_m
        contact = first_contact(panorama, end - start, radius)
        if contact is None or not self.hold_here(start):
            return True
        self.agent_map.block(start + contact)
        return False

    def hold_here(self, start: np.ndarray) -> bool:
        """Count a move held back by the panorama at ``start``.

        Returns:
            False (send it, the env decides) after ``max_held_moves`` moves in a row were
            held at this spot; the count then starts again (a move the env refuses teaches
            the map, and the next ones are checked again).
        """
        held_here = (self._held is not None
                     and np.linalg.norm(start - self._held[0]) <= _SAME_SPOT_M)
        count = self._held[1] + 1 if held_here else 1
        if count > self.config.max_held_moves:
            self._held = (start.copy(), 0)
            return False
        self._held = (start.copy(), count)
        return True

    def stays_below_top(self, start: np.ndarray, end: np.ndarray) -> bool:
        """On an open scan a climb may not end above the scan's top: the flight ceiling a
        refused climb taught, or the measured surfaces' top less the agent's radius.

        The map alone lets a path's node a few centimetres above either through (the SDF
        blends blocked voxels with free ones). A refused climb lowers the flight ceiling, so
        the next plan stays under it; the goal stays. Level and descending moves pass.
        """
        if end[2] <= start[2]:
            return True
        blocked = self.agent_map.blocked
        top = self.agent_map.observed_space.scan_top_z() - self.context.agent_radius_m
        if end[2] <= min(top, blocked.ceiling_z):
            return True
        if top < blocked.ceiling_z:
            self.agent_map.lower_ceiling(max(top, float(start[2])))
        return False

    def panorama_keeps_to_scan(self, start: np.ndarray, end: np.ndarray) -> bool:
        """On an open scan, the env's cone test read from the panorama where the move starts.

        A move that leaves the scanned space there is held and the space past it blocked
        (a guess: the goal stays). After ``max_held_moves`` holds in a row at one spot the
        agent climbs out of the margin instead (:meth:`take_climb`), or, when it cannot,
        the move passes and the env decides.
        """
        panorama = self.panorama_from(start)
        radius = self.context.agent_radius_m
        if panorama is None or not move_leaves_scan(panorama, end - start, radius):
            return True
        if not self.hold_here(start):
            self._climb = self.margin_climb(start, panorama)
            if self._climb is None:
                return True  # the env decides
            return False  # the next plan is the climb
        self.agent_map.block_past_edge(start, end, guessed=True)
        return False

    def margin_climb(self, start: np.ndarray, panorama: np.ndarray) -> np.ndarray | None:
        """Nodes (a planner step apart) of a climb of up to ``margin_climb_m`` straight up
        from ``start``: below the scan's top (``scan_top_margin_m`` under the measured
        surfaces' top, and the flight ceiling) and as far as the panorama shows it clear of
        surfaces; None when less than :data:`MIN_CLIMB_M` is left."""
        height = self.config.margin_climb_m
        if height <= 0:
            return None
        top = min(self.agent_map.observed_space.scan_top_z() - self.config.scan_top_margin_m,
                  self.agent_map.blocked.ceiling_z)
        rise = min(height, top - float(start[2]))
        if rise < MIN_CLIMB_M:
            return None
        radius = self.context.agent_radius_m + self.config.panorama_margin_m
        part = clear_part_of_move(panorama, np.array([0.0, 0.0, rise]), radius)
        if part is None or part[2] < MIN_CLIMB_M:
            return None
        rise = float(part[2])  # cut short below a surface (a slide sideways is not a climb)
        steps = max(1, math.ceil(rise / self.config.planner.step_m - 1e-9))
        heights = np.arange(0, steps + 1) / steps * rise
        return start + heights[:, None] * np.array([0.0, 0.0, 1.0])

    def stays_in_scan(self, start: np.ndarray, end: np.ndarray) -> bool:
        """On an open scan, the edge probe on the agent's grid.

        A path may cross a floor hole's edge or a wall's opening where the goal search's test
        never looked: a move from a point that passes the env's cone test on the agent's map
        towards one that fails it (probed ``edge_probe_m`` beyond the move's end,
        horizontally) is refused, the space past it blocked so that the next plan goes
        elsewhere, and the plan's goal failed.
        """
        grid = self.agent_map.observed_space.grid
        if grid.move_leaves_support(start, end, self.config.edge_probe_m):
            self.agent_map.block_past_edge(start, end, guessed=True)
            self._fail_goal()
            return False
        return True

    # -- goals and refusals ------------------------------------------------------------------
    def inside_scan(self, points: np.ndarray, position: np.ndarray) -> np.ndarray:
        """(N,) bool: ``points`` over measured surface and ``scan_top_margin_m`` below the
        measured surfaces' top, or no higher than the agent at ``position`` stands (where the
        env let it be: over a scan that is mostly floor the measured top can lie below the
        agent); on a scan known open, also over measured surface in every sector of the env's
        support cone."""
        observed = self.agent_map.observed_space
        top = max(observed.scan_top_z() - self.config.scan_top_margin_m, float(position[2]))
        inside = observed.sample(observed.supported(), points) & (points[:, 2] <= top)
        if self._open and self.config.sector_support_after_escape:
            candidates = np.flatnonzero(inside)
            inside[candidates] = observed.sectors_seen_below(points[candidates])
        return inside

    def refused_climb(self, position: np.ndarray, target: np.ndarray) -> bool:
        """Whether an escape refusal of the move to ``target`` came at the scan's open top
        rather than at its side (:func:`~naruto_agent.guards.refused_moves.refused_at_top`, with "all around below" judged by the env's cone test on the
        agent's own grid)."""
        supported = self.agent_map.observed_space.sectors_seen_below(position[None])[0]
        return refused_at_top(position, target, bool(supported))

    @property
    def pending_climb(self) -> np.ndarray | None:
        """The climb out of the margin that the checks planned, not yet taken."""
        return self._climb

    def take_climb(self, position: np.ndarray) -> np.ndarray | None:
        """The pending climb if it starts at ``position`` (checked on the panorama already),
        else None; the pending climb is dropped either way."""
        climb, self._climb = self._climb, None
        if climb is not None and np.linalg.norm(climb[0] - position) <= _SAME_SPOT_M:
            return climb
        return None
