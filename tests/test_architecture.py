"""The library's shape: module sizes, import layers and cycles, no reach into private names.

These read the source with :mod:`ast` (nothing is imported), so they are fast and hold for
every module, including imports made inside functions.
"""

from __future__ import annotations

import ast
import re
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("naruto_gym", "naruto_agent")
MAX_MODULE_LINES = 700

#: Packages from the lowest layer to the highest: a module may import its own package and
#: the ones before it, never one after it.
LAYERS: dict[str, tuple[str, ...]] = {
    "naruto_gym": (),
    "naruto_agent.mapping": ("naruto_gym",),
    "naruto_agent.planning": ("naruto_gym", "naruto_agent.mapping"),
    "naruto_agent.guards": ("naruto_gym", "naruto_agent.mapping"),
    "naruto_agent.policies": (
        "naruto_gym",
        "naruto_agent.mapping",
        "naruto_agent.planning",
        "naruto_agent.guards",
    ),
    "naruto_agent.naruto": (
        "naruto_gym",
        "naruto_agent.mapping",
        "naruto_agent.planning",
        "naruto_agent.guards",
        "naruto_agent.policies",
    ),
    # Draws what policies show (Policy.view_layers); no policy imports it.
    "naruto_agent.recording": (
        "naruto_gym",
        "naruto_agent.mapping",
        "naruto_agent.planning",
        "naruto_agent.guards",
        "naruto_agent.policies",
        "naruto_agent.naruto",
    ),
}


def module_files() -> dict[str, Path]:
    """Dotted module name -> file, for every module of the packages."""
    modules = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            modules[".".join(parts)] = path
    return modules


MODULES = module_files()


def imported_modules(name: str, path: Path) -> set[str]:
    """The package modules that a module imports anywhere (top level or inside functions)."""
    tree = ast.parse(path.read_text())
    found = set()
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            targets = [base] + [f"{base}.{alias.name}" for alias in node.names]
        else:
            continue
        for target in targets:
            if target in MODULES:
                found.add(target)
    found.discard(name)
    return found


def owning_layer(module: str) -> str | None:
    matches = [layer for layer in LAYERS if module == layer or module.startswith(layer + ".")]
    return max(matches, key=len) if matches else None


def test_no_module_is_too_long() -> None:
    long = {
        name: len(path.read_text().splitlines())
        for name, path in MODULES.items()
        if len(path.read_text().splitlines()) > MAX_MODULE_LINES
    }
    assert not long, f"split these modules (at most {MAX_MODULE_LINES} lines each): {long}"


def test_lower_layers_never_import_upper_ones() -> None:
    wrong = []
    for name, path in MODULES.items():
        layer = owning_layer(name)
        if layer is None:
            continue
        allowed = (layer, *LAYERS[layer])
        for target in imported_modules(name, path):
            target_layer = owning_layer(target)
            if target_layer is not None and target_layer not in allowed:
                wrong.append(f"{name} imports {target}")
            elif target_layer is None and layer in LAYERS and target.startswith("naruto_agent"):
                if layer == "naruto_gym":
                    wrong.append(f"{name} imports {target}")
    assert not wrong, "imports against the layers:\n" + "\n".join(wrong)


def test_no_import_cycles() -> None:
    """No cycle between modules, counting imports inside functions (a package's
    ``__init__`` re-exporting its modules is not a cycle of theirs)."""
    graph = defaultdict(set)
    for name, path in MODULES.items():
        if path.name == "__init__.py":
            continue
        for target in imported_modules(name, path):
            if MODULES[target].name != "__init__.py":
                graph[name].add(target)
    cycles = []
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> None:
        state[node] = 1
        stack.append(node)
        for target in sorted(graph[node]):
            if state.get(target) == 1:
                cycles.append(stack[stack.index(target) :] + [target])
            elif target not in state:
                visit(target)
        stack.pop()
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node)
    assert not cycles, "import cycles:\n" + "\n".join(" -> ".join(c) for c in cycles)


