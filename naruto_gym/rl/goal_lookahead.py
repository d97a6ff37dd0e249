"""What each candidate goal of a decision gains, walked on a copy of the goal-action stack.

The env is deterministic given its state, so a ``copy.deepcopy`` of a
:class:`~naruto_gym.rl.goal_actions.GoalActions` stack (env, egocentric map and walker) steps as
the original would, and stepping the copy leaves the original as it was.
:func:`lookahead_curves` walks every candidate of a decision at every goal (``decision="goal"``)
on a copy of its own: the candidate's goal to its end, then the nearest candidate at every later
decision, the same continuation for every candidate, so the curves differ by the first choice
alone. The curves measure how much a decision can decide (``benchmarks/explorer_leverage.py``),
give the gains a goal ranker learns from, and make the *rollout choice*
(``benchmarks/goal_rollout_check.py``): the candidate whose walk gains the most, one step of
policy improvement over the nearest choice with the simulator as its model.

    curves, to_decision = lookahead_curves(stack, count, coverage, horizon=100)
    scores = [gain_area(curve, 100) for curve in curves]
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

from naruto_gym.rl.goal_walker import AWAIT_DECISION

__all__ = ["gain_area", "gain_at", "lookahead_curves"]


def lookahead_curves(
    stack: Any, count: int, coverage: float, horizon: int
) -> tuple[list[np.ndarray], list[int]]:
    """The coverage gained after each env step by each of the first ``count`` candidates.

    Args:
        stack: a :class:`~naruto_gym.rl.goal_actions.GoalActions` stack (``decision="goal"``)
            at a decision: its candidates refreshed, no action set.
        count: the candidates to walk (slots ``0 .. count - 1``).
        coverage: the env's coverage at the decision (the curves are gains over it).
        horizon: env steps each copy walks at least; a copy also walks its candidate's goal to
            its end and stops where the episode ends. Every goal ends after at most
            ``steps_per_goal`` env steps, as in ``GoalActions.step``.

    Returns:
        Per candidate, its gain curve (entry ``k``: the gain after ``k + 1`` env steps; shorter
        than ``horizon`` where the episode ended), and the env steps until the copy's next
        decision (its candidate's goal done, given up or capped).
    """
    curves: list[np.ndarray] = []
    to_decision: list[int] = []
    cap = int(stack.steps_per_goal)
    for slot in range(count):
        trial = copy.deepcopy(stack)
        trial.walker.set_actions(np.array([slot]))
        curve: list[float] = []
        own, decided = True, 0  # decided: the env step at which the current goal was set
        while own or len(curve) < horizon:
            move = int(trial.walker.next_moves()[0])
            if move == AWAIT_DECISION or len(curve) - decided == cap:
                if own:
                    to_decision.append(len(curve))
                    own = False
                trial.walker.refresh_candidates()
                trial.walker.set_actions(np.array([0]))
                decided = len(curve)
                continue
            _, _, terminated, truncated, info = trial.env.step(move)
            curve.append(float(info["coverage"]) - coverage)
            if terminated or truncated:
                break
        if own:
            to_decision.append(len(curve))
        curves.append(np.asarray(curve))
    return curves, to_decision


def gain_at(curve: np.ndarray, steps: int) -> float:
    """The gain after ``steps`` env steps (the last one where the curve ends sooner, 0 before
    the first step)."""
    if steps <= 0 or len(curve) == 0:
        return 0.0
    return float(curve[min(steps, len(curve)) - 1])


def gain_area(curve: np.ndarray, horizon: int) -> float:
    """The mean gain over the first ``horizon`` env steps, the curve held at its last value
    where it ends sooner: what a choice adds to an episode's coverage area over that span."""
    if horizon <= 0:
        raise ValueError(f"horizon must be a positive number of env steps, got {horizon}")
    return float(np.mean([gain_at(curve, k) for k in range(1, horizon + 1)]))
