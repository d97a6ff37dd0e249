"""A PPO model trained by ``benchmarks/train_ppo.py`` as a harness policy.

    naruto-benchmark --policies random frontier naruto_agent.rl.ppo_policy:PPOExplorer \\
        --image-scale 0.1 --policy-kwargs '{"naruto_agent.rl.ppo_policy:PPOExplorer":
        {"model_path": "runs/ppo/final_model.zip"}}'

The env gives raw observations; they are turned into the learning observations the model was
trained on (frames resized to ``size``, depth as a uint8 image, pose as position + 6D
rotation). Evaluate with the camera it was trained with (``--image-scale`` of the training).
"""

from __future__ import annotations

from naruto_agent.policies.adapters import SB3Policy
from naruto_agent.policies.base import Info, Observation
from naruto_gym.rl.observations import LearningObservation


class PPOExplorer(SB3Policy):
    """Loads a Stable-Baselines3 PPO zip (discrete actions) and acts with it.

    Args:
        model_path: the ``.zip`` saved by training.
        size: the frame side the model saw.
        deterministic: act with the mode of the action distribution (False samples, which
            keeps a policy from looping where its mode would).
        top_down_map: the model was trained with the egocentric top-down map
            (``train_ppo.py --top-down-map``); the policy builds it from the observations.
    """

    def __init__(self, model_path: str, size: int = 64, deterministic: bool = False,
                 top_down_map: bool = False) -> None:
        from stable_baselines3 import PPO

        model = PPO.load(model_path, device="cpu")
        self.learning_observation = LearningObservation(size, top_down_map=top_down_map)
        super().__init__(model, deterministic=deterministic,
                         observation_transform=self.learning_observation)

    def reset(self, observation: Observation, info: Info, seed: int | None = None) -> None:
        super().reset(observation, info, seed)
        self.learning_observation.start_episode(self.context.camera, self.context.bounds)
