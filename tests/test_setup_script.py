"""``scripts/setup.sh`` takes torch from pip's configured sources when they serve its CPU
build, else from PyTorch's CPU index; ``TORCH_INDEX_URL`` decides when set.

A stand-in ``python`` answers the dry-run resolve (``pip install --dry-run --report -``) as a
machine's pip would, so no test touches the network; anything else runs this interpreter.
"""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CPU_INDEX = "https://download.pytorch.org/whl/cpu"
CONFIGURED = "pip's configured sources"


def stand_in_python(folder: Path, resolved_version: str | None) -> Path:
    """A ``python`` whose dry-run resolve of torch picks ``resolved_version`` (None: fails,
    as with no reachable index)."""
    report = {"install": [{"metadata": {"name": "torch", "version": resolved_version}}]}
    answer = f"echo '{json.dumps(report)}'" if resolved_version else "exit 1"
    script = folder / "python"
    script.write_text(
        "#!/usr/bin/env bash\n"
        'if [[ " $* " == *" --dry-run "* ]]; then\n'
        f"    {answer}\n"
        "    exit 0\n"
        "fi\n"
        f'exec {sys.executable} "$@"\n'
    )
    script.chmod(script.stat().st_mode | stat.S_IEXEC)
    return script


def torch_source(tmp_path: Path, resolved_version: str | None, **env: str) -> str:
    environment = {k: v for k, v in os.environ.items() if k != "TORCH_INDEX_URL"}
    environment.update(env, PYTHON=str(stand_in_python(tmp_path, resolved_version)))
    result = subprocess.run(
        ["bash", str(ROOT / "scripts" / "setup.sh"), "--torch-index"],
        capture_output=True,
        text=True,
        env=environment,
        timeout=60,
        check=True,
    )
    return result.stdout.strip().split("from: ", 1)[1]


@pytest.mark.parametrize(
    ("resolved", "source"),
    [("2.13.0+cpu", CONFIGURED), ("2.13.0", CPU_INDEX), (None, CPU_INDEX)],
)
def test_configured_sources_are_taken_when_they_serve_the_cpu_build(tmp_path, resolved, source):
    assert torch_source(tmp_path, resolved) == source


def test_torch_index_url_decides_when_set(tmp_path):
    assert torch_source(tmp_path, "2.13.0+cpu", TORCH_INDEX_URL="https://mirror/whl") == (
        "https://mirror/whl"
    )
    assert torch_source(tmp_path, "2.13.0", TORCH_INDEX_URL="") == CONFIGURED


def test_the_readme_names_the_override():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    install = readme.split("## Install", 1)[1].split("\n## ", 1)[0]
    assert "TORCH_INDEX_URL" in install
