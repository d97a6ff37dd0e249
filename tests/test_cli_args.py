"""Flags from a typed dataclass: the parsing every benchmark script relies on."""

from __future__ import annotations

import os
import runpy
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from naruto_agent.cli_args import dataclass_parser, parse_dataclass_args

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


@dataclass
class ExampleArgs:
    max_episode_steps: int = 10
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
        ["--max-episode-steps", "3", "--scale", "0.25", "--scenes", "a", "b", "--no-plots",
         "--device", "cpu"],
    )
    assert args == ExampleArgs(3, 0.25, ["a", "b"], False, "cpu")
    # A list flag given without values is an empty list (benchmarks: "empty: none").
    assert parse_dataclass_args(ExampleArgs, ["--scenes"]).scenes == []


def test_help_text_comes_from_field_docstrings():
    text = dataclass_parser(ExampleArgs).format_help()
    assert "how many steps" in text
    assert "(100 % is full size)" in text  # a percent sign is text, not a format


@pytest.mark.parametrize("script", sorted(p.name for p in BENCHMARKS.glob("*.py")))
def test_every_benchmark_script_prints_its_help(script, monkeypatch, capsys):
    """``--help`` of every benchmark script (the open-scan script's broke on a "10 %" in a
    field's docstring). Run in this process, as ``__main__`` with the script's folder on the
    path as Python would put it: an interpreter per script spent seconds importing the same
    libraries each time. The test below runs one in a fresh interpreter."""
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    monkeypatch.setattr(sys, "argv", [str(BENCHMARKS / script), "--help"])
    with pytest.raises(SystemExit) as stop:
        runpy.run_path(str(BENCHMARKS / script), run_name="__main__")
    assert stop.value.code == 0
    assert "usage" in capsys.readouterr().out


def test_a_benchmark_script_prints_its_help_in_a_fresh_interpreter():
    result = subprocess.run(
        [sys.executable, str(BENCHMARKS / "train_explorer.py"), "--help"],
        capture_output=True, text=True, timeout=120,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    assert "usage" in result.stdout


def test_bad_value_is_rejected():
    with pytest.raises(SystemExit):
        parse_dataclass_args(ExampleArgs, ["--max-episode-steps", "many"])


@dataclass
class FolderArgs:
    output_dir: str = "out"
    max_episode_steps: int = 5
    eval_points: int = 1


@dataclass
class FileArgs:
    output_file: str = "out.json"


@pytest.mark.parametrize(
    ("cls", "old", "new"),
    [
        (FolderArgs, "--out", "--output-dir"),
        (FolderArgs, "--out-dir", "--output-dir"),
        (FolderArgs, "--output", "--output-dir"),
        (FolderArgs, "--results-dir", "--output-dir"),
        (FolderArgs, "--steps", "--max-episode-steps"),
        (FolderArgs, "--episode-steps", "--max-episode-steps"),
        (FolderArgs, "--checkpoints", "--eval-points"),
        (FileArgs, "--out", "--output-file"),
        (FileArgs, "--output", "--output-file"),
    ],
)
def test_an_earlier_spelling_is_refused_naming_the_new_flag(cls, old, new, capsys):
    """No silent alias: argparse would otherwise read "--out" as a prefix of "--output-dir"."""
    with pytest.raises(SystemExit) as raised:
        parse_dataclass_args(cls, [old, "7"])
    assert raised.value.code == 2
    assert f"{old} was renamed: use {new}" in capsys.readouterr().err
    parsed = parse_dataclass_args(cls, [new, "7"])
    assert str(getattr(parsed, new[2:].replace("-", "_"))) == "7"


def test_a_tool_that_has_no_such_concept_keeps_argparse_error(capsys):
    with pytest.raises(SystemExit):
        parse_dataclass_args(FileArgs, ["--steps", "3"])
    assert "unrecognized arguments: --steps" in capsys.readouterr().err


def test_the_device_flags_say_whose_device(capsys):
    """``--device`` is the agent's mapper's; the harness's reference mapper has its own flag."""
    from naruto_agent.benchmark.cli import parse_args as benchmark_args
    from naruto_agent.demo.run import parse_args as demo_args

    assert benchmark_args(["--reference-device", "cpu"]).reference_device == "cpu"
    with pytest.raises(SystemExit):
        benchmark_args(["--device", "cpu"])
    assert "--device was renamed: use --reference-device" in capsys.readouterr().err
    demo = demo_args(["--device", "cpu", "--reference-device", "cpu", "--mapper-kind", "neural"])
    assert (demo.device, demo.reference_device, demo.mapper_kind) == ("cpu", "cpu", "neural")
    with pytest.raises(SystemExit):
        demo_args(["--mapper", "neural"])
    assert "--mapper was renamed: use --mapper-kind" in capsys.readouterr().err


def _script_args_fields(path: Path) -> tuple[list[str], set[str]]:
    """The fields of a script's ``Args`` dataclass and those with a help string under them
    (read from the source: the scripts need not import here)."""
    import ast

    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.ClassDef) and node.name == "Args":
            body = node.body
            fields = [n.target.id for n in body if isinstance(n, ast.AnnAssign)]
            documented = {
                n.target.id for n, following in zip(body, body[1:], strict=False)
                if isinstance(n, ast.AnnAssign) and isinstance(following, ast.Expr)
                and isinstance(following.value, ast.Constant)
            }
            return fields, documented
    return [], set()


