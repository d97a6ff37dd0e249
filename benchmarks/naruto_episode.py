"""One NARUTO episode in the env. Results: docs/benchmarks/naruto-episode.md

Runs :class:`~naruto_agent.naruto.NarutoPolicy` for a step budget on a scene and reports

* the coverage curve and the final coverage (share of the ground-truth surface seen);
* the metrics of the env's reference TSDF map of the episode's frames
  (``gym.make(..., reconstruct=True)``, ``env.unwrapped.reconstruction_metrics()``);
* the metrics of the agent's own map (``policy.reconstruction()``: its mesh, and its SDF for MAD);
* the trajectory length, collisions, the planner's requests and its state counts;
* where the agent's targets were and where it went: top-down pictures at a few steps with
  the frontier of unexplored space (cyan), the most uncertain seen surfaces (orange), the
  goals it chose (white) and its trajectory (red);
* the time per step by phase: mapping (frame integration + reading the planner view),
  planning (goal search + E-RRT + the state machine) and the env (motion, rendering,
  coverage, and the reference TSDF fusion that ``reconstruct=True`` adds), next to the
  published per-frame figures on a V100 (NARUTO, Feng et al., CVPR 2024) for scale;
* the wall time by phase as in the paper's Figure 8 (``phases_s``, printed as a table):
  simulation (motion and rendering of the RGB-D frame and the panorama), mapping (the
  mapper's iterations and keyframes, without the active ray scoring), active ray scoring
  (drawing, scoring and picking the oversampled pool; neural mapper), explored-space update
  (the frontier grid the agent's unknown-space targets come from), planner view, goal
  search, path planning (E-RRT and the recovery planner), rotation planning (the state
  machine's own work: SLERP, look-at, target ordering) and collision checks (the agent's
  checks of its moves on its map); apart from the agent's loop, the env's coverage
  bookkeeping and the reference TSDF fusion. The env's parts are timed by wrapping its
  components (renderer, panorama, coverage tracker, reference fusion), the collision checks
  by wrapping the agent's check; nothing else changes.

It writes a JSON record and two PNGs (the env's top-down render of the trajectory, and the
coverage curve) under ``benchmarks/results/``. The machine's load average is recorded at the
start and the end: on a shared 2-core CPU the timings move with it.

Usage::

    python benchmarks/naruto_episode.py                          # replica_like_room, 500 steps
    python benchmarks/naruto_episode.py --max-episode-steps 200 --image-scale 0.25 --scene two_rooms
    python benchmarks/naruto_episode.py --mapper-kind neural --device cuda   # the published mapper
"""

from __future__ import annotations

import dataclasses
import json
import os
import platform
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from PIL import Image  # noqa: E402
from tqdm import tqdm  # noqa: E402

import naruto_gym  # noqa: E402,F401  (registers the env)
from naruto_agent.benchmark.spec import SceneSpec  # noqa: E402
from naruto_agent.cli_args import parse_dataclass_args
from naruto_agent.episode_loop import (  # noqa: E402
    EpisodeHook,
    StepRecords,
    run_episode_loop,
)
from naruto_agent.mapping import NeuralMapper  # noqa: E402
from naruto_agent.naruto import NarutoPolicy  # noqa: E402
from naruto_gym.evaluation import EpisodeReconstruction  # noqa: E402

REPO_ROOT = Path(__file__).resolve().parents[1]
# NARUTO paper (Feng et al., CVPR 2024), Replica room0 on a V100: per-frame averages.
PUBLISHED_MS_PER_FRAME = {"simulator": 24.4, "mapping": 60.5, "planning": 2.1}


