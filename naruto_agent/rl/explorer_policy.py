"""The map-and-goal explorer trained by ``benchmarks/train_explorer.py``, as a harness policy,
and its untrained twin.

    naruto-benchmark --policies random frontier explorer
    naruto-benchmark --policies explorer --policy-kwargs \\
        '{"explorer": {"model_path": "runs/explorer/final_model.zip"}}'
    naruto-benchmark --policies explorer explorer-untrained goal-walker

It builds the egocentric map from the observations it is handed
(:class:`~naruto_gym.rl.egocentric_map.EgocentricMapBuilder`), finds the candidate goals on
it, asks the PPO model for one (or a repeated discrete move) every ``steps_per_goal`` steps,
and walks it with the planner over its own map
(:class:`~naruto_gym.rl.goal_walker.GoalWalker`): the same observations and actions as in
training, step for step. A model trained on the decision at every goal (``"decision":
"goal"`` in its settings, ``benchmarks/train_goal_explorer.py``) is asked each time its goal
is viewed, given up or lost instead, and at the latest every ``steps_per_goal`` steps. The
training settings (``decision``, ``steps_per_goal``, the number of
candidates, the map's options, the panorama size) are read from the JSON file saved beside the
model (``<model>.json``, written by the training script), so a model and its settings cannot
disagree. Without ``model_path`` it loads the checkpoint shipped in the package
(:data:`PACKAGED_MODEL`), when there is one.

The **untrained twin** (``weights="untrained"``, registered as ``explorer-untrained`` so that
its records and rows stay apart from the explorer's) is the same checkpoint with every layer
re-initialised as PPO initialises a new model, drawn afresh at every episode from the
episode's seed: the same settings, map, candidates and walker, a network that has learned
nothing. Paired with the explorer on the same scenes and seeds, it measures what the training
adds; :class:`~naruto_agent.rl.scripted_explorer.GoalWalkerPolicy` (``goal-walker``) is the
same walker with a fixed, scripted choice.
"""

from __future__ import annotations

import json
from abc import abstractmethod
from pathlib import Path
from typing import Any

import numpy as np

from naruto_agent.policies.base import Info, Observation, Policy
from naruto_agent.policies.registry import register_policy
from naruto_agent.policies.stall_recovery import ReachablePlaces
from naruto_gym.motion.actions import DISCRETE_ACTIONS
from naruto_gym.rl.egocentric_map import EgocentricMapBuilder
from naruto_gym.rl.goal_walker import AWAIT_DECISION, GoalWalker
from naruto_gym.sensors.panorama import EquirectangularCamera

PACKAGED_MODEL = Path(__file__).with_name("checkpoints") / "explorer.zip"
"""The explorer checkpoint shipped in the package (with ``explorer.json`` beside it)."""

#: Settings of a model saved without its JSON file (the training script's defaults).
DEFAULT_SETTINGS: dict[str, Any] = {
    "decision": "interval",
    "steps_per_goal": 20,
    "num_candidates": 8,
    "primitive_actions": True,
    "map_options": {},
    "panorama_shape": [32, 64],
}


def settings_path(model_path: Path) -> Path:
    """The JSON file of a model's training settings: ``<model without .zip>.json``."""
    return model_path.with_suffix(".json")


def read_settings(model_path: str | Path) -> dict[str, Any]:
    """The training settings of a model (:data:`DEFAULT_SETTINGS` under what its JSON file
    holds; the defaults alone without one).

    Raises:
        ValueError: settings of the old grid goals (``goal_grid``): train the model again.
    """
    stored = settings_path(Path(model_path))
    settings = {**DEFAULT_SETTINGS, **(json.loads(stored.read_text()) if stored.exists() else {})}
    if "goal_grid" in settings:
        raise ValueError(
            f"{model_path} was trained on the old grid goals (goal_grid in {stored}); the "
            f"explorer now picks among num_candidates candidate goals: train it again "
            f"with benchmarks/train_explorer.py"
        )
    return settings


def save_settings(model_path: Path, settings: dict[str, Any]) -> Path:
    """Write the training settings beside ``model_path`` (what :class:`MapGoalExplorer`
    reads back); returns the file."""
    path = settings_path(Path(model_path))
    path.write_text(json.dumps({**DEFAULT_SETTINGS, **settings}, indent=1))
    return path


