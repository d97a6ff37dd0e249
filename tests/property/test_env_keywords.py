"""Every keyword of ``NarutoReconEnv`` and ``NarutoReconVectorEnv``, given any value: the env
is made and then resets and steps within its spaces, or making it raises one ``ValueError``
that names the keyword."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import naruto_gym  # noqa: F401
from naruto_gym.envs.naruto_recon_env import NarutoReconEnv
from naruto_gym.sensors.pinhole import PinholeCamera
from naruto_gym.vector import NarutoReconVectorEnv, make_vector_env
from tests.property.scenes import CHEAP, small_room
from tests.property.strategies import any_float, any_integer, odd_value

#: Cheap settings, with the observable surface off (its first computation costs a second).
FAST = {**CHEAP, "observable_only": False}

#: In-range values of each keyword, drawn beside the odd ones (small where the cost grows).
VALID: dict[str, st.SearchStrategy] = {
    "up_axis": st.sampled_from(["z", "y", "-y", "x", "-x", "-z"]),
    "mesh_units": st.sampled_from(["m", "cm", "mm"]),
    "action_mode": st.sampled_from(["pose", "delta", "discrete"]),
    "image_scale": st.floats(0.01, 0.08),
    "max_depth_m": st.floats(0.01, 1e6),
    "panorama_shape": st.one_of(st.none(), st.tuples(st.integers(1, 24), st.integers(1, 48))),
    "agent_radius_m": st.floats(1e-4, 2.0),
    "max_translation_m": st.floats(1e-4, 100.0),
    "max_rotation_deg": st.floats(1e-3, 180.0),
    "escape_no_hit_threshold": st.one_of(st.none(), st.floats(0.0, 1.0)),
    "escape_rule": st.sampled_from(["scanned_space", "published", "off"]),
    "collision_penalty": st.floats(-1e6, 1e6),
    "coverage_samples": st.integers(1, 2000),
    "coverage_range_m": st.floats(1e-3, 1e6),
    "observable_only": st.booleans(),
    "start_clearance_m": st.floats(0.0, 0.5),
    "raycaster_backend": st.sampled_from(["open3d", "embreex"]),
    "pinhole_backend": st.sampled_from(["raycast", "raster", "auto"]),
    "reconstruct": st.booleans(),
    "max_episode_steps": st.one_of(st.none(), st.integers(1, 10**9)),
    "render_mode": st.sampled_from([None, "rgb_array"]),
    "threads": st.one_of(st.none(), st.integers(1, 4)),
}


def _reset_and_step(env: gym.Env) -> None:
    """Reset (a start in free space, or a pose at the room's middle when none has the
    clearance asked for) and step once; every observation lies in the space."""
    try:
        observation, info = env.reset(seed=0)
    except RuntimeError as error:
        assert "no free start position" in str(error)
        pose = np.eye(4)
        pose[:3, 3] = small_room().bounds.mean(axis=0)
        observation, info = env.reset(seed=0, options={"pose": pose})
    assert env.observation_space.contains(observation)
    observation, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert env.observation_space.contains(observation)
    assert isinstance(reward, float) and np.isfinite(reward)
    assert 0.0 <= info["coverage"] <= 1.0


@pytest.mark.parametrize("keyword", sorted(VALID))
@settings(max_examples=8)  # per keyword: 21 keywords
@given(data=st.data())
def test_every_keyword_is_used_or_refused_by_name(keyword, data):
    value = data.draw(st.one_of(odd_value, VALID[keyword]), label=keyword)
    try:
        env = NarutoReconEnv(small_room(), **{**FAST, keyword: value})
    except ValueError as error:
        assert keyword in str(error), str(error)
        return
    if not _costs_time(keyword, value):
        _reset_and_step(env)


#: Sizes past which a valid value costs time, not correctness: such an env is made, not run.
_SMALL = {"image_scale": 0.08, "panorama_shape": 48, "coverage_samples": 2000}


def _costs_time(keyword: str, value) -> bool:
    if keyword not in _SMALL or value is None:
        return False
    return bool(np.max(np.asarray(value, float)) > _SMALL[keyword])


@given(
    width=st.one_of(st.integers(-2, 4000), any_integer),
    height=st.integers(-2, 3000),
    focal=st.one_of(st.floats(-10.0, 5000.0), any_float),
    image_scale=st.one_of(st.floats(1e-4, 0.1), any_float),
)
def test_a_camera_and_an_image_scale_together(width, height, focal, image_scale):
    """The observation has the scaled camera's size, or one clear error is raised."""
    try:
        camera = PinholeCamera(
            width=width, height=height, fx=focal, fy=focal, cx=width / 2.0, cy=height / 2.0
        )
    except (ValueError, TypeError, OverflowError):
        return
    settings = {**FAST, "camera": camera, "image_scale": image_scale}
    try:
        env = NarutoReconEnv(small_room(), **settings)
    except ValueError as error:
        assert "image_scale" in str(error) or "camera" in str(error), str(error)
        return
    scaled = camera.scaled(float(image_scale))
    if scaled.width * scaled.height > 40_000:
        return  # valid, but too large to render in a quick test
    observation, _ = env.reset(seed=0)
    assert observation["rgb"].shape == (scaled.height, scaled.width, 3)
    assert env.observation_space.contains(observation)


