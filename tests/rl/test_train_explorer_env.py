"""The explorer's training script builds its env on shared scenes by default (a documented
flag turns them off) through ``make_vector_env``, with the panorama band when asked."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

pytest.importorskip("stable_baselines3")

from naruto_agent.cli_args import parse_dataclass_args  # noqa: E402
from naruto_gym.rl.explorer_env import TRAIN_MIX  # noqa: E402
from naruto_gym.vector import NarutoReconVectorEnv, SharedSceneStreams  # noqa: E402
from tests.scripts import load_script  # noqa: E402

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "train_explorer.py"


@pytest.fixture(scope="module")
def train_explorer():
    yield load_script(SCRIPT, "train_explorer_under_test")
    del sys.modules["train_explorer_under_test"]


def test_shared_scenes_by_default_and_a_flag_for_a_scene_per_agent(train_explorer):
    args = parse_dataclass_args(train_explorer.Args, ["--num-envs", "4", "--agents-per-scene", "2"])
    assert args.shared_scenes and isinstance(
        train_explorer.training_scenes(args), SharedSceneStreams
    )
    env = train_explorer.make_batched_env(args)
    assert isinstance(env, NarutoReconVectorEnv)
    assert env.settings.panorama_horizon_deg is None
    env.reset(seed=0)
    runtimes = env.scene_runtimes
    assert runtimes[0] is runtimes[1] and runtimes[2] is runtimes[3]
    assert runtimes[0] is not runtimes[2]
    assert train_explorer.agent_streams(args) == [
        *[TRAIN_MIX[0]] * 2,
        *[TRAIN_MIX[1]] * 2,
    ]
    env.close()

    alone = parse_dataclass_args(
        train_explorer.Args,
        ["--num-envs", "4", "--no-shared-scenes", "--panorama-horizon-deg", "30"],
    )
    assert train_explorer.training_scenes(alone) == train_explorer.train_mix(4)
    env = train_explorer.make_batched_env(alone)
    assert env.settings.panorama_horizon_deg == 30
    assert train_explorer.explorer_settings(alone)["panorama_horizon_deg"] == 30
    env.close()


def test_the_chain_steps_in_as_many_workers_as_share_the_scene_groups(train_explorer):
    def workers(*flags: str) -> int:
        return train_explorer.env_workers(parse_dataclass_args(train_explorer.Args, list(flags)))

    # 64 agents in 4 groups of 16: one worker per CPU, as many as share the groups evenly.
    big = ["--num-envs", "64", "--agents-per-scene", "16"]
    assert workers(*big, "--env-threads", "2") == 2
    assert workers(*big, "--env-threads", "3") == 2
    assert workers(*big, "--env-threads", "16") == 4
    assert workers(*big, "--env-threads", "1") == 1
    assert workers("--num-envs", "8", "--no-shared-scenes", "--env-threads", "16") == 8
    assert workers(*big, "--env-workers", "1") == 1
    # By default each of the four train streams gets one group of a quarter of the agents.
    for agents, size in ((8, 2), (16, 4), (64, 16), (2, 1)):
        args = parse_dataclass_args(train_explorer.Args, ["--num-envs", str(agents)])
        assert train_explorer.group_size(args) == size
    eight = parse_dataclass_args(train_explorer.Args, ["--num-envs", "8"])
    assert set(train_explorer.agent_streams(eight)) == set(TRAIN_MIX)


def test_training_with_the_chain_in_workers_and_a_bfloat16_update(train_explorer, tmp_path):
    args = parse_dataclass_args(
        train_explorer.Args,
        [
            "--total-timesteps", "320", "--num-envs", "4", "--agents-per-scene", "2",
            "--env-workers", "2", "--n-steps", "2", "--batch-size", "8", "--n-epochs", "1",
            "--max-episode-steps", "40", "--update-dtype", "bfloat16",
            "--output-dir", str(tmp_path),
        ],
    )  # fmt: skip
    profile = train_explorer.main(args)["profile"]
    assert set(profile["seconds"]) == {
        "env_and_wrappers_in_workers",
        "policy_forward_and_sb3",
        "ppo_update",
    }
    assert profile["env_steps"] == 320 and profile["seconds"]["ppo_update"] > 0
    assert (tmp_path / "explorer.zip").is_file()
    with pytest.raises(SystemExit, match="update-dtype"):
        train_explorer.main(
            parse_dataclass_args(train_explorer.Args, ["--update-dtype", "float16"])
        )


def test_the_update_runs_in_bfloat16_by_default_only_where_the_cpu_computes_in_it(
    train_explorer,
):
    zen4 = "processor\t: 0\nflags\t\t: fpu avx2 avx512f avx512_bf16\n"
    older = "processor\t: 0\nflags\t\t: fpu avx2 avx512f\n"
    sapphire = "flags\t\t: fpu avx512f amx_bf16 amx_tile\n"
    assert train_explorer.cpu_has_bfloat16(zen4)
    assert train_explorer.cpu_has_bfloat16(sapphire)
    assert not train_explorer.cpu_has_bfloat16(older)
    assert not train_explorer.cpu_has_bfloat16("")
    args = parse_dataclass_args(train_explorer.Args, [])
    assert args.update_dtype == "auto"
    expected = "bfloat16" if train_explorer.cpu_has_bfloat16() else "float32"
    assert train_explorer.update_dtype(args) == expected
    explicit = parse_dataclass_args(train_explorer.Args, ["--update-dtype", "float32"])
    assert train_explorer.update_dtype(explicit) == "float32"


def test_a_bfloat16_update_moves_the_parameters_as_the_float32_one(train_explorer):
    """From the same start and the same rollout, the update with the features extractor in
    bfloat16 changes the policy's parameters in nearly the same direction and by nearly as
    much: the policy's and value's heads, and the log-probabilities PPO's ratio is built
    from, stay float32."""
    import torch

    from naruto_gym.rl.explorer_env import EXPLORER_ENV, wrap_explorer
    from naruto_gym.rl.explorer_sb3 import ExplorerFeaturesExtractor
    from naruto_gym.rl.sb3 import Sb3VecEnv
    from naruto_gym.vector import make_vector_env

    settings = {**EXPLORER_ENV, "max_episode_steps": 40, "autoreset_mode": "SameStep"}

    def update(dtype: str) -> tuple[torch.Tensor, torch.Tensor]:
        venv = Sb3VecEnv(wrap_explorer(make_vector_env(4, scene="procedural:small:7", **settings)))
        model = train_explorer.AutocastPPO(
            "MultiInputPolicy", venv, n_steps=4, batch_size=8, n_epochs=2, seed=0, device="cpu",
            policy_kwargs={"features_extractor_class": ExplorerFeaturesExtractor},
        )  # fmt: skip
        model.update_dtype = dtype
        start = torch.nn.utils.parameters_to_vector(model.policy.parameters()).detach().clone()
        model.learn(16)  # one rollout of 4 decisions per agent, one update of 4 steps
        venv.close()
        return start, torch.nn.utils.parameters_to_vector(model.policy.parameters()).detach()

    start, full = update("float32")
    same_start, half = update("bfloat16")
    assert torch.equal(start, same_start)
    assert not torch.equal(full, half)  # the autocast is in effect
    moved, moved_half = full - start, half - start
    assert torch.nn.functional.cosine_similarity(moved, moved_half, dim=0) > 0.98
    assert 0.9 < float(moved_half.norm() / moved.norm()) < 1.1


def test_normalized_rewards_are_saved_with_each_checkpoint_and_resumed(train_explorer, tmp_path):
    """--normalize-reward: PPO learns from rewards scaled by the running return statistics,
    which each checkpoint keeps beside it and --resume reads back."""
    flags = [
        "--num-envs", "4", "--agents-per-scene", "2", "--env-workers", "1", "--n-steps", "2",
        "--batch-size", "8", "--n-epochs", "1", "--max-episode-steps", "40",
        "--checkpoint-every", "160", "--normalize-reward", "--output-dir", str(tmp_path),
    ]  # fmt: skip
    train_explorer.main(parse_dataclass_args(train_explorer.Args,
                                             ["--total-timesteps", "320", *flags]))
    checkpoint = train_explorer.latest_checkpoint(tmp_path)
    stats = train_explorer.reward_stats_path(checkpoint)
    assert stats.is_file()
    args = parse_dataclass_args(train_explorer.Args, ["--total-timesteps", "480", *flags])
    args.resume = True
    venv = train_explorer.normalized_rewards(train_explorer.make_env(args)[0], args, checkpoint)
    try:
        assert venv.norm_reward and not venv.norm_obs and venv.ret_rms.count > 1  # read back
    finally:
        venv.close()
    assert train_explorer.main(args)["env_steps"] == 480
