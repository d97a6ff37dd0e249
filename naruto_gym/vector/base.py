"""What both batched envs share: their keywords, spaces, reset arguments and action checks.

:class:`~naruto_gym.vector.vector_env.NarutoReconVectorEnv` steps its agents in this process;
:class:`~naruto_gym.vector.sharded_env.ShardedVectorEnv` shards them over worker processes,
each running a ``NarutoReconVectorEnv``. Both take the same keywords and answer the Gymnasium
``VectorEnv`` API the same way; :func:`~naruto_gym.vector.make_vector_env` picks one from
``workers``. :class:`BatchedEnvBase` holds what they share, so that a keyword, a reset
argument or an action is checked in one place.
"""

from __future__ import annotations

import dataclasses
from functools import cached_property
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from naruto_gym.envs.settings import EnvSettings
from naruto_gym.envs.validation import check_keyword_names, check_vector_keywords
from naruto_gym.geometry.transforms import validate_pose
from naruto_gym.sensors.panorama import EquirectangularCamera
from naruto_gym.sensors.pinhole import PinholeCamera
from naruto_gym.utils.threads import resolve_threads
from naruto_gym.vector.shared_scenes import SharedSceneStreams

#: The batched envs' own keywords (every other one is ``EnvSettings``').
VECTOR_KEYWORDS = frozenset(
    {
        "num_envs",
        "scene",
        "max_episode_steps",
        "autoreset_mode",
        "scene_cache_size",
        "render_mode",
        "reconstruct",
    }
)


def accepted_keywords() -> frozenset[str]:
    """Every keyword a batched env takes, ``workers`` apart."""
    return VECTOR_KEYWORDS | {item.name for item in dataclasses.fields(EnvSettings)}



def agent_scenes(scene: Any, num_envs: int) -> list[Any] | SharedSceneStreams:
    """Each of ``num_envs`` agents' scene: ``scene`` for all, or one entry of a list per
    agent (a :class:`SharedSceneStreams` as it is: it places the agents itself).

    Raises:
        ValueError: a list whose length is not ``num_envs``.
    """
    if isinstance(scene, SharedSceneStreams):
        return scene
    scenes = scene if isinstance(scene, (list, tuple)) else [scene] * num_envs
    if len(scenes) != num_envs:
        raise ValueError(f"scene list has {len(scenes)} entries for num_envs={num_envs}")
    return list(scenes)


def agent_seeds(seed: int | list[int | None] | None, num_envs: int) -> list[int | None]:
    """A reset's seed per agent: an int gives agent ``i`` ``seed + i``, a list one each, None
    none.

    Raises:
        ValueError: a list whose length is not ``num_envs``.
    """
    if seed is None:
        return [None] * num_envs
    if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
        return [int(seed) + i for i in range(num_envs)]
    seeds = list(seed)
    if len(seeds) != num_envs:
        raise ValueError(f"seed list has length {len(seeds)}; it must match num_envs={num_envs}")
    return seeds