#: Largest checkpoint the package ships.
MAX_PACKAGED_BYTES = 5 * 2**20


def export_checkpoint(model_path: str | Path, out_path: str | Path) -> Path:
    """Write a model for acting only: its weights and settings without the optimiser's
    state (a third of a PPO zip's size; training resumed from it restarts Adam's moments).
    ``out_path`` gets the ``.json`` settings beside it, as the policy reads them.

    Raises:
        ValueError: the exported model is larger than :data:`MAX_PACKAGED_BYTES` (make the
            features smaller, e.g. ``--features-dim``).
    """
    from stable_baselines3 import PPO

    model_path, out_path = Path(model_path), Path(out_path)
    model = PPO.load(model_path, device="cpu")
    policy = model.policy
    policy.optimizer = policy.optimizer_class(
        policy.parameters(), lr=model.lr_schedule(1.0), **policy.optimizer_kwargs
    )
    out_path.parent.mkdir(parents=True, exist_ok=True)
    model.save(out_path)
    stored = settings_path(model_path)
    settings = json.loads(stored.read_text()) if stored.exists() else {}
    save_settings(out_path, settings)
    size = out_path.stat().st_size
    if size > MAX_PACKAGED_BYTES:
        raise ValueError(
            f"{out_path} is {size / 2**20:.1f} MB, more than the package's "
            f"{MAX_PACKAGED_BYTES / 2**20:.0f} MB: train with smaller features (--features-dim)"
        )
    return out_path


#: What ``MapGoalExplorer(weights=...)`` acts with: the checkpoint's weights, or its untrained
#: twin's (every layer re-initialised from the episode's seed).
WEIGHTS = ("trained", "untrained")


def check_weights(weights: str, trained: str) -> str:
    """``weights`` when it is one of :data:`WEIGHTS`.

    Args:
        weights: the keyword given.
        trained: what the trained weights are, for the message ("the checkpoint's").

    Raises:
        ValueError: any other value.
    """
    if weights not in WEIGHTS:
        raise ValueError(
            f"weights must be one of {WEIGHTS} ({trained}, or its untrained twin's), "
            f"got {weights!r}"
        )
    return weights


def reinitialise_weights(model: Any, seed: int) -> None:
    """Give an SB3 model's policy fresh weights, as a new model with the same settings gets
    them (the policy's own initialisation), drawn from ``seed``; the global torch random state
    is left as it was."""
    import torch

    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(int(seed))
        fresh = model.policy_class(
            model.observation_space, model.action_space, model.lr_schedule, **model.policy_kwargs
        )
    model.policy = fresh.to(model.device)


