"""A user's own policy, as a module in the working directory or as a file path, in the registry
and in both command-line tools (``naruto-demo --policy``, ``naruto-benchmark --policies``),
and the benchmark's report of failed episodes."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from naruto_agent.benchmark.cli import main as benchmark_main
from naruto_agent.demo import main as demo_main
from naruto_agent.policies import Policy, policy_class

POLICY_SOURCE = '''
from naruto_agent.policies import Policy


class ForwardTurn(Policy):
    """Forward twice, then turn left (discrete actions)."""

    action_modes = ("discrete",)

    def __init__(self, period: int = 3) -> None:
        super().__init__()
        self.period = period
        self.steps = 0

    def act(self, observation, info=None):
        self.steps += 1
        return 0 if self.steps % self.period else 4


class NeedsMap(ForwardTurn):
    """Reads an observation key the env does not give: its episodes fail."""

    def act(self, observation, info=None):
        return observation["map"]
'''

# Tiny episodes: small frames, few coverage samples, no reference map.
TINY_BENCHMARK = [
    "--scenes", "two_rooms", "--seeds", "0", "--max-episode-steps", "3", "--workers", "0",
    "--image-scale", "0.1", "--no-reconstruct", "--no-plots", "--no-progress",
    "--env-kwargs", '{"panorama_shape": [16, 32], "coverage_samples": 2000}',
]
TINY_DEMO = [
    "--max-episode-steps", "3", "--scene", "two_rooms", "--image-scale", "0.1",
    "--eval-points", "0", "--gif-frames", "0", "--no-viewer", "--no-progress",
    "--eval-samples", "5000",
    "--checkpoint-samples", "5000",
]


@pytest.fixture
def user_folder(tmp_path, monkeypatch):
    """A working directory holding ``mypolicy.py`` and ``policies/forward.py`` (the same
    source), without PYTHONPATH; ``sys.path`` and the imported modules are restored after."""
    (tmp_path / "mypolicy.py").write_text(POLICY_SOURCE)
    (tmp_path / "policies").mkdir()
    (tmp_path / "policies" / "forward.py").write_text(POLICY_SOURCE)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(tmp_path))])
    modules = set(sys.modules)
    yield tmp_path
    for name in set(sys.modules) - modules:
        if name == "mypolicy" or name.startswith("_naruto_policy_file_"):
            del sys.modules[name]


def test_a_module_in_the_working_directory_is_found(user_folder):
    cls = policy_class("mypolicy:ForwardTurn")
    assert issubclass(cls, Policy) and cls.__name__ == "ForwardTurn"
    assert str(user_folder) == sys.path[-1]  # appended: it never shadows an installed module


def test_a_file_path_names_a_policy_and_loads_once(user_folder):
    cls = policy_class("policies/forward.py:ForwardTurn")
    assert cls.__name__ == "ForwardTurn"
    assert policy_class(f"{user_folder}/policies/forward.py:ForwardTurn") is cls
    assert cls(period=2).period == 2


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("policies/missing.py:ForwardTurn", "policy file 'policies/missing.py' does not exist"),
        ("policies/forward.py:Nope", "has no 'Nope' (its Policy subclasses: ForwardTurn, "
                                     "NeedsMap)"),
        ("no_such_module:ForwardTurn", "No module named 'no_such_module'"),
        ("policies/forward.py", "a file needs its class: 'FILE.py:ClassName'"),
        ("policies/broken.py:ForwardTurn", "cannot load policy file 'policies/broken.py': "
                                           "SyntaxError"),
    ],
)
def test_a_missing_file_module_or_class_is_a_clear_error(user_folder, name, message):
    (user_folder / "policies" / "broken.py").write_text("def oops(:\n")
    with pytest.raises(ValueError) as error:
        policy_class(name)
    assert message in str(error.value)


def test_the_demo_runs_a_policy_from_the_working_directory(user_folder, capsys):
    demo_main(["--policy", "mypolicy:ForwardTurn", "--policy-kwargs", '{"period": 2}',
               "--output-dir", "out", *TINY_DEMO])
    metrics = json.loads((user_folder / "out" / "metrics.json").read_text())
    assert metrics["policy"] == "mypolicy:ForwardTurn" and metrics["steps"] == 3


def test_the_demo_takes_a_file_path_and_benchmark_style_kwargs(user_folder):
    demo_main(["--policy", "policies/forward.py:ForwardTurn", "--output-dir", "out", *TINY_DEMO,
               "--policy-kwargs", '{"policies/forward.py:ForwardTurn": {"period": 2}}'])
    assert json.loads((user_folder / "out" / "metrics.json").read_text())["steps"] == 3


def test_the_demo_takes_the_up_axis_as_the_benchmark_does(user_folder, capsys):
    with pytest.raises(SystemExit):
        demo_main(["--scene", "room.obj@w", "--output-dir", "out"])
    assert "write PATH@AXIS with AXIS one of" in capsys.readouterr().err


def test_the_benchmark_runs_a_policy_from_the_working_directory(user_folder, capsys):
    code = benchmark_main([*TINY_BENCHMARK, "--policies", "mypolicy:ForwardTurn", "random",
                           "--output-dir", "runs", "--policy-kwargs",
                           '{"mypolicy:ForwardTurn": {"period": 2}}'])
    assert code == 0, capsys.readouterr()
    record = json.loads(
        (user_folder / "runs/records/two_rooms/ForwardTurn/seed0.json").read_text()
    )
    assert record["status"] == "ok" and record["config"]["policy_kwargs"] == {"period": 2}


def test_the_benchmark_takes_flat_kwargs_for_one_policy(user_folder, capsys):
    code = benchmark_main([*TINY_BENCHMARK, "--policies", "policies/forward.py:ForwardTurn",
                           "--output-dir", "runs", "--policy-kwargs", '{"period": 2}'])
    assert code == 0, capsys.readouterr()
    record = json.loads(
        (user_folder / "runs/records/two_rooms/ForwardTurn/seed0.json").read_text()
    )
    assert record["status"] == "ok" and record["config"]["policy_kwargs"] == {"period": 2}
    assert record["config"]["policy"] == f"{user_folder / 'policies/forward.py'}:ForwardTurn"


def test_the_benchmark_stops_early_on_a_policy_it_cannot_load(user_folder, capsys):
    code = benchmark_main([*TINY_BENCHMARK, "--policies", "random", "mypolicy:Nope",
                           "--output-dir", "runs"])
    assert code == 2
    assert "mypolicy has no 'Nope'" in capsys.readouterr().err
    assert not (user_folder / "runs").exists()


def test_the_benchmark_prints_why_episodes_failed_and_where(user_folder, capsys):
    code = benchmark_main([*TINY_BENCHMARK, "--policies", "mypolicy:NeedsMap", "random",
                           "--output-dir", "runs"])
    assert code == 1
    out = capsys.readouterr().out
    record = Path("runs") / "records" / "two_rooms" / "NeedsMap" / "seed0.json"
    assert "1 failed episode(s)" in out
    assert f"two_rooms/NeedsMap/seed0: KeyError: 'map' (traceback: {record})" in out
    assert "Traceback" in json.loads(record.read_text())["traceback"]


@pytest.mark.slow
def test_spawned_workers_find_the_working_directory_module(user_folder, capsys):
    code = benchmark_main([*TINY_BENCHMARK, "--workers", "1", "--policies",
                           "mypolicy:ForwardTurn", "--output-dir", "runs"])
    assert code == 0, capsys.readouterr()
    assert (user_folder / "runs/records/two_rooms/ForwardTurn/seed0.json").is_file()