@dataclass
class Args:
    """Benchmark settings."""

    scene: str = "replica_like_room"
    """catalogue name or mesh path"""
    up_axis: str = "z"
    """up axis of a mesh file"""
    max_episode_steps: int = 500
    """step budget of the episode"""
    image_scale: float = 0.5
    """camera resolution factor (0.5 gives 340 x 600)"""
    mapper_kind: str = "tsdf"
    """the agent's mapper: tsdf (fast) or neural (the published one; slow on a CPU)"""
    seed: int = 0
    """seed of the env's start pose and of the agent"""
    device: str = "auto"
    """device of the agent's mapper and planner"""
    backend: str = ""
    """neural mapper's compute path: auto (Triton on CUDA where installed), torch (the
    PyTorch reference) or triton; empty keeps the setting of --settings (default auto)"""
    eval_samples: int = 200_000
    """surface samples per mesh for the metrics (200,000 as published)"""
    output_dir: str = str(REPO_ROOT / "benchmarks" / "results")
    """where the JSON and PNGs go"""
    tag: str = ""
    """suffix of the output names (default: scene, mapper and steps; the scene of a mesh
    called mesh.ply is its folder's name, e.g. replica_room0)"""
    target_snapshots: int = 4
    """top-down pictures of the targets, evenly over the episode (0: none)"""
    settings: str = ""
    """JSON object of NarutoPolicy settings, e.g. '{"neural": {"active_score": "grid"}}'"""
    checkpoint_every: int = 100
    """write a progress record (coverage, wall time by phase so far) every n steps (0: never)"""
    env_kwargs: str = ""
    """JSON object of extra env arguments, e.g. '{"pinhole_backend": "auto"}' (the
    rasterised frames: a tenth of the CPU of the ray cast at 680 x 1200)"""
    reference_fusion: str = "auto"
    """the reference TSDF's fusion: "auto" (the env's choice: a background thread where the
    process has a second thread), "background" or "inline" (in the step)"""
    passive_reference: bool = False
    """neural mapper: after the episode, map its frames passively (same mapper settings, no
    active sampling) in this process, and report the episode's time as a ratio to it"""


def parse_args() -> Args:
    return parse_dataclass_args(Args, description=__doc__.split("\n")[0])


def scalar_metrics(metrics: dict) -> dict:
    """The numbers of a metrics dict (drops arrays and nested data)."""
    return {k: v for k, v in metrics.items() if isinstance(v, (int, float, str, bool))}


def save_curve(coverage: list[float], path: Path, title: str) -> None:
    figure, axes = plt.subplots(figsize=(6, 3.5))
    axes.plot(np.arange(len(coverage)), 100.0 * np.asarray(coverage))
    axes.set_xlabel("step")
    axes.set_ylabel("coverage (%)")
    axes.set_ylim(0, 100)
    axes.grid(alpha=0.3)
    axes.set_title(title)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def target_snapshot(env: gym.Env, policy: NarutoPolicy, step: int) -> tuple[np.ndarray, dict]:
    """The top-down map and, in world x-y, the agent's targets, goals and trajectory."""
    base = env.unwrapped
    top_down = base.top_down_map
    policy.refresh_view()
    uncertainty = policy.uncertainty
    values = uncertainty.values.reshape(-1)
    points = uncertainty.grid_points()
    mapper = policy.mapper
    initial = getattr(mapper, "initial_variance", None) or mapper.config.initial_variance
    frontier = points[np.isclose(values, initial)]
    surface = points[(values > 0) & ~np.isclose(values, initial)]
    surface_values = values[(values > 0) & ~np.isclose(values, initial)]
    surface = surface[np.argsort(-surface_values)[:2000]]
    goals = np.array([p["goal"] for p in policy.plans if "goal" in p]).reshape(-1, 3)
    layers = {
        "frontier": frontier,
        "uncertain surface": surface,
        "goals": goals,
        "trajectory": base.trajectory,
    }
    return top_down.image.copy(), {"step": step, **layers}


def save_target_pictures(env: gym.Env, snapshots: list, path: Path, title: str) -> None:
    top_down = env.unwrapped.top_down_map
    figure, axes = plt.subplots(
        1, len(snapshots), figsize=(4.2 * len(snapshots), 3.8), squeeze=False
    )
    styles = {
        "frontier": dict(s=2, c="cyan", alpha=0.5),
        "uncertain surface": dict(s=2, c="orange", alpha=0.5),
        "goals": dict(s=18, c="white", edgecolors="black", marker="*"),
    }
    for axis, (image, layers) in zip(axes[0], snapshots, strict=True):
        axis.imshow(image)
        for name, style in styles.items():
            if len(layers[name]):
                xy = top_down.world_to_pixel(layers[name][:, :2])
                axis.scatter(xy[:, 0], xy[:, 1], label=name, **style)
        path_xy = top_down.world_to_pixel(layers["trajectory"][:, :2])
        axis.plot(path_xy[:, 0], path_xy[:, 1], c="red", lw=1, label="trajectory")
        axis.set_title(f"step {layers['step']}")
        axis.axis("off")
    axes[0][0].legend(loc="lower left", fontsize=6, markerscale=3)
    figure.suptitle(title)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


