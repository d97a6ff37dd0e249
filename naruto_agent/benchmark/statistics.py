"""Means with bootstrap confidence intervals, and paired comparisons of two policies.

A benchmark mean over a few scenes and seeds says little without its uncertainty: a lead
smaller than the spread of three seeds is not a lead. The intervals here are percentile
bootstrap intervals, seeded so that a report is reproducible.

**Over scenes and seeds** (:func:`bootstrap_ci` with ``groups``): each resample draws the
scenes with replacement, then, inside each drawn scene, its seeds with replacement, and takes
the mean of the drawn values. Both sources of spread (which houses, which starts) enter the
interval; with one value per scene it is the ordinary bootstrap over scenes.

**Paired** (:func:`paired_comparison`): two policies run on the same scene with the same seed
start from the same pose, so the difference per (scene, seed) removes the scene's difficulty
from the comparison. The mean difference gets the same two-level interval; each scene gets its
own mean difference with an interval over its seeds. An interval that excludes 0 says the
difference is unlikely to be seed or scene luck at that confidence.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Hashable, Mapping, Sequence
from typing import Any

import numpy as np

CONFIDENCE = 0.95
RESAMPLES = 10_000
SEED = 0


def bootstrap_ci(
    values: Sequence[float] | np.ndarray,
    groups: Sequence[Hashable] | None = None,
    confidence: float = CONFIDENCE,
    resamples: int = RESAMPLES,
    seed: int = SEED,
) -> dict[str, Any]:
    """Mean of ``values`` and its percentile bootstrap interval.

    Args:
        values: the numbers (e.g. one per episode).
        groups: the group of each value (e.g. its scene): resample groups, then values inside
            each drawn group. None: resample the values themselves.
        confidence: the interval's coverage (0 < confidence < 1).
        resamples: bootstrap resamples.
        seed: seed of the resampling (the same data and seed give the same interval).

    Returns:
        ``{"mean", "low", "high", "n"}``; ``low`` and ``high`` equal the mean for one value,
        and every entry is None for no value.

    Raises:
        ValueError: a confidence outside (0, 1), fewer than one resample, or ``groups`` of
            another length than ``values``.
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence}")
    if resamples < 1:
        raise ValueError(f"resamples must be at least 1, got {resamples}")
    data = np.asarray(values, np.float64).ravel()
    if groups is not None and len(groups) != len(data):
        raise ValueError(f"groups has {len(groups)} entries for {len(data)} values")
    if len(data) == 0:
        return {"mean": None, "low": None, "high": None, "n": 0}
    mean = float(data.mean())
    if len(data) == 1:
        return {"mean": mean, "low": mean, "high": mean, "n": 1}
    rng = np.random.default_rng(seed)
    if groups is None:
        draws = rng.integers(0, len(data), size=(resamples, len(data)))
        means = data[draws].mean(axis=1)
    else:
        means = _two_level_means(data, list(groups), rng, resamples)
    tail = 100.0 * (1.0 - confidence) / 2.0
    low, high = np.percentile(means, [tail, 100.0 - tail])
    return {"mean": mean, "low": float(low), "high": float(high), "n": int(len(data))}


def _two_level_means(
    data: np.ndarray, groups: list[Hashable], rng: np.random.Generator, resamples: int
) -> np.ndarray:
    """Means of resamples that draw groups, then members inside each drawn group."""
    members: dict[Hashable, list[int]] = defaultdict(list)
    for index, group in enumerate(groups):
        members[group].append(index)
    keys = list(members)
    sums = np.empty((resamples, len(keys)))
    counts = np.empty(len(keys))
    for column, key in enumerate(keys):
        own = data[members[key]]
        draws = rng.integers(0, len(own), size=(resamples, len(own)))
        sums[:, column] = own[draws].sum(axis=1)
        counts[column] = len(own)
    chosen = rng.integers(0, len(keys), size=(resamples, len(keys)))
    total = np.take_along_axis(sums, chosen, axis=1).sum(axis=1)
    return total / counts[chosen].sum(axis=1)


def paired_comparison(
    a: Mapping[tuple[Hashable, Hashable], float | None],
    b: Mapping[tuple[Hashable, Hashable], float | None],
    confidence: float = CONFIDENCE,
    resamples: int = RESAMPLES,
    seed: int = SEED,
) -> dict[str, Any]:
    """Mean difference ``a - b`` over the (scene, seed) pairs both have, with intervals.

    Args:
        a: value of policy A per ``(scene, seed)`` (None: not measured, left out).
        b: value of policy B per ``(scene, seed)``.
        confidence: the intervals' coverage.
        resamples: bootstrap resamples.
        seed: seed of the resampling.

    Returns:
        ``{"overall": {"mean", "low", "high", "n", "scenes"}, "per_scene": {scene: {"mean",
        "low", "high", "n"}}}``: the overall interval resamples scenes and seeds, a scene's
        resamples its seeds. ``overall["mean"]`` is None when no pair is shared.
    """
    keys = sorted(
        (key for key in a if key in b and a[key] is not None and b[key] is not None),
        key=lambda key: (str(key[0]), str(key[1])),
    )
    differences = np.array([float(a[key]) - float(b[key]) for key in keys])  # type: ignore[arg-type]
    scenes = [key[0] for key in keys]
    overall = bootstrap_ci(differences, scenes, confidence, resamples, seed)
    overall["scenes"] = len(set(scenes))
    per_scene = {}
    for scene in sorted(set(scenes), key=str):
        own = differences[[index for index, key in enumerate(keys) if key[0] == scene]]
        per_scene[scene] = bootstrap_ci(own, None, confidence, resamples, seed)
    return {"overall": overall, "per_scene": per_scene}


def excludes_zero(interval: Mapping[str, Any]) -> bool:
    """True when an interval from :func:`bootstrap_ci` lies wholly above or below 0."""
    low, high = interval.get("low"), interval.get("high")
    if low is None or high is None or interval.get("n", 0) < 2:
        return False
    return low > 0 or high < 0
