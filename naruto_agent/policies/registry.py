"""Policies by name: the registry the demo, the benchmark harness and ``make_policy`` read.

A policy class registers itself with a decorator::

    @register_policy("frontier")
    class FrontierPolicy(Policy): ...

A policy whose module is costly to import (the NARUTO agent's planner and mappers) is also
registered by import path (:func:`register_lazy_policy`), so that listing and looking names up
does not import it: the first lookup imports the module, whose decorator then registers the
class and takes the lazy entry's place (the lookup checks that the two name the same class). Any
``Policy`` subclass can also be named without registering, by its import path
(``"package.module:ClassName"``, a module in the working directory included, as ``python -m``
finds it) or by its file (``"path/to/file.py:ClassName"``), so that the command-line tools
take a user's policy as they find it.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from types import ModuleType
from typing import Any, TypeVar

from naruto_agent.import_paths import import_source, is_file_source, load_target
from naruto_agent.policies.base import Policy

PolicyT = TypeVar("PolicyT", bound=type[Policy])

POLICIES: dict[str, type[Policy]] = {}
"""Registered policy classes by name."""

LAZY_POLICIES: dict[str, str] = {
    "naruto": "naruto_agent.naruto:NarutoPolicy",
    "explorer": "naruto_agent.rl.explorer_policy:MapGoalExplorer",
    "explorer-untrained": "naruto_agent.rl.explorer_policy:UntrainedMapGoalExplorer",
    "goal-walker": "naruto_agent.rl.scripted_explorer:GoalWalkerPolicy",
    "goal-ranker": "naruto_agent.rl.ranker_policy:GoalRankerPolicy",
    "goal-ranker-untrained": "naruto_agent.rl.ranker_policy:UntrainedGoalRankerPolicy",
}
"""Registered names resolved by import path on first lookup (their modules are costly to
import)."""


def register_policy(name: str, *, replace: bool = False) -> Callable[[PolicyT], PolicyT]:
    """A class decorator that registers a :class:`Policy` subclass under ``name``.

    Args:
        name: the registry name (``--policy NAME``).
        replace: let this class take a name another class holds.

    Raises:
        TypeError: the decorated object is not a ``Policy`` subclass.
        ValueError: another class holds the name (and ``replace`` is False).
    """

    def decorator(cls: PolicyT) -> PolicyT:
        if not (isinstance(cls, type) and issubclass(cls, Policy)):
            raise TypeError(f"register_policy({name!r}) needs a Policy subclass, got {cls!r}")
        holder = POLICIES.get(name)
        if holder is not None and holder is not cls and not replace:
            raise ValueError(f"policy name {name!r} is taken by {holder.__module__}."
                             f"{holder.__qualname__}; pick another or pass replace=True")
        POLICIES[name] = cls
        LAZY_POLICIES.pop(name, None)
        return cls

    return decorator


def register_lazy_policy(name: str, target: str) -> None:
    """Register ``"package.module:ClassName"`` under ``name``, imported on first lookup."""
    if ":" not in target:
        raise ValueError(f"target must be 'package.module:ClassName', got {target!r}")
    if name in POLICIES:
        raise ValueError(f"policy name {name!r} is taken by {POLICIES[name].__qualname__}")
    LAZY_POLICIES[name] = target


def policy_names() -> list[str]:
    """Every registered name, imported or lazy, sorted."""
    return sorted(set(POLICIES) | set(LAZY_POLICIES))


def policy_class(name: str) -> type[Policy]:
    """The policy class of a registry name, an import path or a file path.

    Args:
        name: a registered name (:func:`policy_names`), ``"package.module:ClassName"`` (a
            module in the working directory is found without ``PYTHONPATH``), or
            ``"path/to/file.py:ClassName"`` (relative to the working directory).

    Raises:
        ValueError: an unknown name, a module or file that does not exist or does not load,
            a class it does not define, or a class that is not a ``Policy`` subclass.
    """
    if name in POLICIES:
        return POLICIES[name]
    target = LAZY_POLICIES.get(name, name)
    cls = load_target(name, target, "policy", policy_names())
    if cls is None:
        source, _, attribute = target.rpartition(":")
        module = import_source(source, target, "policy")  # loaded already: no second run
        defined = ", ".join(_policy_classes_in(module)) or "none"
        raise ValueError(
            f"cannot import policy {target!r}: {source} has no {attribute!r} (its Policy "
            f"subclasses: {defined})"
        )
    if not (isinstance(cls, type) and issubclass(cls, Policy)):
        raise ValueError(f"{target!r} is not a naruto_agent.policies.Policy subclass")
    registered = POLICIES.get(name)
    if registered is not None and registered is not cls:
        raise ValueError(f"policy name {name!r} names {target!r}, but importing it registered "
                         f"{registered.__module__}.{registered.__qualname__} under that name")
    if name in LAZY_POLICIES:  # no decorator ran on import (none, or imported before)
        register_policy(name)(cls)
    return cls


def is_policy_file(source: str) -> bool:
    """True when the part of a policy name before ``:ClassName`` is a file path (it ends in
    ``.py`` or holds a path separator), not a dotted module name."""
    return is_file_source(source)


def _policy_classes_in(module: ModuleType) -> list[str]:
    """Names of the ``Policy`` subclasses a module defines."""
    return sorted(
        name
        for name, value in vars(module).items()
        if inspect.isclass(value)
        and issubclass(value, Policy)
        and value is not Policy
        and value.__module__ == module.__name__
    )


def make_policy(name: str, **kwargs: Any) -> Policy:
    """Build a policy by registry name, import path or file path (see :func:`policy_class`),
    with constructor keyword arguments."""
    return policy_class(name)(**kwargs)
