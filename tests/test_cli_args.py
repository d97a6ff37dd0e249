"""Flags from a typed dataclass: the parsing every benchmark script relies on."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from naruto_gym.cli_args import dataclass_parser, parse_dataclass_args

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


@dataclass
class ExampleArgs:
    steps: int = 10
    """how many steps"""
    scale: float = 0.5
    """resolution (100 % is full size)"""
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
    # A list flag given without values is an empty list (benchmarks: "empty: none").
    assert parse_dataclass_args(ExampleArgs, ["--scenes"]).scenes == []


def test_help_text_comes_from_field_docstrings():
    text = dataclass_parser(ExampleArgs).format_help()
    assert "how many steps" in text
    assert "(100 % is full size)" in text  # a percent sign is text, not a format


@pytest.mark.parametrize("script", sorted(p.name for p in BENCHMARKS.glob("*.py")))
def test_every_benchmark_script_prints_its_help(script):
    """``--help`` of every benchmark script (the open-scan script's broke on a "10 %" in a
    field's docstring)."""
    result = subprocess.run(
        [sys.executable, str(BENCHMARKS / script), "--help"],
        capture_output=True, text=True, timeout=120,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    assert "usage" in result.stdout


def test_bad_value_is_rejected():
    with pytest.raises(SystemExit):
        parse_dataclass_args(ExampleArgs, ["--steps", "many"])
