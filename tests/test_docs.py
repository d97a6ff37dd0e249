"""The documentation: the MkDocs site builds in strict mode, its API reference lists every
public name, the README stays a short front page, and the hand-written pages stay short and
say what is, not how they came to be."""

from __future__ import annotations

import importlib
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README_MAX_LINES = 250

# Package -> the API page (docs/api/<page>.md) that renders it with mkdocstrings.
API_PAGES = {
    "naruto_gym": "env",
    "naruto_gym.vector": "vector",
    "naruto_gym.wrappers": "wrappers",
    "naruto_gym.scenes": "scenes",
    "naruto_gym.evaluation": "evaluation",
    "naruto_agent.policies": "policies",
    "naruto_agent.guards": "guards",
    "naruto_agent.naruto": "naruto",
    "naruto_agent.mapping": "mapping",
    "naruto_agent.planning": "planning",
    "naruto_agent.benchmark": "benchmark",
    "naruto_agent.recording": "recording",
}


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The site built by ``mkdocs build --strict`` (any warning fails the build)."""
    pytest.importorskip("mkdocs", reason="needs the docs extra: pip install -e '.[docs]'")
    pytest.importorskip("mkdocstrings", reason="needs the docs extra: pip install -e '.[docs]'")
    out = tmp_path_factory.mktemp("site")
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "mkdocs",
            "build",
            "--strict",
            "-f",
            str(ROOT / "mkdocs.yml"),
            "-d",
            str(out),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
    )
    if result.returncode != 0:
        pytest.fail(
            "mkdocs build --strict failed (a warning is an error in strict mode):\n"
            f"{result.stdout}\n{result.stderr}",
            pytrace=False,
        )
    return out


def test_mkdocs_build_strict(site: Path) -> None:
    assert (site / "index.html").is_file()
    assert (site / "api" / "index.html").is_file()


@pytest.mark.parametrize("package", sorted(API_PAGES))
def test_every_public_name_is_in_the_api_reference(site: Path, package: str) -> None:
    module = importlib.import_module(package)
    names = getattr(module, "__all__", None)
    if names is None:
        pytest.skip(f"{package} defines no __all__")
    page = site / "api" / API_PAGES[package] / "index.html"
    assert page.is_file(), f"no API page for {package}: add docs/api/{API_PAGES[package]}.md"
    anchors = set(re.findall(r'id="([^"]+)"', page.read_text(encoding="utf-8")))
    missing = [name for name in names if f"{package}.{name}" not in anchors]
    assert not missing, (
        f"public names of {package} missing from docs/api/{API_PAGES[package]}.md: {missing} "
        "(give them a docstring, or check the page's mkdocstrings options)"
    )


def test_readme_is_short() -> None:
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= README_MAX_LINES, (
        f"README.md has {len(lines)} lines; keep it at most {README_MAX_LINES} and move detail "
        "to docs/"
    )


def _nav_titles(items: list, section: str = "") -> list[tuple[str, str]]:
    """(section, title) of every titled page of an mkdocs ``nav`` list."""
    titles = []
    for item in items:
        if not isinstance(item, dict):
            continue
        for title, value in item.items():
            if isinstance(value, list):
                titles += _nav_titles(value, section or title)
            else:
                titles.append((section, title))
    return titles


def test_no_page_title_twice_in_the_navigation() -> None:
    """Outside the API reference (which mirrors the packages' names), a title names one page."""
    yaml = pytest.importorskip("yaml")
    nav = yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))["nav"]
    titles = [title for section, title in _nav_titles(nav) if section != "API reference"]
    repeated = sorted({title for title in titles if titles.count(title) > 1})
    assert not repeated, f"navigation titles used for two pages in mkdocs.yml: {repeated}"


def test_the_leaderboard_page_has_the_generators_add_your_policy_section() -> None:
    """docs/benchmarks/leaderboard.md is generated; its 'Add your policy' section is the one
    naruto_agent.benchmark.leaderboard writes now (a clone-runnable command, no local paths)."""
    from naruto_agent.benchmark.leaderboard import ADD_YOUR_POLICY, _add_your_policy

    page = (ROOT / "docs" / "benchmarks" / "leaderboard.md").read_text(encoding="utf-8")
    assert "\n".join(_add_your_policy()) in page, (
        "regenerate docs/benchmarks/leaderboard.md (python -m naruto_agent.benchmark.leaderboard)"
    )
    assert "/work" not in ADD_YOUR_POLICY and "model_path" not in ADD_YOUR_POLICY
    policy_file = ADD_YOUR_POLICY.split("--policies ")[1].split(":")[0]
    assert (ROOT / policy_file).is_file(), f"{policy_file} is not in the repository"


#: Hand-written pages are kept short; a generated page (marked GENERATED_MARK in its first
#: lines, as the leaderboard is) may be longer.
HAND_WRITTEN_MAX_LINES = 300
GENERATED_MARK = "<!-- generated by "
#: Pages held to HAND_WRITTEN_MAX_LINES besides every hand-written page of docs/benchmarks/.
SHORT_PAGES = ("docs/policies.md",)
#: Wording of a lab notebook: what was tried, taken back or changed, run by run. A page says
#: what is; that history goes to CHANGELOG.md, one line per change.
DIARY_PHRASES = (
    "tried and not taken",
    "tried and dropped",
    "tried this stop",
    "taken back",
    "changes two checks before",
    "the check before's changes",
    "in the last check",
    "what changed, each from",
    "read step by step",
    "for the record",
)


def _is_generated(page: Path) -> bool:
    head = page.read_text(encoding="utf-8").splitlines()[:5]
    return any(line.startswith(GENERATED_MARK) for line in head)


def _short_pages() -> list[Path]:
    benchmarks = sorted((ROOT / "docs" / "benchmarks").glob("*.md"))
    return [page for page in benchmarks if not _is_generated(page)] + [
        ROOT / path for path in SHORT_PAGES
    ]


def test_the_leaderboard_page_is_recognised_as_generated() -> None:
    """The line limit skips generated pages by their mark: the leaderboard must carry it."""
    assert _is_generated(ROOT / "docs" / "benchmarks" / "leaderboard.md")
    assert not _is_generated(ROOT / "docs" / "benchmarks" / "explorer.md")


@pytest.mark.parametrize("page", _short_pages(), ids=lambda page: page.name)
def test_a_hand_written_page_is_short(page: Path) -> None:
    lines = page.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= HAND_WRITTEN_MAX_LINES, (
        f"{page.relative_to(ROOT)} has {len(lines)} lines; keep a hand-written page at most "
        f"{HAND_WRITTEN_MAX_LINES}: say what is (what it does, how to run it, the machine, the "
        "current table) and leave how it came to be to CHANGELOG.md"
    )


@pytest.mark.parametrize(
    "page",
    sorted((ROOT / "docs").rglob("*.md")),
    ids=lambda page: page.relative_to(ROOT / "docs").as_posix(),
)
def test_a_docs_page_tells_no_story_of_how_it_came_to_be(page: Path) -> None:
    text = page.read_text(encoding="utf-8").lower()
    found = [phrase for phrase in DIARY_PHRASES if phrase in text]
    assert not found, (
        f"{page.relative_to(ROOT)} reads as a lab notebook ({found}): say what is, and put "
        "what was tried or changed in one CHANGELOG.md line of its change"
    )
