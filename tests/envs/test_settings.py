"""Settings stored once: the env's keywords live in one ``EnvSettings`` (its defaults the
signature's), read through ``env.settings``; the batched envs take the same defaults. Every
env, one or batched, draws the reference ray cast's frames by default, and the rasterizer
where it is the faster is one keyword away (``pinhole_backend="auto"``)."""

from __future__ import annotations

import dataclasses
import inspect

import gymnasium as gym
import pytest

import naruto_gym  # noqa: F401
from naruto_gym.envs.naruto_recon_env import NarutoReconEnv
from naruto_gym.envs.settings import PINHOLE_BACKEND, EnvSettings
from naruto_gym.vector import NarutoReconVectorEnv
from tests.property.scenes import CHEAP, small_room

FIELDS = [item.name for item in dataclasses.fields(EnvSettings)]


@pytest.mark.parametrize("name", FIELDS)
def test_the_env_signature_defaults_are_the_settings_defaults(name):
    parameter = inspect.signature(NarutoReconEnv.__init__).parameters[name]
    assert parameter.default == getattr(EnvSettings, name), name


def test_the_env_keeps_no_copy_of_a_setting():
    env = NarutoReconEnv(small_room(), max_translation_m=0.2, **CHEAP)
    assert env.settings is env.runtime.settings
    assert env.settings.max_translation_m == 0.2
    for name in [*FIELDS, "max_rotation_rad"]:
        assert name not in vars(env), f"NarutoReconEnv copies the setting {name}"
    assert env.camera is env.runtime.camera and env.bounds is env.runtime.bounds
    with pytest.raises(AttributeError):
        env.settings.max_translation_m = 1.0  # frozen: one value for the env's life


def test_the_batched_env_reads_the_same_settings_with_the_same_defaults():
    vector = NarutoReconVectorEnv(2, scene=small_room(), **CHEAP)
    single = NarutoReconEnv(small_room(), **CHEAP)
    assert PINHOLE_BACKEND == "auto"
    assert single.settings.pinhole_backend == vector.settings.pinhole_backend == PINHOLE_BACKEND
    assert dataclasses.replace(vector.settings, threads=None) == dataclasses.replace(
        single.settings, threads=None
    )
    for name in FIELDS:
        if name != "camera":  # the batched env's camera is the scaled one, made once
            assert name not in vars(vector), f"the batched env copies the setting {name}"
    assert vector.camera == vector.settings.pinhole_camera == single.camera
    vector.close()


def test_gymnasium_made_envs_draw_rasterized_frames_by_default():
    """Gymnasium's documented calls, with no backend keyword: the rasterized frames (the
    published 680 x 1200 camera, the default room), one env and batched at any worker
    count."""
    single = gym.make("NarutoRecon-v0")
    assert single.unwrapped.settings.pinhole_backend == "auto"
    assert single.unwrapped.renderer.frame_backend == "raster"
    single.close()
    batched = gym.make_vec("NarutoRecon-v0", num_envs=2, vectorization_mode="vector_entry_point")
    assert batched.settings.pinhole_backend == "auto"
    batched.close()
    in_process = gym.make_vec(
        "NarutoRecon-v0", num_envs=2, vectorization_mode="vector_entry_point", workers=1
    )
    assert isinstance(in_process, NarutoReconVectorEnv)
    assert [runtime.renderer.frame_backend for runtime in in_process.scene_runtimes] == [
        "raster",
        "raster",
    ]
    in_process.close()


def test_the_reference_ray_cast_is_one_keyword_away():
    single = gym.make("NarutoRecon-v0", pinhole_backend="raycast")
    assert single.unwrapped.renderer.frame_backend == "raycast"
    single.close()
    batched = gym.make_vec(
        "NarutoRecon-v0", num_envs=2, vectorization_mode="vector_entry_point", workers=1,
        pinhole_backend="raycast",
    )
    assert [runtime.renderer.frame_backend for runtime in batched.scene_runtimes] == [
        "raycast",
        "raycast",
    ]
    batched.close()
