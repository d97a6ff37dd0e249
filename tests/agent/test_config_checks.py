"""The agent's configurations are checked with the helpers the env uses
(:mod:`naruto_gym.utils.checks`): a wrong type, a NaN or a value out of range is one
``ValueError`` naming the setting."""

from __future__ import annotations

import pytest

from naruto_agent.guards.scan_guard import ScanGuardConfig
from naruto_agent.mapping.config import NeuralMapperConfig
from naruto_agent.naruto.config import NarutoConfig
from naruto_agent.naruto.goal_search import GoalSearchConfig
from naruto_agent.naruto.recovery import RecoveryConfig
from naruto_agent.policies.config import FrontierConfig, PassiveConfig, RandomConfig

CASES = [
    (FrontierConfig, "look_around_headings", 0),
    (FrontierConfig, "look_around_headings", 2.5),
    (RandomConfig, "min_run_steps", 0),
    (PassiveConfig, "scan_height_fraction", 1.0),
    (PassiveConfig, "front_clearance_m", float("nan")),
    (NarutoConfig, "planner_voxel_m", 0.0),
    (NarutoConfig, "goal_attempts", True),
    (NarutoConfig, "max_rotation_step_deg", 181.0),
    (NarutoConfig, "margin_climb_m", -0.1),
    (NarutoConfig, "unresolved_visit_looks", float("inf")),
    (NeuralMapperConfig, "hidden_dim", 0),
    (NeuralMapperConfig, "keyframe_pixel_fraction", 1.5),
    (NeuralMapperConfig, "near_m", -1.0),
    (NeuralMapperConfig, "active_top_rays", 5000),
    (NeuralMapperConfig, "active_score", "loudest"),
    (NeuralMapperConfig, "learning_rate", "fast"),
    (GoalSearchConfig, "GoalSearchConfig.top_k", 0),
    (GoalSearchConfig, "GoalSearchConfig.min_range_m", 99.0),
    (GoalSearchConfig, "GoalSearchConfig.explore_first_share", 1.5),
    (RecoveryConfig, "RecoveryConfig.window", 1),
    (RecoveryConfig, "RecoveryConfig.retreat_m", 0.0),
    (ScanGuardConfig, "max_held_moves", -1),
    (ScanGuardConfig, "open_sky_share", 0.0),
]


@pytest.mark.parametrize(("config", "name", "value"), CASES)
def test_a_bad_setting_is_refused_by_name(config, name, value):
    field = name.rpartition(".")[2]
    with pytest.raises(ValueError, match=rf"^{name}( \(or None\))? must be"):
        config(**{field: value})


def test_relations_between_settings_name_both():
    with pytest.raises(ValueError, match="min_run_steps.*max_run_steps"):
        RandomConfig(min_run_steps=9, max_run_steps=3)
    with pytest.raises(ValueError, match="wall_distance_m must be less than lost_wall_m"):
        PassiveConfig(wall_distance_m=2.0, lost_wall_m=1.0)
    with pytest.raises(ValueError, match="far_m must be greater than"):
        NeuralMapperConfig(near_m=2.0, far_m=1.0)


@pytest.mark.parametrize(
    "config",
    [
        FrontierConfig,
        RandomConfig,
        PassiveConfig,
        NarutoConfig,
        NeuralMapperConfig,
        GoalSearchConfig,
        RecoveryConfig,
        ScanGuardConfig,
    ],
)
def test_the_defaults_pass(config):
    config()
