"""Long randomised rollouts: the agent never ends a step inside the clearance, never passes
through a surface, never leaves the bounds, and never escapes a scene with holes."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import naruto_gym  # noqa: F401
from naruto_gym.motion.collision import CollisionChecker, segment_fraction_inside_box
from naruto_gym.sensors.raycaster import RayCaster
from tests.conftest import SAMPLE_MESHES, SHARED_SCENES

TINY = {"image_scale": 0.05, "coverage_samples": 500, "panorama_shape": None}
STEPS_PER_MODE = 400


def _scene_kwargs():
    from naruto_gym.scenes.catalogue import available_scenes

    cases = [pytest.param({"scene": name}, id=name) for name in available_scenes()]
    for name, (relative, up_axis) in SAMPLE_MESHES.items():
        cases.append(
            pytest.param(
                {"scene": str(SHARED_SCENES / relative), "up_axis": up_axis},
                id=name,
                marks=pytest.mark.skipif(
                    not SHARED_SCENES.is_dir(), reason="../shared/scenes is absent"
                ),
            )
        )
    return cases


def _random_action(env, rng: np.random.Generator):
    if env.settings.action_mode == "pose":
        # Far targets anywhere in the bounds, kept for a while: most lie behind walls or
        # furniture, so the straight line towards them runs into surfaces.
        if rng.random() < 0.03 or not hasattr(env, "_test_target"):
            position = rng.uniform(env.bounds[0], env.bounds[1])
            quaternion = rng.normal(size=4)
            env._test_target = np.concatenate(
                [position, quaternion / np.linalg.norm(quaternion)]
            ).astype(np.float32)
        return env._test_target
    if env.settings.action_mode == "delta":
        # Keep pushing in one direction for a while so that walls are actually reached.
        if rng.random() < 0.05 or not hasattr(env, "_test_direction"):
            env._test_direction = rng.uniform(-1, 1, 6).astype(np.float32)
        return env._test_direction
    return int(rng.integers(0, 6)) if rng.random() < 0.8 else int(rng.integers(6, 10))


@pytest.mark.slow
@pytest.mark.parametrize("scene_kwargs", _scene_kwargs())
@pytest.mark.parametrize("action_mode", ["pose", "delta", "discrete"])
def test_randomised_rollout_never_collides(scene_kwargs, action_mode):
    env = gym.make("NarutoRecon-v0", action_mode=action_mode, **TINY, **scene_kwargs).unwrapped
    env.reset(seed=11)
    rng = np.random.default_rng(11)
    radius = env.settings.agent_radius_m
    blocked = 0
    for _ in range(STEPS_PER_MODE):
        previous = env.pose[:3, 3]
        _, _, _, _, info = env.step(_random_action(env, rng))
        position = env.pose[:3, 3]
        blocked += info["collided"]
        assert env.collision.clearance(position) >= radius - 1e-4
        assert np.all(position >= env.bounds[0] + radius - 1e-9)
        assert np.all(position <= env.bounds[1] - radius + 1e-9)
        segment = position - previous
        length = np.linalg.norm(segment)
        if length > 1e-9:
            wall = env.raycaster.cast_distance(previous[None], (segment / length)[None])[0]
            assert wall >= length + radius - 1e-3, "moved through or into a surface"
        assert not env.collision.sees_escape(position)
    assert blocked > 0, "the rollout never reached an obstacle, so it proved nothing"


def test_scene_with_open_top_does_not_let_agent_escape():
    """A room without a ceiling: flying up and out is refused by the panorama check."""
    import trimesh

    parts = []
    for centre, extents in [
        ((0, 0, -0.05), (4, 4, 0.1)),
        ((2.05, 0, 1), (0.1, 4.2, 2)),
        ((-2.05, 0, 1), (0.1, 4.2, 2)),
        ((0, 2.05, 1), (4.2, 0.1, 2)),
        ((0, -2.05, 1), (4.2, 0.1, 2)),
    ]:
        parts.append(trimesh.creation.box(extents=extents, transform=_translation(centre)))
    room = trimesh.util.concatenate(parts)
    caster = RayCaster(room.vertices, room.faces)
    # Generous bounds, as a scan whose bounding box reaches above the walls.
    bounds = np.array([[-3.0, -3.0, -0.1], [3.0, 3.0, 6.0]])
    checker = CollisionChecker(caster, bounds, 0.05, escape_no_hit_threshold=0.5)
    position = np.array([0.0, 0.0, 1.0])
    for _ in range(60):
        result = checker.move(position, position + np.array([0.0, 0.0, 0.1]))
        position = result.position
    assert result.collided and result.reason == "escape"
    assert position[2] < 3.0
    assert not checker.sees_escape(position)


def _translation(centre) -> np.ndarray:
    transform = np.eye(4)
    transform[:3, 3] = centre
    return transform


def test_segment_fraction_inside_box():
    box_min, box_max = np.zeros(3), np.ones(3)
    start = np.array([0.5, 0.5, 0.5])
    assert segment_fraction_inside_box(start, np.array([1.5, 0.5, 0.5]), box_min, box_max) == 0.5
    assert segment_fraction_inside_box(start, np.array([0.6, 0.6, 0.6]), box_min, box_max) == 1.0
