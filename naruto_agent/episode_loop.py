"""The one episode loop of the tools: bind, reset, then ``act`` / ``step`` until the end.

The demo, the benchmark harness, the benchmark scripts and the behaviour fingerprint all run
a policy's episode the same way; what each keeps of it (per-step records, scores at the
evaluation points, recordings, pictures, progress files) is an :class:`EpisodeHook`::

    records = StepRecords()
    result = run_episode_loop(env, policy, max_episode_steps=200, seed=0, hooks=[records])
    records.coverage[-1], result.steps_run, result.seconds["policy"]

The order is fixed, so that an episode is the same whoever runs it:

1. ``policy.bind`` with the env's context and the episode length;
2. every hook's :meth:`~EpisodeHook.before_reset`;
3. ``env.reset(seed=seed, options=policy.reset_options())``, then ``policy.reset`` with the
   same seed, then every hook's :meth:`~EpisodeHook.on_reset`;
4. per step: ``policy.act``, ``env.step``, then every hook's :meth:`~EpisodeHook.on_step`
   in the order given; the episode ends when the env terminates or truncates, or at
   ``max_episode_steps``.

Seconds are kept per phase (:attr:`EpisodeResult.seconds`): ``reset_env``,
``reset_policy``, ``policy`` (``act``), ``env`` (``step``), and each hook's time under its
:attr:`~EpisodeHook.phase` when it names one.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from naruto_gym.utils.checks import check_integer


def eval_point_steps(max_episode_steps: int, eval_points: int) -> list[int]:
    """Steps (1..max_episode_steps-1) at which an episode's reconstruction is scored:
    ``eval_points`` of them spread evenly, the last step not included."""
    if eval_points <= 0 or max_episode_steps < 2:
        return []
    marks = np.linspace(0, max_episode_steps, eval_points + 2)[1:-1]
    return sorted({int(round(mark)) for mark in marks if 1 <= round(mark) < max_episode_steps})


class EpisodeHook:
    """What a tool keeps of an episode; every method does nothing unless overridden.

    Attributes:
        phase: the name under which the loop adds this hook's seconds to
            :attr:`EpisodeResult.seconds` (None: not timed, e.g. a hook that keeps its own).
    """

    phase: str | None = None

    def before_reset(self, env: Any, policy: Any) -> None:
        """After ``policy.bind``, before ``env.reset`` (e.g. to instrument the env)."""

    def on_reset(self, observation: dict[str, Any], info: dict[str, Any]) -> None:
        """After ``env.reset`` and ``policy.reset`` (step 0)."""

    def on_step(
        self, step: int, observation: dict[str, Any], info: dict[str, Any], last: bool
    ) -> None:
        """After step ``step`` (1-based) of the env; ``last``: the episode ends with it."""


@dataclass
class EpisodeResult:
    """How an episode ended.

    Attributes:
        steps_run: steps taken.
        observation: the last observation.
        info: the last step's info (the reset's when no step was taken).
        terminated: whether the env terminated the episode.
        truncated: whether the env truncated it.
        seconds: seconds by phase (see the module's docstring).
    """

    steps_run: int
    observation: dict[str, Any]
    info: dict[str, Any]
    terminated: bool
    truncated: bool
    seconds: dict[str, float]


def run_episode_loop(
    env: Any,
    policy: Any,
    max_episode_steps: int,
    seed: int | None,
    hooks: Sequence[EpisodeHook] = (),
    progress: str | None = None,
    seconds: dict[str, float] | None = None,
) -> EpisodeResult:
    """Run one episode of ``policy`` in ``env`` (a ``gymnasium`` env of this package).

    Args:
        env: the env, made with the episode's length as its time limit.
        policy: a :class:`~naruto_agent.policies.Policy`, not yet bound.
        max_episode_steps: the episode's length in steps (the policy is told it).
        seed: seed of ``env.reset`` and ``policy.reset``.
        hooks: what to keep of the episode, called in this order.
        progress: show a progress bar with this description (None: none).
        seconds: the dict the seconds by phase are added to (a new one when None); pass
            one for hooks that read the running totals while the episode goes on.

    Raises:
        ValueError: ``max_episode_steps`` below 1.
    """
    from tqdm.auto import tqdm

    from naruto_agent.policies import EnvContext

    check_integer("max_episode_steps", max_episode_steps, low=1)
    seconds = {} if seconds is None else seconds
    for phase in ("reset_env", "reset_policy", "policy", "env"):
        seconds.setdefault(phase, 0.0)
    for hook in hooks:
        if hook.phase is not None:
            seconds.setdefault(hook.phase, 0.0)

    def call(hook: EpisodeHook, method: Callable[..., None], *arguments: Any) -> None:
        if hook.phase is None:
            method(*arguments)
            return
        clock = time.perf_counter()
        method(*arguments)
        seconds[hook.phase] += time.perf_counter() - clock

    policy.bind(EnvContext.from_env(env, max_episode_steps=max_episode_steps))
    for hook in hooks:
        call(hook, hook.before_reset, env, policy)
    clock = time.perf_counter()
    observation, info = env.reset(seed=seed, options=policy.reset_options())
    seconds["reset_env"] += time.perf_counter() - clock
    clock = time.perf_counter()
    policy.reset(observation, info, seed=seed)
    seconds["reset_policy"] += time.perf_counter() - clock
    for hook in hooks:
        call(hook, hook.on_reset, observation, info)

    steps_run, terminated, truncated = 0, False, False
    bar = tqdm(
        range(1, max_episode_steps + 1), desc=progress, disable=progress is None, unit="step"
    )
    for step in bar:
        clock = time.perf_counter()
        action = policy.act(observation, info)
        seconds["policy"] += time.perf_counter() - clock
        clock = time.perf_counter()
        observation, _, terminated, truncated, info = env.step(action)
        seconds["env"] += time.perf_counter() - clock
        steps_run = step
        last = terminated or truncated or step == max_episode_steps
        for hook in hooks:
            call(hook, hook.on_step, step, observation, info, last)
        if step % 10 == 0 and "coverage" in info:
            bar.set_postfix(coverage=f"{100 * float(info['coverage']):.1f}%", refresh=False)
        if last:
            break
    bar.close()
    return EpisodeResult(steps_run, observation, info, bool(terminated), bool(truncated), seconds)


@dataclass
class StepRecords(EpisodeHook):
    """The per-step record of an episode: coverage and camera position after the reset and
    every step, and the refused or shortened moves by reason.

    Attributes:
        coverage: the info's ``coverage`` (step 0 first).
        positions: the camera's position (step 0 first).
        collisions: moves the env refused or shortened, by ``collision_reason``.
    """

    coverage: list[float] = field(default_factory=list)
    positions: list[np.ndarray] = field(default_factory=list)
    collisions: Counter[str] = field(default_factory=Counter)

    def on_reset(self, observation: dict[str, Any], info: dict[str, Any]) -> None:
        self._keep(observation, info)

    def on_step(
        self, step: int, observation: dict[str, Any], info: dict[str, Any], last: bool
    ) -> None:
        self._keep(observation, info)
        if info.get("collided", False):
            self.collisions[info.get("collision_reason", "") or "unknown"] += 1

    def _keep(self, observation: dict[str, Any], info: dict[str, Any]) -> None:
        self.coverage.append(float(info["coverage"]))
        self.positions.append(np.asarray(observation["pose"], np.float64)[:3, 3].copy())


class FrameFusion(EpisodeHook):
    """Fuses every frame (the reset's included) into a reference map, e.g.
    :class:`naruto_gym.evaluation.EpisodeReconstruction`, under the ``mapping`` phase."""

    phase = "mapping"

    def __init__(self, reconstruction: Any) -> None:
        self.reconstruction = reconstruction

    def on_reset(self, observation: dict[str, Any], info: dict[str, Any]) -> None:
        self._fuse(observation)

    def on_step(
        self, step: int, observation: dict[str, Any], info: dict[str, Any], last: bool
    ) -> None:
        self._fuse(observation)

    def _fuse(self, observation: dict[str, Any]) -> None:
        self.reconstruction.add_frame(observation["rgb"], observation["depth"], observation["pose"])


class EvalPoints(EpisodeHook):
    """Calls ``evaluate(step, last)`` at the episode's evaluation points
    (:func:`eval_point_steps`), and at its last step too when ``at_last`` is set; its time is
    the ``eval_points`` phase."""

    phase = "eval_points"

    def __init__(
        self,
        max_episode_steps: int,
        eval_points: int,
        evaluate: Callable[[int, bool], None],
        at_last: bool = False,
    ) -> None:
        self.steps = set(eval_point_steps(max_episode_steps, eval_points))
        self.evaluate = evaluate
        self.at_last = at_last and eval_points > 0

    def on_step(
        self, step: int, observation: dict[str, Any], info: dict[str, Any], last: bool
    ) -> None:
        if step in self.steps or (last and self.at_last):
            self.evaluate(step, last)