class PhaseClock:
    """Wall and CPU seconds (the process's, all threads) spent inside wrapped callables, by
    phase name (for the Figure 8 breakdown)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self.cpu_seconds: dict[str, float] = {}

    def wrap(self, name: str, function):  # noqa: ANN001, ANN201
        self.seconds.setdefault(name, 0.0)
        self.cpu_seconds.setdefault(name, 0.0)

        def timed(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
            clock, cpu_clock = time.perf_counter(), time.process_time()
            try:
                return function(*args, **kwargs)
            finally:
                self.seconds[name] += time.perf_counter() - clock
                self.cpu_seconds[name] += time.process_time() - cpu_clock

        return timed

    def clear(self) -> None:
        self.seconds = dict.fromkeys(self.seconds, 0.0)
        self.cpu_seconds = dict.fromkeys(self.cpu_seconds, 0.0)


def instrument(env: gym.Env, policy: NarutoPolicy, clock: PhaseClock) -> None:
    """Wrap the env's components and the agent's move check so that ``clock`` times them.

    The wrappers are instance attributes (the panorama function is looked up in the env's
    module at each call): behaviour is unchanged, only time is recorded.
    """
    from naruto_gym.envs import naruto_recon_env

    base = env.unwrapped
    base.renderer.render = clock.wrap("render", base.renderer.render)
    if not hasattr(naruto_recon_env.render_panorama, "__wrapped_by_phase_clock__"):
        panorama = clock.wrap("panorama", naruto_recon_env.render_panorama)
        panorama.__wrapped_by_phase_clock__ = True
        naruto_recon_env.render_panorama = panorama
    base.coverage.update = clock.wrap("coverage", base.coverage.update)
    if base.reconstruction is not None:
        base.reconstruction.add_frame = clock.wrap("reference_map", base.reconstruction.add_frame)

    def timed_check(check):  # noqa: ANN001, ANN202
        def move_check(start, end):  # noqa: ANN001, ANN202
            # A check may read a stale planner view first: that time is the planner view's.
            view_before = policy.timings["planner_view"]
            started = time.perf_counter()
            try:
                return check(start, end)
            finally:
                spent = time.perf_counter() - started
                clock.seconds["collision_checks"] += spent - (
                    policy.timings["planner_view"] - view_before
                )

        return move_check

    clock.seconds.setdefault("collision_checks", 0.0)
    policy.wrap_move_check(timed_check)


#: Figure 8's phases, in order, then what the env does beyond the agent's loop.
PHASES = (
    "simulation",
    "mapping",
    "active_ray_scoring",
    "explored_space",
    "planner_view",
    "goal_search",
    "path_planning",
    "rotation_planning",
    "collision_checks",
)
OUTSIDE_LOOP = ("coverage_bookkeeping", "reference_tsdf")


def phase_seconds(policy: NarutoPolicy, clock: PhaseClock, env_s: float) -> dict[str, float]:
    """Wall seconds of the episode by phase (Figure 8), from the agent's timings, the
    mapper's counters and the wrapped components."""
    timings = policy.timings
    stats = getattr(policy.mapper, "stats", None)
    scoring = float(getattr(stats, "scoring_seconds", 0.0))
    explored = float(getattr(stats, "observed_space_seconds", 0.0))
    collision = clock.seconds.get("collision_checks", 0.0)
    outside = clock.seconds.get("coverage", 0.0) + clock.seconds.get("reference_map", 0.0)
    return {
        "simulation": env_s - outside,
        "mapping": timings["mapping"] - scoring - explored,
        "active_ray_scoring": scoring,
        "explored_space": explored,
        "planner_view": timings["planner_view"],
        "goal_search": timings["goal_search"],
        "path_planning": timings["rrt"],
        "rotation_planning": timings["control"] - collision,
        "collision_checks": collision,
        "coverage_bookkeeping": clock.seconds.get("coverage", 0.0),
        "reference_tsdf": clock.seconds.get("reference_map", 0.0),
    }


