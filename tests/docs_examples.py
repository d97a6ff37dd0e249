"""Runs the code blocks of README.md and docs/**/*.md as a reader would copy them.

A page's fenced blocks are read in order. ```python blocks run in one Python process per page
that keeps its state from block to block (a reader pasting them one after the other); ```bash
and ```shell blocks run with ``bash -e -o pipefail``. Both run in a fresh folder per page that
holds copies of the repository's scripts (``benchmarks/``, ``examples/``, ``scripts/``), with
``python`` and the package's command-line tools first on ``PATH``, all importing this checkout.
Blocks that only show output or pseudo-code use a fence that is not run (```text, ```bibtex).

HTML comments right before a block (invisible on GitHub and on the site) steer the runner:

``<!-- docs-test: skip (REASON; covered by: ID) -->``
    The block is not run (a long benchmark, an install); the hidden twin ``ID``, a
    size-reduced version of it, runs in its place, so nothing documented goes unchecked.
    ``PAGE#ID`` names a twin on another page that checks the same command. A block the code
    fails names the issue item that fixes it instead of a twin.
``<!-- docs-test: twin ID LANG [slow] [alone] [needs=X,Y]`` ... ``-->``
    A hidden twin: the lines up to the closing ``-->`` are code in LANG (python or bash), run
    where the comment stands. A page with no room for its twins (the README has a line limit)
    keeps them in ``tests/docs_twins/<page path>``; each runs right after the block that names
    it.
``<!-- docs-test: alone -->``
    A Python block that runs in a fresh process of its own, not in the page's session.
``<!-- docs-test: write FILE -->``
    The page tells the reader to save the block as FILE: it is written to the page's folder
    and checked for syntax; the later blocks that use it run it.
``<!-- docs-test: needs X,Y -->``
    Skip cleanly unless each X is there: ``shared`` (the research-only meshes in
    ``../shared/scenes``; implied by a block that mentions ``../shared``), ``gpu`` (CUDA),
    ``network`` (never in tests), or an importable module name (``stable_baselines3``).
``<!-- docs-test: slow -->``
    The test carries ``pytest.mark.slow`` (slow tests still run in CI).
"""

from __future__ import annotations

import importlib.util
import json
import os
import queue
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
TWINS_DIR = REPO_ROOT / "tests" / "docs_twins"
SHARED_DIR = REPO_ROOT.parent / "shared"

#: Fence languages that run, and the language they run as.
RUN_LANGUAGES = {"python": "python", "py": "python", "bash": "bash", "shell": "bash",
                 "sh": "bash"}
#: Fence languages that are shown, never run: output, pseudo-code, citations.
SHOW_LANGUAGES = {"text", "bibtex", "console"}

#: Seconds one block may take before it fails (the machine may be shared: generous).
BLOCK_TIMEOUT_S = 300.0

_FENCE = re.compile(r"^(?P<indent>[ \t]*)(?P<fence>`{3,}|~{3,})[ \t]*(?P<info>[^`]*)$")
_DIRECTIVE = re.compile(r"^\s*<!--\s*docs-test:\s*(?P<body>.*?)\s*-->\s*$")
_TWIN_OPEN = re.compile(r"^\s*<!--\s*docs-test:\s*twin\s+(?P<header>.*?)\s*$")
_COVERED_BY = re.compile(r"covered by:\s*(?P<ids>[\w./#-]+(?:\s*,\s*[\w./#-]+)*)")


class DocsFormatError(ValueError):
    """A docs-test comment or fence the runner cannot read."""


@dataclass
class Block:
    """One code block of a page, as the runner sees it.

    Attributes:
        page: the page's path relative to the repository root.
        line: 1-based line of the block's first code line (the fence's next line) in ``file``.
        language: the fence's language as written (empty when none).
        code: the block's code, its indentation removed.
        twin_id: for a hidden twin, its id; None for a fenced block.
        skip: the reason a fenced block is not run, or None.
        covered_by: ids of the twins that run in a skipped block's place.
        alone: run in a fresh process of its own.
        write: file name the block is saved as before it runs, or None.
        needs: what must be there for the block to run (see the module docstring).
        slow: mark the test slow.
    """

    page: str
    line: int
    language: str
    code: str
    twin_id: str | None = None
    skip: str | None = None
    covered_by: tuple[str, ...] = ()
    alone: bool = False
    write: str | None = None
    needs: tuple[str, ...] = ()
    slow: bool = False
    file: str = ""

    def __post_init__(self) -> None:
        self.file = self.file or self.page

    @property
    def runs_as(self) -> str | None:
        """``"python"`` or ``"bash"`` for a block that runs, None for one that is shown."""
        return RUN_LANGUAGES.get(self.language)

    @property
    def id(self) -> str:
        """The test id: page and line, and the twin's id for a twin."""
        where = f"{self.file}:{self.line}"
        return f"{where}[twin {self.twin_id}]" if self.twin_id else where

    def all_needs(self) -> tuple[str, ...]:
        """The declared needs, plus ``shared`` when the code reads ``../shared``."""
        needs = list(self.needs)
        if "../shared" in self.code and "shared" not in needs:
            needs.append("shared")
        return tuple(needs)