VECTOR_VALID: dict[str, st.SearchStrategy] = {
    "num_envs": st.integers(1, 3),
    "max_episode_steps": st.one_of(st.none(), st.integers(1, 5)),
    "autoreset_mode": st.sampled_from(["NextStep", "SameStep"]),
    "scene_cache_size": st.integers(0, 4),
    "max_depth_m": VALID["max_depth_m"],
    "action_mode": VALID["action_mode"],
    "panorama_shape": VALID["panorama_shape"],
    "workers": st.one_of(st.none(), st.just(1)),
}
#: The env's other keywords, which the batched env takes too (or refuses by name).
SHARED_VALID = {key: value for key, value in VALID.items() if key not in VECTOR_VALID}


@pytest.mark.parametrize("keyword", sorted(VECTOR_VALID))
@settings(max_examples=6)  # per keyword
@given(data=st.data())
def test_every_vector_env_keyword_is_used_or_refused_by_name(keyword, data):
    _check_vector_keyword(
        keyword, data.draw(st.one_of(odd_value, VECTOR_VALID[keyword]), label=keyword)
    )


@pytest.mark.parametrize("keyword", sorted(SHARED_VALID))
@settings(max_examples=3)  # per keyword: the single env's test draws more of each
@given(data=st.data())
def test_every_shared_keyword_of_the_vector_env_is_used_or_refused_by_name(keyword, data):
    _check_vector_keyword(
        keyword, data.draw(st.one_of(odd_value, SHARED_VALID[keyword]), label=keyword)
    )


def _check_vector_keyword(keyword: str, value) -> None:
    """The batched env built with ``keyword=value`` resets and steps inside its spaces, or
    refuses the value with a ``ValueError`` that names the keyword."""
    if keyword == "num_envs" and isinstance(value, (int, np.integer)) and value > 3:
        return  # valid, but many agents cost time, not correctness
    if (
        keyword == "panorama_shape"
        and isinstance(value, tuple)
        and (all(isinstance(v, (int, np.integer)) for v in value) and max(value) > 48)
    ):
        return
    settings = {**FAST, "num_envs": 2, keyword: value}
    try:
        env = make_vector_env(scene=small_room(), **settings)
    except ValueError as error:
        assert keyword in str(error) or (keyword == "autoreset_mode"), str(error)
        return
    try:
        observations, _ = env.reset(seed=0)
    except RuntimeError as error:  # a valid clearance that this small room cannot give
        assert "no free start position" in str(error) and keyword in str(error), str(error)
        env.close()
        return
    assert env.observation_space.contains(observations)
    observations, rewards, terminated, truncated, infos = env.step(env.action_space.sample())
    assert env.observation_space.contains(observations)
    assert np.isfinite(rewards).all()
    env.close()


@pytest.mark.parametrize(
    "value", [0, -1, 0.0, -1e-9, float("nan"), float("inf"), "10", None, 3.402823466385289e38]
)
def test_max_depth_m_out_of_range_is_refused(value):
    """A sensor range of zero, below zero, not finite, not a number or past float32's range
    is refused by name (the depth space's Box would otherwise take or reject it unclearly)."""
    with pytest.raises(ValueError, match="max_depth_m"):
        gym.make("NarutoRecon-v0", max_depth_m=value)


@given(actions=st.one_of(odd_value, st.lists(any_float, min_size=1, max_size=14)))
def test_the_vector_env_steps_or_refuses_any_actions_and_goes_on(actions):
    env = _vector_env()
    env.reset(seed=0)
    try:
        observations, rewards, _, _, _ = env.step(actions)
    except ValueError as error:
        assert "action" in str(error), str(error)
        observations, rewards, _, _, _ = env.step(env.action_space.sample())
    assert env.observation_space.contains(observations)
    assert np.isfinite(rewards).all()


_VECTOR: list[NarutoReconVectorEnv] = []


def _vector_env() -> NarutoReconVectorEnv:
    if not _VECTOR:
        _VECTOR.append(
            NarutoReconVectorEnv(num_envs=2, scene=small_room(), action_mode="delta", **FAST)
        )
    return _VECTOR[0]


@pytest.mark.parametrize("make", [NarutoReconEnv, lambda **kw: NarutoReconVectorEnv(2, **kw)])
def test_an_unknown_keyword_is_refused_by_name(make):
    """A keyword neither env takes (a typo) is refused by name with the keywords it takes,
    not by its settings' dataclass nor by Python's TypeError."""
    with pytest.raises(ValueError, match="unknown keyword.*'max_depht_m'.*max_depth_m"):
        make(scene=small_room(), max_depht_m=5, **FAST)


@pytest.mark.parametrize("make", [NarutoReconEnv, lambda **kw: NarutoReconVectorEnv(2, **kw)])
def test_the_old_name_of_the_episode_length_is_refused_with_the_new_one(make):
    """``step_budget`` was renamed ``max_episode_steps`` (0.x: no alias): either env refuses
    it with an error that names the new keyword, through gymnasium.make too."""
    with pytest.raises(ValueError, match="'step_budget' was renamed: pass max_episode_steps=5"):
        make(scene=small_room(), step_budget=5, **FAST)
    with pytest.raises(ValueError, match="pass max_episode_steps=5"):
        gym.make("NarutoRecon-v0", scene=small_room(), step_budget=5, **FAST)
