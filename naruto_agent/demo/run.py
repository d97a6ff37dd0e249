"""The demo's arguments and its episode loop (see :mod:`naruto_agent.demo` for the outputs).

The loop is the tools' one (:func:`naruto_agent.episode_loop.run_episode_loop`): bind the
policy to the env, reset both with the same seed, ``act`` / ``step`` until the episode's end,
with the env made in the policy's preferred action mode. Its hooks keep what a person wants to
see: the coverage at every step, the completion ratio of the policy's own map at a few
evaluation points, the goals the policy chose, and subsampled ``rgb_array`` frames.
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import json
import os
import sys
import time
import typing
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from naruto_agent.cli_args import dataclass_parser
from naruto_agent.demo.episode import Episode
from naruto_agent.episode_loop import (
    EpisodeHook,
    EvalPoints,
    FrameFusion,
    StepRecords,
    run_episode_loop,
)

#: The default episode length (the README gives its run time).
DEFAULT_MAX_EPISODE_STEPS = 1000
#: Cheaper scoring at the evaluation points of the completion curve than at the end.
EVAL_POINT_CULL_EVERY = 10
#: Demo settings handed to a policy whose constructor takes them (see :func:`policy_settings`).
POLICY_SETTINGS = ("mapper_kind", "device")


class DemoInputError(ValueError):
    """Settings the demo cannot run with: an unknown policy or scene, or a bad value."""


@dataclass
class DemoArgs:
    """Settings of the demo."""

    policy: str = "naruto"
    """a registered policy (listed below), or a Policy subclass as 'package.module:ClassName'
    (a module in the working directory is found) or 'path/to/file.py:ClassName'"""
    scene: str = "replica_like_room"
    """catalogue name, 'NAME:OPENINGS', 'procedural:room:SEED', or a mesh path ('PATH@AXIS'
    gives its up axis, e.g. room.obj@y, as naruto-benchmark takes it)"""
    up_axis: str = "z"
    """up axis of a mesh path written without @AXIS: z, y, -y, x, -x, -z or auto (from a
    recognised dataset layout)"""
    mesh_units: str = "m"
    """length unit of a mesh file (m, cm or mm), rescaled to metres on loading"""
    max_episode_steps: int = DEFAULT_MAX_EPISODE_STEPS
    """length of the episode in steps"""
    seed: int = 0
    """seed of the start pose and of the policy"""
    mapper_kind: str = "tsdf"
    """the policy's mapper, for a policy that takes one (NARUTO: tsdf, fast; neural, the
    published one, slow on a CPU; or one's own as 'package.module:ClassName', see
    docs/mappers.md)"""
    device: str = "auto"
    """device of the policy's mapper, for a policy that takes one (auto: CUDA when present)"""
    reference_device: str = "auto"
    """Open3D device of the reference TSDF mapper that fuses the frames of a policy keeping
    no map of its own (auto, cpu, cuda)"""
    policy_kwargs: str = ""
    """JSON object of further keyword arguments of the policy's constructor, e.g.
    '{"max_run_steps": 20}', or keyed by the policy as naruto-benchmark takes them, e.g.
    '{"random": {"max_run_steps": 20}}'"""
    image_scale: float = 0.25
    """camera resolution factor of the 680 x 1200 (H x W) camera (0.25: 170 x 300)"""
    output_dir: str = "outputs/demo"
    """folder the outputs are written to"""
    eval_points: int = 4
    """completion-ratio evaluation points during the episode (besides the last step)"""
    checkpoint_samples: int = 50_000
    """surface samples per mesh at the evaluation points"""
    eval_samples: int = 200_000
    """surface samples per mesh of the final metrics (200,000 as published)"""
    gif_frames: int = 60
    """frames of the animated GIF (0: no GIF)"""
    gif_width: int = 720
    """width of the GIF's frames in pixels (ground truth, RGB and depth, the agent's map)"""
    viewer: bool = True
    """write the 3D view (viewer.html; needs the viewer extra)"""
    record: bool = True
    """write episode.rrd, a Rerun recording of the episode to scrub through (`rerun
    episode.rrd`; needs the viewer extra)"""
    live: bool = False
    """stream the recording to a Rerun viewer while the episode runs (spawns one here, or
    connects to --live-url)"""
    live_url: str = ""
    """address of a running Rerun viewer for --live (HOST:PORT or
    rerun+http://HOST:PORT/proxy); empty: spawn one here"""
    map_snapshots: int = 10
    """times the agent's map is taken over the episode, for the recording and the GIF"""
    progress: bool = True
    """show a progress bar"""


