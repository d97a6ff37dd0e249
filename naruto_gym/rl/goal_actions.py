"""Goal actions: the policy picks one of ``N`` candidate goals found on its egocentric map every
``K`` steps, and a planner over the agent's own map walks there with the env's discrete moves;
or, with ``decision="goal"`` (:class:`GoalActions` only), at every goal: each action's goal is
walked alone, and the macro-step ends once it is viewed or given up (at most ``K`` steps).

An action is one of

* ``N`` candidates (``num_candidates``, 8 by default), found at every decision
  (:mod:`naruto_gym.rl.goal_candidates`): clusters of obstacles at the agent's height the
  camera has not seen and of free-space edges, each with a viewpoint the planner reaches,
  ranked by path length (candidate 0 the nearest). The observation gains their feature table
  (``"candidates"``, ``(N, F)`` float32; an empty slot is all zeros). The planner
  (:mod:`naruto_gym.rl.goal_planner`) walks a path to the viewpoint over cells the agent's
  rays crossed at its height, away from every obstacle it has seen, with turns and forward
  moves (levelling the camera first, and keeping ``WALK_HEIGHT_M`` above the floor: below
  doorways' lintels); at the viewpoint it turns towards the cluster, only as far as needed
  (half a turn at most). The cluster is then done for the episode, and the walker goes on to
  the nearest candidate for the rest of the ``K`` steps (``decision="interval"``, the
  default), or the macro-step ends there, the next goal the agent's (``decision="goal"``:
  the observation's table then has the ``out_of_sight`` column too; a goal lost when the
  map's slice restarts, or a candidate found while wandering with none, ends it too). An
  empty slot means candidate 0; with no candidate at all the agent walks to the reachable
  place farthest from where it has been (looking for candidates every few steps on the way),
  or turns in place where there is none.
* with ``primitive_actions``, the 10 discrete moves after them (index ``N + m``), each
  repeated for the ``K`` steps; a horizontal move the map does not know to be safe, or a
  vertical one without a panorama hit at least ``step + VERTICAL_MARGIN_M`` above (below) the
  agent, is replaced by a turn in place.

The planner never plans into obstacles or unseen space, so the env refuses a goal's moves only
when its map is wrong (rarely: see the tests). A macro-step's reward is the sum of its ``K``
rewards; its info adds ``"primitive_steps"`` and ``"refusals"`` (moves the env refused).

    env = GoalActions(EgocentricMapObservation(gym.make("NarutoRecon-v0",
                                                        action_mode="discrete")))
    envs = VectorGoalActions(VectorEgocentricMapObservation(NarutoReconVectorEnv(
        16, action_mode="discrete", autoreset_mode="SameStep", max_episode_steps=400)))

:class:`~naruto_gym.rl.goal_walker.GoalWalker` (:mod:`naruto_gym.rl.goal_walker`) is the
same planner without a wrapper (for a policy).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from naruto_gym.rl.egocentric_map import EgocentricMapBuilder
from naruto_gym.rl.goal_walker import AWAIT_DECISION, GoalWalker

__all__ = ["GOAL_STEPS", "GoalActions", "VectorGoalActions"]

#: The most env steps of one decision at every goal (``steps_per_goal`` with
#: ``decision="goal"``): a goal about 8 m of path away with its turns (a step is 0.1 m).
GOAL_STEPS = 100


def _find_map(env: Any) -> EgocentricMapBuilder:
    layer = env
    while layer is not None:
        builder = getattr(layer, "map_builder", None)
        if isinstance(builder, EgocentricMapBuilder):
            return builder
        layer = getattr(layer, "env", None)
    raise ValueError(
        "goal actions plan on the egocentric map: wrap the env in EgocentricMapObservation "
        "(VectorEgocentricMapObservation for the batched env) first"
    )


def _walker_for(env: Any, options: dict[str, Any]) -> GoalWalker:
    settings = env.unwrapped.settings
    if settings.action_mode != "discrete":
        raise ValueError(
            f"goal actions step the env with its discrete moves: make it with "
            f"action_mode='discrete', not {settings.action_mode!r}"
        )
    options = {
        "step_m": settings.max_translation_m,
        "turn_rad": settings.max_rotation_rad,
        **options,
    }
    return GoalWalker(_find_map(env), **options)


def _with_candidates(space: spaces.Dict, walker: GoalWalker) -> spaces.Dict:
    return spaces.Dict({**space.spaces, "candidates": walker.candidate_space})


def _check_steps(steps_per_goal: int) -> int:
    if (
        isinstance(steps_per_goal, bool)
        or int(steps_per_goal) != steps_per_goal
        or (steps_per_goal < 1)
    ):
        raise ValueError(f"steps_per_goal must be a positive integer, got {steps_per_goal!r}")
    return int(steps_per_goal)


class GoalActions(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Goal actions (module docstring) on a single env wrapped in
    :class:`~naruto_gym.rl.egocentric_map.EgocentricMapObservation`; a macro-step ends early
    when the episode does (and with ``decision="goal"`` when its goal is done).

    Args:
        env: the wrapped env (``action_mode="discrete"``).
        steps_per_goal: ``K``, primitive steps per action (the most, with
            ``decision="goal"``).
        **options: :class:`GoalWalker` keywords (``num_candidates``, ``primitive_actions``,
            ``decision``, ...).
    """

    def __init__(self, env: gym.Env, steps_per_goal: int = 20, **options: Any) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, steps_per_goal=steps_per_goal, **options)
        gym.Wrapper.__init__(self, env)
        self.steps_per_goal = _check_steps(steps_per_goal)
        self.walker = _walker_for(env, options)
        self.action_space = self.walker.action_space
        self.observation_space = _with_candidates(env.observation_space, self.walker)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        observation, info = self.env.reset(seed=seed, options=options)
        self.walker.reset()
        return {**observation, "candidates": self.walker.refresh_candidates()[0]}, info

    def step(self, action: Any):
        self.walker.set_actions(np.array([action]))
        total, refusals, steps = 0.0, 0, 0
        while steps < self.steps_per_goal:
            move = int(self.walker.next_moves()[0])
            if move == AWAIT_DECISION:  # the goal is done: the agent chooses the next
                break
            observation, reward, terminated, truncated, info = self.env.step(move)
            total += float(reward)
            refusals += int(bool(info.get("collided", False)))
            steps += 1
            if terminated or truncated:
                break
        info = {**info, "primitive_steps": steps, "refusals": refusals}
        observation = {**observation, "candidates": self.walker.refresh_candidates()[0]}
        return observation, total, terminated, truncated, info


