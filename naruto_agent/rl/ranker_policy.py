"""``goal-ranker``: the explorer's map, candidates and walker deciding at every goal, the goal
chosen by the learned candidate ranker (:mod:`naruto_agent.rl.candidate_ranker`), and its
untrained twin.

    naruto-benchmark --policies goal-ranker goal-ranker-untrained goal-walker \\
        --policy-kwargs '{"goal-walker": {"rule": "nearest", "decision": "goal"}}'
    naruto-benchmark --policies goal-ranker --policy-kwargs \\
        '{"goal-ranker": {"model_path": "runs/goal_ranker/ranker.pt"}}'

The walker is the one of ``goal-walker`` with ``decision="goal"``: it walks the chosen
candidate alone and asks for the next once the goal is viewed, given up or lost; the ranker
scores the candidates of the decision and the walker walks the highest. Without
``model_path`` it loads the ranker shipped in the package (:data:`PACKAGED_RANKER`).

The **untrained twin** (``weights="untrained"``, registered as ``goal-ranker-untrained``) is
the same network with fresh weights drawn at every episode from the episode's seed: the same
walker and candidates, a ranking that has learned nothing. Paired with ``goal-ranker`` on the
same scenes and seeds, it measures what the training adds; ``goal-walker`` with
``decision="goal"`` and a rule (``nearest``: the continuation the ranker's data were measured
with) is the scripted choice of the same action space.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from naruto_agent.policies.base import Info, Observation
from naruto_agent.policies.registry import register_policy
from naruto_agent.rl.candidate_ranker import load_ranker, walker_surroundings
from naruto_agent.rl.explorer_policy import DEFAULT_SETTINGS, CandidateGoalPolicy, check_weights
from naruto_gym.rl.goal_actions import GOAL_STEPS

PACKAGED_RANKER = Path(__file__).with_name("checkpoints") / "goal_ranker.pt"
"""The ranker shipped in the package."""

#: The walker's settings under the ranker: the decision at every goal, candidates only.
RANKER_WALKER = {
    **DEFAULT_SETTINGS,
    "decision": "goal",
    "steps_per_goal": GOAL_STEPS,
    "primitive_actions": False,
}


@register_policy("goal-ranker")
class GoalRankerPolicy(CandidateGoalPolicy):
    """The walker at every goal with the learned ranker's choice (module docstring).

    Args:
        model_path: the ranker file (``benchmarks/train_goal_ranker.py``'s ``ranker.pt``);
            None: the packaged one.
        stall_watchdog: watch the walk for stalls and walk out of one, as ``goal-walker``.
        weights: ``"trained"``, the file's; ``"untrained"``, its untrained twin's (fresh
            weights at every episode from the episode's seed, 0 without one).

    Raises:
        FileNotFoundError: no ranker at ``model_path`` (or none packaged).
        ValueError: a file that is not a ranker, or ``weights`` not one of
            :data:`~naruto_agent.rl.explorer_policy.WEIGHTS`.
    """

    def __init__(
        self,
        model_path: str | None = None,
        stall_watchdog: bool = True,
        weights: str = "trained",
    ) -> None:
        self.weights = check_weights(weights, "the file's")
        self.ranker, self.record = load_ranker(model_path or PACKAGED_RANKER)
        settings = {**RANKER_WALKER, "num_candidates": self.ranker.settings.num_candidates}
        super().__init__(settings, stall_watchdog)

    def reset(self, observation: Observation, info: Info, seed: int | None = None) -> None:
        if self.weights == "untrained":
            self.ranker.reinitialise(0 if seed is None else seed)
        super().reset(observation, info, seed)

    def choose(self, observation: dict[str, np.ndarray]) -> int:
        assert self.walker is not None
        table = observation["candidates"]
        count = int((table[:, 0] > 0).sum())
        return self.ranker.choose(table, walker_surroundings(self.walker, 0, count))


@register_policy("goal-ranker-untrained")
class UntrainedGoalRankerPolicy(GoalRankerPolicy):
    """``goal-ranker``'s untrained twin under its own name (records and leaderboard rows apart):
    :class:`GoalRankerPolicy` with ``weights="untrained"``.

    Args:
        model_path: the ranker whose network the twin has (None: the packaged one).
        stall_watchdog: watch the walk for stalls.
    """

    def __init__(self, model_path: str | None = None, stall_watchdog: bool = True) -> None:
        super().__init__(model_path, stall_watchdog, weights="untrained")
