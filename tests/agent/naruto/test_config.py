"""The NARUTO agent's settings: keyword overrides, and every field described."""

from __future__ import annotations

import ast
import inspect
from dataclasses import fields
from pathlib import Path

import pytest

from naruto_agent.guards import ScanGuardConfig
from naruto_agent.naruto import NarutoConfig, build_config
from naruto_agent.naruto import config as config_module

DOCS = Path(__file__).resolve().parents[3] / "docs" / "agent-config.md"


def field_docstrings() -> dict[str, str]:
    """Field name -> the one-line string that follows it in ``NarutoConfig``'s body."""
    tree = ast.parse(inspect.getsource(config_module))
    body = next(node for node in tree.body
                if isinstance(node, ast.ClassDef) and node.name == "NarutoConfig").body
    found = {}
    for node, after in zip(body[:-1], body[1:], strict=True):
        if (isinstance(node, ast.AnnAssign) and isinstance(after, ast.Expr)
                and isinstance(after.value, ast.Constant)):
            found[node.target.id] = after.value.value
    return found


def test_every_field_has_a_one_line_description_and_a_section_of_the_docs() -> None:
    described = field_docstrings()
    docs = DOCS.read_text()
    for item in fields(NarutoConfig):
        assert "\n" not in described.get(item.name, "\n"), item.name
        assert f"`{item.name}`" in docs, item.name


def test_overrides_reach_fields_and_sections_and_leave_the_base_alone() -> None:
    base = NarutoConfig()
    config = build_config(base, goal_attempts=1, planner={"time_limit_s": 1.0},
                          recovery={"window": 30})
    assert (config.goal_attempts, config.planner.time_limit_s, config.recovery.window) == (
        1, 1.0, 30)
    assert config.planner.step_m == base.planner.step_m
    assert base.goal_attempts == 3 and base.planner.time_limit_s == 2.0
    assert config.goal_search.goal_spacing_z_m == 0.5  # the section's other agent defaults
    with pytest.raises(ValueError, match="unknown recovery settings"):
        build_config(recovery={"windows": 3})
    with pytest.raises(ValueError, match="max_held_moves"):
        build_config(max_held_moves=-1)
    with pytest.raises(ValueError, match="max_rotation_step_deg"):
        NarutoConfig(max_rotation_step_deg=0.0)


def test_the_guard_section_takes_the_names_every_policy_takes() -> None:
    """The guard's fields are given by name or as a section, as for frontier and random; the
    agent's old name of the panorama switch is refused with an error naming the new one."""
    config = build_config(max_held_moves=5, open_sky_share=None, edge_probe_m=0.2,
                          panorama_margin_m=0.02)
    assert config.guard == ScanGuardConfig(max_held_moves=5, open_sky_share=None,
                                           edge_probe_m=0.2, panorama_margin_m=0.02)
    assert NarutoConfig().guard == ScanGuardConfig()  # the agent takes the guard's defaults
    config = build_config(guard={"max_held_moves": 1}, panorama_edge_probe=False)
    assert config.guard.max_held_moves == 1 and not config.guard.panorama_edge_probe
    assert build_config(guard=ScanGuardConfig(max_held_moves=2)).guard.max_held_moves == 2
    with pytest.raises(TypeError, match="'check_moves_on_panorama' is now called 'panorama_ch"):
        build_config(check_moves_on_panorama=False)
    assert not build_config(panorama_check=False).guard.panorama_check
    with pytest.raises(ValueError, match="unknown guard settings"):
        build_config(guard={"max_held_steps": 1})
    with pytest.raises(ValueError, match="unknown NARUTO settings"):
        build_config(max_held=1)


def test_guard_settings_the_agent_does_not_read_are_refused() -> None:
    for name in ("panorama_top_check", "release_held_until_moved"):
        with pytest.raises(ValueError, match=name):
            build_config(**{name: True})