@dataclass
class _Pending:
    """Directives read since the last block, applied to the next fenced block."""

    skip: str | None = None
    covered_by: tuple[str, ...] = ()
    alone: bool = False
    write: str | None = None
    needs: tuple[str, ...] = ()
    slow: bool = False
    lines: list[int] = field(default_factory=list)


def _apply_directive(body: str, pending: _Pending, where: str) -> None:
    words = body.split(None, 1)
    name, rest = words[0], (words[1] if len(words) > 1 else "")
    if name == "skip":
        match = re.fullmatch(r"\((?P<reason>.+)\)", rest.strip())
        if not match:
            raise DocsFormatError(f"{where}: write 'skip (REASON; covered by: ID)'")
        pending.skip = match["reason"].strip()
        covered = _COVERED_BY.search(pending.skip)
        if covered:
            pending.covered_by = tuple(i.strip() for i in covered["ids"].split(","))
    elif name == "alone" and not rest:
        pending.alone = True
    elif name == "slow" and not rest:
        pending.slow = True
    elif name == "write" and rest and " " not in rest.strip():
        pending.write = rest.strip()
    elif name == "needs" and rest:
        pending.needs = tuple(n.strip() for n in rest.split(",") if n.strip())
    else:
        raise DocsFormatError(f"{where}: unknown docs-test directive {body!r}")


def _twin(page: str, file: str, line: int, header: str, code_lines: list[str]) -> Block:
    words = header.split()
    if len(words) < 2 or words[1] not in RUN_LANGUAGES:
        raise DocsFormatError(f"{file}:{line}: write 'docs-test: twin ID LANGUAGE [options]'")
    twin = Block(page=page, file=file, line=line + 1, language=words[1],
                 code=_dedent(code_lines), twin_id=words[0])
    for option in words[2:]:
        if option == "slow":
            twin.slow = True
        elif option == "alone":
            twin.alone = True
        elif option.startswith("needs="):
            twin.needs = tuple(n for n in option[len("needs="):].split(",") if n)
        else:
            raise DocsFormatError(f"{file}:{line}: unknown twin option {option!r}")
    if not twin.code.strip():
        raise DocsFormatError(f"{file}:{line}: twin {words[0]} has no code")
    return twin


def _dedent(lines: list[str]) -> str:
    widths = [len(s) - len(s.lstrip()) for s in lines if s.strip()]
    cut = min(widths, default=0)
    return "\n".join(s[cut:] for s in lines) + "\n"


