"""Checks of settings, each raising a ``ValueError`` that names the setting and what to pass.

One set for every package: the env's keywords (:mod:`naruto_gym.envs.validation`) and the
agent's configurations (``naruto_agent``'s ``config`` modules) are checked with these, so that
a wrong type, a NaN or a value out of range reads the same everywhere.
"""

from __future__ import annotations

import math
from numbers import Integral, Real
from typing import Any

import numpy as np

__all__ = ["check_bool", "check_choice", "check_integer", "check_number", "is_integer", "is_real"]


def is_real(value: Any) -> bool:
    """Whether ``value`` is a real number (NumPy's included) and not a bool."""
    return isinstance(value, Real) and not isinstance(value, (bool, np.bool_))


def is_integer(value: Any) -> bool:
    """Whether ``value`` is an integer (NumPy's included) and not a bool."""
    return isinstance(value, Integral) and not isinstance(value, (bool, np.bool_))


def check_number(
    name: str,
    value: Any,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = True,
    high_open: bool = False,
) -> float:
    """``value`` as a float, or a ``ValueError`` naming ``name``: it must be a finite real
    number (not a bool), above ``low`` (or at least it, ``low_open=False``) and at most
    ``high`` (or below it, ``high_open=True``)."""
    if not is_real(value) or not math.isfinite(float(value)):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    number = float(value)
    if low is not None and (number <= low if low_open else number < low):
        relation = "greater than" if low_open else "at least"
        raise ValueError(f"{name} must be {relation} {low:g}, got {value!r}")
    if high is not None and (number >= high if high_open else number > high):
        relation = "less than" if high_open else "at most"
        raise ValueError(f"{name} must be {relation} {high:g}, got {value!r}")
    return number


def check_integer(name: str, value: Any, *, low: int = 1, high: int | None = None) -> int:
    """``value`` as an int, or a ``ValueError``: an integer (not a bool) in [low, high]."""
    if not is_integer(value) or value < low or (high is not None and value > high):
        upper = f" and at most {high:,}" if high is not None else ""
        raise ValueError(f"{name} must be an integer of at least {low}{upper}, got {value!r}")
    return int(value)


def check_choice(name: str, value: Any, choices: tuple[str, ...]) -> str:
    """``value`` when it is one of the strings ``choices``, else a ``ValueError``."""
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{name} must be one of {choices}, got {value!r}")
    return value


def check_bool(name: str, value: Any) -> bool:
    """``value`` when it is a bool (Python's or NumPy's), else a ``ValueError``."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)
