"""Efficiency metrics of one episode: how fast its completion ratio rises, not only where it ends.

The final completion ratio saturates once a scene is small for the budget (every explorer
ends near 99 % in one room), so it stops telling policies apart. The published systems are
separated on large houses, and later work reports how fast a policy gets there (the area under
the curve, the steps to a level). These functions turn an episode's completion-ratio curve
into such numbers.

**The curve.** A record holds the completion ratio ``c`` (percent) at a few checkpoint steps
and at its last step (``completion_curve``, see :mod:`~naruto_agent.benchmark.runner`), and
the camera position after every step (``trajectory``). ``c`` is the completion ratio of the
*observable* surface where the record has it (the faces a camera inside the scene can see at
all: the whole-surface ratio also counts the outer faces of solid walls and slabs, so it stays
near half in a closed house and never reaches the levels below), else of the whole surface.
Between checkpoints ``c`` is taken as
linear; before the first step it is 0 (nothing is mapped before the episode starts); after the
last step it keeps its last value (an episode that ended early keeps what it mapped). The
path length ``l(t)`` after ``t`` steps is the summed distance between consecutive positions.

**Area over steps.** ``auc_steps = (1 / T) * integral_0^T c(t) dt / 100`` with ``T`` the step
budget: 1.0 for a policy that had everything from step 0, the final ratio / 100 for one that
got it all at the last step; a policy that gets to the same end sooner scores higher.

**Area over path length.** ``auc_path = (1 / D) * integral_0^D c(l) dl / 100`` where ``c(l)``
is the ratio the episode had while its path was at most ``l`` metres long (linear between
checkpoints, kept at its final value beyond the episode's whole path) and ``D`` is the longest
path the budget allows (``T * max_translation_m``), so every episode's path fits under it and
no policy is cut. It
rewards mapping per metre walked; a policy that turns on the spot spends no metres, so read
it together with ``auc_steps``.

**Steps and metres to a level.** ``steps_to[p]`` is the first step at which the linear curve
reaches ``p`` % (rounded up to a whole step), ``metres_to[p]`` the path length at that step;
both are None when the episode never reaches ``p``. Their resolution is the checkpoint
spacing: record more checkpoints (``--eval-points``) for finer values.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

THRESHOLDS_PCT: tuple[int, ...] = (80, 90, 95)
"""Completion-ratio levels (percent) whose steps and metres are reported."""


def completion_points(record: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Steps and completion ratios (percent, of the observable surface where recorded) of a
    record's curve, starting at ``(0, 0)``.

    Checkpoints without a completion ratio are left out; a record without any gives the
    single point ``(0, 0)``.
    """
    steps, ratios = [0], [0.0]
    curve = record.get("completion_curve") or []
    key = ("observable_completion_ratio_pct"
           if any(point.get("observable_completion_ratio_pct") is not None for point in curve)
           else "completion_ratio_pct")
    for point in curve:
        value = point.get(key)
        if value is None or point.get("step") is None:
            continue
        if int(point["step"]) > steps[-1]:
            steps.append(int(point["step"]))
            ratios.append(float(value))
    return np.asarray(steps, np.float64), np.asarray(ratios, np.float64)


def cumulative_path(trajectory: Sequence[Sequence[float]] | np.ndarray) -> np.ndarray:
    """Path length (metres) after each step: ``out[t]`` is the distance walked in ``t`` steps.

    Args:
        trajectory: positions ``(T + 1, 3)``; row 0 is the start, row ``t`` the position
            after step ``t``.
    """
    positions = np.asarray(trajectory, np.float64).reshape(-1, 3)
    if len(positions) == 0:
        return np.zeros(1)
    steps = np.linalg.norm(np.diff(positions, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(steps)])


def checkpoint_paths(record: dict[str, Any], steps: np.ndarray) -> np.ndarray:
    """The path walked (metres) after each of ``steps`` (the checkpoints of
    :func:`completion_points`): from the record's trajectory, or, for an archived copy
    (:mod:`~naruto_agent.benchmark.episode_archive`), from its ``checkpoint_path_m``."""
    steps = np.asarray(steps).astype(int)
    if record.get("trajectory") is None and record.get("checkpoint_path_m") is not None:
        walked = {int(step): float(metres) for step, metres in record["checkpoint_path_m"]}
        return np.asarray([walked[step] for step in steps.tolist()], np.float64)
    path = cumulative_path(record.get("trajectory") or [[0.0, 0.0, 0.0]])
    return path[np.minimum(steps, len(path) - 1)]


def area_under_curve(x: np.ndarray, ratio_pct: np.ndarray, horizon: float) -> float:
    """``(1 / horizon) * integral_0^horizon c(x) dx / 100`` of a piecewise-linear curve.

    Args:
        x: increasing abscissae (steps or metres), the first one 0.
        ratio_pct: the curve's values in percent at ``x``.
        horizon: where the integral stops (> 0); beyond ``x[-1]`` the curve keeps its last
            value, points beyond ``horizon`` are cut.

    Raises:
        ValueError: a horizon that is not positive, or ``x`` and ``ratio_pct`` of different
            lengths.
    """
    x = np.asarray(x, np.float64)
    y = np.asarray(ratio_pct, np.float64)
    if not horizon > 0:
        raise ValueError(f"horizon must be positive, got {horizon}")
    if x.shape != y.shape or x.ndim != 1 or len(x) == 0:
        raise ValueError(f"x and ratio_pct must be 1-D of one length, got {x.shape}, {y.shape}")
    grid = np.concatenate([x[x < horizon], [horizon]])
    values = np.interp(grid, x, y)  # holds the last value beyond x[-1]
    area = float(np.sum(0.5 * (values[1:] + values[:-1]) * np.diff(grid)))
    return area / (100.0 * horizon)