def parse_page(path: Path, root: Path = REPO_ROOT, page: str | None = None) -> list[Block]:
    """Reads every fenced block and hidden twin of a Markdown page, in page order.

    Args:
        path: the page.
        root: the folder file names are relative to.
        page: the page the blocks belong to (default: the file itself).

    Returns:
        The blocks, fenced and hidden twins, in the order they stand on the page.

    Raises:
        DocsFormatError: for an unknown directive, a malformed twin, an unclosed fence, or
            directives that stand before no block.
    """
    file = path.relative_to(root).as_posix()
    page = page or file
    lines = path.read_text(encoding="utf-8").splitlines()
    blocks: list[Block] = []
    pending = _Pending()
    i = 0
    while i < len(lines):
        text = lines[i]
        twin = _TWIN_OPEN.match(text)
        directive = _DIRECTIVE.match(text)
        fence = _FENCE.match(text)
        if twin:
            end = i + 1
            while end < len(lines) and lines[end].strip() != "-->":
                if "-->" in lines[end]:
                    raise DocsFormatError(f"{page}:{end + 1}: end a twin with '-->' alone")
                end += 1
            if end == len(lines):
                raise DocsFormatError(f"{page}:{i + 1}: twin comment never closed")
            blocks.append(_twin(page, file, i + 1, twin["header"], lines[i + 1:end]))
            i = end + 1
            continue
        if directive:
            _apply_directive(directive["body"], pending, f"{page}:{i + 1}")
            pending.lines.append(i + 1)
            i += 1
            continue
        if fence:
            indent, marker = fence["indent"], fence["fence"]
            info = fence["info"].strip()
            language = info.split()[0].lstrip(".").lower() if info else ""
            end = i + 1
            closing = re.compile(rf"^[ \t]*{re.escape(marker[0])}{{{len(marker)},}}[ \t]*$")
            while end < len(lines) and not closing.match(lines[end]):
                end += 1
            if end == len(lines):
                raise DocsFormatError(f"{page}:{i + 1}: unclosed code fence")
            body = [s[len(indent):] if s.startswith(indent) else s.lstrip()
                    for s in lines[i + 1:end]]
            blocks.append(Block(
                page=page, file=file, line=i + 2, language=language, code=_dedent(body),
                skip=pending.skip, covered_by=pending.covered_by, alone=pending.alone,
                write=pending.write, needs=pending.needs, slow=pending.slow,
            ))
            pending = _Pending()
            i = end + 1
            continue
        if text.strip() and pending.lines:
            raise DocsFormatError(
                f"{file}:{pending.lines[0]}: a docs-test directive must stand right before "
                "its code block")
        i += 1
    if pending.lines:
        raise DocsFormatError(f"{file}:{pending.lines[0]}: directive before no code block")
    return blocks


def load_page(path: Path, root: Path = REPO_ROOT, twins_dir: Path = TWINS_DIR) -> list[Block]:
    """A page's blocks with its twins from ``twins_dir`` placed after the blocks naming them.

    Raises:
        DocsFormatError: as :func:`parse_page`, or for a fenced block in a twins file, or a
            twin there that no block of the page names.
    """
    page = path.relative_to(root).as_posix()
    blocks = parse_page(path, root, page)
    twins_file = twins_dir / page
    if not twins_file.is_file():
        return blocks
    outside = parse_page(twins_file, root, page)
    if any(b.twin_id is None for b in outside):
        raise DocsFormatError(f"{twins_file}: holds a code block that is no twin")
    by_id = {b.twin_id: b for b in outside}
    merged: list[Block] = []
    for block in blocks:
        merged.append(block)
        merged += [by_id.pop(t) for t in block.covered_by if t in by_id]
    if by_id:
        raise DocsFormatError(f"{twins_file}: no block of {page} names twins {sorted(by_id)}")
    return merged


def docs_pages(root: Path = REPO_ROOT) -> list[Path]:
    """README.md and every Markdown page under docs/, in a stable order."""
    return [root / "README.md", *sorted((root / "docs").rglob("*.md"))]


def missing_need(block: Block) -> str | None:
    """Why the block cannot run here (a reason to skip with), or None when it can."""
    for need in block.all_needs():
        if need == "shared":
            if not (SHARED_DIR / "scenes").is_dir():
                return "needs ../shared/scenes (the research-only sample meshes)"
        elif need == "gpu":
            if not _cuda_available():
                return "needs a CUDA GPU"
        elif need == "network":
            return "needs the network (tests run offline)"
        elif importlib.util.find_spec(need.split(".")[0]) is None or (
                "." in need and _find_submodule(need) is None):
            return f"needs the Python module {need!r} (an optional extra)"
    return None


def _find_submodule(name: str) -> object | None:
    try:
        return importlib.util.find_spec(name)
    except ModuleNotFoundError:
        return None


def _cuda_available() -> bool:
    if importlib.util.find_spec("torch") is None:
        return False
    import torch

    return bool(torch.cuda.is_available())


# ---------------------------------------------------------------------------------------------
# Running blocks


_DRIVER = r"""
import json, sys, traceback
namespace = {"__name__": "__main__", "__builtins__": __builtins__}
token = sys.argv[1]
for request in sys.stdin:
    request = json.loads(request)
    ok = True
    try:
        exec(compile(request["source"], request["filename"], "exec"), namespace)
    except SystemExit as exit_:
        ok = exit_.code in (None, 0)
        if not ok:
            print(f"SystemExit: {exit_.code!r}", file=sys.stderr)
    except BaseException:
        traceback.print_exc()
        ok = False
    sys.stdout.flush()
    sys.stderr.flush()
    print(token + json.dumps(ok), flush=True)
"""


