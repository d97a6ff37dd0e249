"""Settings stored once: the env's keywords live in one ``EnvSettings`` (its defaults the
signature's), read through ``env.settings``; the batched envs take the same defaults but the
pinhole backend's, which both read from ``naruto_gym.envs.settings``."""

from __future__ import annotations

import dataclasses
import inspect

import pytest

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
    assert PINHOLE_BACKEND == "raycast"
    assert single.settings.pinhole_backend == vector.settings.pinhole_backend == PINHOLE_BACKEND
    assert dataclasses.replace(vector.settings, threads=None) == dataclasses.replace(
        single.settings, threads=None
    )
    for name in FIELDS:
        if name != "camera":  # the batched env's camera is the scaled one, made once
            assert name not in vars(vector), f"the batched env copies the setting {name}"
    assert vector.camera == vector.settings.pinhole_camera == single.camera
    vector.close()