def build_parser() -> argparse.ArgumentParser:
    """The demo's ``argparse`` parser, one flag per field of :class:`DemoArgs`; its epilog
    lists the registered policies, read from the registry (every name ``--policy`` takes)."""
    from naruto_agent.policies import policy_names

    parser = dataclass_parser(
        DemoArgs, description="Run one episode and write what to look at.", prog="naruto-demo"
    )
    parser.epilog = (
        f"registered policies: {', '.join(policy_names())}; any other Policy subclass as "
        "package.module:ClassName or path/to/file.py:ClassName."
    )
    return parser


def parse_args(argv: list[str] | None = None) -> DemoArgs:
    """Parse command-line flags (``--policy naruto --max-episode-steps 500 ...``) into
    :class:`DemoArgs`."""
    return DemoArgs(**vars(build_parser().parse_args(argv)))


def check_args(args: DemoArgs) -> None:
    """Raise ``ValueError`` for settings that cannot run (before anything is built)."""
    if args.max_episode_steps < 1:
        raise ValueError(f"--max-episode-steps must be at least 1, got {args.max_episode_steps}")
    if not 0 < args.image_scale <= 1:
        raise ValueError(f"--image-scale must be in (0, 1], got {args.image_scale}")
    if args.eval_points < 0 or args.gif_frames < 0 or args.map_snapshots < 0:
        raise ValueError("--eval-points, --gif-frames and --map-snapshots must be >= 0")
    if args.checkpoint_samples < 1000 or args.eval_samples < 1000:
        raise ValueError("--checkpoint-samples and --eval-samples must be at least 1000")
    if args.gif_width < 32:
        raise ValueError(f"--gif-width must be at least 32 pixels, got {args.gif_width}")


def build_policy(args: DemoArgs) -> Any:
    """The policy named by ``--policy`` with ``--policy-kwargs``, plus the demo's policy
    settings (``--mapper-kind``, ``--device``) that its constructor takes (:func:`policy_settings`).

    ``--policy-kwargs`` is flat (the constructor's arguments) or keyed by the policy's name,
    as ``naruto-benchmark`` takes it (:func:`~naruto_agent.benchmark.spec.split_policy_kwargs`).

    Raises:
        ValueError: an unknown policy name, an import path that is not a ``Policy``, or
            keyword arguments that are not a JSON object.
    """
    from naruto_agent.benchmark.spec import split_policy_kwargs
    from naruto_agent.policies import policy_class

    cls = policy_class(args.policy)
    try:
        kwargs = json.loads(args.policy_kwargs) if args.policy_kwargs.strip() else {}
    except json.JSONDecodeError as error:
        raise ValueError(f"--policy-kwargs is not valid JSON: {error}") from error
    if not isinstance(kwargs, dict):
        raise ValueError(f"--policy-kwargs must be a JSON object, got {args.policy_kwargs!r}")
    kwargs = split_policy_kwargs(kwargs, [args.policy]).get(args.policy, {})
    kwargs = {**policy_settings(cls, args), **kwargs}
    try:
        return cls(**kwargs)
    except TypeError as error:  # a keyword the constructor does not take
        raise ValueError(f"cannot build policy {args.policy!r} with {kwargs}: {error}") from error