class VectorGoalActions(gym.vector.VectorWrapper):
    """Goal actions (module docstring) on the batched env wrapped in
    :class:`~naruto_gym.rl.egocentric_map.VectorEgocentricMapObservation`: every agent takes
    ``K`` primitive steps per macro-step.

    Episodes must end on macro-step boundaries: the env needs ``SAME_STEP`` autoreset and a
    ``max_episode_steps`` that ``steps_per_goal`` divides, and its agents start together (as
    a full reset starts them).

    Args:
        env: the wrapped batched env (``action_mode="discrete"``).
        steps_per_goal: ``K``, primitive steps per action.
        **options: :class:`GoalWalker` keywords.

    Raises:
        ValueError: the autoreset mode or the episode length does not fit.
        RuntimeError: an episode ended inside a macro-step (after a partial reset).
    """

    def __init__(self, env: gym.vector.VectorEnv, steps_per_goal: int = 20, **options: Any) -> None:
        if options.get("decision", "interval") != "interval":
            raise ValueError(
                "VectorGoalActions decides every steps_per_goal steps for all agents at once "
                "(decision='interval'); a decision at every goal steps each agent on its own: "
                "wrap single envs in GoalActions (GoalDecisionVecEnv for Stable-Baselines3)"
            )
        super().__init__(env)
        self.steps_per_goal = _check_steps(steps_per_goal)
        if env.metadata.get("autoreset_mode") != AutoresetMode.SAME_STEP:
            raise ValueError(
                "VectorGoalActions needs the batched env with "
                "autoreset_mode='SameStep' (episodes end on macro-step bounds)"
            )
        episode = getattr(env.unwrapped, "max_episode_steps", None)
        if episode is None or episode % self.steps_per_goal:
            raise ValueError(
                f"max_episode_steps ({episode}) must be a multiple of steps_per_goal "
                f"({self.steps_per_goal}) so that episodes end on macro-step bounds"
            )
        self.walker = _walker_for(env, options)
        self.single_action_space = self.walker.action_space
        self.action_space = batch_space(self.single_action_space, env.num_envs)
        self.single_observation_space = _with_candidates(env.single_observation_space, self.walker)
        self.observation_space = batch_space(self.single_observation_space, env.num_envs)

    def reset(self, *, seed: Any = None, options: dict[str, Any] | None = None):
        observations, infos = self.env.reset(seed=seed, options=options)
        mask = (options or {}).get("reset_mask")
        self.walker.reset(None if mask is None else np.flatnonzero(mask))
        return {**observations, "candidates": self.walker.refresh_candidates()}, infos

    def step(self, actions: Any):
        self.walker.set_actions(np.asarray(actions))
        total = np.zeros(self.num_envs)
        refusals = np.zeros(self.num_envs, np.int64)
        # The map wrapper's advance skips the learning observation of the steps before the
        # last one (nobody reads it); a wrapper between the two hides it: step then.
        advance = getattr(self.env, "advance", None)
        for step in range(self.steps_per_goal):
            last = step == self.steps_per_goal - 1
            take_step = self.env.step if last or advance is None else advance
            observations, rewards, terminations, truncations, infos = take_step(
                self.walker.next_moves()
            )
            total += rewards
            refusals += np.asarray(infos.get("collided", np.zeros(self.num_envs)), bool)
            ended = terminations | truncations
            if ended.any() and step < self.steps_per_goal - 1:
                raise RuntimeError(
                    "an episode ended inside a macro-step: VectorGoalActions needs every "
                    "agent's episodes to start together and last a multiple of steps_per_goal "
                    "(no partial resets)"
                )
        ended = np.flatnonzero(terminations | truncations)
        if len(ended):
            self.walker.reset(ended)
            if "final_obs" in infos:
                # The finished episodes' maps are gone (the new episodes' maps replaced
                # them): their final observations get an empty candidate table.
                final = np.array(infos["final_obs"], dtype=object)
                empty = np.zeros(self.single_observation_space["candidates"].shape, np.float32)
                for i in np.flatnonzero(infos["_final_obs"]):
                    final[i] = {**final[i], "candidates": empty}
                infos = {**infos, "final_obs": final}
        observations = {**observations, "candidates": self.walker.refresh_candidates()}
        infos = {
            **infos,
            "primitive_steps": np.full(self.num_envs, self.steps_per_goal),
            "_primitive_steps": np.ones(self.num_envs, bool),
            "refusals": refusals,
            "_refusals": np.ones(self.num_envs, bool),
        }
        return observations, total, terminations, truncations, infos