class BatchedEnvBase(gym.vector.VectorEnv):
    """The Gymnasium ``VectorEnv`` parts both batched envs share (see ``NarutoReconVectorEnv``
    for the keywords and the behaviour).

    Attributes:
        num_envs, max_episode_steps, autoreset_mode: as given (checked).
        settings: the agents' :class:`~naruto_gym.envs.settings.EnvSettings`.
        reconstruct: whether each agent fuses a reference map.
        thread_count: the CPUs the compiled loops use (``settings.threads`` resolved).
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int,
        max_episode_steps: int | None,
        autoreset_mode: AutoresetMode | str,
        scene_cache_size: int,
        render_mode: str | None,
        env_kwargs: dict[str, Any],
        owner: str,
    ) -> None:
        if (
            isinstance(num_envs, bool)
            or not isinstance(num_envs, (int, np.integer))
            or (num_envs < 1)
        ):
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        check_vector_keywords(max_episode_steps, scene_cache_size)
        if render_mode is not None:
            raise ValueError(
                "the batched vector env does not render; use "
                "gymnasium.make_vec(..., vectorization_mode='sync', render_mode='rgb_array')"
            )
        try:
            self.autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError as error:
            raise ValueError(
                f"autoreset_mode must be 'NextStep' or 'SameStep', got {autoreset_mode!r}"
            ) from error
        if self.autoreset_mode == AutoresetMode.DISABLED:
            raise ValueError("autoreset_mode DISABLED is not supported; use NextStep or SameStep")
        self.metadata = {**self.metadata, "autoreset_mode": self.autoreset_mode}
        self.num_envs = int(num_envs)
        self.max_episode_steps = max_episode_steps
        self.render_mode = None
        self.reconstruct = bool(env_kwargs.pop("reconstruct", False))
        check_keyword_names(env_kwargs, accepted_keywords(), owner)
        self.settings = EnvSettings(**env_kwargs)
        # Compiled loops (ray filling, shading, coverage) split agents between this many
        # threads; Open3D's casts use the process's default count.
        self.thread_count = resolve_threads(self.settings.threads)
        self._discrete_zeros = np.zeros(self.num_envs, np.int64)
        self._continuous_zeros = np.zeros((self.num_envs, 7))
        self._started = False

    # -- construction helpers ----------------------------------------------------------------
    def _agent_scenes(self, scene: Any) -> list[Any] | SharedSceneStreams:
        return agent_scenes(scene, self.num_envs)

    def _check_pose_actions(self, several_scenes: bool) -> None:
        """Pose actions are bounded by one scene's box: refuse them across several scenes."""
        if self.settings.action_mode == "pose" and several_scenes:
            raise ValueError(
                "action_mode='pose' bounds actions by one scene's box; use 'discrete' or "
                "'delta' with several scenes or a procedural stream"
            )

    def _set_spaces(self, single_observation: spaces.Dict, single_action: spaces.Space) -> None:
        self.single_observation_space = single_observation
        self.single_action_space = single_action
        self.observation_space = batch_space(single_observation, self.num_envs)
        self.action_space = batch_space(single_action, self.num_envs)

    # -- what both take from reset and step --------------------------------------------------
    def _reset_arguments(
        self, seed: int | list[int | None] | None, options: dict[str, Any] | None
    ) -> tuple[list[int | None], np.ndarray, dict[str, Any]]:
        """A reset's per-agent seeds, its ``reset_mask`` and the options left."""
        seeds = agent_seeds(seed, self.num_envs)
        options = dict(options or {})
        mask = options.pop("reset_mask", None)
        if mask is None:
            mask = np.ones(self.num_envs, bool)
        elif not (
            isinstance(mask, np.ndarray)
            and mask.dtype == np.bool_
            and mask.shape == (self.num_envs,)
            and mask.any()
        ):
            raise ValueError(
                f"options['reset_mask'] must be a bool numpy array of shape ({self.num_envs},) "
                "with at least one True"
            )
        unknown = set(options) - {"pose"}
        if unknown:
            raise ValueError(f"unknown reset options {sorted(unknown)}; supported: ['pose']")
        if "pose" in options:
            validate_pose(options["pose"], "options['pose']")
        return seeds, mask, options

    def _validated_actions(self, actions: Any) -> tuple[np.ndarray, np.ndarray]:
        """The actions of a step checked against the action space (after a reset):
        ``(discrete, continuous)``, the unused one zeros (continuous ones padded to 7
        columns)."""
        if not self._started:
            raise RuntimeError("call reset() before step()")
        n = self.num_envs
        action_mode = self.settings.action_mode
        if action_mode == "discrete":
            array = np.asarray(actions)
            if array.shape not in ((n,), (n, 1)) or not np.issubdtype(array.dtype, np.integer):
                raise ValueError(
                    f"discrete actions must be {n} integers in [0, "
                    f"{self.single_action_space.n}), got {actions!r}"
                )
            array = array.reshape(n).astype(np.int64)
            if np.any(array < 0) or np.any(array >= self.single_action_space.n):
                raise ValueError(
                    f"discrete actions must lie in [0, {self.single_action_space.n}), got "
                    f"{array.tolist()}"
                )
            return array, self._continuous_zeros
        try:
            array = np.asarray(actions, dtype=np.float64)
        except (TypeError, ValueError) as error:
            raise ValueError(f"actions must be a numeric array, got {actions!r}") from error
        expected = (n, *self.single_action_space.shape)
        if array.shape != expected:
            raise ValueError(f"{action_mode} actions must have shape {expected}, got {array.shape}")
        if not np.all(np.isfinite(array)):
            raise ValueError("actions contain NaN or inf")
        low, high = self.single_action_space.low, self.single_action_space.high
        if np.any(array < low - 1e-5) or np.any(array > high + 1e-5):
            raise ValueError(
                f"{action_mode} actions lie outside the action space "
                f"[{low.tolist()}, {high.tolist()}]"
            )
        if action_mode == "pose" and np.any(np.linalg.norm(array[:, 3:7], axis=1) < 1e-6):
            raise ValueError(
                "pose action quaternion (x, y, z, w) has zero norm; pass a unit quaternion"
            )
        padded = np.zeros((n, 7))
        padded[:, : array.shape[1]] = array
        return self._discrete_zeros, padded

    # -- views both give ---------------------------------------------------------------------
    @cached_property
    def camera(self) -> PinholeCamera:
        """One agent's pinhole camera (``settings.camera`` at ``settings.image_scale``; made
        once)."""
        return self.settings.pinhole_camera

    @cached_property
    def panorama_camera(self) -> EquirectangularCamera | None:
        """One agent's observation panorama camera (None when the panorama is off; made
        once)."""
        return self.settings.panorama_camera

    @property
    def num_workers(self) -> int:
        """The processes that step the agents (1: this one)."""
        return 1

    @property
    def worker_pids(self) -> list[int]:
        """The process ids of the worker processes (empty when the agents step here)."""
        return []

    @property
    def poses(self) -> np.ndarray:
        """(N, 4, 4) every agent's camera-to-world pose (a copy)."""
        raise NotImplementedError

    @property
    def rays_cast(self) -> int:
        """Rays cast so far for frames, panoramas and escape checks."""
        raise NotImplementedError
