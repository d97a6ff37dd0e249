"""Scenes: meshes loaded into a z-up metric world (:mod:`~naruto_gym.scenes.mesh_scene`,
lengths in :mod:`~naruto_gym.scenes.units`, checks of a scan in
:mod:`~naruto_gym.scenes.scan_checks`), the procedural generator
(:mod:`~naruto_gym.scenes.procedural`), the shipped catalogue
(:mod:`~naruto_gym.scenes.catalogue`), open scans cut from closed scenes
(:mod:`~naruto_gym.scenes.open_scans`), per-episode scene streams
(:mod:`~naruto_gym.scenes.stream`), the cache of generated meshes
(:mod:`~naruto_gym.scenes.scene_cache`), and the benchmark suite
(:mod:`~naruto_gym.scenes.suite`) with its external track
(:mod:`~naruto_gym.scenes.external`), and the folders a dataset's scenes are laid out in
(:mod:`~naruto_gym.scenes.scene_folders`)."""

from naruto_gym.scenes.catalogue import (
    DEFAULT_SCENE,
    available_scenes,
    load_catalogue_scene,
    resolve_scene,
    scene_info,
    scene_path,
)
from naruto_gym.scenes.mesh_scene import (
    Scene,
    load_scene,
    sample_mesh_surface,
    scene_from_trimesh,
)
from naruto_gym.scenes.procedural import (
    SceneLayout,
    generate_apartment,
    generate_layout,
    generate_room,
    make_random_scene,
    random_layout,
    save_scene_ply,
)
from naruto_gym.scenes.suite import (
    SIZE_CLASSES,
    SUITE_VERSION,
    VARIANTS,
    SuiteScene,
    suite_scenes,
    test_seeds,
    train_seeds,
)

__all__ = [
    "DEFAULT_SCENE",
    "SIZE_CLASSES",
    "SUITE_VERSION",
    "VARIANTS",
    "Scene",
    "SceneLayout",
    "SuiteScene",
    "available_scenes",
    "generate_apartment",
    "generate_layout",
    "generate_room",
    "load_catalogue_scene",
    "load_scene",
    "make_random_scene",
    "random_layout",
    "resolve_scene",
    "sample_mesh_surface",
    "save_scene_ply",
    "scene_from_trimesh",
    "scene_info",
    "scene_path",
    "suite_scenes",
    "test_seeds",
    "train_seeds",
]
