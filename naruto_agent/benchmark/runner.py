"""Run one benchmark episode and describe it as a JSON-able record.

The runner builds the env in the policy's preferred action mode, fuses every frame with the
reference TSDF mapper (``naruto_gym.evaluation.EpisodeReconstruction``, the mapper the env's
``reconstruct=True`` option uses; done here so its time is measured apart from the env's),
and times three phases per step: the policy's ``act``, the env's ``step`` (motion, collision
checks, rendering, coverage) and mapping (fusion). Completion ratio is scored at a few
checkpoints with fewer samples, and at the end with the full protocol.

:func:`run_episode_safe` never raises: an episode that crashes comes back as a ``failed``
record with its error and traceback, so the other episodes go on.
"""

from __future__ import annotations

import platform
import time
import traceback
from collections import Counter
from typing import Any

import numpy as np

from naruto_agent.benchmark.records import STATUS_FAILED, STATUS_OK
from naruto_agent.benchmark.spec import EpisodeSpec

ENV_ID = "NarutoRecon-v0"


def checkpoint_steps(steps: int, points: int) -> list[int]:
    """Steps (1..steps-1) at which to score the reconstruction during an episode."""
    if points <= 0 or steps < 2:
        return []
    marks = np.linspace(0, steps, points + 2)[1:-1]
    return sorted({int(round(mark)) for mark in marks if 1 <= round(mark) < steps})


def make_env(spec: EpisodeSpec, action_mode: str) -> Any:
    """The episode's env (``gymnasium.make`` with the spec's settings)."""
    import gymnasium as gym

    import naruto_gym  # noqa: F401  (registers the env ids)

    kwargs = {"image_scale": spec.image_scale, **spec.env_kwargs}
    return gym.make(
        ENV_ID,
        scene=spec.scene,
        up_axis=spec.up_axis,
        action_mode=action_mode,
        max_episode_steps=spec.steps,
        **kwargs,
    )


def timed_step(
    policy: Any,
    env: Any,
    observation: dict[str, Any],
    info: dict[str, Any],
    times: dict[str, float],
) -> tuple[dict[str, Any], bool, bool, dict[str, Any]]:
    """One ``policy.act`` and ``env.step``; their seconds are added to ``times["policy"]`` and
    ``times["env"]``. Returns the new observation, terminated, truncated and info."""
    clock = time.perf_counter()
    action = policy.act(observation, info)
    times["policy"] += time.perf_counter() - clock
    clock = time.perf_counter()
    observation, _, terminated, truncated, info = env.step(action)
    times["env"] += time.perf_counter() - clock
    return observation, terminated, truncated, info


def run_episode(
    spec: EpisodeSpec, progress: bool = False, record_dir: str | None = None
) -> dict[str, Any]:
    """Run one episode and return its record (raises on any error).

    Args:
        spec: the episode.
        progress: show a per-step progress bar.
        record_dir: write a Rerun recording of the episode under this folder
            (``SCENE/POLICY/seedN.rrd``; see :mod:`naruto_agent.recording`).
    """
    from tqdm.auto import tqdm

    from naruto_agent.policies import EnvContext, make_policy

    started = time.perf_counter()
    policy = make_policy(spec.policy, **spec.policy_kwargs)
    env = make_env(spec, policy.preferred_action_mode)
    try:
        base = env.unwrapped
        policy.bind(EnvContext.from_env(env, step_budget=spec.steps))
        reconstruction = None
        if spec.reconstruct:
            from naruto_gym.evaluation import EpisodeReconstruction

            reconstruction = EpisodeReconstruction(base.camera, device=spec.device)

        times = {"policy": 0.0, "env": 0.0, "mapping": 0.0}
        clock = time.perf_counter()
        observation, info = env.reset(seed=spec.seed, options=policy.reset_options())
        reset_s = time.perf_counter() - clock
        policy.reset(observation, info, seed=spec.seed)
        recorder = _recorder(spec, base, record_dir)
        map_mesh = reconstruction.mesh if reconstruction is not None else None
        if recorder is not None:
            recorder.observe(0, observation, info, policy, map_mesh)
        if reconstruction is not None:
            clock = time.perf_counter()
            reconstruction.add_frame(observation["rgb"], observation["depth"], observation["pose"])
            times["mapping"] += time.perf_counter() - clock

        coverage = [float(info["coverage"])]
        positions = [np.asarray(observation["pose"], np.float64)[:3, 3].copy()]
        reasons: Counter[str] = Counter()
        checkpoints = set(checkpoint_steps(spec.steps, spec.eval_points if spec.reconstruct else 0))
        completion_curve: list[dict[str, Any]] = []
        evaluation_s = 0.0
        steps_run = 0
        for step in tqdm(range(1, spec.steps + 1), disable=not progress, desc=spec.episode_id):
            observation, terminated, truncated, info = timed_step(
                policy, env, observation, info, times
            )
            steps_run = step
            if reconstruction is not None:
                clock = time.perf_counter()
                reconstruction.add_frame(
                    observation["rgb"], observation["depth"], observation["pose"]
                )
                times["mapping"] += time.perf_counter() - clock
            coverage.append(float(info["coverage"]))
            positions.append(np.asarray(observation["pose"], np.float64)[:3, 3].copy())
            if info.get("collided", False):
                reasons[info.get("collision_reason", "") or "unknown"] += 1
            if recorder is not None:
                recorder.observe(step, observation, info, policy, map_mesh,
                                 last=terminated or truncated or step == spec.steps)
            if reconstruction is not None and step in checkpoints:
                clock = time.perf_counter()
                scores = _score(reconstruction, base, spec.checkpoint_samples,
                                spec.eval_samples_per_m2)
                evaluation_s += time.perf_counter() - clock
                completion_curve.append({"step": step, **_curve_point(scores)})
                if recorder is not None:
                    recorder.log_scores(step, scores)
            if terminated or truncated:
                break
        if recorder is not None:
            recorder.close()

        metrics: dict[str, Any] = {}
        own_metrics: dict[str, Any] | None = None
        if reconstruction is not None:
            clock = time.perf_counter()
            metrics = _score(reconstruction, base, spec.eval_samples, spec.eval_samples_per_m2)
            own_metrics = _score_own_map(policy, base, spec)
            evaluation_s += time.perf_counter() - clock
            completion_curve.append({"step": steps_run, **_curve_point(metrics)})
        per_step = max(steps_run, 1)
        return {
            "episode_id": spec.episode_id,
            "status": STATUS_OK,
            "error": None,
            "config": spec.as_dict(),
            "config_hash": spec.config_hash,
            "scene": spec.scene_label,
            "policy": spec.policy_label,
            "seed": spec.seed,
            "steps_run": steps_run,
            "action_mode": policy.preferred_action_mode,
            "camera": base.camera.as_dict(),
            "metrics": metrics,
            "own_map_metrics": own_metrics,
            "coverage_final": coverage[-1],
            "coverage_curve": np.round(coverage, 5).tolist(),
            "completion_curve": completion_curve,
            "trajectory": np.round(np.array(positions), 3).tolist(),
            "path_length_m": float(info.get("path_length_m", 0.0)),
            "collisions": int(sum(reasons.values())),
            "collision_reasons": dict(reasons),
            "stalled_steps": int(policy.stalled_steps),
            "stall_recoveries": [event.as_dict() for event in policy.stall_events],
            "wall_time_s": time.perf_counter() - started,
            "reset_s": reset_s,
            "evaluation_s": evaluation_s,
            "time_per_step_ms": {
                phase: 1000.0 * total / per_step for phase, total in times.items()
            },
            "host": platform.node(),
        }
    finally:
        policy.close()
        env.close()


