"""Mappers by name: the registry that ``NarutoPolicy(mapper_kind=...)`` reads.

A mapper kind is named as a policy is (:mod:`naruto_agent.policies.registry`): a registered
name (:func:`mapper_names`: ``"tsdf"``, ``"neural"`` and what :func:`register_mapper` added),
an import path ``"package.module:ClassName"`` (a module in the working directory is found) or
a file path ``"path/to/file.py:ClassName"`` (:mod:`naruto_agent.import_paths`).

What a name resolves to is a *mapper factory*: a class (or function) called once per episode
as ``factory(bounds, camera, **settings)``, with ``bounds`` the scene's (2, 3) world box in
metres and ``camera`` the frames' :class:`~naruto_gym.sensors.pinhole.PinholeCamera`. A
factory that names a ``device`` parameter also gets the agent's device (``"auto"``,
``"cpu"``, ``"cuda[:N]"``), and one that names a ``seed`` parameter gets a seed drawn from the
agent's randomness, so that episodes repeat. What it returns must have every member of
:class:`~naruto_agent.mapping.base.Mapper`, or it is refused with what it lacks.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import replace
from typing import Any, TypeVar

import numpy as np

from naruto_agent.import_paths import load_target
from naruto_agent.mapping.base import MAPPER_MEMBERS, Mapper, missing_members, missing_methods
from naruto_agent.mapping.config import NeuralMapperConfig
from naruto_agent.mapping.neural_mapper import NeuralMapper
from naruto_agent.mapping.tsdf_mapper import TsdfMapperConfig, TsdfUncertaintyMapper
from naruto_gym.sensors.pinhole import PinholeCamera

FactoryT = TypeVar("FactoryT", bound=Callable[..., Any])

MAPPERS: dict[str, Callable[..., Any]] = {}
"""Registered mapper factories by name."""

#: Where the members a mapper must have are explained.
_GUIDE = "see naruto_agent.mapping.Mapper and docs/mappers.md"


def register_mapper(name: str, *, replace: bool = False) -> Callable[[FactoryT], FactoryT]:
    """A decorator that registers a mapper class (or factory function) under ``name``.

    Args:
        name: the registry name (``NarutoPolicy(mapper_kind=name)``).
        replace: let this factory take a name another holds.

    Raises:
        TypeError: the decorated object is not callable, or is a class that lacks a method
            of :class:`~naruto_agent.mapping.base.Mapper`.
        ValueError: another factory holds the name (and ``replace`` is False).
    """

    def decorator(factory: FactoryT) -> FactoryT:
        _refuse_incomplete(factory, f"register_mapper({name!r}): {factory!r}", TypeError)
        holder = MAPPERS.get(name)
        if holder is not None and holder is not factory and not replace:
            raise ValueError(
                f"mapper name {name!r} is taken by {holder.__module__}."
                f"{holder.__qualname__}; pick another or pass replace=True"
            )
        MAPPERS[name] = factory
        return factory

    return decorator


def mapper_names() -> list[str]:
    """Every registered mapper name, sorted."""
    return sorted(MAPPERS)


def mapper_factory(kind: str) -> Callable[..., Any]:
    """The factory of a mapper kind: a registered name, an import path or a file path.

    A class is checked for the methods of :class:`~naruto_agent.mapping.base.Mapper` here,
    before any episode (its ``observed_space`` is checked on the mapper it builds).

    Raises:
        ValueError: an unknown name, a module or file that does not load, a name it does not
            define, something that is not callable, or a class that lacks a method (the
            message names what is missing).
    """
    if not isinstance(kind, str):
        raise ValueError(f"mapper_kind must be a string, got {kind!r}")
    if kind in MAPPERS:
        return MAPPERS[kind]
    factory = load_target(kind, kind, "mapper", mapper_names())
    if factory is None:
        source, _, attribute = kind.rpartition(":")
        raise ValueError(f"cannot import mapper {kind!r}: {source} has no {attribute!r}")
    _refuse_incomplete(factory, f"mapper {kind!r}", ValueError)
    return factory


def _refuse_incomplete(factory: object, label: str, error: type[Exception]) -> None:
    """Raise ``error`` naming what ``factory`` lacks: it is not callable, or it is a class
    without a method of :class:`~naruto_agent.mapping.base.Mapper`."""
    if not callable(factory):
        raise error(f"{label} is not a class or function, got {factory!r}")
    lacking = missing_methods(factory) if isinstance(factory, type) else []
    if lacking:
        raise error(f"{label} lacks what the NARUTO agent reads: {', '.join(lacking)} ({_GUIDE})")


def make_mapper(
    kind: str,
    bounds: np.ndarray,
    camera: PinholeCamera,
    *,
    device: str = "auto",
    rng: np.random.Generator | None = None,
    settings: dict[str, Any] | None = None,
) -> Mapper:
    """Build the mapper of ``kind`` for a scene (see the module docstring).

    Args:
        kind: a registered name, ``"package.module:ClassName"`` or ``"file.py:ClassName"``.
        bounds: (2, 3) world box of the scene, metres.
        camera: intrinsics of the frames.
        device: handed to a factory with a ``device`` parameter.
        rng: a seed is drawn from it for a factory with a ``seed`` parameter (one draw; a
            fresh generator when None); a factory without one leaves it untouched.
        settings: further keyword arguments of the factory.

    Raises:
        ValueError: as :func:`mapper_factory`, settings the factory does not take, or a
            mapper that lacks a member of :class:`~naruto_agent.mapping.base.Mapper` (the
            message names what is missing).
    """
    factory = mapper_factory(kind)
    kwargs = dict(settings or {})
    parameters = _named_parameters(factory)
    for name in ("device", "seed"):
        if name in kwargs:
            raise ValueError(f"mapper settings must not hold {name!r}: the agent passes it")
    if "device" in parameters:
        kwargs["device"] = device
    if "seed" in parameters:
        kwargs["seed"] = int((rng or np.random.default_rng()).integers(2**31 - 1))
    try:
        mapper = factory(bounds, camera, **kwargs)
    except TypeError as error:  # a setting the factory does not take, or a bad signature
        raise ValueError(
            f"cannot build mapper {kind!r} with settings {sorted(kwargs)}: {error}"
        ) from error
    lacking = missing_members(mapper)
    if lacking:
        raise ValueError(
            f"mapper {kind!r} built a {type(mapper).__qualname__} that lacks "
            f"what the NARUTO agent reads: {', '.join(lacking)}; a mapper has "
            f"{', '.join(MAPPER_MEMBERS)} ({_GUIDE})"
        )
    return mapper


def _named_parameters(factory: Callable[..., Any]) -> set[str]:
    """The parameter names of a factory's signature (empty when it has none to read)."""
    try:
        return set(inspect.signature(factory).parameters)
    except (TypeError, ValueError):
        return set()


@register_mapper("tsdf")
def tsdf_mapper(
    bounds: np.ndarray,
    camera: PinholeCamera,
    *,
    device: str = "auto",
    config: TsdfMapperConfig | None = None,
    **settings: Any,
) -> TsdfUncertaintyMapper:
    """The TSDF mapper: ``config`` (the defaults when None) with ``settings`` and the device
    applied."""
    config = replace(config or TsdfMapperConfig(), device=device, **settings)
    return TsdfUncertaintyMapper(bounds, camera, config)


@register_mapper("neural")
def neural_mapper(
    bounds: np.ndarray,
    camera: PinholeCamera,
    *,
    device: str = "auto",
    seed: int = 0,
    config: NeuralMapperConfig | None = None,
    **settings: Any,
) -> NeuralMapper:
    """The neural mapper (the published one): ``config`` (the defaults when None) with
    ``settings``, the device and the seed applied."""
    config = replace(config or NeuralMapperConfig(), device=device, seed=seed, **settings)
    return NeuralMapper(bounds, camera, config)
