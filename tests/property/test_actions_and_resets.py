"""Actions of every action mode and reset options, given anything: the env steps (or resets)
and stays inside its spaces, or raises one ``ValueError`` and is left as it was; after every
error the same env object still resets and steps."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from naruto_gym.envs.naruto_recon_env import NarutoReconEnv
from naruto_gym.geometry.transforms import look_at_rotation, make_pose
from tests.property.scenes import CHEAP, small_room
from tests.property.strategies import any_float, any_integer, odd_value


@cache
def _env(mode: str) -> NarutoReconEnv:
    env = NarutoReconEnv(small_room(), action_mode=mode, **CHEAP)
    env.reset(seed=0)
    return env


def _still_works(env: NarutoReconEnv) -> None:
    """The env resets and steps after an error."""
    observation, _ = env.reset(seed=1)
    assert env.observation_space.contains(observation)
    observation, _, _, _, _ = env.step(env.action_space.sample())
    assert env.observation_space.contains(observation)


def _actions(mode: str) -> st.SearchStrategy:
    size = {"pose": 7, "delta": 6, "discrete": 1}[mode]
    arrays = hnp.arrays(
        dtype=st.sampled_from([np.float64, np.float32, np.float16, np.int64, np.int8,
                               np.uint8, np.bool_, np.complex64]),
        shape=st.one_of(st.just((size,)), hnp.array_shapes(max_dims=3, max_side=8)),
        elements=None,
    )
    return st.one_of(
        odd_value,
        arrays,
        st.lists(any_float, min_size=size, max_size=size),
        st.lists(st.floats(-1.0, 1.0), min_size=size, max_size=size),
        st.lists(st.text(max_size=2), min_size=size, max_size=size),
        any_integer,
        st.just(np.array(["a"] * size)),
    )


@pytest.mark.parametrize("mode", ["pose", "delta", "discrete"])
@given(data=st.data())
def test_any_action_steps_or_is_refused_leaving_the_env_unchanged(mode, data):
    env = _env(mode)
    action = data.draw(_actions(mode), label="action")
    before = env.pose, env.trajectory.copy()
    try:
        observation, reward, terminated, truncated, info = env.step(action)
    except ValueError as error:
        assert "action" in str(error)
        np.testing.assert_array_equal(env.pose, before[0])
        np.testing.assert_array_equal(env.trajectory, before[1])
        _still_works(env)
        return
    assert env.observation_space.contains(observation)
    assert isinstance(reward, float) and np.isfinite(reward)
    assert isinstance(terminated, bool) and isinstance(truncated, bool)
    assert np.isfinite(env.pose).all()


def _poses() -> st.SearchStrategy:
    low, high = small_room().bounds
    position = st.tuples(
        *(st.floats(float(a) - 2.0, float(b) + 2.0) for a, b in zip(low, high, strict=True))
    )
    rotations = st.one_of(
        st.just(np.eye(3)),
        hnp.arrays(np.float64, (3, 3), elements=st.floats(-2.0, 2.0)),  # mostly not rotations
        st.just(np.diag([1.0, 1.0, -1.0])),  # a reflection
        st.just(np.zeros((3, 3))),
    )

    def pose(rotation: np.ndarray, position: tuple[float, float, float]) -> np.ndarray:
        matrix = np.eye(4)
        matrix[:3, :3] = rotation
        matrix[:3, 3] = position
        return matrix

    return st.one_of(
        st.builds(pose, rotations, position),
        hnp.arrays(np.float64, st.sampled_from([(4, 4), (3, 4), (16,), (4, 4, 1)]),
                   elements=any_float),
        odd_value,
    )


@given(pose=_poses(), seed=st.one_of(st.none(), any_integer, st.booleans()))
def test_any_reset_pose_and_seed_resets_or_is_refused(pose, seed):
    env = _env("pose")
    try:
        observation, info = env.reset(seed=seed, options={"pose": pose})
    except ValueError as error:
        assert "pose" in str(error) or "seed" in str(error), str(error)
        _still_works(env)
        return
    assert env.observation_space.contains(observation)
    np.testing.assert_allclose(env.pose, pose, atol=1e-6)
    _still_works(env)


@given(seed=any_integer)
def test_seeds_of_every_integer_width(seed):
    env = _env("discrete")
    try:
        first, _ = env.reset(seed=seed)
    except ValueError as error:
        assert seed < 0 and "seed" in str(error)
        _still_works(env)
        return
    again, _ = env.reset(seed=int(seed))
    np.testing.assert_array_equal(first["pose"], again["pose"])


@given(options=odd_value)
def test_any_options_value_resets_or_is_refused(options):
    env = _env("delta")
    try:
        env.reset(seed=0, options=options)
    except ValueError as error:
        assert "option" in str(error), str(error)
        _still_works(env)


def test_a_pose_inside_furniture_starts_there_and_moves_out_or_stays():
    """A recorded pose is replayed exactly, even inside an object; steps then never make
    things worse than blocked moves."""
    env = _env("delta")
    scene = small_room()
    centre = scene.vertices[scene.faces[len(scene.faces) // 2]].mean(axis=0)
    pose = make_pose(look_at_rotation(centre, centre + [1.0, 0.0, 0.0]), centre)
    env.reset(seed=0, options={"pose": pose})
    for _ in range(5):
        observation, reward, _, _, _ = env.step(env.action_space.sample())
        assert env.observation_space.contains(observation) and np.isfinite(reward)
    _still_works(env)


@pytest.mark.parametrize("seed", [np.int8(3), np.uint16(7), np.int32(11), np.uint64(2**64 - 1)])
def test_numpy_integer_seeds_are_taken(seed):
    """NumPy integer seeds, which Gymnasium itself refuses with an error that is not a
    ValueError, are taken as the same Python int."""
    env = _env("discrete")
    first, _ = env.reset(seed=seed)
    again, _ = env.reset(seed=int(seed))
    np.testing.assert_array_equal(first["pose"], again["pose"])


@pytest.mark.parametrize("seed", [-1, np.int64(-5), True, 1.5, "3"])
def test_seeds_that_are_not_non_negative_integers_are_refused(seed):
    env = _env("discrete")
    with pytest.raises(ValueError, match="seed"):
        env.reset(seed=seed)
    _still_works(env)