def policy_settings(cls: type, args: DemoArgs) -> dict[str, Any]:
    """The demo settings of :data:`POLICY_SETTINGS` that ``cls`` takes, with their values
    in ``args`` (name -> value).

    A policy takes a setting when its constructor has a keyword parameter of that name, or
    a ``config`` parameter typed as a dataclass with a field of that name together with
    ``**`` keyword overrides. Any policy can so opt in (by name, not by class), and one that
    does not is never handed a keyword it would refuse.
    """
    try:
        parameters = inspect.signature(cls).parameters
    except (TypeError, ValueError):  # no introspectable constructor: pass nothing
        return {}
    named = {
        name
        for name, parameter in parameters.items()
        if parameter.kind
        in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    }
    overrides = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values())
    if overrides and "config" in named:
        named |= _config_fields(cls)
    return {name: getattr(args, name) for name in POLICY_SETTINGS if name in named}


def _config_fields(cls: type) -> set[str]:
    """Field names of the dataclass(es) that ``cls``'s ``config`` parameter is typed as."""
    try:
        hint = typing.get_type_hints(cls.__init__).get("config")
    except Exception:  # annotations that do not resolve: no fields known
        return set()
    candidates = typing.get_args(hint) or (hint,)
    return {
        field.name
        for candidate in candidates
        if isinstance(candidate, type) and dataclasses.is_dataclass(candidate)
        for field in dataclasses.fields(candidate)
    }


def chosen_goals(policy: Any) -> np.ndarray:
    """(G, 3) goals a policy chose this episode, in order; empty when it does not say.

    The NARUTO agent logs every planning request (``plans``, a ``goal`` per successful
    search); the frontier policy keeps the goals it reached (``visited_goals``).
    """
    plans = getattr(policy, "plans", None)
    goals: list[Any] = []
    if isinstance(plans, list):
        goals = [plan["goal"] for plan in plans if isinstance(plan, dict) and "goal" in plan]
    elif isinstance(getattr(policy, "visited_goals", None), list):
        goals = list(policy.visited_goals)
    return np.asarray(goals, dtype=np.float64).reshape(-1, 3)


class _MapSource:
    """The episode's reconstruction: the policy's own map, or a reference fusion of frames."""

    def __init__(self, policy: Any, camera: Any, device: str) -> None:
        self.policy = policy
        self.own = callable(getattr(policy, "mesh", None))
        self.reference = None
        if not self.own:
            from naruto_gym.evaluation import EpisodeReconstruction

            self.reference = EpisodeReconstruction(camera, device=device)
        self.label = (
            f"the policy's own map ({type(policy).__name__}.mesh())"
            if self.own
            else "reference TSDF fusion of the episode's frames (the policy keeps no map)"
        )

    def add_frame(self, observation: dict[str, np.ndarray]) -> None:
        if self.reference is not None:
            self.reference.add_frame(observation["rgb"], observation["depth"], observation["pose"])

    def mesh(self) -> trimesh.Trimesh:
        return self.policy.mesh() if self.own else self.reference.mesh()


def _score(env: Any, mesh: trimesh.Trimesh, **kwargs: Any) -> dict[str, Any] | None:
    """Metrics of ``mesh`` against the ground truth; None when there is nothing to score."""
    if len(mesh.faces) == 0:
        return None
    try:
        return env.unwrapped.evaluate(mesh, **kwargs)
    except ValueError:  # culling kept no face: nothing of the map is in view yet
        return None


def _curve_point(step: int, metrics: dict[str, Any] | None) -> dict[str, Any]:
    keys = (
        "completion_ratio_pct",
        "observable_completion_ratio_pct",
        "completion_cm",
        "accuracy_cm",
    )
    return {"step": step, **{key: (metrics or {}).get(key) for key in keys}}


def make_env(args: DemoArgs, scene: Any, action_mode: str) -> Any:
    """The episode's env: the default camera scaled, the episode's length as its time
    limit."""
    import gymnasium as gym

    import naruto_gym  # noqa: F401  (registers the env ids)

    return gym.make(
        "NarutoRecon-v0",
        scene=scene,
        action_mode=action_mode,
        image_scale=args.image_scale,
        max_episode_steps=args.max_episode_steps,
        render_mode="rgb_array",
    )


