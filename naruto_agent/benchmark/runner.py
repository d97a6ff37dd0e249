"""Run one benchmark episode and describe it as a JSON-able record.

The runner builds the env in the policy's preferred action mode and runs the tools' episode
loop (:func:`naruto_agent.episode_loop.run_episode_loop`) with hooks that fuse every frame
with the reference TSDF mapper (``naruto_gym.evaluation.EpisodeReconstruction``, the mapper
the env's ``reconstruct=True`` option uses; done here so its time is measured apart from the
env's), keep the per-step record, record the episode and score it at the evaluation points.
Three phases per step are timed: the policy's ``act``, the env's ``step`` (motion, collision
checks, rendering, coverage) and mapping (fusion). Completion ratio is scored at the
evaluation points with fewer samples, and at the end with the full protocol.

:func:`run_episode_safe` never raises: an episode that crashes comes back as a ``failed``
record with its error and traceback, so the other episodes go on.
"""

from __future__ import annotations

import platform
import time
import traceback
from typing import Any

import numpy as np

from naruto_agent.benchmark.checks import leaderboard_differences
from naruto_agent.benchmark.records import STATUS_FAILED, STATUS_OK, source_commit
from naruto_agent.benchmark.reference_frames import ReferenceFusion, reference_camera
from naruto_agent.benchmark.spec import EpisodeSpec, SceneSpec
from naruto_agent.benchmark.step_progress import step_hooks
from naruto_agent.episode_loop import (
    EpisodeHook,
    EvalPoints,
    StepRecords,
    run_episode_loop,
)

ENV_ID = "NarutoRecon-v0"


def make_env(spec: EpisodeSpec, action_mode: str) -> Any:
    """The episode's env (``gymnasium.make`` with the spec's settings)."""
    import gymnasium as gym

    import naruto_gym  # noqa: F401  (registers the env ids)

    kwargs = {"image_scale": spec.image_scale, **spec.env_kwargs}
    return gym.make(
        ENV_ID,
        scene=spec.scene,
        up_axis=spec.up_axis,
        mesh_units=spec.mesh_units,
        action_mode=action_mode,
        max_episode_steps=spec.steps,
        **kwargs,
    )


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
    from naruto_agent.policies import make_policy

    started = time.perf_counter()
    policy = make_policy(spec.policy, **spec.policy_kwargs)
    env = make_env(spec, policy.preferred_action_mode)
    try:
        base = env.unwrapped
        records = StepRecords()
        hooks: list[EpisodeHook] = []
        reconstruction = None
        truth, truth_scene = _ground_truth(spec, base)
        if spec.reconstruct:
            from naruto_gym.evaluation import EpisodeReconstruction

            camera = reference_camera(spec.reference_image_scale)
            reconstruction = EpisodeReconstruction(camera, device=spec.device)
            hooks.append(ReferenceFusion(reconstruction))
        hooks.append(records)
        hooks.extend(step_hooks(spec.episode_id))  # moves the harness's progress bar
        recorder = _recorder(spec, base, record_dir)
        if recorder is not None:
            map_mesh = reconstruction.mesh if reconstruction is not None else None
            hooks.append(_RecorderHook(recorder, policy, map_mesh))
        completion_curve: list[dict[str, Any]] = []

        def evaluate(step: int, last: bool) -> None:
            scores = _score(
                reconstruction,
                base,
                truth_scene,
                spec.checkpoint_samples,
                spec.eval_samples_per_m2,
            )
            completion_curve.append({"step": step, **_curve_point(scores)})
            if recorder is not None:
                recorder.log_scores(step, scores)

        eval_points = spec.eval_points if spec.reconstruct else 0
        hooks.append(EvalPoints(spec.steps, eval_points, evaluate))
        result = run_episode_loop(
            env,
            policy,
            spec.steps,
            spec.seed,
            hooks,
            progress=spec.episode_id if progress else None,
        )
        if recorder is not None:
            recorder.close()
        steps_run, info, seconds = result.steps_run, result.info, result.seconds
        times = {phase: seconds.get(phase, 0.0) for phase in ("policy", "env", "mapping")}
        evaluation_s = seconds["eval_points"]

        metrics: dict[str, Any] = {}
        own_metrics: dict[str, Any] | None = None
        if reconstruction is not None:
            clock = time.perf_counter()
            metrics = _score(
                reconstruction, base, truth_scene, spec.eval_samples, spec.eval_samples_per_m2
            )
            own_metrics = _score_own_map(policy, base, spec, truth_scene)
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
            # How the scores were made: the reference map's camera, the ground truth, and
            # what differs from the leaderboard's settings.
            "reference_camera": None if reconstruction is None else reconstruction.camera.as_dict(),
            "ground_truth": truth.as_dict(),
            "leaderboard": leaderboard_differences(spec.as_dict()),
            "metrics": metrics,
            "own_map_metrics": own_metrics,
            "coverage_final": records.coverage[-1],
            "coverage_curve": np.round(records.coverage, 5).tolist(),
            "completion_curve": completion_curve,
            "trajectory": np.round(np.array(records.positions), 3).tolist(),
            "path_length_m": float(info.get("path_length_m", 0.0)),
            "collisions": int(sum(records.collisions.values())),
            "collision_reasons": dict(records.collisions),
            "stalled_steps": int(policy.stalled_steps),
            "stall_recoveries": [event.as_dict() for event in policy.stall_events],
            "wall_time_s": time.perf_counter() - started,
            "reset_s": seconds["reset_env"],
            "evaluation_s": evaluation_s,
            "time_per_step_ms": {
                phase: 1000.0 * total / per_step for phase, total in times.items()
            },
            "host": platform.node(),
            "commit": source_commit(),
        }
    finally:
        policy.close()
        env.close()


