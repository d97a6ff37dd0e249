"""The explorer's untrained twin: the packaged checkpoint's settings and architecture with
every layer re-initialised from the episode's seed, under its own name."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3 import PPO  # noqa: E402

from naruto_agent.benchmark.spec import build_specs  # noqa: E402
from naruto_agent.policies.base import EnvContext  # noqa: E402
from naruto_agent.policies.registry import make_policy, policy_class  # noqa: E402
from naruto_agent.rl.explorer_policy import (  # noqa: E402
    PACKAGED_MODEL,
    MapGoalExplorer,
    UntrainedMapGoalExplorer,
)
from tests.agent.rl.small_env import ENV  # noqa: E402

if not PACKAGED_MODEL.exists():
    pytest.skip("no explorer checkpoint is shipped", allow_module_level=True)


def _episode(policy: MapGoalExplorer, seed: int, steps: int = 45) -> list[int]:
    env = gym.make("NarutoRecon-v0", **ENV)
    policy.bind(EnvContext.from_env(env))
    observation, info = env.reset(seed=seed)
    policy.reset(observation, info, seed=seed)
    moves = []
    for _ in range(steps):
        moves.append(policy.act(observation, info))
        observation, _, _, _, info = env.step(moves[-1])
    env.close()
    return moves


def _parameters(model: PPO) -> dict[str, np.ndarray]:
    return {key: value.detach().numpy().copy() for key, value in model.policy.state_dict().items()}


def test_the_twin_has_the_checkpoints_settings_and_shapes_but_other_weights():
    trained = MapGoalExplorer()
    twin = make_policy("explorer", weights="untrained")
    assert twin.settings == trained.settings and twin.weights == "untrained"
    _episode(twin, seed=4, steps=1)
    ours, theirs = _parameters(twin.model), _parameters(trained.model)
    assert ours.keys() == theirs.keys()
    assert all(ours[key].shape == theirs[key].shape for key in ours)
    weights = [key for key in ours if key.endswith("weight")]
    assert weights and not any(np.array_equal(ours[key], theirs[key]) for key in weights)
    # The checkpoint itself is untouched: a trained explorer still acts with its weights.
    again = _parameters(PPO.load(PACKAGED_MODEL, device="cpu"))
    assert all(np.array_equal(again[key], theirs[key]) for key in theirs)


def test_the_same_seed_gives_the_same_twin_and_walk_another_seed_another_twin():
    first, second = UntrainedMapGoalExplorer(), UntrainedMapGoalExplorer()
    assert _episode(first, seed=5) == _episode(second, seed=5)
    weights_five = _parameters(first.model)
    _episode(first, seed=6, steps=1)
    assert not np.array_equal(
        weights_five["action_net.weight"], _parameters(first.model)["action_net.weight"]
    )


def test_the_twin_has_its_own_name_and_records_and_bad_weights_are_refused():
    assert policy_class("explorer-untrained") is UntrainedMapGoalExplorer
    specs = build_specs(
        ["procedural:room:7"], ["explorer", "explorer-untrained", "goal-walker"], [0], 10
    )
    assert [spec.policy_label for spec in specs] == [
        "explorer",
        "explorer-untrained",
        "goal-walker",
    ]
    with pytest.raises(ValueError, match="untrained"):
        MapGoalExplorer(weights="random")
