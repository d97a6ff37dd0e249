"""Vector-env versions of the learning wrappers (:mod:`naruto_gym.wrappers.learning`): the same
transforms on the batch, for both autoreset modes.

Gymnasium's ``VectorObservationWrapper`` refuses ``SAME_STEP`` autoreset, which
Stable-Baselines3 needs; this wrapper supports it by also transforming
``info["final_obs"]`` (with the finished episode's state) before the new episodes start.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from naruto_gym.wrappers.observation import ObservationTransform

__all__ = ["VectorTransformObservation"]


class VectorTransformObservation(gym.vector.VectorWrapper):
    """Applies an :class:`ObservationTransform` to every observation of a vector env.

    Episode starts are read from the infos' ``step`` (0 on a reset), so per-episode state (the
    egocentric map) restarts with each sub-env's episode; scene bounds come from
    ``env.unwrapped.scene_runtimes`` (a ``NarutoReconVectorEnv``; none elsewhere).
    """

    def __init__(self, env: gym.vector.VectorEnv, transform: ObservationTransform) -> None:
        super().__init__(env)
        self.transform = transform
        self.single_observation_space = transform.space(env.single_observation_space)
        self.observation_space = batch_space(self.single_observation_space, env.num_envs)
        transform.bind(getattr(env.unwrapped, "camera", None), env.num_envs)

    def _bounds(self) -> list[np.ndarray | None]:
        scenes = getattr(self.env.unwrapped, "scene_runtimes", None)
        if scenes is None:
            return [None] * self.num_envs
        return [scene.bounds if scene is not None else None for scene in scenes]

    def _starts(self, infos: dict[str, Any]) -> np.ndarray:
        steps = infos.get("step")
        mask = infos.get("_step")
        if steps is None or mask is None:
            return np.zeros(0, np.int64)
        return np.flatnonzero(mask & (steps == 0))

    def reset(self, *, seed: Any = None, options: dict[str, Any] | None = None):
        observations, infos = self.env.reset(seed=seed, options=options)
        self.transform.reset_envs(self._bounds(), self._starts(infos))
        return self.transform.apply(observations), infos

    def step(self, actions: Any):
        observations, rewards, terminations, truncations, infos = self.env.step(actions)
        if "final_obs" in infos:
            infos = dict(infos)
            final = np.array(infos["final_obs"], dtype=object)
            for i in np.flatnonzero(infos["_final_obs"]):
                batch = {key: value[None] for key, value in final[i].items()}
                applied = self.transform.apply(batch, np.array([i]))
                final[i] = {key: value[0] for key, value in applied.items()}
            infos["final_obs"] = final
        if self.env.metadata.get("autoreset_mode") != AutoresetMode.DISABLED:
            self.transform.reset_envs(self._bounds(), self._starts(infos))
        return self.transform.apply(observations), rewards, terminations, truncations, infos