class _RecorderHook(EpisodeHook):
    """Writes every step of the episode to an :class:`~naruto_agent.recording.EpisodeRecorder`
    (the map, when ``map_mesh`` gives one, on the recorder's schedule)."""

    def __init__(self, recorder: Any, policy: Any, map_mesh: Any) -> None:
        self.recorder = recorder
        self.policy = policy
        self.map_mesh = map_mesh

    def on_reset(self, observation: dict[str, Any], info: dict[str, Any]) -> None:
        self.recorder.observe(0, observation, info, self.policy, self.map_mesh)

    def on_step(
        self, step: int, observation: dict[str, Any], info: dict[str, Any], last: bool
    ) -> None:
        self.recorder.observe(step, observation, info, self.policy, self.map_mesh, last=last)


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


def _ground_truth(spec: EpisodeSpec, env: Any) -> tuple[Any, Any]:
    """The episode's :class:`~naruto_gym.evaluation.GroundTruth` and its surface (the env's
    scene unless the scene folder names another, e.g. Replica's ``mesh_culled.ply``)."""
    from naruto_gym.evaluation import find_ground_truth, load_ground_truth

    scene = SceneSpec(spec.scene, spec.up_axis, spec.mesh_units)
    truth = find_ground_truth(
        scene.scene if scene.is_path else None, spec.up_axis, spec.ground_truth
    )
    return truth, load_ground_truth(truth, env.scene, spec.mesh_units)


def _score(
    reconstruction: Any, env: Any, truth_scene: Any, num_samples: int, samples_per_m2: float
) -> dict[str, Any]:
    """Metrics of the episode's reference map, on the whole and on the observable surface."""
    return reconstruction.evaluate(
        truth_scene,
        num_samples=num_samples,
        reference_samples_per_m2=samples_per_m2 or None,
        renderer=env.renderer,
        observable_mask=env.observable_surface.mask,
    )


def _score_own_map(
    policy: Any, env: Any, spec: EpisodeSpec, truth_scene: Any
) -> dict[str, Any] | None:
    """Metrics of the policy's own map (MAD with its SDF), None for a policy without one."""
    own = policy.reconstruction()
    if own is None:
        return None
    if len(own.mesh.faces) == 0:
        return {"note": "the policy's own map has no surface"}
    settings = dict(
        num_samples=spec.eval_samples,
        reference_samples_per_m2=spec.eval_samples_per_m2 or None,
        sdf=own.sdf,
    )
    if truth_scene is env.scene:
        return env.evaluate(own.mesh, **settings)
    from naruto_gym.evaluation import evaluate_reconstruction, trajectory_length

    metrics = evaluate_reconstruction(
        own.mesh,
        truth_scene,
        poses=env.poses,
        camera=env.camera,
        renderer=env.renderer,
        observable_mask=env.observable_surface.mask,
        **settings,
    )
    return {**metrics.as_dict(), "trajectory_length_m": trajectory_length(env.poses)}


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
