"""The demo's files: mesh, metrics, curves, the trajectory picture and the animated GIF.

Every writer takes what the episode produced (:class:`naruto_agent.demo.episode.Episode`) and a
path, and returns the path it wrote; :func:`write_all` writes them all into one folder.
"""

from __future__ import annotations

import csv
import json
import os
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only: no display on servers
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from PIL import Image, ImageDraw  # noqa: E402

from naruto_agent.demo.episode import Episode  # noqa: E402

#: Metrics of the final score copied to the top level of ``metrics.json``.
SCORE_KEYS = (
    "accuracy_cm",
    "completion_cm",
    "completion_ratio_pct",
    "observable_completion_ratio_pct",
    "observable_completion_cm",
    "precision_pct",
    "fscore_pct",
)
CURVE_COLUMNS = (
    "step",
    "coverage_pct",
    "completion_ratio_pct",
    "observable_completion_ratio_pct",
    "completion_cm",
    "accuracy_cm",
)
#: What the whole-surface completion figures count, printed beside them: the observable ones
#: are those to read, as no camera inside a room sees the outer faces of its walls.
WHOLE_SURFACE_NOTE = (
    "counts every face of the mesh, the outer faces of walls and other sides no camera "
    "inside can see included"
)
#: How long the GIF shows each frame, and its last one (milliseconds).
GIF_FRAME_MS = 120
GIF_LAST_FRAME_MS = 2000


def metrics_record(
    args: dict[str, Any],
    episode: Episode,
    final: dict[str, Any] | None,
    seconds: dict[str, float],
    load_average: list[tuple[float, float, float]],
) -> dict[str, Any]:
    """The JSON-able record of the episode: scores at the top, then how it was obtained.

    Args:
        args: the demo's settings.
        episode: what the episode produced.
        final: the final metrics of the episode's mesh (None when it had nothing to score).
        seconds: wall time of the episode loop and of the final evaluation.
        load_average: the machine's load averages at the start and the end.
    """
    steps = max(episode.steps_run, 1)
    per_step = {phase: 1000.0 * total / steps for phase, total in episode.times_s.items()}
    # What one step of the agent costs: its decision, the env and any reference fusion.
    per_step["total"] = sum(per_step[phase] for phase in ("policy", "env", "mapping"))
    scores = {key: (final or {}).get(key) for key in SCORE_KEYS}
    return {
        "policy": args["policy"],
        "scene": args["scene"],
        "seed": args["seed"],
        "steps": episode.steps_run,
        "image_size": list(episode.camera_size),
        **scores,
        "coverage_pct": 100.0 * episode.coverage[-1],
        "path_length_m": episode.path_length_m,
        "collisions": int(sum(episode.collisions.values())),
        "collision_reasons": dict(episode.collisions),
        "stalled_steps": episode.stalled_steps,
        "stall_recoveries": episode.stall_recoveries,
        "goals_chosen": len(episode.goals),
        "time_per_step_ms": per_step,
        "policy_time_per_step_ms": {
            phase: 1000.0 * total / steps for phase, total in episode.policy_detail_s.items()
        },
        "map": episode.map_source,
        "mesh_faces": int(len(episode.mesh.faces)),
        "evaluation": {
            "samples": args["eval_samples"],
            "threshold_m": (final or {}).get("threshold_m"),
            "faces_evaluated": (final or {}).get("faces_evaluated"),
            "note": (final or {}).get("note", "the reconstruction was empty: nothing scored"),
            "checkpoint_samples": args["checkpoint_samples"],
        },
        "seconds": dict(seconds),
        "load_average": {"start": list(load_average[0]), "end": list(load_average[1])},
        "cpu_count": os.cpu_count(),
        "args": args,
    }


def write_metrics(path: Path, metrics: dict[str, Any]) -> Path:
    """``metrics.json``."""
    path.write_text(json.dumps(metrics, indent=2))
    return path


def write_mesh(path: Path, episode: Episode) -> Path:
    """The reconstruction as a binary PLY (with vertex colours when the map has them)."""
    episode.mesh.export(path)
    return path


