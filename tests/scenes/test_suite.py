"""The benchmark scene suite: its named data, its size classes and the validity of every test
scene for every policy (spawnable start, open doorways, every room reachable)."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from naruto_gym.scenes import SIZE_CLASSES, SUITE_VERSION, VARIANTS, SuiteScene, suite_scenes
from naruto_gym.scenes import suite as suite_module
from naruto_gym.scenes.catalogue import resolve_scene
from naruto_gym.scenes.procedural import (
    SIZE_CLASS_KINDS,
    SIZE_CLASSES_VERSION,
    generate_layout,
    make_random_scene,
    scene_to_ply_bytes,
    size_class_layout,
    size_class_scene,
)
from naruto_gym.scenes.scene_cache import CACHE_DIR_ENV, cache_dir, size_class_path
from naruto_gym.scenes.stream import SPLIT_SEEDS, parse_procedural_name
from naruto_gym.sensors.raycaster import RayCaster
from tests.scenes.layout_checks import (
    assert_doorways_open,
    assert_furniture_clear,
    assert_rooms_joined,
    reachable_rooms,
)

# (rooms without corridors, floor area in m²) per size class, as the suite promises them.
CLASS_LIMITS = {
    "small": ((2, 3), (40.0, 60.0)),
    "flat": ((6, 8), (100.0, 120.0)),
    "house": ((12, 20), (200.0, 350.0)),
}


# ---------------------------------------------------------------------------------------
# The named data
# ---------------------------------------------------------------------------------------
def test_constants():
    assert isinstance(SUITE_VERSION, str) and SUITE_VERSION
    assert SIZE_CLASSES == ("small", "flat", "house")
    assert VARIANTS == ("closed", "open")


def test_default_suite_is_the_closed_test_split_of_every_class():
    scenes = suite_scenes()
    assert all(isinstance(scene, SuiteScene) for scene in scenes)
    assert [s.size_class for s in scenes] == [
        c for c in SIZE_CLASSES for _ in suite_module.test_seeds(c)
    ]
    assert {s.split for s in scenes} == {"test"} and {s.variant for s in scenes} == {"closed"}
    assert len({s.scene for s in scenes}) == len(scenes)
    assert len({s.label for s in scenes}) == len(scenes)
    for scene in scenes:
        assert scene.budget == suite_module.budget(scene.size_class)
        kind = suite_module.SCENE_KINDS[scene.size_class]
        assert scene.scene == f"procedural:{kind}:{scene.seed}"
        spec = parse_procedural_name(scene.scene)
        assert not spec.is_stream and spec.seed == scene.seed and spec.openings is None


def test_budgets_grow_with_the_size_class():
    budgets = [suite_module.budget(c) for c in SIZE_CLASSES]
    assert budgets == sorted(budgets) and budgets[0] > 0


@pytest.mark.parametrize("size_class", SIZE_CLASSES)
def test_test_seeds_are_fixed_many_and_outside_the_train_range(size_class):
    seeds = suite_module.test_seeds(size_class)
    assert isinstance(seeds, tuple) and len(seeds) >= 8 and len(set(seeds)) == len(seeds)
    assert seeds == suite_module.test_seeds(size_class)
    train = suite_module.train_seeds(size_class)
    assert isinstance(train, range) and len(train) >= 100_000
    assert not set(seeds) & set(train[:1]) and all(seed not in train for seed in seeds)
    # The train range is the procedural streams' train split: a policy trained on
    # "procedural:<kind>" never sees a test scene.
    assert (train.start, train.stop) == SPLIT_SEEDS["train"]


def test_open_variant_and_train_split():
    open_scenes = suite_scenes("test", "small", "open")
    assert all(s.scene.endswith(":no_ceiling+holes") and s.variant == "open" for s in open_scenes)
    assert all(parse_procedural_name(s.scene).openings == "no_ceiling+holes" for s in open_scenes)
    both = suite_scenes("test", ["house"], VARIANTS)
    assert len(both) == 2 * len(suite_module.test_seeds("house"))
    train = suite_scenes("train", train_count=3)
    assert len(train) == 3 * len(SIZE_CLASSES)
    assert all(s.seed in suite_module.train_seeds(s.size_class) for s in train)
    assert suite_module.scene_name("flat") == "procedural:flat:train"
    assert suite_module.scene_name("small", variant="open", split="test") == (
        "procedural:small:test:no_ceiling+holes"
    )
    assert parse_procedural_name("procedural:small:test:no_ceiling+holes").is_stream


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: suite_scenes("validation"), "unknown split 'validation'"),
        (lambda: suite_scenes(size_classes=["mansion"]), "unknown size class 'mansion'"),
        (lambda: suite_scenes(variants=["ajar"]), "unknown variant 'ajar'"),
        (lambda: suite_scenes(size_classes=[]), "no size class"),
        (lambda: suite_scenes("train", train_count=-1), "train_count"),
        (lambda: suite_module.test_seeds("castle"), "unknown size class 'castle'"),
        (lambda: suite_module.train_seeds("castle"), "small, flat, house"),
        (
            lambda: suite_module.budget("apartment"),
            "size class 'apartment' was renamed: use --size-class flat",
        ),
        (lambda: suite_module.budget("castle"), "unknown size class"),
        (lambda: suite_module.scene_name("small", -3), "non-negative"),
        (lambda: parse_procedural_name("procedural:house:5:no_roof"), "unknown scan opening"),
        (lambda: size_class_layout("castle", 0), "size-class kind"),
        (lambda: size_class_layout("house", -1), "non-negative"),
        (lambda: generate_layout(0, (12.0, 9.0, 2.8), 4, corridor_width=0.5), "corridor_width"),
    ],
)
def test_bad_input_raises_a_clear_error(call, message):
    with pytest.raises(ValueError, match=message):
        call()


# ---------------------------------------------------------------------------------------
# The size classes
# ---------------------------------------------------------------------------------------
def _suite_layouts():
    return [
        (
            scene.label,
            scene.size_class,
            size_class_layout(suite_module.SCENE_KINDS[scene.size_class], scene.seed),
        )
        for scene in suite_scenes()
    ]


SUITE_LAYOUTS = _suite_layouts()


@pytest.mark.parametrize("case", SUITE_LAYOUTS, ids=[case[0] for case in SUITE_LAYOUTS])
def test_test_scenes_keep_the_class_limits(case):
    _, size_class, layout = case
    (least, most), (low, high) = CLASS_LIMITS[size_class]
    rooms = [room for room in layout.rooms if room.kind != "corridor"]
    corridors = [room for room in layout.rooms if room.kind == "corridor"]
    assert least <= len(rooms) <= most
    width, depth, _ = layout.size
    assert low - 1.0 <= width * depth <= high + 1.0
    if size_class == "house":
        assert corridors, "a house has corridors"
        assert sum(
            o.kind
            in ("moving_boxes", "stray_chair", "stool", "laundry_basket", "side_table", "shoe_rack")
            for o in layout.objects
        ) >= len(rooms)
    if size_class == "small":
        assert not corridors
    # The cells tile the footprint, and the rooms are joined through doorways.
    assert sum(room.cell.area for room in layout.rooms) == pytest.approx(width * depth)
    assert_rooms_joined(layout)
    assert_furniture_clear(layout)


@pytest.mark.parametrize("case", SUITE_LAYOUTS, ids=[case[0] for case in SUITE_LAYOUTS])
def test_every_test_scene_is_valid_for_every_policy(case):
    """The mesh itself: the start is clear, every doorway open and every room reachable."""
    _, _, layout = case
    scene = layout.to_scene()
    caster = RayCaster(scene.vertices, scene.faces)
    points = np.array([layout.start_position, *layout.room_points])
    assert np.all(caster.unsigned_distance(points) >= 0.3)
    assert_doorways_open(layout, caster)
    assert reachable_rooms(layout, caster, z=1.0) == list(range(len(layout.rooms)))


def test_size_classes_are_deterministic_and_differ_by_seed():
    for kind in SIZE_CLASS_KINDS:
        first = size_class_layout(kind, 7)
        assert first == size_class_layout(kind, 7)
        assert [r.cell for r in first.rooms] != [r.cell for r in size_class_layout(kind, 8).rooms]


def test_older_kinds_keep_their_scenes():
    # "apartment" keeps naming the 4-9 room scenes; the suite's class of that size is "flat".
    layout = make_random_scene(0, "apartment")
    assert parse_procedural_name("procedural:apartment:0").kind == "apartment"
    assert resolve_scene("procedural:apartment:0").faces.shape == layout.faces.shape


# ---------------------------------------------------------------------------------------
# Generated on demand, cached on disk
# ---------------------------------------------------------------------------------------
def test_scenes_are_generated_once_into_the_cache(tmp_path, monkeypatch):
    monkeypatch.setenv(CACHE_DIR_ENV, str(tmp_path))
    name = suite_scenes("test", "small")[0].scene
    scene = resolve_scene(name)
    path = size_class_path("small", suite_module.test_seeds("small")[0])
    assert path.is_file() and path.parent.parent == cache_dir()
    stamp = path.stat().st_mtime_ns
    again = resolve_scene(name)
    assert path.stat().st_mtime_ns == stamp
    np.testing.assert_array_equal(again.vertices, scene.vertices)
    np.testing.assert_array_equal(again.faces, scene.faces)
    opened = resolve_scene(f"{name}:no_ceiling+holes")
    assert opened.name.endswith(":no_ceiling+floor_hole+wall_holes")
    # The open variant has no ceiling: a ray straight up from the start escapes.
    start = np.array(size_class_layout("small", suite_module.test_seeds("small")[0]).start_position)
    closed_up = RayCaster(scene.vertices, scene.faces).cast(start, np.array([[0.0, 0, 1]]))
    open_up = RayCaster(opened.vertices, opened.faces).cast(start, np.array([[0.0, 0, 1]]))
    assert closed_up.hit_mask.all() and not open_up.hit_mask.any()


# One scene per class, pinned: a generator change that gives a seed another scene must bump
# SIZE_CLASSES_VERSION (the cache folder and SUITE_VERSION follow), then update these.
PINNED_SCENES = {
    ("small", 1000001): "422aaa0923b411b22ab3cc1fa31b7093914005bb3afde3702934294936f09396",
    ("flat", 1000001): "9ed9c116c83182145ec66c898292dd510c18f1b124f9425080eb17ae0629746f",
    ("house", 1000001): "7d922b3dc1d6f93734fe44fcece40f66f7245c3c215f1a8a186ad52d4c0b1860",
}


@pytest.mark.parametrize("key", sorted(PINNED_SCENES), ids=lambda key: f"{key[0]}-{key[1]}")
def test_suite_scenes_are_pinned_to_their_version(key):
    kind, seed = key
    digest = hashlib.sha256(scene_to_ply_bytes(size_class_scene(kind, seed))).hexdigest()
    assert digest == PINNED_SCENES[key], (
        f"{kind} seed {seed} gives another scene than in size-class version "
        f"{SIZE_CLASSES_VERSION}: bump SIZE_CLASSES_VERSION in "
        "naruto_gym/scenes/procedural/size_classes.py, then update PINNED_SCENES"
    )
    assert SUITE_VERSION.endswith(f".{SIZE_CLASSES_VERSION}")