SCRIPTS = sorted([*BENCHMARKS.glob("*.py"), *(BENCHMARKS.parent / "scripts").glob("*.py"),
                  *(BENCHMARKS.parent / "examples").glob("*.py")])


#: Field names the tools no longer use: one concept, one name (naruto_agent.cli_args).
RENAMED_FIELDS = {"out", "out_dir", "output", "results_dir", "run_dir", "steps",
                  "episode_steps", "step_budget", "checkpoints", "mapper"}


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda path: f"{path.parent.name}/{path.name}")
def test_no_script_uses_an_earlier_name(script):
    fields, _ = _script_args_fields(script)
    assert not RENAMED_FIELDS & set(fields), f"{script.name}: {RENAMED_FIELDS & set(fields)}"


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda path: f"{path.parent.name}/{path.name}")
def test_every_option_of_every_script_has_help(script):
    fields, documented = _script_args_fields(script)
    missing = [name for name in fields if name not in documented]
    assert not missing, f"{script.name}: no help string under {missing} in its Args"


def _help(argv: list[str]) -> str:
    result = subprocess.run(
        [sys.executable, *argv, "--help"], capture_output=True, text=True, timeout=120,
        cwd=BENCHMARKS.parent, env={**os.environ, "PYTHONPATH": str(BENCHMARKS.parent)},
    )
    assert result.returncode == 0, result.stderr[-2000:]
    return " ".join(result.stdout.split())  # argparse wraps lines: compare words


def test_benchmark_help_lists_every_policy_and_scene_form():
    from naruto_agent.benchmark.cli import build_parser
    from naruto_agent.policies import policy_names

    text = " ".join(build_parser().format_help().split())
    assert "naruto" in policy_names()
    assert f"registered policies: {', '.join(policy_names())};" in text
    for form in ("procedural:room:SEED", "NAME:OPENINGS", "PATH@AXIS", "--up-axis",
                 "package.module:ClassName", "path/to/file.py:ClassName",
                 '{"random": {"max_run_steps": 20}}', '{"max_run_steps": 20}'):
        assert form in text, form


def test_demo_help_gives_the_same_conventions():
    from naruto_agent.cli_args import dataclass_parser
    from naruto_agent.demo.run import DemoArgs

    text = " ".join(dataclass_parser(DemoArgs).format_help().split())
    for form in ("PATH@AXIS", "path/to/file.py:ClassName", '{"random": {"max_run_steps": 20}}',
                 "680 x 1200 (H x W)", "170 x 300"):
        assert form in text, form


def test_replica_passive_help_is_whole():
    text = _help([str(BENCHMARKS / "replica_passive.py")])
    assert "On office0 the result is set beside the published passive figure." in text
    assert "see docs/replica.md)." in text and "::" not in text
    assert "--scene-dir SCENE_DIR scene folder with mesh.ply, traj.txt and cam_params.json" in text


def test_train_ppo_default_budget_is_the_documented_one():
    """The docs train and evaluate with 250-step episodes: the script's default agrees."""
    text = _help([str(BENCHMARKS / "train_ppo.py")])
    assert "250, as the reported runs and their evaluation) (default: 250)" in text
    docs = BENCHMARKS.parent / "docs"
    assert "every 250-step episode" in (docs / "benchmarks" / "ppo.md").read_text()
    assert "--max-episode-steps 250" in (docs / "rl.md").read_text()


@dataclass
class PluralArgs:
    policies: list[str] = field(default_factory=lambda: ["passive"])
    policy_kwargs: str = "{}"
    classes: list[str] = field(default_factory=list)
    seeds: list[int] = field(default_factory=lambda: [0])
    seed: int = 7


def test_a_list_flag_answers_to_its_singular():
    args = parse_dataclass_args(PluralArgs, ["--policy", "mine", "--class", "small"])
    # Without the alias argparse would take "--policy" as short for "--policy-kwargs".
    assert args.policies == ["mine"] and args.policy_kwargs == "{}"
    assert args.classes == ["small"]
    # A singular that is another field keeps that field's meaning.
    args = parse_dataclass_args(PluralArgs, ["--seed", "3", "--seeds", "1", "2"])
    assert args.seed == 3 and args.seeds == [1, 2]
