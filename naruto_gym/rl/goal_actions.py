"""Goal actions: the policy picks a long-term goal on its egocentric map every ``K`` steps and
a planner over the agent's own map walks there with the env's discrete moves.

An action is one of

* ``goal_grid**2`` goals: the cells of a ``goal_grid x goal_grid`` grid laid over the far
  scale of the egocentric map (:mod:`naruto_gym.rl.egocentric_map`; 12.8 m around the agent
  by default, index ``row * goal_grid + column``, row 0 ahead). The planner
  (:mod:`naruto_gym.rl.goal_planner`) searches a path over the cells the agent's rays crossed
  at its height, away from every obstacle it has seen, to the reachable cell nearest the goal,
  and follows it with turns and forward moves for ``K`` steps (levelling the camera first),
  planning again when new obstacles block the path; at the goal it turns in place.
* with ``primitive_actions``, the 10 discrete moves after them (index ``goal_grid**2 + m``),
  each repeated for the ``K`` steps; a horizontal move the map does not know to be safe, or a
  vertical one without a panorama hit at least ``step + VERTICAL_MARGIN_M`` above (below) the
  agent, is replaced by a turn in place.

The planner never plans into obstacles or unseen space, so the env refuses a goal's moves only
when its map is wrong (rarely: see the tests). A macro-step's reward is the sum of its ``K``
rewards; its info adds ``"primitive_steps"`` and ``"refusals"`` (moves the env refused).

    env = GoalActions(EgocentricMapObservation(gym.make("NarutoRecon-v0",
                                                        action_mode="discrete")))
    envs = VectorGoalActions(VectorEgocentricMapObservation(NarutoReconVectorEnv(
        16, action_mode="discrete", autoreset_mode="SameStep", max_episode_steps=400)))

:class:`GoalWalker` is the same planner without a wrapper (for a policy).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from naruto_gym.motion.actions import DISCRETE_ACTIONS
from naruto_gym.rl.egocentric_map import EgocentricMapBuilder
from naruto_gym.rl.goal_planner import (
    REACHED,
    REPLAN,
    TURN_LEFT,
    follow_path,
    move_is_safe,
    plan_path,
)

__all__ = ["GoalActions", "GoalWalker", "VectorGoalActions"]

MOVE_UP = DISCRETE_ACTIONS.index("move_up")
LOOK_UP = DISCRETE_ACTIONS.index("look_up")
LOOK_DOWN = DISCRETE_ACTIONS.index("look_down")
MOVE_DOWN = DISCRETE_ACTIONS.index("move_down")
#: Free space kept above or below the agent after a vertical move (radius and margin).
VERTICAL_MARGIN_M = 0.2


class GoalWalker:
    """Turns goal or primitive actions into one primitive move per step, for every agent of
    an :class:`EgocentricMapBuilder`.

    Args:
        map_builder: the agents' maps (updated by its owner after every step).
        goal_grid: goals per side of the grid over the far map.
        primitive_actions: actions past the goals are the discrete moves.
        step_m: length of a move (the env's ``max_translation_m``).
        turn_rad: angle of a turn (the env's ``max_rotation_deg`` in radians).
        inflate: cells around an obstacle the planner keeps out of.
        max_path: longest path kept (a longer one is followed in parts).
    """

    def __init__(
        self,
        map_builder: EgocentricMapBuilder,
        goal_grid: int = 8,
        primitive_actions: bool = True,
        step_m: float = 0.1,
        turn_rad: float = float(np.deg2rad(20.0)),
        inflate: int = 1,
        max_path: int = 512,
    ) -> None:
        if goal_grid < 1:
            raise ValueError(f"goal_grid must be positive, got {goal_grid}")
        self.map = map_builder
        self.goal_grid = int(goal_grid)
        self.primitive_actions = bool(primitive_actions)
        self.step_m = float(step_m)
        self.turn_rad = float(turn_rad)
        self.inflate = int(inflate)
        n = map_builder.num_envs
        self.paths = np.zeros((n, max_path, 2), np.int64)
        self.lengths = np.zeros(n, np.int64)
        self.cursors = np.zeros((n, 1), np.int64)
        self.goals = np.zeros((n, 2))
        self.primitives = np.full(n, -1, np.int64)  # -1: walking to a goal
        half_m = map_builder.cells * map_builder.far_cell_m / 2
        self.radius = int(np.ceil(half_m * np.sqrt(2) / map_builder.cell_m)) + 1

    @property
    def num_goals(self) -> int:
        return self.goal_grid**2

    @property
    def action_space(self) -> spaces.Discrete:
        extra = len(DISCRETE_ACTIONS) if self.primitive_actions else 0
        return spaces.Discrete(self.num_goals + extra)

    def goal_position(self, env: int, goal: int) -> np.ndarray:
        """World (x, y) of goal cell ``goal`` for agent ``env`` at its last pose."""
        pose = self.map.poses[env]
        row, column = divmod(int(goal), self.goal_grid)
        span = self.map.cells * self.map.far_cell_m
        ahead = span * (0.5 - (row + 0.5) / self.goal_grid)
        right = span * ((column + 0.5) / self.goal_grid - 0.5)
        heading = np.arctan2(pose[1, 2], pose[0, 2])
        forward = np.array([np.cos(heading), np.sin(heading)])
        rightward = np.array([forward[1], -forward[0]])
        return pose[:2, 3] + ahead * forward + right * rightward

    def set_actions(self, actions: np.ndarray, envs: np.ndarray | None = None) -> None:
        """Start the macro-step of ``actions`` (one per env of ``envs``, default all).

        Raises:
            ValueError: an action outside :attr:`action_space`.
        """
        envs = np.arange(self.map.num_envs) if envs is None else np.asarray(envs)
        actions = np.asarray(actions, np.int64).reshape(len(envs))
        bad = (actions < 0) | (actions >= self.action_space.n)
        if bad.any():
            raise ValueError(
                f"goal actions are 0..{self.action_space.n - 1} ({self.num_goals} goals"
                f"{' then the 10 discrete moves' if self.primitive_actions else ''}), "
                f"got {actions[bad].tolist()}"
            )
        for i, action in zip(envs, actions, strict=True):
            if action < self.num_goals:
                self.primitives[i] = -1
                self.goals[i] = self.goal_position(int(i), int(action))
                self._plan(int(i))
            else:
                self.primitives[i] = action - self.num_goals

    def _plan(self, i: int) -> None:
        self.lengths[i] = plan_path(
            self.map.grids[i],
            self.map.origins[i],
            self.map.cell_m,
            self.map.poses[i][:2, 3].copy(),
            self.goals[i],
            self.radius,
            self.inflate,
            self.paths[i],
        )
        self.cursors[i, 0] = 0

    def next_moves(self, envs: np.ndarray | None = None) -> np.ndarray:
        """The primitive move of each agent of ``envs`` (default all) for its current pose."""
        envs = np.arange(self.map.num_envs) if envs is None else np.asarray(envs)
        moves = np.empty(len(envs), np.int64)
        for row, i in enumerate(envs):
            moves[row] = self._move(int(i))
        return moves

    def _move(self, i: int) -> int:
        grid, origin, cell_m = self.map.grids[i], self.map.origins[i], self.map.cell_m
        pose = self.map.poses[i]
        primitive = self.primitives[i]
        if primitive >= 0:
            if primitive in (MOVE_UP, MOVE_DOWN):
                clearance = (
                    self.map.clearance_up if primitive == MOVE_UP else (self.map.clearance_down)
                )
                return (
                    int(primitive)
                    if clearance[i] > self.step_m + VERTICAL_MARGIN_M
                    else (TURN_LEFT)
                )
            if move_is_safe(grid, origin, cell_m, pose, primitive, self.step_m, self.inflate):
                return int(primitive)
            return TURN_LEFT
        pitch = float(np.arcsin(np.clip(pose[2, 2], -1.0, 1.0)))
        if abs(pitch) > 0.5 * self.turn_rad + 1e-6:
            # Walk with the camera level: a pitched one sees floor or ceiling only.
            return LOOK_DOWN if pitch > 0 else LOOK_UP
        def follow() -> tuple[int, int]:
            return follow_path(
                grid,
                origin,
                cell_m,
                pose,
                self.paths[i],
                self.lengths[i],
                self.cursors[i],
                self.step_m,
                self.turn_rad,
                self.inflate,
            )

        move, status = follow()
        if status == REPLAN:
            self._plan(i)  # the path ran into a newly seen obstacle: plan again, once
            move, status = follow()
            if status == REPLAN:
                move = TURN_LEFT
        if status == REACHED:
            self.lengths[i] = 0
        return int(move)


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
    when the episode does.

    Args:
        env: the wrapped env (``action_mode="discrete"``).
        steps_per_goal: ``K``, primitive steps per action.
        **options: :class:`GoalWalker` keywords (``goal_grid``, ``primitive_actions``, ...).
    """

    def __init__(self, env: gym.Env, steps_per_goal: int = 20, **options: Any) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, steps_per_goal=steps_per_goal, **options)
        gym.Wrapper.__init__(self, env)
        self.steps_per_goal = _check_steps(steps_per_goal)
        self.walker = _walker_for(env, options)
        self.action_space = self.walker.action_space

    def step(self, action: Any):
        self.walker.set_actions(np.array([action]))
        total, refusals, steps = 0.0, 0, 0
        while steps < self.steps_per_goal:
            move = int(self.walker.next_moves()[0])
            observation, reward, terminated, truncated, info = self.env.step(move)
            total += float(reward)
            refusals += int(bool(info.get("collided", False)))
            steps += 1
            if terminated or truncated:
                break
        info = {**info, "primitive_steps": steps, "refusals": refusals}
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

    def step(self, actions: Any):
        self.walker.set_actions(np.asarray(actions))
        total = np.zeros(self.num_envs)
        refusals = np.zeros(self.num_envs, np.int64)
        for step in range(self.steps_per_goal):
            observations, rewards, terminations, truncations, infos = self.env.step(
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
        infos = {
            **infos,
            "primitive_steps": np.full(self.num_envs, self.steps_per_goal),
            "_primitive_steps": np.ones(self.num_envs, bool),
            "refusals": refusals,
            "_refusals": np.ones(self.num_envs, bool),
        }
        return observations, total, terminations, truncations, infos
