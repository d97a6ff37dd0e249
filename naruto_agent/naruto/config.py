"""The NARUTO agent's settings (:class:`NarutoConfig`) and their keyword overrides.

Every setting, its default and the reason for it are explained in ``docs/agent-config.md``.
The open-scan guard's settings are the ``guard`` section, the
:class:`~naruto_agent.guards.ScanGuardConfig` that the frontier and random policies take too,
filled from keywords as theirs are (:func:`~naruto_agent.policies.config.build_config`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Any

from naruto_agent.guards import ScanGuardConfig
from naruto_agent.mapping import NeuralMapperConfig, TsdfMapperConfig
from naruto_agent.naruto.goal_search import GoalSearchConfig
from naruto_agent.naruto.recovery import RecoveryConfig
from naruto_agent.planning import PlannerConfig
from naruto_agent.policies.config import pop_guard_settings, refuse_renamed_settings
from naruto_gym.utils.checks import check_integer, check_number

#: The shipped mappers, each with its settings section of the same name.
MAPPERS = ("tsdf", "neural")
"""The shipped mappers (``NarutoPolicy(mapper_kind=...)``), each set by the
:class:`NarutoConfig` section of its name; any other registered name or import path is
taken too (:mod:`naruto_agent.mapping.registry`)."""


def _goal_search_defaults() -> GoalSearchConfig:
    return GoalSearchConfig(goal_spacing_z_m=0.5, distance_discount_m=3.0,
                            discount_by_travel=True, explore_first_share=0.75)


def _planner_defaults() -> PlannerConfig:
    return PlannerConfig(time_limit_s=2.0)


@dataclass
class NarutoConfig:
    """Settings of the NARUTO agent (Feng et al., NARUTO, CVPR 2024).

    Defaults follow the published system except where ``docs/agent-config.md`` gives the
    reason for another value; every choice beyond the paper can be switched off.
    """

    planner_voxel_m: float = 0.1
    """voxel size of the planner's SDF and uncertainty volumes, metres"""
    view_every_mapping_steps: int = 1
    """read the planner view after every n-th mapping step"""
    lazy_planner_view: bool = True
    """read the planner view only when planning or a move check needs it"""
    max_rotation_step_deg: float = 20.0
    """largest turn per frame, degrees (published: 10)"""
    skip_views_in_image: bool = True
    """at a goal, skip views whose target is already in the image"""
    goal_attempts: int = 3
    """best goals tried in turn with E-RRT before staying (published: 1)"""
    shortcut_paths: bool = True
    """replace the E-RRT path's zigzag by the straight free segments it allows"""
    shortcut_margin_m: float = 0.0
    """clearance a shortcut segment keeps on top of the planner's, metres"""
    reachable_iterations: int = 2000
    """extensions of the goal search's fallback tree (and of the wander recovery's)"""
    check_moves_on_map: bool = True
    """check every move against the agent's newest map (and with ``guard``) before sending it"""
    margin_climb_m: float = 0.3
    """height of a climb out of an open scan's margin when the holds run out (0: off)"""
    escape_radius_m: float = 0.3
    """how far to look for free space when the map puts the agent in a clearance (0: off)"""
    arrival_tolerance_m: float = 0.01
    """a moving agent farther than this from its commanded node was stopped by the env"""
    use_panorama: bool = True
    """integrate the env's depth panorama into the map's measure of explored space"""
    panorama_every: int = 5
    """integrate the panorama every n-th frame"""
    goals_in_observed_space: bool = True
    """candidate goals must lie in space the frames measured free"""
    stay_in_scanned_space: bool = True
    """candidate goals and frontier targets must lie over measured surface, below its top"""
    scan_top_margin_m: float = 0.3
    """candidate goals lie at least this far below the measured surfaces' top, metres"""
    sector_support_after_escape: bool = True
    """once the scan is known open, goals and moves must pass the env's support-cone test"""
    unresolved_visit_looks: float = 4.0
    """looks a reached goal adds to every target it was chosen for (0: off)"""
    initial_look_around: bool = True
    """the first plan of an episode is a turn in place that looks all around"""
    seed: int = 0
    """seed of the agent's randomness when ``reset`` gets none"""
    stall_watchdog: bool = True
    """the stall watchdog (:mod:`naruto_agent.policies.watchdog`; docs/agent-config.md)"""
    guard: ScanGuardConfig = field(default_factory=ScanGuardConfig)
    """the open-scan guard: the panorama check, held moves, the scan's edge, the open sky"""
    recovery: RecoveryConfig = field(default_factory=RecoveryConfig)
    """stall detection and recovery settings"""
    goal_search: GoalSearchConfig = field(default_factory=_goal_search_defaults)
    """goal search settings (published, except height spacing, discount and explore-first)"""
    planner: PlannerConfig = field(default_factory=_planner_defaults)
    """E-RRT settings (time limit 2 s; the seed is redrawn for every request)"""
    tsdf: TsdfMapperConfig = field(default_factory=TsdfMapperConfig)
    """settings of the TSDF mapper (``mapper_kind="tsdf"``)"""
    neural: NeuralMapperConfig = field(default_factory=NeuralMapperConfig)
    """settings of the neural mapper (``mapper_kind="neural"``)"""

    def __post_init__(self) -> None:
        check_number("planner_voxel_m", self.planner_voxel_m, low=0.0)
        for name in ("view_every_mapping_steps", "goal_attempts", "panorama_every"):
            check_integer(name, getattr(self, name), low=1)
        check_number("max_rotation_step_deg", self.max_rotation_step_deg, low=0.0, high=180.0)
        for name in (
            "unresolved_visit_looks",
            "escape_radius_m",
            "arrival_tolerance_m",
            "scan_top_margin_m",
            "shortcut_margin_m",
            "margin_climb_m",
        ):
            check_number(name, getattr(self, name), low=0.0, low_open=False)
        if self.guard.panorama_top_check or self.guard.release_held_until_moved:
            raise ValueError("the agent reads an open scan's top from its own map "
                             "(sector_support_after_escape) and counts held moves per spot: "
                             "guard.panorama_top_check and guard.release_held_until_moved "
                             "must be False")
        self.planner.validate()


