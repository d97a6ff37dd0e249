"""The policy registry, the policies' configs and the keywords that fill them."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from naruto_agent.benchmark.cli import build_parser
from naruto_agent.guards import ScanGuardConfig
from naruto_agent.policies import (
    LAZY_POLICIES,
    POLICIES,
    FrontierConfig,
    FrontierPolicy,
    PassiveConfig,
    PassivePolicy,
    Policy,
    RandomConfig,
    RandomPolicy,
    make_policy,
    policy_class,
    policy_names,
    register_lazy_policy,
    register_policy,
)


class _StandStill(Policy):
    def act(self, observation, info=None):
        return np.zeros(7, np.float32)


@pytest.fixture
def registry():
    """The registry as it is, restored after the test."""
    policies, lazy = dict(POLICIES), dict(LAZY_POLICIES)
    yield
    POLICIES.clear()
    POLICIES.update(policies)
    LAZY_POLICIES.clear()
    LAZY_POLICIES.update(lazy)


def test_the_baselines_register_themselves_and_naruto_stays_lazy():
    assert policy_class("frontier") is FrontierPolicy
    assert policy_class("random") is RandomPolicy
    assert policy_class("passive") is PassivePolicy
    assert policy_names() == sorted(
        {"explorer", "explorer-untrained", "frontier", "goal-ranker", "goal-ranker-untrained",
         "goal-walker", "naruto", "passive", "random"} | set(POLICIES)
    )
    # Looking the names up never imports the agent (its module imports torch).
    assert "naruto" in LAZY_POLICIES or "naruto_agent.naruto" in sys.modules


def test_register_policy_decorator_names_a_class(registry):
    decorated = register_policy("stand_still")(_StandStill)
    assert decorated is _StandStill
    assert isinstance(make_policy("stand_still"), _StandStill)
    assert "stand_still" in policy_names()
    register_policy("stand_still")(_StandStill)  # the same class again: fine
    with pytest.raises(ValueError, match="taken"):
        register_policy("frontier")(_StandStill)
    register_policy("frontier", replace=True)(_StandStill)
    assert policy_class("frontier") is _StandStill
    with pytest.raises(TypeError, match="Policy subclass"):
        register_policy("dict")(dict)


def test_a_lazy_entry_is_imported_on_first_lookup(registry):
    register_lazy_policy("lazy_frontier", "naruto_agent.policies.frontier:FrontierPolicy")
    assert "lazy_frontier" in policy_names() and "lazy_frontier" not in POLICIES
    assert policy_class("lazy_frontier") is FrontierPolicy
    assert POLICIES["lazy_frontier"] is FrontierPolicy and "lazy_frontier" not in LAZY_POLICIES
    # A module that registers its class itself takes the lazy entry's place.
    register_lazy_policy("stand_still", f"{__name__}:_StandStill")
    register_policy("stand_still")(_StandStill)
    assert "stand_still" not in LAZY_POLICIES and policy_class("stand_still") is _StandStill
    with pytest.raises(ValueError, match="package.module:ClassName"):
        register_lazy_policy("bad", "no_colon")


def test_lookup_errors_are_clear():
    with pytest.raises(ValueError, match="unknown policy 'nope'.*frontier"):
        policy_class("nope")
    with pytest.raises(ValueError, match="cannot import"):
        policy_class("no_such_module_x:Thing")
    with pytest.raises(ValueError, match="not a naruto_agent.policies.Policy subclass"):
        policy_class("json:dumps")


def test_benchmark_help_lists_every_registered_policy():
    text = build_parser().format_help()
    for name in ("passive", "random", "frontier", "naruto"):
        assert name in text.split("registered policies:")[1]


def test_keywords_fill_the_config_and_its_guard_section():
    policy = FrontierPolicy(voxel_size_m=0.2, max_held_moves=5, panorama_check=False)
    assert policy.config.voxel_size_m == 0.2
    assert policy.config.guard.max_held_moves == 5 and not policy.config.guard.panorama_check
    assert policy.config.guard.margin_start_passes  # frontier's own guard defaults stay
    assert policy.guard.config is policy.config.guard
    base = FrontierConfig(inflation_voxels=2)
    policy = FrontierPolicy(config=base, guard={"panorama_margin_m": 0.02}, replan_every=5)
    assert policy.config.inflation_voxels == 2 and policy.config.replan_every == 5
    assert policy.config.guard.panorama_margin_m == 0.02
    assert policy.config is not base and base.replan_every == 10  # the policy owns a copy
    guard = ScanGuardConfig(max_held_moves=1)
    assert RandomPolicy(guard=guard).config.guard == guard
    assert RandomPolicy(7).config.seed == 7 and RandomPolicy(7).seed == 7
    assert PassivePolicy(lost_wall_m=2.0).config == PassiveConfig(lost_wall_m=2.0)
    assert RandomPolicy(config=RandomConfig(max_redraws=2)).config.max_redraws == 2


def test_unknown_and_invalid_settings_are_refused():
    with pytest.raises(TypeError, match="no setting \\['nope'\\]"):
        FrontierPolicy(nope=1)
    with pytest.raises(TypeError, match="no setting"):
        PassivePolicy(max_held_moves=2)  # passive has no guard
    with pytest.raises(ValueError, match="look_around_headings must be an integer"):
        FrontierPolicy(look_around_headings=0)
    with pytest.raises(ValueError, match="min_run_steps"):
        RandomConfig(min_run_steps=0)
    with pytest.raises(ValueError, match="open_sky_share"):
        ScanGuardConfig(open_sky_share=0.0)
    with pytest.raises(TypeError, match="guard must be"):
        FrontierPolicy(guard=3)


def test_old_setting_names_are_refused_with_the_new_name():
    with pytest.raises(TypeError, match="'panorama_move_check' is now called 'panorama_check'"):
        FrontierPolicy(panorama_move_check=False)
    with pytest.raises(TypeError, match="pass max_held_moves=2 instead"):
        RandomPolicy(max_held_steps=2)
    with pytest.raises(TypeError, match="'max_held_steps' is now called"):
        RandomPolicy(max_held_steps=2, max_held_moves=3)
    assert RandomPolicy(max_held_moves=2).config.guard.max_held_moves == 2


def test_naruto_stays_lazy_until_looked_up_and_then_registers_itself(registry):
    """``import naruto_agent.policies`` never imports the agent; its module registers the
    class with the decorator, and the lazy entry names that same class."""
    import subprocess

    code = ("import sys, naruto_agent.policies as p; p.policy_names(); "
            "assert 'naruto_agent.naruto' not in sys.modules; "
            "assert 'naruto' in p.LAZY_POLICIES and 'naruto' not in p.POLICIES; "
            "from naruto_agent.naruto import NarutoPolicy; "
            "assert p.POLICIES['naruto'] is NarutoPolicy and 'naruto' not in p.LAZY_POLICIES")
    subprocess.run([sys.executable, "-c", code], check=True)
    from naruto_agent.naruto import NarutoPolicy

    assert policy_class("naruto") is NarutoPolicy
    assert policy_class(LAZY_POLICIES.get("naruto", "naruto_agent.naruto:NarutoPolicy")) is (
        NarutoPolicy)


def test_a_lazy_entry_and_the_class_its_module_registers_must_agree(registry, tmp_path,
                                                                    monkeypatch):
    (tmp_path / "decoy_policies.py").write_text(
        "from naruto_agent.policies import RandomPolicy, register_policy\n"
        "class Decoy(RandomPolicy):\n"
        "    pass\n"
        "register_policy('decoy')(RandomPolicy)  # another class under the lazy name\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    register_lazy_policy("decoy", "decoy_policies:Decoy")
    with pytest.raises(ValueError, match="names 'decoy_policies:Decoy', but importing it"):
        policy_class("decoy")
    monkeypatch.delitem(sys.modules, "decoy_policies")