class _DemoHooks(EpisodeHook):
    """What the demo keeps of each step besides :class:`StepRecords`: the watch's pictures,
    snapshots and recording (the watch made by ``make_watch`` once the env is reset), and the
    completion scores at the evaluation points."""

    def __init__(
        self, args: DemoArgs, env: Any, source: _MapSource, make_watch: Callable[[], Any]
    ) -> None:
        self.env = env
        self.source = source
        self.make_watch = make_watch
        self.watch: Any = None
        self.cheap = {"num_samples": args.checkpoint_samples, "cull_every": EVAL_POINT_CULL_EVERY}
        self.curve: list[dict[str, Any]] = []
        self.eval_points = EvalPoints(
            args.max_episode_steps, args.eval_points, self.score, at_last=True
        )

    def on_reset(self, observation: dict[str, Any], info: dict[str, Any]) -> None:
        self.watch = self.make_watch()
        self.watch.observe(0, observation, info, last=False)

    def on_step(
        self, step: int, observation: dict[str, Any], info: dict[str, Any], last: bool
    ) -> None:
        self.watch.observe(step, observation, info, last)

    def score(self, step: int, last: bool) -> None:
        mesh = self.watch.final_mesh(step) if last else None
        scores = _score(self.env, self.source.mesh() if mesh is None else mesh, **self.cheap)
        self.curve.append(_curve_point(step, scores))
        self.watch.scores(step, scores)


def run_episode(args: DemoArgs, env: Any, policy: Any, recorder: Any | None = None) -> Episode:
    """Run one episode of ``policy`` in ``env`` and keep what the outputs need (and write
    it to ``recorder``, an :class:`~naruto_agent.recording.EpisodeRecorder`, when given)."""
    from naruto_agent.demo.watch import EpisodeWatch

    base = env.unwrapped
    source = _MapSource(policy, base.camera, args.reference_device)
    times = {"pictures": 0.0, "recording": 0.0}

    def make_watch() -> EpisodeWatch:
        return EpisodeWatch(
            env,
            policy,
            source.mesh,
            args.max_episode_steps,
            args.gif_frames,
            args.gif_width,
            args.map_snapshots,
            recorder,
            times,
        )

    records = StepRecords()
    demo = _DemoHooks(args, env, source, make_watch)
    hooks: list[EpisodeHook] = [records, demo, demo.eval_points]
    if source.reference is not None:
        hooks.insert(0, FrameFusion(source.reference))
    result = run_episode_loop(
        env,
        policy,
        args.max_episode_steps,
        args.seed,
        hooks,
        progress=f"{args.policy} on {args.scene}" if args.progress else None,
    )
    watch = demo.watch
    final_mesh = watch.final_mesh(result.steps_run)
    watch.close()
    seconds = result.seconds
    times = {
        "policy": seconds["policy"],
        "env": seconds["env"],
        "mapping": seconds.get("mapping", 0.0),
        "pictures": times["pictures"],
        "eval_points": seconds["eval_points"],
        "recording": times["recording"],
    }
    return Episode(
        steps_run=result.steps_run,
        coverage=records.coverage,
        completion_curve=demo.curve,
        poses=base.poses,
        goals=chosen_goals(policy),
        frames=watch.frames,
        collisions=records.collisions,
        path_length_m=float(result.info.get("path_length_m", 0.0)),
        times_s=times,
        mesh=source.mesh() if final_mesh is None else final_mesh,
        map_source=source.label,
        camera_size=(base.camera.height, base.camera.width),
        policy_detail_s=dict(getattr(policy, "timings", {}) or {}),
        stalled_steps=policy.stalled_steps,
        stall_recoveries=[event.as_dict() for event in policy.stall_events],
    )


