"""Every registered policy is named where a user looks for the policies: ``naruto-demo
--help`` (read from the registry), the README's policy table and the first-hour page's
expected ``--help`` output."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from naruto_agent.demo.run import build_parser
from naruto_agent.policies import POLICIES, Policy, policy_names, register_policy

ROOT = Path(__file__).resolve().parents[3]


def help_policies(help_text: str) -> list[str]:
    """The names after "registered policies:" in a help text, up to the first ";"."""
    flat = " ".join(help_text.split())
    listed = flat.split("registered policies:", 1)[1].split(";", 1)[0]
    return [name.strip() for name in listed.split(",")]


def test_demo_help_lists_every_registered_policy(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["--help"])
    assert help_policies(capsys.readouterr().out) == policy_names()


def test_demo_help_reads_the_registry_at_the_time_it_is_asked():
    @register_policy("test-listed-policy")
    class Listed(Policy):
        action_modes = ("discrete",)

        def act(self, observation, info):
            return 0

    try:
        assert "test-listed-policy" in help_policies(build_parser().format_help())
    finally:
        POLICIES.pop("test-listed-policy")


def test_the_readme_policy_table_has_every_registered_policy():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("## Policies and the NARUTO agent", 1)[1].split("\n\n", 2)[1]
    named = set(
        re.findall(
            r"`([\w-]+)`",
            " ".join(line.split("|")[1] for line in section.splitlines() if line.startswith("| `")),
        )
    )
    assert set(policy_names()) <= named, set(policy_names()) - named


def test_first_hour_shows_the_help_listing_every_registered_policy():
    text = (ROOT / "docs" / "first-hour.md").read_text(encoding="utf-8")
    shown = text.split("naruto-demo --help | tail -n 3", 1)[1].split("```text\n", 1)[1]
    assert help_policies(shown.split("```", 1)[0]) == policy_names()