def private_names_defined(tree: ast.AST) -> set[str]:
    """Private names a module defines: functions, classes, attributes it sets on ``self`` or
    ``cls``, and module or local names."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif (
            isinstance(node, ast.Attribute)
            and isinstance(node.ctx, ast.Store)
            and isinstance(node.value, ast.Name)
            and node.value.id in ("self", "cls")
        ):
            names.add(node.attr)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return {name for name in names if name.startswith("_")}


def private_reach(path: Path) -> list[str]:
    """``something._name`` in a module that does not define ``_name`` itself: a read of
    another module's private attribute."""
    tree = ast.parse(path.read_text())
    own = private_names_defined(tree)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute):
            if isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"):
                continue  # a class's own or inherited (protected) attribute
            attr = node.attr
            if attr.startswith("_") and not attr.startswith("__") and attr not in own:
                found.append(f"{path.relative_to(ROOT)}:{node.lineno} .{attr}")
        elif isinstance(node, ast.ImportFrom) and node.module:
            for alias in node.names:
                if alias.name.startswith("_") and not alias.name.startswith("__"):
                    found.append(f"{path.relative_to(ROOT)}:{node.lineno} imports {alias.name}")
    return found


#: Private names of other libraries that have no public equivalent.
THIRD_PARTY_PRIVATE = {"_asdict", "_replace", "_fields", "_make", "_np_random"}


@pytest.mark.parametrize("folder", [*PACKAGES, "benchmarks"])
def test_no_reads_of_other_modules_private_attributes(folder: str) -> None:
    found = [
        hit
        for path in sorted((ROOT / folder).rglob("*.py"))
        for hit in private_reach(path)
        if hit.rpartition(".")[2] not in THIRD_PARTY_PRIVATE
    ]
    assert not found, "add a public seam for these:\n" + "\n".join(found)


def test_no_stack_walks() -> None:
    users = [
        str(path.relative_to(ROOT))
        for package in PACKAGES
        for path in (ROOT / package).rglob("*.py")
        if "_getframe" in path.read_text()
    ]
    assert not users, f"pass what these need as arguments instead: {users}"


def test_the_wrappers_package_imports_its_modules_at_the_top() -> None:
    """``naruto_gym.wrappers`` (metrics, observation, learning, vector) imports the package's
    modules at the top of each file, never inside a function: its dependencies are in sight
    and run one way (observation <- vector <- learning)."""
    hidden = []
    for name, path in MODULES.items():
        if not name.startswith("naruto_gym.wrappers"):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                for inner in ast.walk(node):
                    if isinstance(inner, ast.ImportFrom) and (inner.module or "").startswith(
                        "naruto_gym"
                    ):
                        hidden.append(f"{name}:{inner.lineno} imports {inner.module}")
    assert not hidden, "imports inside functions:\n" + "\n".join(hidden)


PACKAGE_INITS = sorted(path for name, path in MODULES.items() if path.name == "__init__.py")


@pytest.mark.parametrize("init", PACKAGE_INITS, ids=lambda path: path.parent.name)
def test_every_package_says_what_it_holds(init: Path) -> None:
    """Each package opens with a docstring; a top-level package's names every one of its
    subpackages and modules, so that a part added is a part described."""
    doc = ast.get_docstring(ast.parse(init.read_text())) or ""
    where = init.relative_to(ROOT)
    assert doc.strip(), f"{where} has no docstring: say in one line what the package holds"
    if init.parent.name not in PACKAGES:
        return
    parts = [path.stem for path in init.parent.glob("*.py") if path.name != "__init__.py"]
    parts += [path.name for path in init.parent.iterdir() if (path / "__init__.py").is_file()]
    unnamed = sorted(part for part in parts if not re.search(rf"\b{part}\b", doc))
    assert not unnamed, f"{where}'s docstring does not name {unnamed}: say what they hold"
