"""Mappers by name or import path, the Mapper protocol, and the refusal of incomplete mappers."""

from __future__ import annotations

import typing

import gymnasium as gym
import numpy as np
import pytest

import naruto_gym  # noqa: F401  (registers the env)
from naruto_agent.mapping import (
    MAPPER_MEMBERS,
    Mapper,
    NeuralMapper,
    NeuralMapperConfig,
    ObservedSpace,
    TsdfUncertaintyMapper,
    make_mapper,
    mapper_names,
    register_mapper,
    registry,
)
from naruto_agent.naruto import NarutoPolicy
from naruto_agent.policies import EnvContext
from naruto_gym.sensors.pinhole import PinholeCamera

BOUNDS = np.array([[0.0, 0.0, 0.0], [2.0, 2.0, 1.5]])
CAMERA = PinholeCamera(width=40, height=30, fx=30.0, fy=30.0, cx=19.5, cy=14.5)


class NoPanorama:
    """Has every method but integrate_panorama and planner_view."""

    def __init__(self, bounds: np.ndarray, camera: PinholeCamera) -> None:
        self.observed_space = ObservedSpace(bounds)

    def integrate(self, rgb, depth, camera_to_world, frame_index):  # noqa: ANN001, ANN201
        return True

    def sdf(self, points):  # noqa: ANN001, ANN201
        return np.ones(len(points))

    def extract_mesh(self, voxel_size=0.02):  # noqa: ANN001, ANN201
        return None


class NoObservedSpace(NoPanorama):
    """Every method, but its observed space is a dict, not an ObservedSpace."""

    def __init__(self, bounds: np.ndarray, camera: PinholeCamera) -> None:
        self.observed_space = {}

    def integrate_panorama(self, panorama, position) -> None:  # noqa: ANN001
        pass

    def planner_view(self, voxel_size=0.1):  # noqa: ANN001, ANN201
        return None


@pytest.fixture
def clean_registry(monkeypatch):
    """The registry as shipped, restored after the test."""
    monkeypatch.setattr(registry, "MAPPERS", dict(registry.MAPPERS))


def test_the_protocol_lists_every_member_the_agent_reads():
    members = set(typing.get_type_hints(Mapper)) | {
        name for name, value in vars(Mapper).items() if callable(value) and name[0] != "_"
    }
    assert members == set(MAPPER_MEMBERS)
    assert "observed_space" in members


def test_the_shipped_mappers_are_registered_and_keep_the_agents_seed_draws():
    assert {"tsdf", "neural"} <= set(mapper_names())
    rng = np.random.default_rng(7)
    tsdf = make_mapper("tsdf", BOUNDS, CAMERA, device="cpu", rng=rng)
    assert isinstance(tsdf, TsdfUncertaintyMapper) and isinstance(tsdf, Mapper)
    # The TSDF mapper takes no seed: the agent's randomness is left as it was.
    assert rng.integers(1000) == np.random.default_rng(7).integers(1000)
    config = NeuralMapperConfig(hash_log2_table_size=10, tune_cpu_allocator=False)
    neural = make_mapper(
        "neural",
        BOUNDS,
        CAMERA,
        device="cpu",
        rng=np.random.default_rng(3),
        settings={"config": config},
    )
    assert isinstance(neural, NeuralMapper) and isinstance(neural, Mapper)
    assert neural.config.seed == np.random.default_rng(3).integers(2**31 - 1)
    assert neural.config.hash_log2_table_size == 10 and str(neural.device) == "cpu"


def test_an_unknown_name_lists_the_registered_ones_and_the_import_path_form():
    with pytest.raises(ValueError) as error:
        NarutoPolicy(mapper_kind="octomap")
    message = str(error.value)
    assert "unknown mapper 'octomap'" in message
    assert "['neural', 'tsdf']" in message and "'package.module:ClassName'" in message