def print_phase_table(phases: dict[str, float], steps: int, episode_s: float) -> None:
    loop = sum(phases[name] for name in PHASES)
    print("\n| phase | total (s) | per step (ms) | share of the agent's loop |")
    print("|---|---|---|---|")
    for name in (*PHASES, *OUTSIDE_LOOP):
        share = f"{100 * phases[name] / loop:.1f} %" if name in PHASES and loop > 0 else "-"
        print(
            f"| {name.replace('_', ' ')} | {phases[name]:.1f} | "
            f"{1000 * phases[name] / max(steps, 1):.1f} | {share} |"
        )
    print(
        f"| agent's loop (sum of the phases) | {loop:.1f} | {1000 * loop / max(steps, 1):.1f} | |"
    )
    print(f"| episode wall time | {episode_s:.1f} | {1000 * episode_s / max(steps, 1):.1f} | |")


def passive_reference(env: gym.Env, policy: NarutoPolicy, args: Args) -> dict:
    """Map the episode's frames passively, right after it in the same process.

    The agent's neural mapper settings without active ray sampling and without the
    explored-space grid (nothing plans on it), fed the frames of the episode's poses; only
    the frames the mapper reads are rendered, and rendering is timed apart (the passive
    reference of the goal "episode at most 2x the passive mapping" is the mapping alone).
    """
    base = env.unwrapped
    config = dataclasses.replace(policy.mapper.config, active_sampling=False, unknown_space=False)
    mapper = NeuralMapper(policy.context.bounds, base.camera, config)
    render_s = render_cpu_s = 0.0
    started, cpu_started = time.perf_counter(), time.process_time()
    for index, pose in enumerate(tqdm(base.poses, desc="passive reference")):
        if len(mapper.required_pixels(index)) == 0:
            continue
        clock, cpu_clock = time.perf_counter(), time.process_time()
        rgb, depth = base.renderer.render(pose)
        render_s += time.perf_counter() - clock
        render_cpu_s += time.process_time() - cpu_clock
        mapper.integrate(rgb, depth, pose, index)
    mapping_s = time.perf_counter() - started - render_s
    mapping_cpu_s = time.process_time() - cpu_started - render_cpu_s
    metrics = base.evaluate(
        mapper.extract_mesh(0.02), num_samples=args.eval_samples, sdf=mapper.sdf
    )
    return {
        "frames": len(base.poses),
        "iterations": mapper.stats.iterations,
        "mapping_s": mapping_s,
        "mapping_cpu_s": mapping_cpu_s,
        "render_s": render_s,
        "mesh_metrics": scalar_metrics(metrics),
    }


class Instrument(EpisodeHook):
    """Wraps the env's components and the agent's move check once the policy is bound
    (:func:`instrument`)."""

    def __init__(self, clock: PhaseClock) -> None:
        self.clock = clock

    def before_reset(self, env: gym.Env, policy: NarutoPolicy) -> None:
        instrument(env, policy, self.clock)


class TargetSnapshots(EpisodeHook):
    """Top-down pictures of the agent's targets at ``count`` steps evenly over the episode
    (:func:`target_snapshot`); their wall and CPU seconds are kept apart, as they are not
    the agent's time."""

    def __init__(self, max_episode_steps: int, count: int) -> None:
        self.steps = (
            set(np.linspace(0, max_episode_steps, count + 1)[1:].astype(int).tolist())
            if count > 0
            else set()
        )
        self.pictures: list = []
        self.seconds = self.cpu_seconds = 0.0
        self.env: gym.Env | None = None
        self.policy: NarutoPolicy | None = None

    def before_reset(self, env: gym.Env, policy: NarutoPolicy) -> None:
        self.env, self.policy = env, policy

    def on_step(self, step: int, observation: dict, info: dict, last: bool) -> None:
        if step in self.steps:
            clock, cpu_clock = time.perf_counter(), time.process_time()
            self.pictures.append(target_snapshot(self.env, self.policy, step))
            self.seconds += time.perf_counter() - clock
            self.cpu_seconds += time.process_time() - cpu_clock


