"""RLlib PPO on naruto-gym: register the env, run a few PPO iterations on a local Ray instance.

Needs ``pip install "naruto-gym[ray]"`` (Ray with RLlib); without it, or with a Ray that lacks
a piece of RLlib (``ray[default]`` alone has no ``dm_tree``), it says so and exits. The env
each RLlib env runner builds
is ``NarutoRecon-v0`` with discrete actions, a low-resolution camera and the learning
observations of ``naruto_gym.wrappers.for_learning``, flattened to one vector (RLlib's
default model for vectors is an MLP; use a custom RLModule for a CNN).

    python examples/rllib_ppo.py --iterations 2
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym

import naruto_gym  # noqa: F401  (registers the ids)
from naruto_gym.cli_args import parse_dataclass_args
from naruto_gym.sensors.pinhole import PinholeCamera
from naruto_gym.wrappers import for_learning

ENV_NAME = "NarutoReconFlat-v0"
INSTALL_HINT = "pip install 'naruto-gym[ray]'"


@dataclass
class Args:
    iterations: int = 2
    """PPO training iterations"""
    size: int = 16
    """square side of the frames fed to the MLP"""
    episode_steps: int = 50
    """episode budget"""
    train_batch_size: int = 200
    """env steps per iteration"""
    num_envs_per_env_runner: int = 2
    """envs in the local env runner"""
    scene: str = "two_rooms"
    """scene of every episode"""


def make_env(config: dict[str, Any]) -> gym.Env:
    """The env RLlib builds: learning observations flattened to one float vector."""
    env = gym.make(
        "NarutoRecon-v0", scene=config.get("scene", "two_rooms"), action_mode="discrete",
        camera=PinholeCamera(32, 32, 16, 16, 15.5, 15.5), panorama_shape=None,
        coverage_samples=config.get("coverage_samples", 3000),
        max_episode_steps=config.get("episode_steps", 50),
    )
    env = for_learning(env, size=config.get("size", 16), depth="float")
    return gym.wrappers.FlattenObservation(
        gym.wrappers.TransformObservation(env, _as_float, _float_space(env.observation_space))
    )


def _as_float(observation: dict[str, Any]) -> dict[str, Any]:
    return {key: value.astype("float32") / (255.0 if value.dtype == "uint8" else 1.0)
            for key, value in observation.items()}


def _float_space(space: gym.spaces.Dict) -> gym.spaces.Dict:
    return gym.spaces.Dict({
        key: gym.spaces.Box(-float("inf"), float("inf"), box.shape, "float32")
        for key, box in space.spaces.items()
    })


def import_rllib() -> tuple[Any, Any, Any]:
    """``ray``, RLlib's ``PPOConfig`` and ``register_env``.

    Raises:
        SystemExit: Ray or any piece RLlib imports is missing (the message says what to
            install).
    """
    try:
        import ray
        from ray.rllib.algorithms.ppo import PPOConfig
        from ray.tune.registry import register_env
    except ImportError as error:
        missing = getattr(error, "name", None) or str(error)
        raise SystemExit(
            f"examples/rllib_ppo.py needs Ray with RLlib, and {missing!r} does not import "
            f"({type(error).__name__}: {error}); install it with: {INSTALL_HINT}"
        ) from error
    return ray, PPOConfig, register_env


def main(args: Args) -> list[dict[str, Any]]:
    ray, PPOConfig, register_env = import_rllib()  # noqa: N806 (RLlib's class name)
    register_env(ENV_NAME, make_env)
    ray.init(num_cpus=2, include_dashboard=False, ignore_reinit_error=True,
             log_to_driver=False)
    config = (
        PPOConfig()
        .environment(ENV_NAME, env_config={"scene": args.scene, "size": args.size,
                                           "episode_steps": args.episode_steps})
        .env_runners(num_env_runners=0, num_envs_per_env_runner=args.num_envs_per_env_runner,
                     rollout_fragment_length="auto")
        .training(train_batch_size_per_learner=args.train_batch_size, minibatch_size=50,
                   num_epochs=2)
    )
    build = getattr(config, "build_algo", None) or config.build  # older Ray: build()
    algorithm = build()
    results = []
    try:
        for iteration in range(args.iterations):
            result = algorithm.train()
            runners = result.get("env_runners", {})
            steps = runners.get("num_env_steps_sampled_lifetime")
            print(f"iteration {iteration + 1}: env steps {steps}, "
                  f"episode return mean {runners.get('episode_return_mean')}")
            results.append(result)
    finally:
        algorithm.stop()
        ray.shutdown()
    return results


if __name__ == "__main__":
    main(parse_dataclass_args(Args))
