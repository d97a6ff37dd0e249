"""Every copyable code block of README.md and docs/**/*.md runs, so the docs cannot drift from
the code. How blocks run and how a page marks a long block for a size-reduced twin:
tests/docs_examples.py."""

from __future__ import annotations

import ast
import builtins
import re
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.docs_examples import (
    REPO_ROOT,
    RUN_LANGUAGES,
    SHOW_LANGUAGES,
    Block,
    PageRun,
    docs_pages,
    load_page,
    missing_need,
    parse_page,
)

#: A skipped block with no twin must name the issue item whose fix it waits for.
ISSUE_ITEM = re.compile(r"issue \d+ item \d+")

PAGES = {path.relative_to(REPO_ROOT).as_posix(): load_page(path) for path in docs_pages()}
BLOCKS = [block for blocks in PAGES.values() for block in blocks]
RUN_BLOCKS = [block for block in BLOCKS if block.runs_as is not None]


def _param(block: Block) -> object:
    marks = [pytest.mark.slow] if block.slow else []
    return pytest.param(block, id=block.id, marks=marks)


@pytest.fixture(scope="module")
def page_runs(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, PageRun]]:
    """One PageRun per page, made at its first block, closed after the module."""
    runs: dict[str, PageRun] = {}

    def get(block: Block) -> PageRun:
        if block.page not in runs:
            slug = block.page.replace("/", "_").removesuffix(".md")
            runs[block.page] = PageRun(PAGES[block.page], tmp_path_factory.mktemp(slug))
        return runs[block.page]

    yield get  # type: ignore[misc]
    for run in runs.values():
        for session in ([run.session] if run.session else []) + run.retired:
            session.retire()  # all at once: interpreters take a while to exit
    for run in runs.values():
        run.close()


@pytest.mark.parametrize("block", [_param(b) for b in RUN_BLOCKS])
def test_docs_block_runs(block: Block, page_runs) -> None:
    if block.skip is not None:
        pytest.skip(block.skip)
    reason = missing_need(block)
    if reason is not None:
        pytest.skip(reason)
    outcome, failed_before = page_runs(block).run(block)
    if not outcome.ok:
        note = (
            f"\n(earlier blocks of this page failed: {', '.join(failed_before)})"
            if failed_before
            else ""
        )
        pytest.fail(
            f"{block.id} ({block.runs_as}) failed after {outcome.seconds:.1f} s:\n"
            f"{block.code}\n--- output ---\n{outcome.output[-6000:]}{note}",
            pytrace=False,
        )


#: README.md's Python blocks: a reader copies one alone, so each must run alone.
README_PYTHON = [b for b in PAGES["README.md"] if b.runs_as == "python" and b.write is None]


def unbound_names(code: str) -> list[str]:
    """Names the code reads but never binds (assignment, import, def, argument) and that are
    no builtins: what it needs from an earlier block."""
    tree = ast.parse(code)
    bound = set(dir(builtins))
    read = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Name):
            if isinstance(node.ctx, ast.Load):
                read.append(node.id)
            else:
                bound.add(node.id)
        elif isinstance(node, ast.alias):
            bound.add((node.asname or node.name).split(".")[0])
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            bound.add(node.name)
        elif isinstance(node, ast.arg):
            bound.add(node.arg)
    return sorted({name for name in read if name not in bound})


def test_unbound_names_finds_what_a_block_takes_from_an_earlier_one() -> None:
    assert unbound_names("env = gym.make('x')\nprint(env, len([]))\n") == ["gym"]
    assert unbound_names("import gymnasium as gym\nfrom a import b\nenv = gym.make(b)\n") == []


@pytest.mark.parametrize("block", [_param(b) for b in README_PYTHON])
def test_each_readme_python_block_runs_alone(block: Block, tmp_path: Path) -> None:
    """Each README Python block runs when copied alone into a fresh interpreter (imports
    included); a block too long to run here binds every name it uses, and its twin runs."""
    if block.skip is not None:
        missing = unbound_names(block.code)
        assert not missing, f"{block.id} uses {missing} without defining or importing them"
        return
    reason = missing_need(block)
    if reason is not None:
        pytest.skip(reason)
    run = PageRun([block], tmp_path)
    try:
        outcome, _ = run.run(block)
    finally:
        run.close()
    assert outcome.ok, f"{block.id} fails when run alone:\n{block.code}\n{outcome.output[-4000:]}"


def test_every_fence_says_whether_it_runs() -> None:
    known = set(RUN_LANGUAGES) | SHOW_LANGUAGES
    unknown = [
        f"{b.id} ({b.language or 'no language'})"
        for b in BLOCKS
        if b.twin_id is None and b.language not in known
    ]
    assert not unknown, (
        f"code fences whose language neither runs ({sorted(RUN_LANGUAGES)}) nor is shown "
        f"({sorted(SHOW_LANGUAGES)}): {unknown}; use ```text for output and pseudo-code"
    )


def _twins(page: str) -> dict[str, Block]:
    return {b.twin_id: b for b in PAGES.get(page, []) if b.twin_id is not None}


