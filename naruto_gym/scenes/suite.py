"""The benchmark suite: a fixed, versioned list of unseen generated houses in three size classes.

A comparison at a budget where every policy covers the whole scene cannot tell policies
apart, and a test scene a policy was tuned on says nothing about scenes it has not seen. The
suite therefore names, per size class, a range of training seeds and a disjoint, fixed list of
test seeds, and a step budget at which no policy has covered the scene yet:

=============  ======================  ===========  =======  ============================
size class     scene kind              floor area   rooms    plan
=============  ======================  ===========  =======  ============================
``small``      ``procedural:small``    40-60 m²     2-3      rooms opening into each other
``flat``       ``procedural:flat``     100-120 m²   6-8      open plan or a hallway
``house``      ``procedural:house``    200-350 m²   12-20    corridors, clutter
=============  ======================  ===========  =======  ============================

The test seeds are 1000000-1000007 in every class, the budgets :data:`BUDGETS`. A class is
named as its scene kind: ``flat``, an apartment, is not ``procedural:apartment``, the older
4-9 room scenes, whose seeds keep their scenes. The training seeds are those of the
``"procedural:<kind>"`` scene streams' train split, ``[0, 1000000)``; the test seeds lie in
their test split, so a policy trained on a stream has never seen a test scene.

Each scene comes in two variants: ``closed`` (the generated building) and ``open`` (cut open as
real scans are: no ceiling, a hole in the floor, two holes in exterior walls, see
:mod:`naruto_gym.scenes.open_scans`), named ``"procedural:<kind>:<seed>:no_ceiling+holes"``.
Scenes are generated on first use and cached on disk
(:func:`naruto_gym.scenes.catalogue.cache_dir`), never stored in the repository.

:data:`SUITE_VERSION` changes whenever a suite name would give another scene, seed list or
budget, so results recorded under one version are never compared with another's.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from naruto_gym.scenes.procedural import SIZE_CLASSES_VERSION
from naruto_gym.scenes.stream import SPLIT_SEEDS

_SEEDS_AND_BUDGETS_VERSION = 1
SUITE_VERSION = f"{_SEEDS_AND_BUDGETS_VERSION}.{SIZE_CLASSES_VERSION}"
"""Version of the suite, ``"<seeds and budgets>.<scenes>"``: either part is bumped whenever
the seeds or budgets, or the scenes of a name change."""

SIZE_CLASSES = ("small", "flat", "house")
"""The size classes, smallest first, each named as its ``procedural:<kind>`` scene kind."""

RENAMED_SIZE_CLASSES = {"apartment": "flat"}
"""Earlier names of size classes -> their names now. Results recorded under an earlier name
are read under the current one (:func:`current_size_class`); a command given an earlier name
is refused with the name to use, because ``apartment`` also names the
``procedural:apartment`` scenes."""

VARIANTS = ("closed", "open")
"""``closed``: the generated building; ``open``: no ceiling, holes in floor and walls."""

SPLITS = ("train", "test")
"""The suite's splits: a range of training seeds and a fixed list of test seeds per class."""

OPEN_OPENINGS = "no_ceiling+holes"
"""The scan openings of the ``open`` variant (see :mod:`naruto_gym.scenes.open_scans`)."""

SCENE_KINDS = {"small": "small", "flat": "flat", "house": "house"}
"""The ``procedural:<kind>`` scene kind of each size class."""

BUDGETS = {"small": 400, "flat": 800, "house": 1500}
"""Step budget per size class: long enough to explore, short enough that no policy has
covered every surface at the end (see the scenes page for the coverage curves it rests on)."""

TEST_SEEDS_PER_CLASS = 8
"""How many test scenes each size class has."""
_TEST_START = SPLIT_SEEDS["test"][0]
_TEST_SEEDS = {
    size_class: tuple(range(_TEST_START, _TEST_START + TEST_SEEDS_PER_CLASS))
    for size_class in SIZE_CLASSES
}


@dataclass(frozen=True)
class SuiteScene:
    """One scene of the suite.

    Attributes:
        scene: the scene name ``gym.make(scene=...)`` and
            :func:`~naruto_gym.scenes.catalogue.resolve_scene` accept, e.g.
            ``"procedural:house:1000000"`` or ``"procedural:house:1000000:no_ceiling+holes"``.
        size_class: one of :data:`SIZE_CLASSES`.
        split: ``"train"`` or ``"test"``.
        seed: the scene's generator seed.
        variant: one of :data:`VARIANTS`.
        budget: the step budget of the size class.
    """

    scene: str
    size_class: str
    split: str
    seed: int
    variant: str
    budget: int

    @property
    def label(self) -> str:
        """Short name for tables and folders, e.g. ``"house-1000000"`` or
        ``"house-1000000-open"``."""
        suffix = "" if self.variant == "closed" else f"-{self.variant}"
        return f"{self.size_class}-{self.seed}{suffix}"


