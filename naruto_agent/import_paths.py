"""Load a user's code by the name the command-line tools take: ``"package.module:Name"`` or
``"path/to/file.py:Name"``.

The policy registry (:mod:`naruto_agent.policies.registry`) and the mapper registry
(:mod:`naruto_agent.mapping.registry`) both take a user's class as they find it, so that a
policy or a mapper need not be registered, installed or on ``PYTHONPATH``:

* ``"package.module:Name"``: imported as ``python -m`` would find it; a module in the working
  directory is found too (the directory is appended to ``sys.path``, so it never shadows an
  installed module).
* ``"path/to/file.py:Name"``: the file is executed once per path (absolute, or relative to the
  working directory); later loads return the same module, so its classes stay the same
  objects.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import os
import sys
from pathlib import Path
from types import ModuleType
from typing import Any


def is_file_source(source: str) -> bool:
    """True when the part of a name before ``:Name`` is a file path (it ends in ``.py`` or
    holds a path separator), not a dotted module name."""
    return source.endswith(".py") or "/" in source or os.sep in source


def load_target(name: str, target: str, what: str, registered: list[str]) -> Any:
    """What ``target`` (``"source:Name"``) names: the ``Name`` attribute of the module or file
    ``source`` (None when it has none).

    Args:
        name: the name as the user gave it (a registered name, or the target itself).
        target: ``"package.module:Name"`` or ``"path/to/file.py:Name"``.
        what: what the name is of (``"policy"``, ``"mapper"``), for the messages.
        registered: the registered names, for the message of a name that is neither.

    Raises:
        ValueError: ``target`` names no ``source:Name``, or its module or file does not load
            (:func:`import_source`).
    """
    if ":" not in target:
        hint = " (a file needs its class: 'FILE.py:ClassName')" if target.endswith(".py") else ""
        raise ValueError(
            f"unknown {what} {name!r}{hint}; use one of {registered}, "
            "'package.module:ClassName' or 'path/to/file.py:ClassName'"
        )
    source, _, attribute = target.rpartition(":")
    return getattr(import_source(source, target, what), attribute, None)


def import_source(source: str, target: str, what: str) -> ModuleType:
    """The module that ``source`` names: a dotted module name or a ``.py`` file path.

    Args:
        source: the part of ``target`` before ``:Name``.
        target: the whole name (``"source:Name"``), for the messages.
        what: what the name is of (``"policy"``, ``"mapper"``), for the messages and the
            name a file's module gets in ``sys.modules``.

    Raises:
        ValueError: a module that does not exist or fails to import, or a file that does not
            exist, is not a ``.py`` file or fails to load (the message says which).
    """
    if is_file_source(source):
        return _load_file(source, what)
    return _import_module(source, target, what)


def _import_module(module_name: str, target: str, what: str) -> ModuleType:
    """Import a module by name; one that is not on ``sys.path`` is looked for in the working
    directory too (appended to ``sys.path``, so it never shadows an installed module)."""
    try:
        return importlib.import_module(module_name)
    except ModuleNotFoundError as error:
        top = module_name.partition(".")[0]
        cwd = os.getcwd()
        if error.name != top:  # the module was found; something it imports was not
            raise ValueError(f"cannot import {what} {target!r}: {error}") from error
        if cwd in sys.path or not _importable_from(cwd, top):
            raise ValueError(
                f"cannot import {what} {target!r}: {error} (searched sys.path and the working "
                f"directory {cwd}; name a file instead: 'path/to/file.py:ClassName')"
            ) from error
        sys.path.append(cwd)
    except ImportError as error:
        raise ValueError(f"cannot import {what} {target!r}: {error}") from error
    try:
        return importlib.import_module(module_name)
    except ImportError as error:
        raise ValueError(f"cannot import {what} {target!r}: {error}") from error


def _importable_from(folder: str, top: str) -> bool:
    """True when ``folder`` holds the module or package ``top`` (a package may be a folder
    without ``__init__.py``, as ``examples/`` is)."""
    base = Path(folder) / top
    return base.with_suffix(".py").is_file() or base.is_dir()


def _load_file(source: str, what: str) -> ModuleType:
    """Execute a ``.py`` file once per path (later calls get the same module).

    Raises:
        ValueError: the file does not exist, is not a ``.py`` file or fails to load.
    """
    path = Path(source).expanduser()
    if not path.is_absolute():
        path = Path.cwd() / path
    if not path.is_file():
        raise ValueError(
            f"{what} file {source!r} does not exist (looked at {path}); give a path to a .py "
            "file, absolute or relative to the working directory"
        )
    if path.suffix != ".py":
        raise ValueError(f"{what} file {source!r} is not a .py file")
    path = path.resolve()
    digest = hashlib.sha1(str(path).encode()).hexdigest()[:10]
    module_name = f"_naruto_{what}_file_{digest}_{path.stem}"
    if module_name in sys.modules:
        return sys.modules[module_name]
    spec = importlib.util.spec_from_file_location(module_name, path)
    if spec is None or spec.loader is None:
        raise ValueError(f"cannot load {what} file {source!r}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module  # dataclasses and pickling look classes up there
    try:
        spec.loader.exec_module(module)
    except Exception as error:  # the user's file: any error is a load failure
        del sys.modules[module_name]
        raise ValueError(
            f"cannot load {what} file {source!r}: {type(error).__name__}: {error}"
        ) from error
    return module