@dataclass
class Outcome:
    """What running a block gave."""

    ok: bool
    output: str
    seconds: float


def _kill(process: subprocess.Popen) -> None:
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    process.wait()


class PythonSession:
    """One Python process that executes blocks in a shared namespace, as a reader's REPL."""

    def __init__(self, cwd: Path, env: dict[str, str]) -> None:
        self.token = f"@@docs-test-{uuid.uuid4().hex}@@"
        self.process = subprocess.Popen(
            [sys.executable, "-u", "-c", _DRIVER, self.token], cwd=cwd, env=env,
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            text=True, bufsize=1, start_new_session=True,
        )
        self.lines: queue.Queue[str | None] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.lines.put(line)
        self.lines.put(None)

    def run(self, block: Block, timeout_s: float = BLOCK_TIMEOUT_S) -> Outcome:
        """Executes the block; its tracebacks carry the page's line numbers."""
        start = time.perf_counter()
        source = "\n" * (block.line - 1) + block.code
        request = json.dumps({"source": source, "filename": block.file})
        assert self.process.stdin is not None
        try:
            self.process.stdin.write(request + "\n")
            self.process.stdin.flush()
        except BrokenPipeError:
            return Outcome(False, "the page's Python process has exited", 0.0)
        output: list[str] = []
        deadline = start + timeout_s
        while True:
            try:
                line = self.lines.get(timeout=max(0.0, deadline - time.perf_counter()))
            except queue.Empty:
                self.close()
                output.append(f"\n[timed out after {timeout_s:.0f} s]")
                return Outcome(False, "".join(output), time.perf_counter() - start)
            if line is None:
                output.append(f"\n[the Python process exited with {self.process.wait()}]")
                return Outcome(False, "".join(output), time.perf_counter() - start)
            if self.token in line:  # after the block's last output, even one with no newline
                before, _, after = line.partition(self.token)
                output.append(before)
                return Outcome(bool(json.loads(after)), "".join(output),
                               time.perf_counter() - start)
            output.append(line)

    def retire(self) -> None:
        """Asks the process to end (it exits when it reads the end of its input)."""
        if self.process.stdin is not None and not self.process.stdin.closed:
            try:
                self.process.stdin.close()
            except BrokenPipeError:
                pass

    def close(self) -> None:
        """Ends the process and waits for it."""
        self.retire()
        try:
            self.process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            _kill(self.process)


def run_command(argv: list[str], cwd: Path, env: dict[str, str],
                timeout_s: float = BLOCK_TIMEOUT_S) -> Outcome:
    """Runs a command in its own process group; kills the group on timeout."""
    start = time.perf_counter()
    process = subprocess.Popen(argv, cwd=cwd, env=env, stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        output, _ = process.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        _kill(process)
        return Outcome(False, f"[timed out after {timeout_s:.0f} s]",
                       time.perf_counter() - start)
    return Outcome(process.returncode == 0, output, time.perf_counter() - start)


def console_scripts() -> dict[str, str]:
    """The package's console scripts from pyproject.toml: name -> ``module:function``."""
    text = (REPO_ROOT / "pyproject.toml").read_text(encoding="utf-8")
    section = re.search(r"^\[project\.scripts\]\n(?P<body>(?:[^\[].*\n|\n)*)", text, re.M)
    if section is None:
        return {}
    return dict(re.findall(r'^([\w-]+)\s*=\s*"([\w.]+:\w+)"', section["body"], re.M))


def _shims(folder: Path) -> Path:
    """A folder of ``python`` and the package's console scripts, all on this interpreter.

    A console script is a Python file run by path, as pip's launchers do, so that its import
    path starts with its own folder and not with the working directory; this checkout comes
    next, even where a block sets ``PYTHONPATH`` itself.
    """
    folder.mkdir(parents=True, exist_ok=True)
    for name in ("python", "python3"):
        (folder / name).symlink_to(sys.executable)
    for name, target in console_scripts().items():
        module, function = target.split(":")
        script = folder / f"{name}.py"
        script.write_text(f"import sys\n\nsys.path.insert(1, {str(REPO_ROOT)!r})  # this checkout\n"
                          f"from {module} import {function}\n\n"
                          f"if __name__ == '__main__':\n    sys.argv[0] = {name!r}\n"
                          f"    sys.exit({function}())\n")
        shim = folder / name
        shim.write_text(f'#!/bin/sh\nexec "{sys.executable}" "{script}" "$@"\n')
        shim.chmod(0o755)
    return folder


def page_folder(base: Path) -> Path:
    """A reader's working folder: copies of the repository's scripts, ``../shared`` beside it.

    Returns:
        The folder to run a page's blocks in (``base/repo``).
    """
    work = base / "repo"
    work.mkdir(parents=True)
    for name in ("examples", "scripts"):
        shutil.copytree(REPO_ROOT / name, work / name,
                        ignore=shutil.ignore_patterns("__pycache__"))
    (work / "benchmarks" / "results").mkdir(parents=True)
    for script in (REPO_ROOT / "benchmarks").glob("*.py"):
        shutil.copy2(script, work / "benchmarks" / script.name)
    shutil.copy2(REPO_ROOT / "pyproject.toml", work / "pyproject.toml")
    if SHARED_DIR.is_dir():
        (base / "shared").symlink_to(SHARED_DIR)
    return work


def block_env(shims: Path) -> dict[str, str]:
    """The environment blocks run in: this checkout first on the import path, no display."""
    env = dict(os.environ)
    env["PATH"] = f"{shims}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = os.pathsep.join(
        p for p in (str(REPO_ROOT), env.get("PYTHONPATH", "")) if p)
    env["MPLBACKEND"] = "Agg"
    env.pop("DISPLAY", None)
    return env


