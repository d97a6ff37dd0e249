"""The open-scan guard: what a policy reads about a move before it sends it.

A policy knows a scan only from its observations. The 0.1 m maps it builds from depth miss
thin or small surfaces by a few centimetres (a table's edge, a chair's leg) and blur the
scan's edge by up to a voxel, and on an open scan (no ceiling, a missing wall, a floor hole)
the env refuses a move that would leave the scanned space where nothing in the map marks the
place. The guard reads the move's way from the depth panorama taken where the agent stands,
as a robot reads its range sensor, and tells the policy to hold the move back when

* the agent's sphere would touch a surface the panorama shows (``panorama_check``);
* the move climbs above the surfaces the panorama shows (``panorama_top_check``: the open top
  of a scan without a ceiling);
* the move leaves the scanned space as the env judges it (``panorama_edge_probe`` on the
  panorama; ``edge_probe_m`` on the policy's own map).

A reading can be wrong (a coarse panorama, a start in the scan's margin), so after
``max_held_moves`` moves held back in a row at one spot the next one goes through and the env
decides: the agent never stays put for good. The guard also keeps whether the scan is known
to be open: from an escape refusal, or from a depth frame that sees the sky
(``open_sky_share``). What a held move means (mark the surface in the map, plan again, draw a
new run) is the policy's to decide.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from naruto_agent.guards.panorama_clearance import (
    clear_part_of_move,
    first_contact,
    floor_edge_profile,
    move_leaves_scan,
    steep_miss_share,
    surface_top,
)
from naruto_agent.mapping.occupancy import OccupancyGrid
from naruto_gym.sensors.pinhole import PinholeCamera
from naruto_gym.utils.checks import check_integer, check_number

#: Holds this close together (metres) count as held at one spot.
SAME_SPOT_M = 1e-3


@dataclass
class ScanGuardConfig:
    """Settings of the :class:`ScanGuard`.

    Attributes:
        panorama_check: read each move's way from the depth panorama (when the observation
            has one) before it is sent; False turns every panorama reading of the guard off.
        panorama_margin_m: the surface reading keeps the env's agent radius plus this.
        panorama_edge_probe: with ``panorama_check``, also hold a move the panorama shows
            leaving the scanned space (:func:`~naruto_agent.guards.panorama_clearance.
            move_leaves_scan`: the env's cone test on the panorama's surface points, which
            places the floor's edge to within a few centimetres where a 0.1 m grid blurs it).
        panorama_top_check: with ``panorama_check``, also hold a climb that would end above
            the height under which most of the surface the panorama shows lies
            (:func:`~naruto_agent.guards.panorama_clearance.surface_top`): indoors a ceiling,
            without one the wall tops, above which the env refuses a climb.
        scan_edge_margin_m: probe the scan's edge at the agent radius and again at the radius
            plus this (None: at the radius only). The wider probe sees an edge a pixel off,
            at the price of a wider berth, which suits a policy with no goal to reach.
        margin_start_passes: a move that starts in the scan's margin (the cube around the
            agent not wholly over scanned surface) is never held for leaving it: the env
            decides. For a policy that gives its goal up whenever a move is held, holding
            every move in the margin (low over a floor hole) can leave no goal in reach.
        full_floor_polar_deg: where the panorama shows scanned surface all around below, out
            to this angle from straight down, no move of a step can leave the scan, and the
            edge probe (tens of milliseconds) is skipped; None: always probe.
        edge_probe_m: on the policy's own map, a move from a point that passes the env's
            test towards one this far beyond its end (horizontally) that fails it heads over
            the edge (:meth:`OccupancyGrid.move_leaves_support`).
        max_held_moves: after this many moves held back in a row at one spot, the next one
            is let through and the env decides.
        release_held_until_moved: once ``max_held_moves`` were held, every move is let
            through until the agent moves (:meth:`ScanGuard.moved`); False: one move is let
            through and the count starts again.
        open_sky_share: the scan counts as open once this share of a depth frame's pixels
            that look at least 35 degrees up or down hit nothing (indoors such a ray meets a
            ceiling or a floor within the sensor's range); None: only an escape refusal
            tells.
    """

    panorama_check: bool = True
    panorama_margin_m: float = 0.01
    panorama_edge_probe: bool = True
    panorama_top_check: bool = False
    scan_edge_margin_m: float | None = None
    margin_start_passes: bool = False
    full_floor_polar_deg: float | None = None
    edge_probe_m: float = 0.15
    max_held_moves: int = 3
    release_held_until_moved: bool = False
    open_sky_share: float | None = 0.05

    def __post_init__(self) -> None:
        for name in ("panorama_margin_m", "edge_probe_m"):
            check_number(name, getattr(self, name), low=0.0, low_open=False)
        check_integer("max_held_moves", self.max_held_moves, low=0)
        if self.scan_edge_margin_m is not None:
            check_number("scan_edge_margin_m (or None)", self.scan_edge_margin_m, low=0.0,
                         low_open=False)
        if self.open_sky_share is not None:
            check_number("open_sky_share (or None)", self.open_sky_share, low=0.0, high=1.0)


class HeldMoves:
    """Moves held back in a row at one spot, and when the next one is let through.

    Args:
        limit: moves held in a row before the next one is let through.
    """

    def __init__(self, limit: int) -> None:
        self.limit = limit
        #: Moves held in a row so far.
        self.count = 0
        #: Where the last one was held (when the caller tells).
        self.spot: np.ndarray | None = None

    @property
    def exhausted(self) -> bool:
        """``limit`` moves were held in a row: the next one is let through."""
        return self.count >= self.limit

    def hold(self, spot: np.ndarray | None = None) -> bool:
        """Count one more held move; False when ``limit`` were held in a row already (the
        move is let through, and the count starts again).

        Args:
            spot: where the agent stands; a hold at another spot starts the count again.
                None: the caller resets the count itself (:meth:`reset`).
        """
        if spot is not None:
            spot = np.array(spot, np.float64)
            if self.spot is None or np.linalg.norm(spot - self.spot) > SAME_SPOT_M:
                self.count = 0
            self.spot = spot
        if self.count >= self.limit:
            self.count = 0
            return False
        self.count += 1
        return True

    def reset(self) -> None:
        """No move held."""
        self.count = 0
        self.spot = None


class ScanGuard:
    """Reads moves off the depth panorama and the policy's map before they are sent.

    Args:
        config: the guard's settings.
        agent_radius_m: radius of the agent's collision sphere (the env's; policies set it
            from :class:`~naruto_agent.policies.EnvContext` when they are bound).

    Attributes:
        scan_open: the scan is known to be open (an escape refusal, or the sky seen).
        holds: moves held for a surface in the way (a policy with one count for every
            reading uses this one for all).
        edge_holds: moves held for leaving the scan.
    """

    def __init__(self, config: ScanGuardConfig | None = None, agent_radius_m: float = 0.05) -> None:
        self.config = config if config is not None else ScanGuardConfig()
        self.agent_radius_m = agent_radius_m
        self.scan_open = False
        self.holds = HeldMoves(self.config.max_held_moves)
        self.edge_holds = HeldMoves(self.config.max_held_moves)
        self._panorama: tuple[np.ndarray, np.ndarray] | None = None  # (panorama, where)

    # -- state ----------------------------------------------------------------------------
    def reset(self) -> None:
        """Start an episode: the scan is not known open, no move held (the hold limits are
        read from the config again), no panorama kept."""
        self.scan_open = False
        self._panorama = None
        for holds in (self.holds, self.edge_holds):
            holds.reset()
            holds.limit = self.config.max_held_moves

    def moved(self) -> None:
        """The agent moved: the hold counts start again."""
        self.holds.reset()
        self.edge_holds.reset()

    def note_escape(self) -> None:
        """The env refused a move for leaving the scanned space: the scan is open."""
        self.scan_open = True

    def observe_depth(self, depth: np.ndarray, pose: np.ndarray, camera: PinholeCamera) -> bool:
        """Note a depth frame (``open_sky_share``); returns :attr:`scan_open`."""
        if not self.scan_open and self.config.open_sky_share is not None:
            self.scan_open = steep_miss_share(depth, pose, camera) >= self.config.open_sky_share
        return self.scan_open

    def panorama(self, observation: dict[str, np.ndarray]) -> np.ndarray | None:
        """The observation's depth panorama when the guard reads it (``panorama_check``)."""
        return observation.get("panorama") if self.config.panorama_check else None

    def observe_panorama(self, panorama: np.ndarray | None, spot: np.ndarray) -> None:
        """Keep the newest depth panorama (None: the observation has none) and the spot it
        was taken at, for a policy that checks moves later in its step (:meth:`panorama_at`).
        """
        self._panorama = (None if panorama is None
                          else (np.asarray(panorama), np.asarray(spot, np.float64).copy()))

    def panorama_at(self, spot: np.ndarray) -> np.ndarray | None:
        """The kept panorama (:meth:`observe_panorama`) when it was taken at ``spot`` (within
        :data:`SAME_SPOT_M`) and the guard reads panoramas (``panorama_check``); None
        otherwise: a panorama says nothing about a move that starts elsewhere."""
        if not self.config.panorama_check or self._panorama is None:
            return None
        panorama, taken_at = self._panorama
        return panorama if np.linalg.norm(spot - taken_at) <= SAME_SPOT_M else None

    @property
    def clearance_m(self) -> float:
        """The clearance the surface reading keeps: agent radius plus ``panorama_margin_m``."""
        return self.agent_radius_m + self.config.panorama_margin_m

    # -- readings (pure) ------------------------------------------------------------------
    def surface_contact(self, panorama: np.ndarray, move: np.ndarray) -> np.ndarray | None:
        """The surface point (relative to the agent) the panorama shows in the move's way,
        or None (:func:`~naruto_agent.guards.panorama_clearance.first_contact`)."""
        return first_contact(panorama, move, self.clearance_m)

    def climbs_above_top(self, panorama: np.ndarray, move: np.ndarray) -> bool:
        """The move climbs above the height under which most of the surface the panorama
        shows lies (``panorama_top_check``)."""
        return bool(move[2] > 0.0 and move[2] > surface_top(panorama))

    def leaves_scan(self, panorama: np.ndarray, move: np.ndarray) -> bool:
        """The panorama shows the move leaving the scanned space as the env judges it, probed
        at the agent radius (and at the radius plus ``scan_edge_margin_m``)."""
        config = self.config
        if config.full_floor_polar_deg is not None and not np.isfinite(
            floor_edge_profile(panorama, max_polar_deg=config.full_floor_polar_deg)
        ).any():
            return False
        radius = self.agent_radius_m
        probes = [radius]
        if config.scan_edge_margin_m is not None:
            probes.append(radius + config.scan_edge_margin_m)
        return any(move_leaves_scan(panorama, move, probe,
                                    margin_start_passes=config.margin_start_passes)
                   for probe in probes)

    def way_blocked(self, panorama: np.ndarray, move: np.ndarray) -> bool:
        """The panorama shows the move touching a surface, climbing above the surfaces'
        top (``panorama_top_check``) or leaving the scan (``panorama_edge_probe``); False
        without ``panorama_check``."""
        config = self.config
        if not config.panorama_check:
            return False
        if self.surface_contact(panorama, move) is not None:
            return True
        if config.panorama_top_check and self.climbs_above_top(panorama, move):
            return True
        return config.panorama_edge_probe and self.leaves_scan(panorama, move)

    def clear_part(self, panorama: np.ndarray, move: np.ndarray) -> np.ndarray | None:
        """The part of a move the panorama shows clear (slid along the surface it would
        touch, or cut short of it; the move itself when clear), or None when no part is
        worth sending (:func:`~naruto_agent.guards.panorama_clearance.clear_part_of_move`)."""
        return clear_part_of_move(panorama, move, self.clearance_m)

    def map_leaves_scan(self, grid: OccupancyGrid, start: np.ndarray, end: np.ndarray) -> bool:
        """On the policy's own map, the move heads over the edge of the measured floor
        (``edge_probe_m``)."""
        return grid.move_leaves_support(start, end, self.config.edge_probe_m)

    def inside_scan(
        self,
        grid: OccupancyGrid,
        points: np.ndarray,
        z_band: tuple[float, float] | None = None,
        where: np.ndarray | None = None,
    ) -> np.ndarray:
        """(N,) bool: the env's scanned-space test read on the policy's own map.

        A point passes when it lies within ``z_band`` (min, max metres, when given), is
        marked in ``where`` (when given), and the policy has measured surface in every sector
        of the env's downward support cone from it (:meth:`OccupancyGrid.sectors_seen_below`).
        """
        points = np.asarray(points, np.float64).reshape(-1, 3)
        inside = np.ones(len(points), bool) if where is None else np.array(where, bool)
        if z_band is not None:
            inside &= (points[:, 2] >= z_band[0]) & (points[:, 2] <= z_band[1])
        index = np.flatnonzero(inside)
        inside[index] = grid.sectors_seen_below(points[index])
        return inside

    # -- held readings --------------------------------------------------------------------
    def hold_for_surface(
        self, panorama: np.ndarray | None, move: np.ndarray, spot: np.ndarray | None = None
    ) -> np.ndarray | None:
        """The surface point (relative to the agent) in the move's way when the move is
        held back for it; None when it goes: the way is clear, there is no panorama
        reading, or ``max_held_moves`` were held in a row (the env decides).

        Args:
            panorama: the depth panorama taken where the agent stands, or None.
            move: (3,) the move's displacement.
            spot: where the agent stands (see :meth:`HeldMoves.hold`).
        """
        if not self.config.panorama_check or panorama is None or self._releasing(self.holds):
            return None
        contact = self.surface_contact(panorama, move)
        if contact is None or not self.holds.hold(spot):
            return None
        return contact

    def hold_for_edge(
        self, panorama: np.ndarray | None, move: np.ndarray, spot: np.ndarray | None = None
    ) -> bool:
        """Whether the move is held back for leaving the scan as the panorama shows it
        (``panorama_edge_probe``), counted in :attr:`edge_holds`; arguments as
        :meth:`hold_for_surface`."""
        config = self.config
        if (not (config.panorama_check and config.panorama_edge_probe) or panorama is None
                or self._releasing(self.edge_holds)):
            return False
        return self.leaves_scan(panorama, move) and self.edge_holds.hold(spot)

    def surface_holds_spent(self, panorama: np.ndarray | None) -> bool:
        """The surface reading held ``max_held_moves`` moves at this spot and lets the next
        through (with ``release_held_until_moved``, until the agent moves)."""
        return self.config.panorama_check and panorama is not None and self.holds.exhausted

    def _releasing(self, holds: HeldMoves) -> bool:
        return self.config.release_held_until_moved and holds.exhausted