@pytest.mark.parametrize(
    ("kind", "message"),
    [
        ("no_such_module:Mapper", "No module named 'no_such_module'"),
        (f"{__name__}:Missing", f"{__name__} has no 'Missing'"),
        (f"{__name__}:BOUNDS", "is not a class or function"),
        (
            f"{__name__}:NoPanorama",
            "lacks what the NARUTO agent reads: integrate_panorama(), planner_view()",
        ),
    ],
)
def test_a_bad_import_path_is_refused_when_the_policy_is_built(kind, message):
    with pytest.raises(ValueError) as error:
        NarutoPolicy(mapper_kind=kind)
    assert message in str(error.value)


def test_a_mapper_whose_observed_space_is_wrong_is_refused_when_built():
    with pytest.raises(ValueError) as error:
        make_mapper(f"{__name__}:NoObservedSpace", BOUNDS, CAMERA)
    message = str(error.value)
    assert "lacks what the NARUTO agent reads: observed_space (an ObservedSpace; got a dict)" in (
        message
    )
    assert "observed_space, integrate, integrate_panorama, planner_view, sdf, extract_mesh" in (
        message
    )


def test_settings_the_mapper_does_not_take_are_a_clear_error():
    with pytest.raises(ValueError, match="cannot build mapper 'tsdf' with settings"):
        make_mapper("tsdf", BOUNDS, CAMERA, settings={"voxel": 0.1})
    with pytest.raises(ValueError, match="must not hold 'device'"):
        make_mapper("tsdf", BOUNDS, CAMERA, settings={"device": "cpu"})
    with pytest.raises(ValueError, match="pass tsdf=\\{'voxel_size_m': 0.04\\}"):
        NarutoPolicy(mapper_kind="tsdf", mapper_settings={"voxel_size_m": 0.04})


def test_register_mapper_names_a_class_and_refuses_an_incomplete_one(clean_registry):
    @register_mapper("recording-test")
    class Complete(NoObservedSpace):
        def __init__(
            self,
            bounds: np.ndarray,
            camera: PinholeCamera,
            *,
            device: str,
            seed: int,
            extra: int = 0,
        ) -> None:
            self.observed_space = ObservedSpace(bounds)
            self.device, self.seed, self.extra = device, seed, extra

    mapper = make_mapper(
        "recording-test",
        BOUNDS,
        CAMERA,
        device="cpu",
        rng=np.random.default_rng(1),
        settings={"extra": 4},
    )
    assert isinstance(mapper, Complete) and (mapper.device, mapper.extra) == ("cpu", 4)
    assert mapper.seed == np.random.default_rng(1).integers(2**31 - 1)
    assert "recording-test" in mapper_names()
    with pytest.raises(ValueError, match="is taken by"):
        register_mapper("recording-test")(NoObservedSpace)
    with pytest.raises(
        TypeError, match="lacks what the NARUTO agent reads: integrate_panorama\\(\\), planner_view"
    ):
        register_mapper("incomplete")(NoPanorama)


class RecordingMapper:
    """A TSDF mapper that notes the name of every member read from it."""

    read: set[str] = set()

    def __init__(self, bounds: np.ndarray, camera: PinholeCamera, *, device: str) -> None:
        self._inner = TsdfUncertaintyMapper(bounds, camera)

    def __getattr__(self, name: str) -> object:
        RecordingMapper.read.add(name)
        return getattr(self._inner, name)


def test_the_agent_reads_nothing_outside_the_protocol(clean_registry):
    """A short episode, the view layers and the reconstruction read only Mapper members."""
    register_mapper("recording")(RecordingMapper)
    RecordingMapper.read = set()
    env = gym.make(
        "NarutoRecon-v0",
        scene="replica_like_room",
        image_scale=0.1,
        panorama_shape=(16, 32),
        max_episode_steps=41,
    )
    policy = NarutoPolicy(
        mapper_kind="recording", device="cpu", initial_look_around=False, panorama_every=1
    )
    policy.bind(EnvContext.from_env(env))
    observation, info = env.reset(seed=0, options=policy.reset_options())
    policy.reset(observation, info, seed=0)
    for _ in range(12):
        observation, _, _, _, info = env.step(policy.act(observation, info))
    policy.view_layers()
    policy.reconstruction()
    assert policy.plans, "the agent never planned on the mapper"
    assert RecordingMapper.read <= set(MAPPER_MEMBERS)
    assert RecordingMapper.read == set(MAPPER_MEMBERS)  # and it reads every one of them