def _recorder(spec: EpisodeSpec, env: Any, record_dir: str | None) -> Any | None:
    """The episode's recorder under ``record_dir`` (None without one)."""
    if record_dir is None:
        return None
    from pathlib import Path

    from naruto_agent.recording import EpisodeRecorder

    path = Path(record_dir) / f"{spec.episode_id}.rrd"
    recorder = EpisodeRecorder(path, env.camera, title=spec.episode_id)
    recorder.log_scene(env.scene)
    return recorder


def _score(
    reconstruction: Any, env: Any, num_samples: int, samples_per_m2: float
) -> dict[str, Any]:
    """Metrics of the episode's reference map, on the whole and on the observable surface."""
    return reconstruction.evaluate(
        env.scene,
        num_samples=num_samples,
        reference_samples_per_m2=samples_per_m2 or None,
        renderer=env.renderer,
        observable_mask=env.observable_surface.mask,
    )


def _score_own_map(policy: Any, env: Any, spec: EpisodeSpec) -> dict[str, Any] | None:
    """Metrics of the policy's own map (MAD with its SDF), None for a policy without one."""
    own = policy.reconstruction()
    if own is None:
        return None
    if len(own.mesh.faces) == 0:
        return {"note": "the policy's own map has no surface"}
    return env.evaluate(
        own.mesh,
        num_samples=spec.eval_samples,
        reference_samples_per_m2=spec.eval_samples_per_m2 or None,
        sdf=own.sdf,
    )


def _curve_point(scores: dict[str, Any]) -> dict[str, Any]:
    return {
        key: scores.get(key)
        for key in (
            "completion_ratio_pct",
            "observable_completion_ratio_pct",
            "completion_cm",
            "accuracy_cm",
        )
    }


def failed_record(spec: EpisodeSpec, error: BaseException | str, trace: str = "") -> dict[str, Any]:
    """The record of an episode that crashed."""
    message = error if isinstance(error, str) else f"{type(error).__name__}: {error}"
    return {
        "episode_id": spec.episode_id,
        "status": STATUS_FAILED,
        "error": message,
        "traceback": trace,
        "config": spec.as_dict(),
        "config_hash": spec.config_hash,
        "scene": spec.scene_label,
        "policy": spec.policy_label,
        "seed": spec.seed,
        "host": platform.node(),
    }


def run_episode_safe(
    spec_data: dict[str, Any] | EpisodeSpec, record_dir: str | None = None
) -> dict[str, Any]:
    """:func:`run_episode` that returns a ``failed`` record instead of raising.

    Takes the spec as a dict too, which is what worker processes and Ray tasks receive;
    ``record_dir`` as :func:`run_episode`'s.
    """
    spec = spec_data if isinstance(spec_data, EpisodeSpec) else EpisodeSpec.from_dict(spec_data)
    started = time.perf_counter()
    try:
        return run_episode(spec, record_dir=record_dir)
    except Exception as error:  # noqa: BLE001 (an episode's crash must not stop the others)
        record = failed_record(spec, error, traceback.format_exc())
        record["wall_time_s"] = time.perf_counter() - started
        return record