def mean_over_steps(curve: Sequence[float], steps: int) -> float:
    """Mean of a per-step curve (e.g. a record's ``coverage_curve``) over its first ``steps``
    steps, the last value held when the curve is shorter: the coverage area of the explorer's
    benchmark pages (a step-sampled mean, not the leaderboard's trapezoid
    :func:`area_under_curve`)."""
    values = np.asarray(curve[:steps], float)
    if len(values) < steps:
        values = np.concatenate([values, np.full(steps - len(values), values[-1])])
    return float(values.mean())


def first_reach(x: np.ndarray, ratio_pct: np.ndarray, level_pct: float) -> float | None:
    """The first abscissa where the piecewise-linear curve reaches ``level_pct``, or None."""
    x = np.asarray(x, np.float64)
    y = np.asarray(ratio_pct, np.float64)
    above = np.nonzero(y >= level_pct)[0]
    if len(above) == 0:
        return None
    index = int(above[0])
    if index == 0:
        return float(x[0])
    x0, x1, y0, y1 = x[index - 1], x[index], y[index - 1], y[index]
    return float(x0 + (level_pct - y0) / (y1 - y0) * (x1 - x0))


def path_horizon_m(record: dict[str, Any]) -> float:
    """``D`` of ``auc_path``: the step budget times the env's longest move per step."""
    from naruto_gym.envs.settings import EnvSettings

    config = record.get("config") or {}
    budget = int(config.get("steps") or record.get("steps_run") or 1)
    env_kwargs = config.get("env_kwargs") or {}
    step_m = float(env_kwargs.get("max_translation_m", EnvSettings.max_translation_m))
    return budget * step_m


def episode_efficiency(
    record: dict[str, Any], thresholds_pct: Sequence[float] = THRESHOLDS_PCT
) -> dict[str, Any]:
    """The efficiency metrics of one record (see the module docstring for the definitions).

    Returns:
        ``auc_steps`` and ``auc_path`` (0..1, None without a completion curve),
        ``steps_to_<p>`` and ``metres_to_<p>`` for each level ``p`` (None when not reached),
        and ``path_m`` (the whole path, metres).
    """
    if record.get("trajectory") is None and record.get("efficiency") is not None:
        return _archived_efficiency(record, thresholds_pct)
    steps, ratios = completion_points(record)
    config = record.get("config") or {}
    budget = int(config.get("steps") or record.get("steps_run") or 1)
    path = cumulative_path(record.get("trajectory") or [[0.0, 0.0, 0.0]])
    out: dict[str, Any] = {"path_m": float(path[-1])}
    if len(steps) < 2:
        out.update(auc_steps=None, auc_path=None)
        for level in thresholds_pct:
            out[f"steps_to_{level:g}"] = None
            out[f"metres_to_{level:g}"] = None
        return out
    out["auc_steps"] = area_under_curve(steps, ratios, float(budget))
    at_points = path[np.minimum(steps.astype(int), len(path) - 1)]
    # The path is monotone but may stand still: keep the best ratio at each distance.
    metres, best = _monotone(at_points, ratios)
    out["auc_path"] = area_under_curve(metres, best, path_horizon_m(record))
    for level in thresholds_pct:
        reached = first_reach(steps, ratios, level)
        step = None if reached is None else int(math.ceil(reached - 1e-9))
        out[f"steps_to_{level:g}"] = step
        out[f"metres_to_{level:g}"] = (
            None if step is None else float(path[min(step, len(path) - 1)])
        )
    return out


def _archived_efficiency(
    record: dict[str, Any], thresholds_pct: Sequence[float]
) -> dict[str, Any]:
    """The efficiency an archived copy keeps (computed from the trajectory it left out), for
    the levels it was computed at."""
    stored = record["efficiency"]
    keys = ["path_m", "auc_steps", "auc_path"]
    for level in thresholds_pct:
        keys += [f"steps_to_{level:g}", f"metres_to_{level:g}"]
    missing = [key for key in keys if key not in stored]
    if missing:
        raise ValueError(
            f"the archived episode {record.get('episode_id')} keeps no {', '.join(missing)} "
            f"(it was archived with the levels {THRESHOLDS_PCT}); compute other levels from "
            "its full record"
        )
    return {key: stored[key] for key in keys}


def _monotone(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Strictly increasing ``x``; at a repeated ``x`` (the camera stood still) the last value."""
    keep_x: list[float] = []
    keep_y: list[float] = []
    for xi, yi in zip(x.tolist(), y.tolist(), strict=True):
        if keep_x and xi <= keep_x[-1]:
            keep_y[-1] = yi
        else:
            keep_x.append(xi)
            keep_y.append(yi)
    return np.asarray(keep_x), np.asarray(keep_y)
