"""RLlib PPO on naruto-gym: each env runner steps one batched env (many agents in one process).

Needs ``pip install "naruto-gym[ray]"`` (Ray with RLlib); without it, or with a Ray that lacks
a piece of RLlib (``ray[default]`` alone has no ``dm_tree``), it says so and exits.

RLlib's new API stack gives every env runner a Gymnasium vector env. With
``gym_env_vectorize_mode="vector_entry_point"`` (the default here) RLlib asks the registered
env creator, ``naruto_gym.rl.rllib_env.make_rllib_env``, for the whole vector at once, and it
answers with the batched ``NarutoReconVectorEnv`` (``gym.make_vec("NarutoRecon-v0",
num_envs=..., vectorization_mode="vector_entry_point")``): one process per runner steps all
its ``num_envs_per_env_runner`` agents together, instead of one env object per agent.
``--vectorization-mode sync`` or ``async`` gives Gymnasium's own vectors of single envs (for
comparison). Observations are the learning observations of ``naruto_gym.wrappers.for_learning``
(discrete actions, a 32 x 32 camera, no panorama), flattened to one float vector for RLlib's
default MLP (use a custom RLModule for a CNN).

    python examples/rllib_ppo.py --iterations 2                   # a local Ray instance
    python examples/rllib_ppo.py --address auto --num-env-runners 8   # a running cluster
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import naruto_gym  # noqa: F401  (registers the ids)
from naruto_agent.cli_args import parse_dataclass_args
from naruto_gym.rl.rllib_env import make_rllib_env
from naruto_gym.sensors.pinhole import PinholeCamera

ENV_NAME = "NarutoReconFlat-v0"
INSTALL_HINT = "pip install 'naruto-gym[ray]'"
#: How an env runner builds its vector env (``gymnasium.VectorizeMode`` values).
VECTORIZATION_MODES = ("vector_entry_point", "sync", "async")


@dataclass
class Args:
    iterations: int = 2
    """PPO training iterations"""
    size: int = 16
    """square side of the frames fed to the MLP"""
    max_episode_steps: int = 50
    """episode budget"""
    train_batch_size: int = 400
    """env steps per iteration (all env runners together)"""
    minibatch_size: int = 100
    """SGD minibatch"""
    num_env_runners: int = 0
    """remote env runners (Ray actors, one CPU each); 0: the driver samples"""
    num_envs_per_env_runner: int = 8
    """agents each env runner steps together"""
    num_cpus_per_env_runner: int = 1
    """CPUs Ray reserves for each remote env runner"""
    vectorization_mode: str = "vector_entry_point"
    """vector_entry_point (the batched env), sync or async (Gymnasium's vectors of envs)"""
    scene: str = "two_rooms"
    """scene of every episode (a name, a mesh path or a stream such as procedural:room)"""
    address: str | None = None
    """Ray cluster to join (auto, or ray://host:10001); none: start a local instance"""
    num_cpus: int | None = None
    """CPUs of the local Ray instance (none: all the machine has; ignored with --address)"""
    seed: int | None = None
    """seed of the env runners' first reset"""


def env_config(args: Args) -> dict[str, Any]:
    """The ``env_config`` RLlib hands ``make_rllib_env`` on every env runner: discrete
    actions, a 32 x 32 camera, no panorama, frames resized to ``size``, flattened."""
    if args.vectorization_mode not in VECTORIZATION_MODES:
        raise ValueError(f"vectorization_mode must be one of {VECTORIZATION_MODES}, got "
                         f"{args.vectorization_mode!r}")
    return {
        "size": args.size, "flatten": True, "scene": args.scene, "action_mode": "discrete",
        "camera": PinholeCamera(32, 32, 16, 16, 15.5, 15.5), "panorama_shape": None,
        "coverage_samples": 3000, "max_episode_steps": args.max_episode_steps,
    }


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


def init_ray(ray: Any, args: Args) -> None:
    """Joins the cluster at ``args.address``, or starts a local instance."""
    if args.address:
        ray.init(address=args.address, ignore_reinit_error=True, log_to_driver=False)
    else:
        ray.init(num_cpus=args.num_cpus, include_dashboard=False, ignore_reinit_error=True,
                 log_to_driver=False)


def build_algorithm(PPOConfig: Any, args: Args) -> Any:  # noqa: N803 (RLlib's class name)
    """PPO on the new API stack (RLModule, Learner, EnvRunner with connectors v2)."""
    config = (
        PPOConfig()
        .api_stack(enable_rl_module_and_learner=True,
                   enable_env_runner_and_connector_v2=True)
        .environment(ENV_NAME, env_config=env_config(args))
        .env_runners(num_env_runners=args.num_env_runners,
                     num_envs_per_env_runner=args.num_envs_per_env_runner,
                     num_cpus_per_env_runner=args.num_cpus_per_env_runner,
                     gym_env_vectorize_mode=args.vectorization_mode,
                     rollout_fragment_length="auto")
        .training(train_batch_size_per_learner=args.train_batch_size,
                  minibatch_size=min(args.minibatch_size, args.train_batch_size), num_epochs=2)
        .debugging(seed=args.seed)
    )
    return config.build_algo()


def main(args: Args) -> list[dict[str, Any]]:
    env_config(args)  # a bad --vectorization-mode fails before Ray starts
    ray, PPOConfig, register_env = import_rllib()  # noqa: N806 (RLlib's class name)
    register_env(ENV_NAME, make_rllib_env)
    init_ray(ray, args)
    results = []
    algorithm = None
    try:
        algorithm = build_algorithm(PPOConfig, args)
        for iteration in range(args.iterations):
            result = algorithm.train()
            runners = result.get("env_runners", {})
            steps = runners.get("num_env_steps_sampled_lifetime")
            print(f"iteration {iteration + 1}: env steps {steps}, "
                  f"episode return mean {runners.get('episode_return_mean')}")
            results.append(result)
    finally:
        if algorithm is not None:
            algorithm.stop()
        ray.shutdown()
    return results


if __name__ == "__main__":
    main(parse_dataclass_args(Args))