def prepare(args: DemoArgs) -> tuple[Any, Any]:
    """The scene and the policy of the settings, checked before any work.

    Raises:
        DemoInputError: bad settings, an unknown policy or scene (the message says which).
    """
    from naruto_agent.benchmark.spec import parse_scene
    from naruto_gym.scenes.catalogue import resolve_scene

    try:
        check_args(args)
        policy = build_policy(args)
        scene_spec = parse_scene(args.scene, args.up_axis)
        scene = resolve_scene(scene_spec.scene, scene_spec.up_axis, args.mesh_units)
    except (ValueError, FileNotFoundError) as error:
        raise DemoInputError(str(error)) from error
    return scene, policy


def run_demo(args: DemoArgs) -> dict[str, Any]:
    """Run the episode, score it, write every output into ``args.output_dir``; return the
    metrics.

    Raises:
        DemoInputError: bad settings, an unknown policy or scene.
    """
    from naruto_agent.demo import outputs, viewer

    load_start = os.getloadavg()
    begun = time.perf_counter()
    scene, policy = prepare(args)
    out = Path(args.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    env = make_env(args, scene, policy.preferred_action_mode)
    try:
        recorder = _recorder(args, env, out)
        started = time.perf_counter()
        try:
            episode = run_episode(args, env, policy, recorder)
        finally:
            policy.close()
        loop_s = time.perf_counter() - started
        clock = time.perf_counter()
        final = _score(env, episode.mesh, num_samples=args.eval_samples)
        evaluation_s = time.perf_counter() - clock
        metrics = outputs.metrics_record(
            args=asdict(args),
            episode=episode,
            final=final,
            seconds={"episode": loop_s, "evaluation": evaluation_s},
            load_average=[load_start, os.getloadavg()],
        )
        clock = time.perf_counter()
        base = env.unwrapped
        written = outputs.write_all(out, episode, metrics, base, title=_title(args))
        if args.viewer:
            page = viewer.write_viewer(
                out / "viewer.html",
                episode.mesh,
                base.scene,
                episode.poses,
                base.camera,
                episode.goals,
                title=_title(args),
            )
            if page is not None:
                written.append(page)
        metrics["seconds"]["outputs"] = time.perf_counter() - clock
        # From the call on: policy, scene and env built, the episode, scoring, the files.
        metrics["seconds"]["total"] = time.perf_counter() - begun
        if recorder is not None and recorder.path is not None:
            written.append(recorder.path)
        metrics["outputs"] = sorted([path.name for path in written] + ["metrics.json"])
        outputs.write_metrics(out / "metrics.json", metrics)
    finally:
        env.close()
    print(outputs.summary_text(metrics, out))
    return metrics


def _recorder(args: DemoArgs, env: Any, out: Path) -> Any | None:
    """The episode's recorder (:func:`~naruto_agent.demo.watch.make_recorder`); a live viewer
    that cannot be reached is bad input (the message says what to do)."""
    from naruto_agent.demo.watch import make_recorder
    from naruto_agent.recording import LiveViewerError

    base = env.unwrapped
    try:
        return make_recorder(
            out / "episode.rrd",
            base.camera,
            _title(args),
            args.record,
            args.live,
            args.live_url,
            scene=base.scene,
        )
    except (LiveViewerError, ValueError) as error:
        raise DemoInputError(str(error)) from error


def _title(args: DemoArgs) -> str:
    name = f"NARUTO ({args.mapper_kind})" if args.policy == "naruto" else args.policy
    return f"{name} on {args.scene}, seed {args.seed}"


def main(argv: list[str] | None = None) -> None:
    """Entry point of ``naruto-demo``: bad input ends with a one-line error (exit status 2).

    Returns None, which a console script turns into exit status 0 (the metrics are in
    ``metrics.json``; :func:`run_demo` returns them too).
    """
    args = parse_args(argv)
    try:
        run_demo(args)
    except DemoInputError as error:
        print(f"naruto-demo: error: {error}", file=sys.stderr)
        raise SystemExit(2) from error