def _resolve(page: str, reference: str) -> Block | None:
    """The twin a skip names: ``ID`` on its own page, ``PAGE#ID`` on another."""
    other, _, twin_id = reference.rpartition("#")
    return _twins(other or page).get(twin_id)


def test_every_skipped_block_has_a_twin_that_runs() -> None:
    problems = []
    for page, blocks in PAGES.items():
        for block in blocks:
            if block.skip is None:
                continue
            if block.runs_as is None:
                problems.append(f"{block.id}: a skip marker on a block that never runs")
            if not block.covered_by and not ISSUE_ITEM.search(block.skip):
                problems.append(
                    f"{block.id}: skipped without 'covered by: TWIN' (or, for a "
                    "block the code fails, the issue item that fixes it)"
                )
            problems += [
                f"{block.id}: no twin {t!r}" for t in block.covered_by if _resolve(page, t) is None
            ]
    assert not problems, "\n".join(problems)


def test_every_twin_stands_in_for_a_skipped_block() -> None:
    named = {
        (_resolve(page, t).page, _resolve(page, t).twin_id)
        for page, blocks in PAGES.items()
        for b in blocks
        for t in b.covered_by
        if _resolve(page, t) is not None
    }
    problems = []
    for blocks in PAGES.values():
        seen: set[str] = set()
        for twin in (b for b in blocks if b.twin_id is not None):
            if (twin.page, twin.twin_id) not in named:
                problems.append(f"{twin.id}: no skipped block names twin {twin.twin_id!r}")
            if twin.twin_id in seen:
                problems.append(f"{twin.id}: twin id {twin.twin_id!r} used twice on its page")
            seen.add(twin.twin_id)
    assert not problems, "\n".join(problems)


def test_the_runner_reads_directives_and_twins(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text(
        "Text.\n\n<!-- docs-test: skip (long; covered by: short) -->\n```bash\nsleep 100\n```\n"
        "<!-- docs-test: twin short bash slow needs=shared\nsleep 0\n-->\n\n"
        "<!-- docs-test: write m.py -->\n```python\nX = 1\n```\n\n"
        "    ```text\n    output\n    ```\n",
        encoding="utf-8",
    )
    long, twin, module, output = parse_page(page, tmp_path)
    assert (long.skip, long.covered_by, long.line) == ("long; covered by: short", ("short",), 5)
    assert (twin.twin_id, twin.code, twin.slow, twin.needs) == (
        "short",
        "sleep 0\n",
        True,
        ("shared",),
    )
    assert (module.write, module.runs_as, output.runs_as, output.code) == (
        "m.py",
        "python",
        None,
        "output\n",
    )


def test_a_python_page_keeps_its_state_and_reports_page_lines(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text(
        "```python\nx = 41\nprint('no newline', end='')\n```\n\n"
        "```python\nx += 1\nassert x == 0, x\n```\n",
        encoding="utf-8",
    )
    first, second = parse_page(page, tmp_path)
    run = PageRun([first, second], tmp_path / "run")
    try:
        outcome, failed_before = run.run(second)  # runs the first block before it
    finally:
        run.close()
    assert run.results[0].ok and run.results[0].output == "no newline"
    assert not outcome.ok and not failed_before
    assert "AssertionError: 42" in outcome.output and 'page.md", line 8' in outcome.output


def test_a_shell_block_runs_in_a_copy_with_this_checkouts_tools(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text(
        "```bash\ntest -f scripts/setup.sh && test -d benchmarks/results && test -d examples\n"
        "python -c 'import naruto_gym, sys; print(naruto_gym.__file__)'\n"
        "PYTHONPATH=. naruto-benchmark --help > /dev/null\n```\n\n"
        "```bash\nfalse\necho never\n```\n",
        encoding="utf-8",
    )
    first, second = parse_page(page, tmp_path)
    run = PageRun([first, second], tmp_path / "run")
    try:
        outcome, _ = run.run(first)
        failing, _ = run.run(second)
    finally:
        run.close()
    assert outcome.ok, outcome.output
    assert outcome.output.strip().startswith(str(REPO_ROOT / "naruto_gym"))
    assert not failing.ok and "never" not in failing.output
    launcher = (tmp_path / "run" / "bin" / "naruto-benchmark.py").read_text(encoding="utf-8")
    assert "if __name__ == '__main__':" in launcher  # spawned workers re-import it
    assert repr(str(REPO_ROOT)) in launcher  # this checkout, whatever PYTHONPATH a block sets


def test_the_policies_page_example_is_the_one_in_examples() -> None:
    """docs/policies.md's example policy is shipped as examples/my_policies.py (the file the
    leaderboard's 'Add your policy' command runs from a clone): the two stay the same."""
    written = [b for b in PAGES["docs/policies.md"] if b.write == "my_policies.py"]
    assert len(written) == 1, "docs/policies.md should save one block as my_policies.py"
    shipped = (REPO_ROOT / "examples" / "my_policies.py").read_text(encoding="utf-8")
    assert written[0].code == shipped, (
        "docs/policies.md's my_policies.py block and examples/my_policies.py differ: copy the "
        "page's block into the file"
    )