class PageRun:
    """Runs one page's blocks in order in one folder, the Python ones in one session."""

    def __init__(self, blocks: list[Block], base: Path) -> None:
        self.blocks = blocks
        self.work = page_folder(base)
        self.env = block_env(_shims(base / "bin"))
        self.session: PythonSession | None = None
        self.retired: list[PythonSession] = []
        self.results: dict[int, Outcome] = {}

    def runnable(self, block: Block) -> bool:
        """Whether the runner runs this block here (a run language, no skip, needs met)."""
        return (block.runs_as is not None and block.skip is None
                and missing_need(block) is None)

    def run(self, block: Block) -> tuple[Outcome, list[str]]:
        """Runs the block after every earlier runnable block of the page not yet run (but the
        slow ones before a block that is not slow, so that ``-m "not slow"`` runs none).

        Returns:
            The block's outcome, and the ids of earlier blocks that failed.
        """
        index = self.blocks.index(block)
        for earlier, before in enumerate(self.blocks[:index]):
            if (earlier not in self.results and self.runnable(before)
                    and (block.slow or not before.slow)):
                self.results[earlier] = self._run(before)
        if index not in self.results:
            self.results[index] = self._run(block)
        if self.session is not None and not any(
                self._in_session(b) for b in self.blocks[index + 1:]):
            self.session.retire()  # the page's last Python block: free its memory now
            self.retired.append(self.session)
            self.session = None
        failed = [self.blocks[i].id for i in range(index)
                  if i in self.results and not self.results[i].ok]
        return self.results[index], failed

    def _in_session(self, block: Block) -> bool:
        return (self.runnable(block) and block.runs_as == "python" and not block.alone
                and block.write is None)

    def _run(self, block: Block) -> Outcome:
        if block.write is not None:
            target = self.work / block.write
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(block.code, encoding="utf-8")
            if block.runs_as == "python":  # the blocks that import it run it
                try:
                    compile(block.code, str(target), "exec")
                except SyntaxError as error:
                    return Outcome(False, f"{type(error).__name__}: {error}", 0.0)
                return Outcome(True, "", 0.0)
            return run_command(["bash", "-n", block.write], self.work, self.env)
        if block.runs_as == "bash":
            script = self.work.parent / (re.sub(r"\W+", "_", block.id) + ".sh")
            script.write_text(block.code, encoding="utf-8")
            return run_command(["bash", "-e", "-o", "pipefail", str(script)], self.work,
                               self.env)
        if block.alone:
            session = PythonSession(self.work, self.env)
            try:
                return session.run(block)
            finally:
                session.close()
        if self.session is None or self.session.process.poll() is not None:
            self.session = PythonSession(self.work, self.env)
        return self.session.run(block)

    def close(self) -> None:
        """Ends the page's Python sessions."""
        if self.session is not None:
            self.session.retire()
            self.retired.append(self.session)
            self.session = None
        for session in self.retired:
            session.close()
        self.retired.clear()
