"""NARUTO's checks of the scanned space: the shared scan guard read with the agent's own map.

A robot checks its range sensor before it moves; this agent checks every move with the
open-scan guard that every policy shares (:class:`~naruto_agent.guards.ScanGuard`): the
0.1 m map's distance field misses a surface by a few centimetres here and there, the depth
panorama taken where the agent stands does not. The guard also keeps whether the scan is known
to be open (no ceiling, a missing wall, a floor hole), where the env refuses moves that leave
the scanned space. Closed scenes give no such sign, and there only the panorama's surface
check runs. On an open scan a move must also

* end below the scan's top (the measured surfaces' top on the agent's map, or the flight
  ceiling a refused climb taught);
* keep to the scanned space as the panorama shows it (:meth:`ScanGuard.leaves_scan
  <naruto_agent.guards.ScanGuard.leaves_scan>`);
* not cross the scan's edge as the agent's own grid shows it (:meth:`ScanGuard.map_leaves_scan
  <naruto_agent.guards.ScanGuard.map_leaves_scan>`).

One count (:attr:`ScanGuard.holds <naruto_agent.guards.ScanGuard.holds>`) serves the surface
and the edge readings: after ``max_held_moves`` moves held in a row at one spot the next goes
to the env (its refusal teaches the map as any other), or, at an open scan's edge, the agent
climbs out of the margin first (``margin_climb_m``).

:class:`NarutoScanChecks` holds what is the agent's own: what a held move does to its map and
goal, the scan's top on its map, the climb out of the margin, and which points lie inside the
scan for its goals.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from naruto_agent.guards.refused_moves import refused_at_top
from naruto_agent.guards.scan_guard import SAME_SPOT_M, ScanGuard
from naruto_agent.naruto.agent_map import AgentMap
from naruto_agent.naruto.config import NarutoConfig

#: A climb out of an open scan's margin shorter than this is not worth it (metres).
MIN_CLIMB_M = 0.02


def _no_goal_failed() -> None:
    """What checks without a goal to fail do when a check fails the goal: nothing."""


class NarutoScanChecks:
    """The agent's checks of moves and goals against the scanned space, on the shared guard.

    Args:
        config: the agent's settings (``guard`` is the guard's).
        guard: the episode's scan guard (bound to the env's agent radius); the policy feeds
            it the frames (:meth:`ScanGuard.observe_depth
            <naruto_agent.guards.ScanGuard.observe_depth>`, :meth:`ScanGuard.observe_panorama
            <naruto_agent.guards.ScanGuard.observe_panorama>`) and the escape refusals.
        agent_map: the agent's map; checks that fail block space in it.
        fail_goal: called when a check fails the current plan's goal (a move that would
            cross the scan's edge as the agent's grid shows it).
    """

    def __init__(self, config: NarutoConfig, guard: ScanGuard, agent_map: AgentMap,
                 fail_goal: Callable[[], None] = _no_goal_failed) -> None:
        self.config = config
        self.guard = guard
        self.agent_map = agent_map
        self._fail_goal = fail_goal
        self._climb: np.ndarray | None = None  # a climb out of an open scan's margin, next

    @property
    def _open_scan_checks(self) -> bool:
        """The scan is known open and the open-scan checks are on
        (``sector_support_after_escape``)."""
        return self.guard.scan_open and self.config.sector_support_after_escape

    # -- move checks -------------------------------------------------------------------------
    def check_move(self, start: np.ndarray, end: np.ndarray) -> bool:
        """Every check of the move from ``start`` to ``end``: the panorama shows the way
        clear, and on an open scan (``sector_support_after_escape``) the move stays below the
        top, keeps to the scan on the panorama and stays in the scan on the agent's grid."""
        if not self.panorama_shows_way_clear(start, end):
            return False
        if self._open_scan_checks:
            return (self.stays_below_top(start, end) and self.panorama_keeps_to_scan(start, end)
                    and self.stays_in_scan(start, end))
        return True

    def panorama_shows_way_clear(self, start: np.ndarray, end: np.ndarray) -> bool:
        """The move read on the panorama taken where it starts (:meth:`ScanGuard.
        hold_for_surface <naruto_agent.guards.ScanGuard.hold_for_surface>`): a move held for
        a surface in its way is not sent and the surface point is blocked in the map (the
        goal stays)."""
        contact = self.guard.hold_for_surface(self.guard.panorama_at(start), end - start,
                                              spot=start)
        if contact is None:
            return True
        self.agent_map.block(start + contact)
        return False

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
        top = self.agent_map.observed_space.scan_top_z() - self.guard.agent_radius_m
        if end[2] <= min(top, blocked.ceiling_z):
            return True
        if top < blocked.ceiling_z:
            self.agent_map.lower_ceiling(max(top, float(start[2])))
        return False

    def panorama_keeps_to_scan(self, start: np.ndarray, end: np.ndarray) -> bool:
        """On an open scan, the env's cone test read from the panorama where the move starts
        (``guard.panorama_edge_probe``; :meth:`ScanGuard.leaves_scan
        <naruto_agent.guards.ScanGuard.leaves_scan>`).

        A move that leaves the scanned space there is held and the space past it blocked
        (a guess: the goal stays). After ``max_held_moves`` holds in a row at one spot the
        agent climbs out of the margin instead (:meth:`take_climb`), or, when it cannot,
        the move passes and the env decides.
        """
        panorama = self.guard.panorama_at(start)
        if (panorama is None or not self.guard.config.panorama_edge_probe
                or not self.guard.leaves_scan(panorama, end - start)):
            return True
        if not self.guard.holds.hold(start):
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
        surfaces (:meth:`ScanGuard.clear_part <naruto_agent.guards.ScanGuard.clear_part>`);
        None when less than :data:`MIN_CLIMB_M` is left."""
        height = self.config.margin_climb_m
        if height <= 0:
            return None
        top = min(self.agent_map.observed_space.scan_top_z() - self.config.scan_top_margin_m,
                  self.agent_map.blocked.ceiling_z)
        rise = min(height, top - float(start[2]))
        if rise < MIN_CLIMB_M:
            return None
        part = self.guard.clear_part(panorama, np.array([0.0, 0.0, rise]))
        if part is None or part[2] < MIN_CLIMB_M:
            return None
        rise = float(part[2])  # cut short below a surface (a slide sideways is not a climb)
        steps = max(1, math.ceil(rise / self.config.planner.step_m - 1e-9))
        heights = np.arange(0, steps + 1) / steps * rise
        return start + heights[:, None] * np.array([0.0, 0.0, 1.0])

    def stays_in_scan(self, start: np.ndarray, end: np.ndarray) -> bool:
        """On an open scan, the edge probe on the agent's grid (:meth:`ScanGuard.
        map_leaves_scan <naruto_agent.guards.ScanGuard.map_leaves_scan>`).

        A path may cross a floor hole's edge or a wall's opening where the goal search's test
        never looked: a move that heads over the edge of the measured floor is refused, the
        space past it blocked so that the next plan goes elsewhere, and the plan's goal
        failed.
        """
        if self.guard.map_leaves_scan(self.agent_map.observed_space.grid, start, end):
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
        support cone (:meth:`ScanGuard.inside_scan
        <naruto_agent.guards.ScanGuard.inside_scan>`)."""
        observed = self.agent_map.observed_space
        top = max(observed.scan_top_z() - self.config.scan_top_margin_m, float(position[2]))
        inside = observed.sample(observed.supported(), points) & (points[:, 2] <= top)
        if self._open_scan_checks:
            inside = self.guard.inside_scan(observed.grid, points, where=inside)
        return inside

    def refused_climb(self, position: np.ndarray, target: np.ndarray) -> bool:
        """Whether an escape refusal of the move to ``target`` came at the scan's open top
        rather than at its side (:func:`~naruto_agent.guards.refused_moves.refused_at_top`,
        with "all around below" judged by the env's cone test on the agent's own grid)."""
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
        if climb is not None and np.linalg.norm(climb[0] - position) <= SAME_SPOT_M:
            return climb
        return None
