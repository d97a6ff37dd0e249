"""``examples/rllib_ppo.py`` names its install command for any missing piece of RLlib, and the
``ray`` extra brings RLlib (the test extra does not: RLlib pins an older Gymnasium, so its
tests run in the second environment of ``scripts/rllib_env.sh``)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.scripts import load_script

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "rllib_ppo.py"
HINT = "pip install 'naruto-gym[ray]'"


def _example():
    return load_script(EXAMPLE, "rllib_ppo_hint")


@pytest.mark.parametrize("blocked", ["ray", "ray.rllib.algorithms.ppo", "ray.tune.registry"])
def test_a_missing_module_gives_the_install_hint(monkeypatch, blocked):
    example = _example()
    monkeypatch.setitem(sys.modules, blocked, None)  # its import now fails
    with pytest.raises(SystemExit) as exit_info:
        example.main(example.Args(iterations=1))
    assert HINT in str(exit_info.value)


def test_a_missing_dependency_of_rllib_gives_the_install_hint():
    """``ray[default]`` without RLlib's extras: ``import ray.rllib`` fails on ``tree``
    (dm_tree). Run in a fresh interpreter, where RLlib was not imported yet."""
    code = (
        "import runpy, sys; sys.modules['tree'] = None; sys.argv = ['rllib_ppo.py']; "
        f"runpy.run_path({str(EXAMPLE)!r}, run_name='__main__')"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=300, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert result.returncode == 1
    assert HINT in result.stderr and "Traceback" not in result.stderr, result.stderr[-2000:]


def test_the_ray_extra_brings_rllib_and_the_test_extra_does_not():
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"][
        "optional-dependencies"]
    ray = [dep for dep in extras["ray"] if dep.startswith("ray[")]
    assert ray and "rllib" in ray[0], extras["ray"]
    test_ray = [dep for dep in extras["test"] if dep.startswith("ray[")]
    assert test_ray and "rllib" not in test_ray[0], extras["test"]
