"""Settings of the baseline policies, one dataclass per policy, and how keywords fill them.

Every policy takes its settings as one config (``FrontierPolicy(config=FrontierConfig(...))``)
or as keyword arguments named after the config's fields (``FrontierPolicy(voxel_size_m=0.2)``),
which is what ``--policy-kwargs`` of the demo and the benchmark harness pass. The shared
open-scan guard's settings (:class:`~naruto_agent.guards.ScanGuardConfig`) sit in the
config's ``guard`` section and are given by name as well (``FrontierPolicy(max_held_moves=5)``),
or as ``guard={...}``.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any, TypeVar

from naruto_agent.guards.scan_guard import ScanGuardConfig
from naruto_gym.utils.checks import check_integer, check_number

ConfigT = TypeVar("ConfigT")

#: Keywords renamed when the policies came to share one guard: old name -> new name. The old
#: names are refused with an error that names the new one (no aliases before 1.0).
RENAMED_SETTINGS: dict[str, str] = {
    "panorama_move_check": "panorama_check",  # FrontierPolicy
    "check_moves_on_panorama": "panorama_check",  # NarutoConfig's name of the same switch
    "max_held_steps": "max_held_moves",  # RandomPolicy
}

GUARD_FIELDS: frozenset[str] = frozenset(item.name for item in fields(ScanGuardConfig))
"""The fields of :class:`~naruto_agent.guards.ScanGuardConfig`: a config with a ``guard``
section also takes them by name."""


def _frontier_guard() -> ScanGuardConfig:
    return ScanGuardConfig(margin_start_passes=True, release_held_until_moved=True)


def _random_guard() -> ScanGuardConfig:
    return ScanGuardConfig(panorama_top_check=True, scan_edge_margin_m=0.05,
                           full_floor_polar_deg=70.0, open_sky_share=None)


@dataclass
class FrontierConfig:
    """Settings of :class:`~naruto_agent.policies.FrontierPolicy` (see docs/policies.md).

    Attributes:
        voxel_size_m: occupancy voxel size.
        pixel_stride: integrate every n-th depth pixel in each direction.
        max_range_m: depth range integrated into the map.
        min_cluster_voxels: smallest frontier cluster worth a visit.
        inflation_voxels: keep paths this many voxels away from occupied voxels.
        height_margin_m: paths stay this far inside the bounds' floor and ceiling.
        goal_radius_voxels: a goal lies within this many voxels of its frontier cluster.
        visited_radius_m: frontier voxels this close to a visited goal are ignored.
        min_goal_distance_m: goals closer than this (path length) are taken only when no
            farther one is left: the frontier right around the agent is mostly what a camera
            with a limited field of view has not looked at yet (straight up or down), which
            a look-around there would not fix.
        look_around_headings: headings of the full turn (at the start, and when done).
        look_pitches_deg: pitches the full turn cycles through.
        look_focus_sweep_deg: at a goal, the look-around views the frontier cluster and the
            headings this far to either side of it.
        max_focus_pitch_deg: the largest pitch used to look at a frontier cluster.
        replan_every: while moving, check the goal every this many steps.
        lookahead_voxels: how far along the path a shortcut may reach.
        scanned_space_support: once the scan is known open, keep the frontier, goals and
            (where it can) paths where the env's scanned-space test passes on the policy's
            own map: frontier past a missing wall or over an open top can never be resolved
            from inside, and chasing it pulls the agent to the scan's edge again and again.
        support_on_closed_scans: hold to that test on closed scans too, until no frontier
            it keeps is left: it keeps the agent from the many small clusters around
            furniture low in a room, and explores closed and open scans of one building
            alike.
        edge_arrival_m: a move the guard's edge probe refuses within this path length of
            the goal counts as arriving there (the look-around from there sees the goal's
            cluster nearly as well) instead of giving the goal up.
        scan_top_quantile: with ``scanned_space_support``, paths stay ``scan_top_margin_m``
            below the height under which this share of the occupied voxels lies.
        scan_top_margin_m: see ``scan_top_quantile``.
        support_below_m: with ``scanned_space_support``, while no frontier passes the full
            test, a frontier voxel counts with measured surface below it, at most this far
            down ...
        support_reach_m: ... and this far sideways.
        guard: the open-scan guard (surface, top and edge readings, held moves); frontier
            lets a move from the scan's margin through and, once ``max_held_moves`` were
            held at one spot, every move until the agent moves.
        stall_watchdog: watch the walk for stalls (:mod:`naruto_agent.policies.watchdog`) and
            recover from them.
    """

    voxel_size_m: float = 0.1
    pixel_stride: int = 4
    max_range_m: float = 5.0
    min_cluster_voxels: int = 8
    inflation_voxels: int = 1
    height_margin_m: float = 0.3
    goal_radius_voxels: float = 4.0
    visited_radius_m: float = 0.8
    min_goal_distance_m: float = 1.0
    look_around_headings: int = 6
    look_pitches_deg: tuple[float, ...] = (-25.0, 20.0)
    look_focus_sweep_deg: float = 60.0
    max_focus_pitch_deg: float = 60.0
    replan_every: int = 10
    lookahead_voxels: int = 10
    scanned_space_support: bool = True
    support_on_closed_scans: bool = True
    edge_arrival_m: float = 0.5
    scan_top_quantile: float = 0.99
    scan_top_margin_m: float = 0.0
    support_below_m: float = 3.0
    support_reach_m: float = 0.3
    guard: ScanGuardConfig = field(default_factory=_frontier_guard)
    stall_watchdog: bool = True

    def __post_init__(self) -> None:
        check_integer("look_around_headings", self.look_around_headings, low=1)
        if not self.look_pitches_deg:
            raise ValueError("look_pitches_deg needs at least one pitch")


@dataclass
class RandomConfig:
    """Settings of :class:`~naruto_agent.policies.RandomPolicy`.

    Attributes:
        seed: seed of the policy's generator (``reset(seed=...)`` overrides it).
        min_run_steps: a run lasts a uniform number of steps from this ...
        max_run_steps: ... to this.
        max_climb: largest vertical component of a run's (unit) direction.
        max_pitch_deg: the camera's pitch is drawn uniformly within +-this per run.
        sweep_yaw_deg: while walking, the camera swings this far to either side of the
            run's heading (0: it looks straight ahead) ...
        sweep_period_steps: ... once every this many steps (16 at 45 degrees: at most
            18 degrees a step, inside the env's turn limit).
        height_margin_m: runs turn back vertically within this distance of the bounds'
            floor and ceiling.
        avoid_blocked_deg: a new direction after a block is at least this far from the
            blocked one.
        max_redraws: new runs drawn at one step while the guard shows the way blocked,
            before the walk sweeps the headings around it.
        sweep_headings: the sweep looks at this many headings (level, then climbing and
            sinking) for a clear way before the walk holds (0: no sweep).
        guard: the open-scan guard; the walk also reads the open top from the panorama,
            probes the edge at a second, wider radius, and holds (turns in place) for
            ``max_held_moves`` steps before it sends the clear part of the move.
        stall_watchdog: watch the walk for stalls (:mod:`naruto_agent.policies.watchdog`) and
            recover from them.
    """

    seed: int | None = None
    min_run_steps: int = 5
    max_run_steps: int = 40
    max_climb: float = 0.3
    max_pitch_deg: float = 30.0
    sweep_yaw_deg: float = 45.0
    sweep_period_steps: int = 16
    height_margin_m: float = 0.3
    avoid_blocked_deg: float = 60.0
    max_redraws: int = 8
    sweep_headings: int = 16
    guard: ScanGuardConfig = field(default_factory=_random_guard)
    stall_watchdog: bool = True

    def __post_init__(self) -> None:
        check_integer("min_run_steps", self.min_run_steps, low=1)
        if self.min_run_steps > self.max_run_steps:
            raise ValueError(
                f"need 1 <= min_run_steps <= max_run_steps, got {self.min_run_steps}, "
                f"{self.max_run_steps}"
            )
        check_number("sweep_yaw_deg", self.sweep_yaw_deg, low=0.0, low_open=False, high=90.0)
        check_integer("sweep_period_steps", self.sweep_period_steps, low=2)


@dataclass
class PassiveConfig:
    """Settings of :class:`~naruto_agent.policies.PassivePolicy`.

    Attributes:
        fit_to_budget: subsample a longer trajectory uniformly to the episode's step budget.
        position_tolerance_m: a replayed pose counts as reached within this distance ...
        rotation_tolerance_deg: ... and this rotation.
        max_blocked_steps: skip a replayed pose after this many steps without progress.
        scan_height_fraction: scripted scan height as a fraction of the bounds' height.
        wall_distance_m: distance kept to the wall on the right.
        front_clearance_m: turn left when a wall is this close ahead.
        lost_wall_m: the wall counts as lost (turn right, around a corner or into a doorway)
            when nothing is this close on the right.
        sweep_yaw_deg: the camera's heading sweeps between this far right of the walking
            direction (the wall) and 150 degrees further left (ahead and across the room).
        sweep_pitch_deg: amplitude of the camera's up/down sweep.
        sweep_period_steps: period of the sideways sweep (the pitch sweep uses 1.6 times it).
        loop_min_steps: a loop of the wall follower is closed when the agent comes back
            within ``loop_close_m`` of where it was at least this many steps ago ...
        loop_close_m: ... (see ``loop_min_steps``);
        loop_min_gain: when a closed loop added less coverage than this (a share, 0..1),
            the follower leaves that wall across the room to find another one (an island of
            furniture, or a room it would otherwise circle forever).
        stall_watchdog: watch the walk for stalls (:mod:`naruto_agent.policies.watchdog`) and
            recover from them (on: the wall follower's own rules miss spinning in place).
    """

    fit_to_budget: bool = True
    position_tolerance_m: float = 1e-3
    rotation_tolerance_deg: float = 0.5
    max_blocked_steps: int = 3
    scan_height_fraction: float = 0.45
    wall_distance_m: float = 0.6
    front_clearance_m: float = 0.5
    lost_wall_m: float = 1.2
    sweep_yaw_deg: float = 100.0
    sweep_pitch_deg: float = 30.0
    sweep_period_steps: int = 50
    loop_min_steps: int = 80
    loop_close_m: float = 0.3
    loop_min_gain: float = 0.02
    stall_watchdog: bool = True

    def __post_init__(self) -> None:
        check_number(
            "scan_height_fraction", self.scan_height_fraction, low=0.0, high=1.0, high_open=True
        )
        check_number("front_clearance_m", self.front_clearance_m, low=0.0)
        if self.wall_distance_m >= self.lost_wall_m:
            raise ValueError(
                f"wall_distance_m must be less than lost_wall_m, got {self.wall_distance_m} "
                f"and {self.lost_wall_m}"
            )


def build_config(
    config_type: type[ConfigT], config: ConfigT | None = None, **settings: Any
) -> ConfigT:
    """A policy's config: ``config`` (default ``config_type()``) with keyword overrides.

    Fields of ``config_type`` are given by name; so are the fields of its ``guard`` section
    (:class:`~naruto_agent.guards.ScanGuardConfig`), which may also come whole as
    ``guard=`` (a dict of its fields or a ``ScanGuardConfig``). The result is a new
    object: the policy owns it.

    Raises:
        TypeError: a keyword that names no setting (as a constructor would), or an old name
            of :data:`RENAMED_SETTINGS` (the message names the new one).
    """
    refuse_renamed_settings(settings)
    base = config if config is not None else config_type()
    own = {item.name for item in fields(config_type)}  # type: ignore[arg-type]
    has_guard = "guard" in own
    guard_updates = pop_guard_settings(settings, own) if has_guard else {}
    unknown = sorted(set(settings) - own)
    if unknown:
        known = sorted(own | (GUARD_FIELDS if has_guard else set()))
        raise TypeError(f"{config_type.__name__} has no setting {unknown}; known: {known}")
    if has_guard:
        guard = settings.pop("guard", base.guard)  # type: ignore[attr-defined]
        settings["guard"] = guard_section(base.guard, guard,  # type: ignore[attr-defined]
                                          guard_updates)
    return replace(base, **settings)  # type: ignore[type-var]


def refuse_renamed_settings(settings: Mapping[str, Any]) -> None:
    """Refuse the old names of :data:`RENAMED_SETTINGS` among ``settings``.

    Raises:
        TypeError: an old name was given; the message names the setting to use instead.
    """
    for old, new in RENAMED_SETTINGS.items():
        if old in settings:
            raise TypeError(f"the policy setting {old!r} is now called {new!r}: pass "
                            f"{new}={settings[old]!r} instead")


def pop_guard_settings(settings: dict[str, Any], own: Collection[str]) -> dict[str, Any]:
    """Take the keywords that name a field of the guard section (:data:`GUARD_FIELDS`) and
    no field of the config itself (``own``) out of ``settings``, and return them."""
    return {name: settings.pop(name) for name in list(settings)
            if name in GUARD_FIELDS and name not in own}


def guard_section(
    base: ScanGuardConfig, guard: ScanGuardConfig | Mapping[str, Any], updates: Mapping[str, Any]
) -> ScanGuardConfig:
    """A config's guard section: ``guard`` (a ``ScanGuardConfig``, or a dict of fields that
    override ``base``) with the fields of ``updates`` on top.

    Raises:
        TypeError: ``guard`` is neither, or a dict or ``updates`` names no guard field.
    """
    if isinstance(guard, Mapping):
        guard = replace(base, **guard)
    if not isinstance(guard, ScanGuardConfig):
        raise TypeError(f"guard must be a ScanGuardConfig or a dict of its fields, got "
                        f"{type(guard).__name__}")
    return replace(guard, **updates)