def curve_rows(episode: Episode) -> list[dict[str, Any]]:
    """One row per step: coverage (%) always, the completion scores at the evaluation points."""
    scored = {point["step"]: point for point in episode.completion_curve}
    rows = []
    for step, coverage in enumerate(episode.coverage):
        point = scored.get(step, {})
        row = {"step": step, "coverage_pct": round(100.0 * coverage, 4)}
        row.update({key: point.get(key) for key in CURVE_COLUMNS[2:]})
        rows.append(row)
    return rows


def write_curves(
    folder: Path, episode: Episode, title: str, metrics: dict[str, Any] | None = None
) -> list[Path]:
    """``curves.csv`` (a row per step; completion columns filled at the evaluation points only) and
    ``curves.png`` (coverage, and the completion ratios at the evaluation points, with the final
    full-protocol scores of ``metrics`` as stars)."""
    rows = curve_rows(episode)
    csv_path = folder / "curves.csv"
    with open(csv_path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=CURVE_COLUMNS)
        writer.writeheader()
        for row in rows:
            writer.writerow({key: "" if value is None else value for key, value in row.items()})

    figure, (left, right) = plt.subplots(1, 2, figsize=(10, 3.8))
    left.plot([row["step"] for row in rows], [row["coverage_pct"] for row in rows])
    left.set_ylabel("coverage of the observable surface (%)")
    left.set_title("coverage")
    points = [p for p in episode.completion_curve if p.get("completion_ratio_pct") is not None]
    steps = [p["step"] for p in points]
    for key, label in (
        ("observable_completion_ratio_pct", "observable surface"),
        ("completion_ratio_pct", "whole surface"),
    ):
        values = [p.get(key) for p in points]
        if values and all(value is not None for value in values):
            line = right.plot(steps, values, marker="o", label=f"{label}, evaluation points")[0]
            final = (metrics or {}).get(key)
            if final is not None:
                right.plot(
                    episode.steps_run,
                    final,
                    marker="*",
                    markersize=14,
                    color=line.get_color(),
                    markeredgecolor="black",
                    linestyle="none",
                    label=f"{label}, final: {final:.1f} %",
                )
    right.set_ylabel("completion ratio @5 cm (%)")
    right.set_title("completion of the map")
    if metrics is not None:
        right.set_title(
            f"completion of the map\n(evaluation points: "
            f"{metrics['evaluation']['checkpoint_samples']:,} samples; final: "
            f"{metrics['evaluation']['samples']:,})",
            fontsize=10,
        )
    if points:
        right.legend(loc="lower right", fontsize=7)
    for axis in (left, right):
        axis.set_xlabel("step")
        axis.set_ylim(0, 100)
        axis.set_xlim(0, 1.04 * max(len(rows) - 1, 1))  # room for the final stars
        axis.grid(alpha=0.3)
    figure.suptitle(title)
    figure.tight_layout()
    png_path = folder / "curves.png"
    figure.savefig(png_path, dpi=110)
    plt.close(figure)
    return [csv_path, png_path]


def write_trajectory(path: Path, episode: Episode, env: Any, title: str) -> Path:
    """The trajectory (coloured by step) and the chosen goals on the scene's top-down map."""
    from naruto_gym.rendering.topdown import TopDownMap

    top_down = TopDownMap(env.scene, env.raycaster)
    positions = episode.poses[:, :3, 3]
    pixels = top_down.world_to_pixel(positions[:, :2])
    figure, axis = plt.subplots(figsize=(7, 6.2))
    axis.imshow(top_down.image)
    if len(pixels) > 1:
        segments = np.stack([pixels[:-1], pixels[1:]], axis=1)
        lines = LineCollection(segments, cmap="plasma", linewidths=1.6)
        lines.set_array(np.arange(1, len(pixels)))
        axis.add_collection(lines)
        figure.colorbar(lines, ax=axis, fraction=0.04, pad=0.02, label="step")
    axis.plot(*pixels[0], "o", color="lime", markeredgecolor="black", label="start")
    axis.plot(*pixels[-1], "s", color="red", markeredgecolor="black", label="end", zorder=4)
    if len(episode.goals):
        goal_pixels = top_down.world_to_pixel(episode.goals[:, :2])
        axis.scatter(
            goal_pixels[:, 0],
            goal_pixels[:, 1],
            marker="*",
            s=120,
            c="white",
            edgecolors="black",
            zorder=3,
            label=f"goals chosen ({len(goal_pixels)})",
        )
    axis.set_title(
        f"{title}\npath {episode.path_length_m:.1f} m, coverage {100 * episode.coverage[-1]:.1f} %",
        fontsize=10,
    )
    # Below the map, so that it hides no part of the path.
    axis.legend(loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=3, fontsize=8)
    axis.set_axis_off()
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path