class ProgressFile(EpisodeHook):
    """Every ``--checkpoint-every`` steps, a progress record of the episode so far: coverage,
    wall and CPU time (pictures left out) and the wall time by phase."""

    def __init__(
        self,
        args: Args,
        path: Path,
        records: StepRecords,
        snapshots: TargetSnapshots,
        clock: PhaseClock,
        seconds: dict[str, float],
        started: float,
        cpu_started: float,
    ) -> None:
        self.args, self.path, self.records, self.snapshots = args, path, records, snapshots
        self.clock, self.seconds = clock, seconds
        self.started, self.cpu_started = started, cpu_started
        self.policy: NarutoPolicy | None = None

    def before_reset(self, env: gym.Env, policy: NarutoPolicy) -> None:
        self.policy = policy

    def on_step(self, step: int, observation: dict, info: dict, last: bool) -> None:
        if step % self.args.checkpoint_every:
            return
        env_s = self.seconds["reset_env"] + self.seconds["env"]
        progress = {
            "args": dataclasses.asdict(self.args),
            "steps_run": step,
            "wall_s": time.perf_counter() - self.started - self.snapshots.seconds,
            "cpu_s": time.process_time() - self.cpu_started - self.snapshots.cpu_seconds,
            "phases_s": phase_seconds(self.policy, self.clock, env_s),
            "coverage_curve": np.round(self.records.coverage, 5).tolist(),
            "path_length_m": float(info.get("path_length_m", 0.0)),
            "load_average": os.getloadavg(),
        }
        self.path.write_text(json.dumps(progress, indent=2))


def json_object(text: str, flag: str, what: str) -> dict:
    """The dict a ``--flag`` holds as JSON ({} when empty), or exit saying what is wrong."""
    try:
        value = json.loads(text) if text else {}
    except json.JSONDecodeError as error:
        raise SystemExit(f"{flag} must be a JSON object of {what}: {error}") from error
    if not isinstance(value, dict):
        raise SystemExit(f"{flag} must be a JSON object, got {text!r}")
    return value


