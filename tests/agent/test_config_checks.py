"""The agent's configurations are checked with the helpers the env uses
(:mod:`naruto_gym.utils.checks`): a wrong type, a NaN or a value out of range is one
``ValueError`` naming the setting."""

from __future__ import annotations

import numpy as np
import pytest

from naruto_agent.benchmark.spec import EpisodeSpec, parse_scene
from naruto_agent.guards.scan_guard import ScanGuardConfig
from naruto_agent.mapping.config import NeuralMapperConfig
from naruto_agent.mapping.cpu_allocator import keep_freed_memory_for_reuse
from naruto_agent.mapping.encoding import HashGridEncoding, level_resolutions
from naruto_agent.mapping.meshing import mesh_from_sdf_function
from naruto_agent.mapping.observed_space import ObservedSpaceConfig
from naruto_agent.mapping.sdf_volume import SdfVolume
from naruto_agent.mapping.tsdf_mapper import TsdfMapperConfig
from naruto_agent.naruto.config import NarutoConfig
from naruto_agent.naruto.goal_search import GoalSearchConfig
from naruto_agent.naruto.recovery import RecoveryConfig
from naruto_agent.policies.config import FrontierConfig, PassiveConfig, RandomConfig
from naruto_agent.policies.layers import LinesLayer, PointsLayer

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
    (ObservedSpaceConfig, "voxel_size_m", 0.0),
    (ObservedSpaceConfig, "rays_per_frame", 0),
    (ObservedSpaceConfig, "support_below_m", -1.0),
    (ObservedSpaceConfig, "top_quantile", 1.5),
    (ObservedSpaceConfig, "look_weight", -0.1),
    (ObservedSpaceConfig, "look_behind_surface_m", float("nan")),
    (TsdfMapperConfig, "min_observation_weight", 0.0),
    (TsdfMapperConfig, "truncation_m", float("nan")),
    (TsdfMapperConfig, "map_every", 0),
    (TsdfMapperConfig, "observed_rays_per_frame", 1.5),
    (TsdfMapperConfig, "grazing_weighting", "yes"),
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
        ObservedSpaceConfig,
        TsdfMapperConfig,
    ],
)
def test_the_defaults_pass(config):
    config()


SPEC = {"scene": "replica_like_room", "policy": "random", "seed": 0, "steps": 10}


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: EpisodeSpec(**{**SPEC, "steps": 0}), "steps must be an integer of at least 1"),
        (lambda: EpisodeSpec(**{**SPEC, "seed": -1}), "seed must be an integer of at least 0"),
        (lambda: EpisodeSpec(**SPEC, image_scale=0.0), "image_scale must be greater than 0"),
        (lambda: EpisodeSpec(**SPEC, eval_points=-1), "eval_points must be an integer"),
        (
            lambda: EpisodeSpec(**SPEC, eval_samples_per_m2=-1.0),
            r"eval_samples_per_m2 \(0: no density bound\) must be at least 0",
        ),
        (lambda: EpisodeSpec(**SPEC, up_axis="w"), "up_axis must be one of"),
        (lambda: parse_scene("room.ply", up_axis="w"), "up_axis must be one of"),
        (
            lambda: PointsLayer("goal", [[0, 0, 0]], colour=(300, 0, 0)),
            "layer 'goal' colour red must be an integer of at least 0 and at most 255, got 300",
        ),
        (
            lambda: PointsLayer("goal", [[0, 0, 0]], colour=(1, 2)),
            "layer 'goal' colour is three integers",
        ),
        (
            lambda: PointsLayer("goal", [[0, 0, 0]], radius_m=-0.1),
            "layer 'goal' radius_m must be greater than 0",
        ),
        (
            lambda: LinesLayer("path", (), width_m=float("nan")),
            "layer 'path' width_m must be a finite number",
        ),
        (
            lambda: SdfVolume(np.zeros((2, 2, 2)), np.zeros(3), 0.0),
            r"voxel_size \(metres\) must be greater than 0",
        ),
        (
            lambda: SdfVolume.from_function(
                lambda p: p[:, 0], np.array([[0, 0, 0], [1, 1, 1.0]]), 0.5, padding=-1.0
            ),
            r"padding \(metres\) must be at least 0",
        ),
        (
            lambda: mesh_from_sdf_function(
                lambda p: p[:, 0], np.array([[0, 0, 0], [1, 1, 1.0]]), 0
            ),
            r"voxel_size \(metres\) must be greater than 0",
        ),
        (lambda: level_resolutions(0, 16, 256.0), "num_levels must be an integer of at least 1"),
        (lambda: level_resolutions(4, 16, 8.0), "finest_resolution must be at least 16"),
        (lambda: HashGridEncoding(log2_table_size=27), "log2_table_size must be an integer"),
        (
            lambda: keep_freed_memory_for_reuse(0),
            r"mmap_threshold_bytes \(glibc's maximum is 32 MiB\) must be an integer",
        ),
    ],
)
def test_the_harness_layers_and_grids_refuse_a_bad_value_by_name(make, message):
    """The harness's episode spec, a policy's view layers and the mapping grids check their
    values with the same helpers: one ValueError naming the value and what to pass."""
    with pytest.raises(ValueError, match=f"^{message}"):
        make()
