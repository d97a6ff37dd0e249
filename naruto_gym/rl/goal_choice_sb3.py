"""Stable-Baselines3 pieces of the decision at every goal (``decision="goal"`` of
:mod:`naruto_gym.rl.goal_actions`): the agents as an SB3 ``VecEnv`` that steps each on its
own (a decision lasts until its goal is done), and a policy that scores every candidate with
the same small network.

    from stable_baselines3 import PPO
    from naruto_gym.rl.goal_choice_sb3 import CandidateScorerPolicy, GoalDecisionVecEnv

    venv = GoalDecisionVecEnv(8, max_episode_steps=400)
    model = PPO(CandidateScorerPolicy, venv, gamma=0.95)

The policy's choice is a softmax over the valid candidates of scores computed per candidate
by shared weights from the candidate's row of the feature table, the mean of every valid
row's embedding and a context of the map, panorama and pose: permuting the candidates
permutes the probabilities, and an empty slot gets none. The value reads the context and the
mean embedding (unchanged by a permutation).

Needs ``pip install naruto-gym[sb3]``.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.policies import MultiInputActorCriticPolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

from naruto_gym.rl.egocentric_map import EgocentricMapObservation
from naruto_gym.rl.explorer_env import EXPLORER_ENV, TRAIN_MIX
from naruto_gym.rl.explorer_sb3 import channels_first, channels_last, map_encoder, panorama_encoder
from naruto_gym.rl.goal_actions import GOAL_STEPS, GoalActions
from naruto_gym.rl.goal_candidates import CANDIDATE_FEATURES
from naruto_gym.scenes.stream import parse_procedural_name

__all__ = [
    "CandidateScorer",
    "CandidateScorerPolicy",
    "GoalContextExtractor",
    "GoalDecisionVecEnv",
    "make_goal_stack",
]

#: The score of an empty candidate slot: its probability is 0 to float precision.
MASKED_SCORE = -1e8
_VALID = CANDIDATE_FEATURES.index("valid")


def make_goal_stack(
    scene: str,
    max_episode_steps: int,
    steps_per_goal: int = GOAL_STEPS,
    num_candidates: int = 8,
    map_options: dict[str, Any] | None = None,
    **env_kwargs: Any,
) -> GoalActions:
    """One agent's env with the egocentric map and the goal actions deciding at every goal
    (candidates only), at the explorer's env settings (:data:`EXPLORER_ENV`, under
    ``env_kwargs``)."""
    env = gym.make(
        "NarutoRecon-v0",
        scene=scene,
        max_episode_steps=max_episode_steps,
        **{**EXPLORER_ENV, **env_kwargs},
    )
    return GoalActions(
        EgocentricMapObservation(env, **(map_options or {})),
        steps_per_goal,
        num_candidates=num_candidates,
        primitive_actions=False,
        decision="goal",
    )


class GoalDecisionVecEnv(VecEnv):
    """Agents deciding at every goal, as a Stable-Baselines3 ``VecEnv``: each agent its own
    :func:`make_goal_stack`, stepped one after the other, so each SB3 step is one decision of
    every agent, as many env steps as its goal takes (``info["primitive_steps"]``). Agent
    ``i`` plays scene stream ``scenes[i % len(scenes)]``: a new generated scene of the
    stream's split every ``episodes_per_scene`` episodes, seeds drawn from ``seed``.

    Args:
        num_envs: agents.
        max_episode_steps: env steps per episode.
        steps_per_goal: the most env steps per decision.
        num_candidates: candidate slots.
        scenes: scene streams (``"procedural:small:train"``...).
        episodes_per_scene: episodes an agent plays on a scene before it draws the next.
        seed: seed of the scene and episode draws.
        map_options: :class:`~naruto_gym.rl.egocentric_map.EgocentricMapBuilder` keywords.
        **env_kwargs: ``NarutoReconEnv`` keywords over :data:`EXPLORER_ENV`.

    Raises:
        ValueError: a name that is not a scene stream, or a count below 1.
    """

    def __init__(
        self,
        num_envs: int,
        max_episode_steps: int = 400,
        steps_per_goal: int = GOAL_STEPS,
        num_candidates: int = 8,
        scenes: tuple[str, ...] = TRAIN_MIX,
        episodes_per_scene: int = 4,
        seed: int = 0,
        map_options: dict[str, Any] | None = None,
        **env_kwargs: Any,
    ) -> None:
        if num_envs < 1 or episodes_per_scene < 1:
            raise ValueError(
                f"num_envs and episodes_per_scene must be at least 1, got {num_envs} and "
                f"{episodes_per_scene}"
            )
        self.specs = [parse_procedural_name(scenes[i % len(scenes)]) for i in range(num_envs)]
        for name, spec in zip(scenes, self.specs, strict=False):
            if not spec.is_stream:
                raise ValueError(
                    f"{name!r} is one scene; GoalDecisionVecEnv takes scene streams such as "
                    f"'procedural:small:train'"
                )
        self.stack_options: dict[str, Any] = {
            "max_episode_steps": max_episode_steps,
            "steps_per_goal": steps_per_goal,
            "num_candidates": num_candidates,
            "map_options": map_options,
            **env_kwargs,
        }
        self.episodes_per_scene = episodes_per_scene
        self.rngs = [np.random.default_rng([seed, i]) for i in range(num_envs)]
        self.episodes = np.zeros(num_envs, np.int64)
        self.stacks: list[GoalActions | None] = [None] * num_envs
        for i in range(num_envs):
            self._stack(i)
        first = self._stack(0)
        super().__init__(num_envs, first.observation_space, first.action_space)
        self._actions: np.ndarray | None = None

    def _stack(self, i: int) -> GoalActions:
        """Agent ``i``'s stack, on a new scene of its stream when its scene is done (called
        between episodes)."""
        stack = self.stacks[i]
        due = self.episodes[i] > 0 and self.episodes[i] % self.episodes_per_scene == 0
        if stack is None or due:
            if stack is not None:
                stack.close()
            spec = self.specs[i]
            name = f"procedural:{spec.kind}:{spec.draw_seed(self.rngs[i])}"
            name += f":{spec.openings}" if spec.openings else ""
            stack = self.stacks[i] = make_goal_stack(name, **self.stack_options)
        return stack

    def _reset_agent(self, i: int) -> dict[str, np.ndarray]:
        observation, _ = self._stack(i).reset(seed=int(self.rngs[i].integers(2**31)))
        return observation

    def _batch(self, observations: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
        return {key: np.stack([o[key] for o in observations]) for key in observations[0]}

    def reset(self) -> dict[str, np.ndarray]:
        return self._batch([self._reset_agent(i) for i in range(self.num_envs)])

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self) -> tuple[Any, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        assert self._actions is not None
        observations, rewards, dones, infos = [], [], [], []
        for i, action in enumerate(self._actions):
            stack = self.stacks[i]
            assert stack is not None
            observation, reward, terminated, truncated, info = stack.step(int(action))
            info = dict(info)
            if terminated or truncated:
                info["terminal_observation"] = observation
                info["TimeLimit.truncated"] = bool(truncated and not terminated)
                info["final_info"] = dict(info)
                self.episodes[i] += 1
                observation = self._reset_agent(i)
            observations.append(observation)
            rewards.append(reward)
            dones.append(terminated or truncated)
            infos.append(info)
        return (
            self._batch(observations),
            np.asarray(rewards, np.float32),
            np.asarray(dones, bool),
            infos,
        )

    def close(self) -> None:
        for stack in self.stacks:
            if stack is not None:
                stack.close()

    def seed(self, seed: int | None = None) -> list[int | None]:
        if seed is not None:
            self.rngs = [np.random.default_rng([seed, i]) for i in range(self.num_envs)]
        return [None if seed is None else seed + i for i in range(self.num_envs)]

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self.stacks[i], attr_name) for i in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        for i in self._get_indices(indices):
            setattr(self.stacks[i], attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any
    ) -> list[Any]:
        return [
            getattr(self.stacks[i], method_name)(*method_args, **method_kwargs)
            for i in self._get_indices(indices)
        ]

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def get_images(self) -> list[np.ndarray]:
        raise NotImplementedError("GoalDecisionVecEnv does not render")


class GoalContextExtractor(BaseFeaturesExtractor):
    """The context of a decision and its candidates: a CNN over the ``map``, one over the
    ``panorama`` and an MLP over the ``pose``, projected to ``context_dim``; the
    ``candidates`` table is handed on as it is (flattened after the context), for
    :class:`CandidateScorer` to score row by row.

    Args:
        observation_space: ``Dict`` with ``map``, ``panorama``, ``pose`` and ``candidates``.
        context_dim: size of the context.
    """

    def __init__(self, observation_space: spaces.Dict, context_dim: int = 128) -> None:
        missing = {"map", "panorama", "pose", "candidates"} - set(observation_space.spaces)
        if missing:
            raise ValueError(
                f"GoalContextExtractor needs the egocentric map observation with the goal "
                f"actions' candidates; {sorted(missing)} missing from {observation_space}"
            )
        table = observation_space["candidates"].shape
        super().__init__(observation_space, context_dim + int(np.prod(table)))
        self.context_dim = context_dim
        self.table_shape = (int(table[0]), int(table[1]))
        channels, height, width = channels_first(observation_space["map"])
        self.map = map_encoder(channels)
        pano_channels, pano_height, pano_width = channels_first(observation_space["panorama"])
        self.panorama = panorama_encoder(pano_channels)
        pose_size = int(np.prod(observation_space["pose"].shape))
        self.pose = torch.nn.Sequential(torch.nn.Linear(pose_size, 32), torch.nn.ReLU())
        with torch.no_grad():
            width_out = (
                self.map(torch.zeros(1, channels, height, width)).shape[1]
                + self.panorama(torch.zeros(1, pano_channels, pano_height, pano_width)).shape[1]
                + 32
            )
        self.head = torch.nn.Sequential(torch.nn.Linear(width_out, context_dim), torch.nn.ReLU())

    def forward(self, observations: dict[str, torch.Tensor]) -> torch.Tensor:
        context = self.head(
            torch.cat(
                [
                    self.map(channels_last(observations["map"])),
                    self.panorama(channels_last(observations["panorama"])),
                    self.pose(observations["pose"].flatten(1)),
                ],
                1,
            )
        )
        return torch.cat([context, observations["candidates"].flatten(1)], 1)


class CandidateScorer(torch.nn.Module):
    """The policy's and value's heads over :class:`GoalContextExtractor`'s output (SB3's
    ``mlp_extractor`` slot): each candidate's row is embedded by one MLP; its score is one
    MLP of its embedding, the mean embedding of the valid rows and the context, the same
    weights for every slot; empty slots score :data:`MASKED_SCORE`. The actor's latent is
    the scores themselves (the policy's logits), the critic's an MLP of the context and the
    mean embedding.

    Args:
        context_dim: size of the context.
        num_candidates: candidate slots (``N``).
        num_features: columns of the table (``F``).
        hidden: width of the embeddings and hidden layers.
    """

    def __init__(
        self, context_dim: int, num_candidates: int, num_features: int, hidden: int = 64
    ) -> None:
        super().__init__()
        self.context_dim, self.shape = context_dim, (num_candidates, num_features)
        self.embed = torch.nn.Sequential(
            torch.nn.Linear(num_features, hidden),
            torch.nn.ReLU(),
            torch.nn.Linear(hidden, hidden),
            torch.nn.ReLU(),
        )
        self.score = torch.nn.Sequential(
            torch.nn.Linear(2 * hidden + context_dim, hidden),
            torch.nn.ReLU(),
            torch.nn.Linear(hidden, 1),
        )
        self.value = torch.nn.Sequential(
            torch.nn.Linear(hidden + context_dim, hidden), torch.nn.ReLU()
        )
        self.latent_dim_pi = num_candidates
        self.latent_dim_vf = hidden

    def _parts(
        self, features: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """The context, each row's embedding, the valid slots and the valid rows' mean
        embedding."""
        context = features[:, : self.context_dim]
        table = features[:, self.context_dim :].reshape(-1, *self.shape)
        valid = table[..., _VALID] > 0
        embedded = self.embed(table)
        weights = valid.unsqueeze(-1).to(embedded.dtype)
        mean = (embedded * weights).sum(1) / weights.sum(1).clamp(min=1.0)
        return context, embedded, valid, mean

    def forward_actor(self, features: torch.Tensor) -> torch.Tensor:
        context, embedded, valid, mean = self._parts(features)
        count = embedded.shape[1]
        joint = torch.cat(
            [
                embedded,
                mean.unsqueeze(1).expand(-1, count, -1),
                context.unsqueeze(1).expand(-1, count, -1),
            ],
            -1,
        )
        scores = self.score(joint).squeeze(-1)
        return scores.masked_fill(~valid, MASKED_SCORE)

    def forward_critic(self, features: torch.Tensor) -> torch.Tensor:
        context, _, _, mean = self._parts(features)
        return self.value(torch.cat([context, mean], 1))

    def forward(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.forward_actor(features), self.forward_critic(features)


class CandidateScorerPolicy(MultiInputActorCriticPolicy):
    """SB3's actor-critic policy with the choice scored per candidate
    (:class:`GoalContextExtractor` and :class:`CandidateScorer`; module docstring): the
    action distribution's logits are the candidates' scores (no layer after them), the last
    score layer starts near 0 (a near-uniform first choice among the valid candidates).

    Args:
        observation_space: the goal actions' observation (with ``candidates``).
        action_space: ``Discrete(N)``, one action per candidate slot.
        lr_schedule: SB3's learning-rate schedule.
        hidden: width of :class:`CandidateScorer`.
        **kwargs: ``MultiInputActorCriticPolicy`` keywords (``features_extractor_kwargs``:
            ``context_dim``).

    Raises:
        ValueError: an action space that is not one action per candidate slot.
    """

    def __init__(
        self,
        observation_space: spaces.Dict,
        action_space: spaces.Space,
        lr_schedule: Any,
        hidden: int = 64,
        **kwargs: Any,
    ) -> None:
        slots = observation_space["candidates"].shape[0]
        if not isinstance(action_space, spaces.Discrete) or int(action_space.n) != slots:
            raise ValueError(
                f"CandidateScorerPolicy picks one of the {slots} candidate slots: the action "
                f"space must be Discrete({slots}) (goal actions without primitive_actions), "
                f"got {action_space}"
            )
        self.hidden = hidden
        kwargs.setdefault("features_extractor_class", GoalContextExtractor)
        super().__init__(observation_space, action_space, lr_schedule, **kwargs)

    def _build_mlp_extractor(self) -> None:
        extractor = self.features_extractor
        assert isinstance(extractor, GoalContextExtractor)
        self.mlp_extractor = CandidateScorer(
            extractor.context_dim, *extractor.table_shape, hidden=self.hidden
        )

    def _build(self, lr_schedule: Any) -> None:
        super()._build(lr_schedule)
        self.action_net = torch.nn.Identity()
        last = self.mlp_extractor.score[-1]
        torch.nn.init.orthogonal_(last.weight, gain=0.01)
        torch.nn.init.zeros_(last.bias)
        self.optimizer = self.optimizer_class(
            self.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs
        )

    def _get_constructor_parameters(self) -> dict[str, Any]:
        return {**super()._get_constructor_parameters(), "hidden": self.hidden}