def main(args: Args) -> dict:
    load_start = os.getloadavg()
    env_kwargs = json_object(args.env_kwargs, "--env-kwargs", "env arguments")
    settings = json_object(args.settings, "--settings", "NarutoPolicy settings")
    if args.backend:
        settings["neural"] = {**settings.get("neural", {}), "backend": args.backend}
    # One step more than the budget, so the env's final-metrics wrapper (which scores on
    # truncation) does not run inside a timed step; the metrics are computed below.
    env = gym.make(
        "NarutoRecon-v0",
        scene=args.scene,
        up_axis=args.up_axis,
        image_scale=args.image_scale,
        max_episode_steps=args.max_episode_steps + 1,
        reconstruct=True,
        render_mode="rgb_array",
        **env_kwargs,
    )
    base = env.unwrapped
    if args.reference_fusion != "auto":
        if args.reference_fusion not in ("background", "inline"):
            raise SystemExit(
                f"--reference-fusion {args.reference_fusion!r}: use auto, background or inline"
            )
        base.reconstruction = EpisodeReconstruction(
            base.camera, fuse_in_background=args.reference_fusion == "background"
        )
    policy = NarutoPolicy(mapper_kind=args.mapper_kind, device=args.device, **settings)
    # a mapper given by import path ("pkg.mod:Class", "file.py:Class") is named by its class
    mapper_name = args.mapper_kind.rsplit(":", 1)[-1]
    tag = args.tag or (
        f"{SceneSpec(args.scene).label}_{mapper_name}_{args.max_episode_steps}steps"
    )
    output_dir = Path(args.output_dir)
    output_dir.mkdir(parents=True, exist_ok=True)
    clock_phases = PhaseClock()
    records = StepRecords()
    snapshots = TargetSnapshots(args.max_episode_steps, args.target_snapshots)
    seconds: dict[str, float] = {}
    # CPU time of the process (all its threads): on a shared machine it moves far less with
    # the other jobs than wall time, so ratios between runs at different loads use it.
    started, cpu_started = time.perf_counter(), time.process_time()
    hooks: list[EpisodeHook] = [Instrument(clock_phases), records, snapshots]
    if args.checkpoint_every > 0:
        hooks.append(
            ProgressFile(
                args,
                output_dir / f"naruto_episode_{tag}_progress.json",
                records,
                snapshots,
                clock_phases,
                seconds,
                started,
                cpu_started,
            )
        )
    result = run_episode_loop(
        env,
        policy,
        args.max_episode_steps,
        args.seed,
        hooks,
        progress=f"NARUTO {args.scene}",
        seconds=seconds,
    )
    info = result.info
    coverage = records.coverage
    collisions = int(sum(records.collisions.values()))
    env_s = seconds["reset_env"] + seconds["env"]
    reset_s = seconds["reset_policy"]
    final_fusion_wait_s = 0.0
    if base.reconstruction is not None:
        # Frames still queued for the background fusion are the episode's: wait for them.
        clock = time.perf_counter()
        base.reconstruction.mapper  # noqa: B018 - the property waits for the queue
        final_fusion_wait_s = time.perf_counter() - clock
    episode_s = time.perf_counter() - started - snapshots.seconds  # pictures: not the agent's
    episode_cpu_s = time.process_time() - cpu_started - snapshots.cpu_seconds
    # The trajectory (one flattened camera-to-world matrix per line, like Replica's
    # traj.txt), so its frames can be mapped passively for comparison
    # (benchmarks/mapping_quality.py --trajectory).
    np.savetxt(
        output_dir / f"naruto_episode_{tag}_poses.txt", np.asarray(base.poses).reshape(-1, 16)
    )
    steps_run = len(coverage) - 1

    clock = time.perf_counter()
    reference = base.reconstruction_metrics(num_samples=args.eval_samples)
    clock_mesh = time.perf_counter()
    own_map = policy.reconstruction()  # the same map (mesh and SDF) the harness scores
    mesh_s = time.perf_counter() - clock_mesh
    own = base.evaluate(own_map.mesh, num_samples=args.eval_samples, sdf=own_map.sdf)
    evaluation_s = time.perf_counter() - clock - mesh_s

    timings = policy.timings
    phases = phase_seconds(policy, clock_phases, env_s)
    phases["reference_tsdf"] += final_fusion_wait_s
    per_step = 1000.0 / max(steps_run, 1)
    phases_ms = {
        "mapping": per_step * (timings["mapping"] + timings["planner_view"]),
        "planning": per_step * (timings["goal_search"] + timings["rrt"] + timings["control"]),
        "env": per_step * env_s,
    }
    detail_ms = {name: per_step * seconds for name, seconds in timings.items()}
    plans = policy.plans
    outcomes = Counter(plan.get("outcome", "?") for plan in plans)
    planned = [plan for plan in plans if plan.get("outcome") == "planned"]
    record = {
        "args": dataclasses.asdict(args),
        "steps_run": steps_run,
        "camera": base.camera.as_dict(),
        "coverage_start": coverage[0],
        "coverage_final": coverage[-1],
        "coverage_curve": np.round(coverage, 5).tolist(),
        "reference_tsdf_metrics": scalar_metrics(reference),
        "agent_mesh_metrics": scalar_metrics(own),
        "agent_mesh_faces": int(len(own_map.mesh.faces)),
        "path_length_m": float(info.get("path_length_m", 0.0)),
        "collisions": collisions,
        "agent_detected_collisions": policy.machine.collisions,
        "states": {state.value: count for state, count in Counter(policy.machine.history).items()},
        "planning_requests": len(plans),
        "planning_outcomes": dict(outcomes),
        "fallback_searches": sum(bool(plan.get("fallback")) for plan in plans),
        "mean_goal_search_ms": float(np.mean([p["search_ms"] for p in plans if "search_ms" in p]))
        if plans
        else 0.0,
        "mean_rrt_ms": float(np.mean([p["rrt_ms"] for p in planned])) if planned else 0.0,
        "time_per_step_ms": phases_ms,
        "phases_s": phases,
        "wrapped_components_cpu_s": dict(clock_phases.cpu_seconds),
        "phases_ms_per_step": {name: per_step * seconds for name, seconds in phases.items()},
        "phase_shares_of_loop": {
            name: phases[name] / max(sum(phases[p] for p in PHASES), 1e-9) for name in PHASES
        },
        "neural_mapper_settings": policy.mapper.config.to_dict()
        if args.mapper_kind == "neural"
        else None,
        "neural_mapper_backend": getattr(policy.mapper, "backend", None),
        "neural_mapper_cuda_graphs": getattr(policy.mapper, "cuda_graph_status", None),
        "mapping_iterations": int(getattr(getattr(policy.mapper, "stats", None), "iterations", 0)),
        "time_per_step_detail_ms": detail_ms,
        "published_v100_ms_per_frame": PUBLISHED_MS_PER_FRAME,
        "reset_s": reset_s,
        "env_reset_s": seconds["reset_env"],
        # The reference fusion's own time; with a background thread, reference_tsdf above is
        # only what the episode waited for it (checks, copies, a full queue).
        "reference_fusion_s": base.reconstruction.fusion_seconds
        if base.reconstruction is not None
        else 0.0,
        "reference_fusion_in_background": base.reconstruction is not None
        and base.reconstruction.fuses_in_background,
        "episode_s": episode_s,
        "episode_cpu_s": episode_cpu_s,
        "mesh_s": mesh_s,
        "evaluation_s": evaluation_s,
        "load_average_start": load_start,
        "load_average_end": os.getloadavg(),
        "cpu_count": os.cpu_count(),
        "host": platform.node(),
    }
    if args.passive_reference and args.mapper_kind == "neural":
        passive = passive_reference(env, policy, args)
        # The env's reference TSDF fusion scores the episode; it is not the agent's work.
        agent_s = episode_s - phases.get("reference_tsdf", 0.0)
        agent_cpu_s = episode_cpu_s - clock_phases.cpu_seconds.get("reference_map", 0.0)
        passive.update(
            episode_to_passive_wall=episode_s / passive["mapping_s"],
            episode_without_reference_tsdf_to_passive_wall=agent_s / passive["mapping_s"],
            episode_to_passive_cpu=episode_cpu_s / passive["mapping_cpu_s"],
            episode_without_reference_tsdf_to_passive_cpu=agent_cpu_s / passive["mapping_cpu_s"],
            reference_tsdf_cpu_s=clock_phases.cpu_seconds.get("reference_map", 0.0),
            load_average_end=os.getloadavg(),
        )
        record["passive_reference"] = passive
    json_path = output_dir / f"naruto_episode_{tag}.json"
    json_path.write_text(json.dumps(record, indent=2))
    Image.fromarray(env.render()).save(output_dir / f"naruto_episode_{tag}_topdown.png")
    save_curve(
        coverage,
        output_dir / f"naruto_episode_{tag}_coverage.png",
        f"NARUTO ({args.mapper_kind}) on {args.scene}",
    )
    if snapshots.pictures:
        save_target_pictures(
            env,
            snapshots.pictures,
            output_dir / f"naruto_episode_{tag}_targets.png",
            f"NARUTO ({args.mapper_kind}) on {args.scene}: targets and path",
        )
    env.close()

    print(
        f"\nNARUTO ({args.mapper_kind} mapper"
        + (f", {record['neural_mapper_backend']} backend" if args.mapper_kind == "neural" else "")
        + f") on {args.scene}, {steps_run} steps, "
        f"image scale {args.image_scale} ({base.camera.width} x {base.camera.height})"
    )
    marks = np.linspace(0, steps_run, 6).astype(int)
    print("coverage (%): " + ", ".join(f"step {m}: {100 * coverage[m]:.1f}" for m in marks))
    for name, metrics in (("reference TSDF", reference), ("agent's own mesh", own)):
        print(
            f"{name:>17}: accuracy {metrics['accuracy_cm']:.2f} cm, completion "
            f"{metrics['completion_cm']:.2f} cm, completion ratio "
            f"{metrics['completion_ratio_pct']:.2f} %, MAD {metrics['mad_cm']:.2f} cm"
        )
    print(
        f"path length {record['path_length_m']:.2f} m, env collisions {collisions}, "
        f"planning requests {len(plans)} {dict(outcomes)}"
    )
    print(
        "time per step (ms): "
        + ", ".join(f"{k} {v:.1f}" for k, v in phases_ms.items())
        + "  | published V100: "
        + ", ".join(f"{k} {v}" for k, v in PUBLISHED_MS_PER_FRAME.items())
    )
    print("  detail: " + ", ".join(f"{k} {v:.1f}" for k, v in detail_ms.items()))
    print_phase_table(phases, steps_run, episode_s)
    print(f"episode CPU time (all threads of the process): {episode_cpu_s:.1f} s")
    if "passive_reference" in record:
        passive = record["passive_reference"]
        print(
            f"passive mapping of the same {passive['frames']} frames: {passive['mapping_s']:.1f} s "
            f"wall, {passive['mapping_cpu_s']:.1f} s CPU; episode / passive: "
            f"{passive['episode_to_passive_wall']:.2f}x wall "
            f"({passive['episode_without_reference_tsdf_to_passive_wall']:.2f}x without the "
            f"reference TSDF), {passive['episode_to_passive_cpu']:.2f}x CPU "
            f"({passive['episode_without_reference_tsdf_to_passive_cpu']:.2f}x without it); "
            f"passive map "
            f"completion ratio {passive['mesh_metrics']['completion_ratio_pct']:.2f} %"
        )
    print(
        f"load average start {load_start[0]:.2f}, end {record['load_average_end'][0]:.2f} "
        f"on {os.cpu_count()} cores; written {json_path}"
    )
    return record


if __name__ == "__main__":
    main(parse_args())