def write_gif(path: Path, episode: Episode) -> Path | None:
    """The subsampled ``rgb_array`` frames as a looping GIF, each labelled with its step and
    coverage; None when the episode kept no frames."""
    if not episode.frames:
        return None
    pictures = []
    for step, frame in episode.frames:
        picture = Image.fromarray(frame)
        label = f"step {step}  coverage {100 * episode.coverage[step]:.1f} %"
        draw = ImageDraw.Draw(picture)
        draw.rectangle([0, 0, 8 + 6 * len(label), 16], fill=(0, 0, 0))
        draw.text((4, 3), label, fill=(255, 255, 255))
        # One adaptive palette per frame: the map's colours stay faithful.
        pictures.append(picture.quantize(colors=128))
    durations = [GIF_FRAME_MS] * (len(pictures) - 1) + [GIF_LAST_FRAME_MS]
    pictures[0].save(path, save_all=True, append_images=pictures[1:], duration=durations, loop=0)
    return path


def write_all(
    folder: Path, episode: Episode, metrics: dict[str, Any], env: Any, title: str
) -> list[Path]:
    """Mesh, curves, trajectory picture and GIF into ``folder`` (metrics are written last,
    by the caller, once every output is listed)."""
    written = [write_mesh(folder / "reconstruction.ply", episode)]
    written += write_curves(folder, episode, title, metrics)
    written.append(write_trajectory(folder / "trajectory.png", episode, env, title))
    gif = write_gif(folder / "episode.gif", episode)
    if gif is not None:
        written.append(gif)
    return written


def summary_text(metrics: dict[str, Any], folder: Path) -> str:
    """What the demo prints at the end."""

    def number(key: str, unit: str, digits: int = 2) -> str:
        value = metrics.get(key)
        return "n/a" if value is None else f"{value:.{digits}f} {unit}"

    height, width = metrics["image_size"]
    times = metrics["time_per_step_ms"]
    phases = ", ".join(f"{phase} {times[phase]:.0f}" for phase in ("policy", "env", "mapping"))
    return "\n".join(
        [
            f"{metrics['policy']} on {metrics['scene']}, seed {metrics['seed']}: "
            f"{metrics['steps']} steps, {height} x {width} (H x W) frames",
            f"  observable completion ratio {number('observable_completion_ratio_pct', '%')} "
            f"| observable completion {number('observable_completion_cm', 'cm')} "
            f"(of the surface a camera inside the scene can see)",
            f"  whole-surface completion ratio {number('completion_ratio_pct', '%')} "
            f"| whole-surface completion {number('completion_cm', 'cm')}: {WHOLE_SURFACE_NOTE}",
            f"  map: {metrics['map']}, {metrics['mesh_faces']:,} faces | accuracy "
            f"{number('accuracy_cm', 'cm')} (its surface to the ground truth)",
            f"  coverage {metrics['coverage_pct']:.2f} % | path length "
            f"{metrics['path_length_m']:.2f} m | collisions {metrics['collisions']} | time "
            f"per step {times['total']:.0f} ms ({phases})",
            f"  {metrics['seconds'].get('total', 0.0):.0f} s in all: episode "
            f"{metrics['seconds']['episode']:.0f} s, scoring "
            f"{metrics['seconds']['evaluation']:.0f} s, outputs "
            f"{metrics['seconds'].get('outputs', 0.0):.0f} s; load average "
            f"{metrics['load_average']['start'][0]:.1f} -> {metrics['load_average']['end'][0]:.1f} "
            f"on {metrics['cpu_count']} cores",
            f"  written to {folder}: {', '.join(metrics.get('outputs', []))}",
        ]
    )