#: The settings that are sections of their own, by field name.
SECTIONS: dict[str, type] = {"goal_search": GoalSearchConfig, "planner": PlannerConfig,
                             "recovery": RecoveryConfig, "guard": ScanGuardConfig,
                             "tsdf": TsdfMapperConfig, "neural": NeuralMapperConfig}


def build_config(config: NarutoConfig | None = None, **settings: Any) -> NarutoConfig:
    """A :class:`NarutoConfig` with keyword overrides.

    Top-level fields are given by name (``goal_attempts=1``); a section takes a dict of its
    fields (``goal_search={"top_k": 1}``, ``planner={"time_limit_s": 1.0}``) or an instance.
    The fields of the ``guard`` section are also given by name (``max_held_moves=5``); their
    old names (:data:`~naruto_agent.policies.config.RENAMED_SETTINGS`) are refused with a
    ``TypeError`` naming the new one, as for every policy.
    JSON-able, so benchmark specs can carry them.

    Args:
        config: the settings to start from (the defaults when None).
        **settings: :class:`NarutoConfig` fields to override.

    Returns:
        A new config; ``config`` is left as it was.

    Raises:
        ValueError: for an unknown setting or section field, or an invalid value.
        TypeError: for an old name of a guard setting (the message names the new one).
    """
    refuse_renamed_settings(settings)
    settings = dict(settings)
    config = config or NarutoConfig()
    known = {f.name for f in fields(NarutoConfig)}
    guard_updates = pop_guard_settings(settings, known)
    unknown = set(settings) - known
    if unknown:
        raise ValueError(f"unknown NARUTO settings {sorted(unknown)}; known: {sorted(known)} "
                         f"and the fields of guard")
    updates: dict[str, Any] = {}
    for name, value in settings.items():
        if name in SECTIONS and isinstance(value, dict):
            section = getattr(config, name)
            section_fields = {f.name for f in fields(SECTIONS[name])}
            bad = set(value) - section_fields
            if bad:
                raise ValueError(f"unknown {name} settings {sorted(bad)}; known: "
                                 f"{sorted(section_fields)}")
            value = replace(section, **value)
        updates[name] = value
    if guard_updates:
        updates["guard"] = replace(updates.get("guard", config.guard), **guard_updates)
    return replace(config, **updates)