def current_size_class(name: str) -> str:
    """The size class ``name`` stands for now: a name of :data:`RENAMED_SIZE_CLASSES` gives the
    class that replaced it, any other name itself (for reading recorded results)."""
    return RENAMED_SIZE_CLASSES.get(name, name)


def renamed_size_class_message(name: str) -> str | None:
    """The error for a size class given under an earlier name, or None for any other name."""
    if name not in RENAMED_SIZE_CLASSES:
        return None
    return f"size class {name!r} was renamed: use --size-class {RENAMED_SIZE_CLASSES[name]}"


def _check_size_class(size_class: str) -> None:
    if size_class not in SIZE_CLASSES:
        renamed = renamed_size_class_message(size_class)
        raise ValueError(
            renamed or f"unknown size class {size_class!r}; use one of {', '.join(SIZE_CLASSES)}"
        )


def _as_tuple(values: str | Iterable[str], what: str, allowed: tuple[str, ...]) -> tuple[str, ...]:
    """``values`` (one name or several) as a tuple, each checked against ``allowed``."""
    items = (values,) if isinstance(values, str) else tuple(values)
    if not items:
        raise ValueError(f"no {what} given; give at least one of {', '.join(allowed)}")
    for item in items:
        if item not in allowed:
            raise ValueError(f"unknown {what} {item!r}; use {', '.join(allowed)}")
    return items


def train_seeds(size_class: str) -> range:
    """The training seeds of a size class: the scene streams' train split, disjoint from
    :func:`test_seeds`.

    Raises:
        ValueError: an unknown size class.
    """
    _check_size_class(size_class)
    return range(*SPLIT_SEEDS["train"])


def test_seeds(size_class: str) -> tuple[int, ...]:
    """The fixed test seeds of a size class (the same ones in every suite version unless
    :data:`SUITE_VERSION` says otherwise).

    Raises:
        ValueError: an unknown size class.
    """
    _check_size_class(size_class)
    return _TEST_SEEDS[size_class]


def budget(size_class: str) -> int:
    """The step budget of a size class (:data:`BUDGETS`).

    Raises:
        ValueError: an unknown size class.
    """
    _check_size_class(size_class)
    return BUDGETS[size_class]


def scene_name(
    size_class: str, seed: int | None = None, variant: str = "closed", split: str = "train"
) -> str:
    """The scene name of one suite scene, or with ``seed=None`` of the class's scene stream
    (a new scene of ``split`` at every reset of the batched env, e.g. for training).

    Raises:
        ValueError: an unknown size class, variant or split, or a negative seed.
    """
    _check_size_class(size_class)
    _as_tuple(variant, "variant", VARIANTS)
    _as_tuple(split, "split", SPLITS)
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
        raise ValueError(f"seed must be a non-negative integer or None, got {seed!r}")
    middle = split if seed is None else str(seed)
    suffix = "" if variant == "closed" else f":{OPEN_OPENINGS}"
    return f"procedural:{SCENE_KINDS[size_class]}:{middle}{suffix}"


def suite_scenes(
    split: str = "test",
    size_classes: str | Iterable[str] = SIZE_CLASSES,
    variants: str | Iterable[str] = ("closed",),
    *,
    train_count: int = TEST_SEEDS_PER_CLASS,
) -> list[SuiteScene]:
    """The scenes of one split: per size class, per variant, per seed, in that order.

    Args:
        split: ``"test"`` (the fixed test seeds) or ``"train"`` (the first ``train_count``
            training seeds; train on the stream of :func:`scene_name` for more).
        size_classes: the classes to list (default: all three, smallest first).
        variants: ``"closed"``, ``"open"`` or both.
        train_count: how many training seeds per class the train split lists.

    Raises:
        ValueError: an unknown split, size class or variant (the message lists the known
            ones), or a negative ``train_count``.
    """
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; use {' or '.join(SPLITS)}")
    classes = _as_tuple(size_classes, "size class", SIZE_CLASSES)
    kinds = _as_tuple(variants, "variant", VARIANTS)
    if train_count < 0:
        raise ValueError(f"train_count must be >= 0, got {train_count}")
    out = []
    for size_class in classes:
        seeds = (
            test_seeds(size_class)
            if split == "test"
            else tuple(train_seeds(size_class)[:train_count])
        )
        for variant in kinds:
            for seed in seeds:
                out.append(
                    SuiteScene(
                        scene=scene_name(size_class, seed, variant),
                        size_class=size_class,
                        split=split,
                        seed=seed,
                        variant=variant,
                        budget=BUDGETS[size_class],
                    )
                )
    return out
