"""Flags from a typed dataclass: the parsing every benchmark script relies on."""

from __future__ import annotations

from dataclasses import dataclass, field

import pytest

from naruto_gym.cli_args import dataclass_parser, parse_dataclass_args


@dataclass
class ExampleArgs:
    steps: int = 10
    """how many steps"""
    scale: float = 0.5
    scenes: list[str] = field(default_factory=lambda: ["room"])
    plots: bool = True
    device: str | None = None


def test_defaults_and_types():
    args = parse_dataclass_args(ExampleArgs, [])
    assert args == ExampleArgs()
    args = parse_dataclass_args(
        ExampleArgs,
        ["--steps", "3", "--scale", "0.25", "--scenes", "a", "b", "--no-plots", "--device", "cpu"],
    )
    assert args == ExampleArgs(3, 0.25, ["a", "b"], False, "cpu")


def test_help_text_comes_from_field_docstrings():
    assert "how many steps" in dataclass_parser(ExampleArgs).format_help()


def test_bad_value_is_rejected():
    with pytest.raises(SystemExit):
        parse_dataclass_args(ExampleArgs, ["--steps", "many"])
