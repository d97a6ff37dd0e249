"""Packaging: the project builds a wheel and an sdist, and the wheel works where it is installed.

The wheel is installed into a fresh virtual environment that sees this interpreter's
packages (so that numpy, Open3D and torch are not downloaded again) but not this checkout:
the test runs from an empty folder and checks that ``naruto_gym`` is imported from the
virtual environment. The wheel ships no meshes; the shipped scene is generated from its seed
into a cache folder on first use, as on a user's machine.
"""

from __future__ import annotations

import os
import subprocess
import sys
import venv
from pathlib import Path

import pytest

import naruto_gym

tomllib = pytest.importorskip("tomllib")  # Python 3.11+

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


def test_version_is_the_same_everywhere() -> None:
    assert naruto_gym.__version__ == PYPROJECT["project"]["version"]


def test_torch_has_no_upper_bound() -> None:
    """Users with a newer torch must not get it downgraded by ``pip install``."""
    torch = [dep for dep in PYPROJECT["project"]["dependencies"] if dep.startswith("torch")]
    assert torch and "<" not in torch[0], torch


def test_the_embreex_backend_has_an_extra_of_its_name() -> None:
    """One name: the extra that installs the embreex ray caster is ``embreex``, as the install
    hint of the ray caster says."""
    extras = PYPROJECT["project"]["optional-dependencies"]
    assert "embree" not in extras and extras["embreex"] == ["embreex>=2.17"]
    source = (ROOT / "naruto_gym" / "sensors" / "raycaster.py").read_text()
    assert "naruto-gym[embreex]" in source and "naruto-gym[embree]" not in source


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An sdist of this checkout and a wheel built from that sdist (in a temporary folder, so
    the checkout gets no build/ folder; without network: no build isolation)."""
    pytest.importorskip("build")
    out = tmp_path_factory.mktemp("dist")
    result = subprocess.run(
        [sys.executable, "-m", "build", "--no-isolation", "--outdir", str(out), str(ROOT)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return out


def test_build_gives_a_wheel_and_an_sdist(built: Path) -> None:
    version = PYPROJECT["project"]["version"]
    assert len(list(built.glob(f"naruto_gym-{version}-*.whl"))) == 1
    assert len(list(built.glob(f"naruto_gym-{version}.tar.gz"))) == 1


@pytest.mark.slow
def test_wheel_installs_and_steps_in_a_fresh_environment(built: Path, tmp_path: Path) -> None:
    wheel = next(built.glob("*.whl"))
    env_dir = tmp_path / "venv"
    venv.EnvBuilder(system_site_packages=True, with_pip=False).create(env_dir)
    python = env_dir / "bin" / "python"
    # Without the caller's PYTHONPATH: a checkout on it (its egg-info) makes pip take the
    # package as installed already and skip the wheel.
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "NARUTO_GYM_ASSETS_DIR")}
    install = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "--python",
            str(python),
            "install",
            "--no-deps",
            "--no-index",
            "--quiet",
            str(wheel),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        env=env,
    )
    if install.returncode != 0 and "no such option: --python" in install.stderr:
        pytest.skip("pip is too old for --python")
    assert install.returncode == 0, install.stderr[-3000:]
    script = (
        "import gymnasium as gym, naruto_gym, numpy as np\n"
        "print(naruto_gym.__file__)\n"
        "env = gym.make('NarutoRecon-v0', image_scale=0.05)\n"
        "obs, info = env.reset(seed=0)\n"
        "obs, reward, terminated, truncated, info = env.step(env.action_space.sample())\n"
        "assert obs['rgb'].shape[2] == 3 and isinstance(reward, float)\n"
        "print('stepped', info['coverage'])\n"
    )
    work = tmp_path / "elsewhere"
    work.mkdir()
    env["NARUTO_GYM_CACHE_DIR"] = str(tmp_path / "cache")
    result = subprocess.run(
        [str(python), "-c", script],
        cwd=work,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    first_line = result.stdout.splitlines()[0]
    assert first_line.startswith(str(env_dir)), f"imported from {first_line}, not the wheel"
    assert "stepped" in result.stdout
    assert any((tmp_path / "cache").rglob("replica_like_room.ply")), "scene not generated"
