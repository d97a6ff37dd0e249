"""The map-and-goal explorer trained by ``benchmarks/train_explorer.py``, as a harness policy.

    naruto-benchmark --policies random frontier explorer
    naruto-benchmark --policies explorer --policy-kwargs \\
        '{"explorer": {"model_path": "runs/explorer/final_model.zip"}}'

It builds the egocentric map from the observations it is handed
(:class:`~naruto_gym.rl.egocentric_map.EgocentricMapBuilder`), finds the candidate goals on
it, asks the PPO model for one (or a repeated discrete move) every ``steps_per_goal`` steps,
and walks it with the planner over its own map
(:class:`~naruto_gym.rl.goal_walker.GoalWalker`): the same observations and actions as in
training, step for step. The training settings (``steps_per_goal``, the number of
candidates, the map's options, the panorama size) are read from the JSON file saved beside the
model (``<model>.json``, written by the training script), so a model and its settings cannot
disagree. Without ``model_path`` it loads the checkpoint shipped in the package
(:data:`PACKAGED_MODEL`), when there is one.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from naruto_agent.policies.base import Info, Observation, Policy
from naruto_agent.policies.registry import register_policy
from naruto_agent.policies.watchdog import StallEvent
from naruto_gym.rl.egocentric_map import EgocentricMapBuilder
from naruto_gym.rl.goal_walker import GoalWalker
from naruto_gym.sensors.panorama import EquirectangularCamera

PACKAGED_MODEL = Path(__file__).with_name("checkpoints") / "explorer.zip"
"""The explorer checkpoint shipped in the package (with ``explorer.json`` beside it)."""

#: Settings of a model saved without its JSON file (the training script's defaults).
DEFAULT_SETTINGS: dict[str, Any] = {
    "steps_per_goal": 20,
    "num_candidates": 8,
    "primitive_actions": True,
    "map_options": {},
    "panorama_shape": [32, 64],
}


def settings_path(model_path: Path) -> Path:
    """The JSON file of a model's training settings: ``<model without .zip>.json``."""
    return model_path.with_suffix(".json")


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


@register_policy("explorer")
class MapGoalExplorer(Policy):
    """A PPO model over the egocentric map that picks candidate goals walked by a planner.

    Args:
        model_path: the SB3 ``.zip`` (its ``.json`` settings beside it); None: the packaged
            checkpoint.
        deterministic: act with the mode of the action distribution (False samples).
        stall_watchdog: watch the walk for stalls (:mod:`naruto_agent.policies.watchdog`) and
            walk out of one (:meth:`recover_from_stall`); False: the model and walker alone.

    Raises:
        FileNotFoundError: no ``model_path`` and no packaged checkpoint, or a missing file
            (the message says how to train one).
        ValueError: the model's action space does not match its settings.
    """

    action_modes = ("discrete",)
    required_observations = ("depth", "pose", "panorama")

    def __init__(
        self,
        model_path: str | None = None,
        deterministic: bool = False,
        stall_watchdog: bool = True,
    ) -> None:
        super().__init__()
        from stable_baselines3 import PPO

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
        stored = settings_path(path)
        self.settings = {
            **DEFAULT_SETTINGS,
            **(json.loads(stored.read_text()) if stored.exists() else {}),
        }
        if "goal_grid" in self.settings:
            raise ValueError(
                f"{path} was trained on the old grid goals (goal_grid in {stored}); the "
                f"explorer now picks among num_candidates candidate goals: train it again "
                f"with benchmarks/train_explorer.py"
            )
        self.model = PPO.load(path, device="cpu")
        goals = int(self.settings["num_candidates"])
        expected = goals + (10 if self.settings["primitive_actions"] else 0)
        if int(self.model.action_space.n) != expected:
            raise ValueError(
                f"{path} acts in {self.model.action_space.n} actions, but its settings "
                f"({stored}) give {expected}: keep the .json the training wrote beside it"
            )
        self.deterministic = bool(deterministic)
        self.steps_per_goal = int(self.settings["steps_per_goal"])
        self.map: EgocentricMapBuilder | None = None
        self.walker: GoalWalker | None = None
        self._until_decision = 0  # steps until the model picks the next action
        self._panorama_stride = (1, 1)
        self._band: EquirectangularCamera | None = None
        self.use_stall_watchdog(enabled=stall_watchdog)

    def reset(self, observation: Observation, info: Info, seed: int | None = None) -> None:
        super().reset(observation, info, seed)
        if seed is not None:
            self.model.set_random_seed(seed)
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
            learning = {key: value[0] for key, value in self.map.observe(batch).items()}
            learning["candidates"] = self.walker.refresh_candidates()[0]
            action, _ = self.model.predict(learning, deterministic=self.deterministic)
            self.walker.set_actions(np.array([int(action)]))
            self._until_decision = self.steps_per_goal
        self._until_decision -= 1
        return int(self.walker.next_moves()[0])

    def recover_from_stall(self, event: StallEvent) -> str:
        """Walk out of the stay: the goal in hand (or a repeated move) is given up for the
        nearest candidate past the stay's every position by the stay radius and a step, or
        the reachable place farthest from the trail (:meth:`GoalWalker.leave
        <naruto_gym.rl.goal_walker.GoalWalker.leave>`); the model picks again a whole
        macro-step later."""
        assert self.walker is not None
        return self.walker.leave(0, *self.stay_of(event))
