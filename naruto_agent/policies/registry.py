"""Policies by name: the registry the demo, the benchmark harness and ``make_policy`` read.

A policy class registers itself with a decorator::

    @register_policy("frontier")
    class FrontierPolicy(Policy): ...

A policy whose module is costly to import (the NARUTO agent's planner and mappers) is also
registered by import path (:func:`register_lazy_policy`), so that listing and looking names up
does not import it: the first lookup imports the module, whose decorator then registers the
class and takes the lazy entry's place (the lookup checks that the two name the same class).
Any ``Policy`` subclass can also be named by its import path, ``"package.module:ClassName"``,
without registering.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any, TypeVar

from naruto_agent.policies.base import Policy

PolicyT = TypeVar("PolicyT", bound=type[Policy])

POLICIES: dict[str, type[Policy]] = {}
"""Registered policy classes by name."""

LAZY_POLICIES: dict[str, str] = {"naruto": "naruto_agent.naruto:NarutoPolicy"}
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
    """The policy class of a registry name or a ``"package.module:ClassName"`` import path.

    Raises:
        ValueError: an unknown name, a path that does not import, or a class that is not a
            ``Policy`` subclass.
    """
    if name in POLICIES:
        return POLICIES[name]
    target = LAZY_POLICIES.get(name, name)
    if ":" not in target:
        raise ValueError(
            f"unknown policy {name!r}; use one of {policy_names()} or "
            "'package.module:ClassName'"
        )
    module_name, _, attribute = target.partition(":")
    try:
        cls = getattr(importlib.import_module(module_name), attribute)
    except (ImportError, AttributeError) as error:
        raise ValueError(f"cannot import policy {target!r}: {error}") from error
    if not (isinstance(cls, type) and issubclass(cls, Policy)):
        raise ValueError(f"{target!r} is not a naruto_agent.policies.Policy subclass")
    registered = POLICIES.get(name)
    if registered is not None and registered is not cls:
        raise ValueError(f"policy name {name!r} names {target!r}, but importing it registered "
                         f"{registered.__module__}.{registered.__qualname__} under that name")
    if name in LAZY_POLICIES:  # no decorator ran on import (none, or imported before)
        register_policy(name)(cls)
    return cls


def make_policy(name: str, **kwargs: Any) -> Policy:
    """Build a policy by registry name or import path, with constructor keyword arguments."""
    return policy_class(name)(**kwargs)