class CandidateGoalPolicy(Policy):
    """The explorer's agent without its choice: the egocentric map built from the observations
    (:class:`~naruto_gym.rl.egocentric_map.EgocentricMapBuilder`), the candidate goals found on
    it, one action chosen every ``steps_per_goal`` steps by :meth:`choose` (with the settings'
    ``decision`` ``"goal"``: also each time the walker has done the goal, step for step as
    the goal actions' ``decision="goal"``), walked by the
    planner (:class:`~naruto_gym.rl.goal_walker.GoalWalker`), and a stall watchdog whose
    recovery walks out of the stay.

    Args:
        settings: the training settings (:data:`DEFAULT_SETTINGS`' keys, and
            ``panorama_horizon_deg`` where the map reads only that band of the panorama).
        stall_watchdog: watch the walk for stalls (:mod:`naruto_agent.policies.watchdog`) and
            walk out of one (:meth:`recover_from_stall`); False: the choice and walker alone.
    """

    action_modes = ("discrete",)
    required_observations = ("depth", "pose", "panorama")

    def __init__(self, settings: dict[str, Any], stall_watchdog: bool = True) -> None:
        super().__init__()
        self.settings = {**DEFAULT_SETTINGS, **settings}
        self.steps_per_goal = int(self.settings["steps_per_goal"])
        self.map: EgocentricMapBuilder | None = None
        self.walker: GoalWalker | None = None
        self._until_decision = 0  # steps until the next choice
        self._panorama_stride = (1, 1)
        self._band: EquirectangularCamera | None = None
        self.use_stall_watchdog(enabled=stall_watchdog)

    @property
    def action_count(self) -> int:
        """Actions :meth:`choose` picks among: the candidate slots, then the 10 discrete moves
        where the settings have ``primitive_actions``."""
        moves = len(DISCRETE_ACTIONS) if self.settings["primitive_actions"] else 0
        return int(self.settings["num_candidates"]) + moves

    @abstractmethod
    def choose(self, observation: dict[str, np.ndarray]) -> int:
        """The action of a decision (0 .. :attr:`action_count` - 1; a candidate slot, an empty
        one meaning the nearest candidate) from the explorer's observation: the map's
        (``map``, ``panorama``, ``pose``...) and the ``candidates`` feature table
        (:data:`~naruto_gym.rl.goal_candidates.CANDIDATE_FEATURES`, nearest first)."""

    def reset(self, observation: Observation, info: Info, seed: int | None = None) -> None:
        super().reset(observation, info, seed)
        trained = tuple(self.settings["panorama_shape"])
        given = np.shape(observation["panorama"])
        if given[0] % trained[0] or given[1] % trained[1]:
            raise ValueError(
                f"the env's panorama is {given}, the explorer was trained on {trained}: make "
                f"the env with panorama_shape={trained} (or a whole multiple of it)"
            )
        self._panorama_stride = (given[0] // trained[0], given[1] // trained[1])
        # A model trained on the panorama band (panorama_horizon_deg) sees the band here too,
        # whether the env casts only those rows or every row.
        horizon = self.settings.get("panorama_horizon_deg")
        self._band = (
            None
            if horizon is None
            else EquirectangularCamera(height=trained[0], width=trained[1], horizon_deg=horizon)
        )
        context = self.context
        self.map = EgocentricMapBuilder(
            1,
            context.camera,
            trained,
            max_depth_m=context.max_depth_m,
            **self.settings["map_options"],
        )
        self.walker = GoalWalker(
            self.map,
            num_candidates=int(self.settings["num_candidates"]),
            primitive_actions=bool(self.settings["primitive_actions"]),
            step_m=context.max_translation_m,
            turn_rad=context.max_rotation_rad,
            decision=str(self.settings["decision"]),
        )
        self.map.reset(np.zeros(1, np.int64), np.asarray(observation["pose"])[None])
        self.walker.reset()
        self._until_decision = 0

    def _batch(self, observation: Observation) -> dict[str, np.ndarray]:
        rows, columns = self._panorama_stride
        panorama = np.asarray(observation["panorama"])[::rows, ::columns]
        if self._band is not None:
            panorama = self._band.keep_cast_rows(panorama)
        return {
            "depth": np.asarray(observation["depth"])[None],
            "pose": np.asarray(observation["pose"])[None],
            "panorama": panorama[None],
        }

    def act(self, observation: Observation, info: Info | None = None) -> int:
        if self.map is None or self.walker is None:
            raise RuntimeError("call reset() before act()")
        batch = self._batch(observation)
        self.map.update(batch)
        if self.check_stall(observation, info) is not None:
            self._until_decision = self.steps_per_goal  # the recovery's walk gets a macro-step
        elif self._until_decision == 0:
            self._decide(batch)
        move = int(self.walker.next_moves()[0])
        if move == AWAIT_DECISION:  # the goal is done (decision "goal"): the next one
            self._decide(batch)
            move = int(self.walker.next_moves()[0])
        self._until_decision -= 1
        return move

    def _decide(self, batch: dict[str, np.ndarray]) -> None:
        """A decision of :meth:`choose` on the map and candidates as they are now."""
        assert self.map is not None and self.walker is not None
        choice = {key: value[0] for key, value in self.map.observe(batch).items()}
        choice["candidates"] = self.walker.refresh_candidates()[0]
        self.walker.set_actions(np.array([int(self.choose(choice))]))
        self._until_decision = self.steps_per_goal

    def reachable_places(self, position: np.ndarray) -> ReachablePlaces | None:
        """The places the walker's map reaches on its current slice, at the agent's height
        (:meth:`GoalWalker.reachable_places
        <naruto_gym.rl.goal_walker.GoalWalker.reachable_places>`)."""
        assert self.walker is not None
        points, lengths = self.walker.reachable_places(0)
        heights = np.full((len(points), 1), float(position[2]))
        return ReachablePlaces(np.hstack([points, heights]), lengths)

    def walk_out(self, position: np.ndarray, goal: np.ndarray) -> str:
        """The walker steps out of the stay to ``goal`` without turning first and keeps it
        until it is there (:meth:`GoalWalker.walk_out
        <naruto_gym.rl.goal_walker.GoalWalker.walk_out>`); the next choice comes a whole
        macro-step later."""
        assert self.walker is not None and self.stall_watchdog is not None
        spots, radius = self.stay_of(self.stall_watchdog.events[-1])
        if self.walker.walk_out(0, goal[:2], spots[-1], radius):
            return "the walker's path"
        return "no path on the walker's map: turn in place"


@register_policy("explorer")
class MapGoalExplorer(CandidateGoalPolicy):
    """A PPO model over the egocentric map that picks candidate goals walked by a planner.

    Args:
        model_path: the SB3 ``.zip`` (its ``.json`` settings beside it); None: the packaged
            checkpoint.
        deterministic: act with the mode of the action distribution (False samples).
        stall_watchdog: watch the walk for stalls (:mod:`naruto_agent.policies.watchdog`) and
            walk out of one (:meth:`recover_from_stall`); False: the model and walker alone.
        weights: ``"trained"``, the checkpoint's; ``"untrained"``, its untrained twin's: every
            layer re-initialised at each episode from the episode's seed (0 without one), as
            PPO initialises a new model of the same settings (:func:`reinitialise_weights`).

    Raises:
        FileNotFoundError: no ``model_path`` and no packaged checkpoint, or a missing file
            (the message says how to train one).
        ValueError: the model's action space does not match its settings, or ``weights`` is
            not one of :data:`WEIGHTS`.
    """

    def __init__(
        self,
        model_path: str | None = None,
        deterministic: bool = False,
        stall_watchdog: bool = True,
        weights: str = "trained",
    ) -> None:
        from stable_baselines3 import PPO

        check_weights(weights, "the checkpoint's")
        path = Path(model_path) if model_path is not None else PACKAGED_MODEL
        if not path.exists():
            hint = (
                (
                    "no explorer checkpoint is shipped in this version: train one with "
                    "benchmarks/train_explorer.py and pass model_path=<output_dir>/"
                    "final_model.zip"
                )
                if model_path is None
                else ("pass the .zip that benchmarks/train_explorer.py wrote")
            )
            raise FileNotFoundError(f"explorer model {path} not found; {hint}")
        super().__init__(read_settings(path), stall_watchdog)
        self.model = PPO.load(path, device="cpu")
        if int(self.model.action_space.n) != self.action_count:
            raise ValueError(
                f"{path} acts in {self.model.action_space.n} actions, but its settings "
                f"({settings_path(path)}) give {self.action_count}: keep the .json the "
                f"training wrote beside it"
            )
        self.deterministic = bool(deterministic)
        self.weights = weights

    def reset(self, observation: Observation, info: Info, seed: int | None = None) -> None:
        if self.weights == "untrained":
            reinitialise_weights(self.model, 0 if seed is None else seed)
        if seed is not None:
            self.model.set_random_seed(seed)
        super().reset(observation, info, seed)

    def choose(self, observation: dict[str, np.ndarray]) -> int:
        action, _ = self.model.predict(observation, deterministic=self.deterministic)
        return int(action)


@register_policy("explorer-untrained")
class UntrainedMapGoalExplorer(MapGoalExplorer):
    """The explorer's untrained twin under its own name (records and leaderboard rows apart
    from the explorer's): :class:`MapGoalExplorer` with ``weights="untrained"``.

    Args:
        model_path: the checkpoint whose settings and architecture the twin has (None: the
            packaged one).
        deterministic: act with the mode of the action distribution (False samples).
        stall_watchdog: watch the walk for stalls.
    """

    def __init__(
        self,
        model_path: str | None = None,
        deterministic: bool = False,
        stall_watchdog: bool = True,
    ) -> None:
        super().__init__(model_path, deterministic, stall_watchdog, weights="untrained")
