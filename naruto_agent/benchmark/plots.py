"""Benchmark plots: coverage and completion ratio against steps, top-down trajectories."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only; no display on servers and in workers
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from naruto_agent.benchmark.records import STATUS_OK  # noqa: E402

_COLOURS = plt.get_cmap("tab10")


def _ok_by_scene(records: list[dict[str, Any]]) -> dict[str, dict[str, list[dict[str, Any]]]]:
    grouped: dict[str, dict[str, list[dict[str, Any]]]] = defaultdict(lambda: defaultdict(list))
    for record in records:
        if record.get("status") == STATUS_OK:
            grouped[record["scene"]][record["policy"]].append(record)
    return grouped


def _policy_colours(records: list[dict[str, Any]]) -> dict[str, Any]:
    policies = sorted({record["policy"] for record in records})
    return {policy: _COLOURS(index % 10) for index, policy in enumerate(policies)}


def _mean_std_curves(curves: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Mean and std of curves of possibly different lengths (cut to the shortest)."""
    length = min(len(curve) for curve in curves)
    stack = np.stack([curve[:length] for curve in curves])
    return stack.mean(axis=0), stack.std(axis=0)


def plot_curves(records: list[dict[str, Any]], path: str | Path) -> Path | None:
    """Coverage (top row) and completion ratio (bottom row) against steps, a column per
    scene, a line per policy (mean over seeds, shaded +- std)."""
    grouped = _ok_by_scene(records)
    if not grouped:
        return None
    colours = _policy_colours(records)
    scenes = sorted(grouped)
    figure, axes = plt.subplots(
        2, len(scenes), figsize=(4.5 * len(scenes), 7), squeeze=False, sharex="col"
    )
    for column, scene in enumerate(scenes):
        top, bottom = axes[0, column], axes[1, column]
        for policy, members in sorted(grouped[scene].items()):
            colour = colours[policy]
            mean, std = _mean_std_curves(
                [100.0 * np.asarray(record["coverage_curve"], float) for record in members]
            )
            steps = np.arange(len(mean))
            top.plot(steps, mean, color=colour, label=f"{policy} (n={len(members)})")
            top.fill_between(steps, mean - std, mean + std, color=colour, alpha=0.2)
            points = [
                [(0, 0.0)]
                + [
                    (point["step"], point["completion_ratio_pct"])
                    for point in record.get("completion_curve", [])
                    if point.get("completion_ratio_pct") is not None
                ]
                for record in members
            ]
            if all(len(curve) > 1 for curve in points):
                length = min(len(curve) for curve in points)
                x = np.array([[p[0] for p in curve[:length]] for curve in points]).mean(axis=0)
                y = np.array([[p[1] for p in curve[:length]] for curve in points])
                bottom.errorbar(
                    x,
                    y.mean(axis=0),
                    yerr=y.std(axis=0),
                    color=colour,
                    marker="o",
                    capsize=3,
                    label=policy,
                )
        top.set_title(scene)
        top.set_ylabel("coverage (%)")
        bottom.set_ylabel("completion ratio @5 cm (%)")
        bottom.set_xlabel("step")
        top.grid(alpha=0.3)
        bottom.grid(alpha=0.3)
        top.legend(loc="lower right", fontsize=8)
    figure.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path


def _top_down_background(record: dict[str, Any]) -> tuple[np.ndarray, Any] | None:
    """A top-down picture of the record's scene and its world -> pixel mapping."""
    from naruto_gym.rendering.topdown import TopDownMap
    from naruto_gym.scenes.catalogue import resolve_scene
    from naruto_gym.sensors.raycaster import RayCaster

    config = record["config"]
    scene = resolve_scene(
        config["scene"], config.get("up_axis", "z"), config.get("mesh_units", "m")
    )
    top_down = TopDownMap(scene, RayCaster(scene.vertices, scene.faces))
    return top_down.image, top_down


def plot_trajectories(records: list[dict[str, Any]], out_dir: str | Path) -> list[Path]:
    """One figure per scene (``trajectories_<scene>.png``): a panel per policy with every
    seed's trajectory drawn over the scene seen from above."""
    grouped = _ok_by_scene(records)
    written = []
    for scene, by_policy in sorted(grouped.items()):
        first = next(iter(by_policy.values()))[0]
        image, top_down = _top_down_background(first)
        policies = sorted(by_policy)
        figure, axes = plt.subplots(
            1, len(policies), figsize=(4.2 * len(policies), 4.4), squeeze=False
        )
        for axis, policy in zip(axes[0], policies, strict=True):
            axis.imshow(image)
            for index, record in enumerate(sorted(by_policy[policy], key=lambda r: r["seed"])):
                positions = np.asarray(record["trajectory"], float)
                pixels = top_down.world_to_pixel(positions[:, :2])
                axis.plot(
                    pixels[:, 0],
                    pixels[:, 1],
                    color=_COLOURS(index % 10),
                    linewidth=1.0,
                    label=f"seed {record['seed']}",
                )
                axis.plot(*pixels[0], marker="o", color=_COLOURS(index % 10), markersize=4)
            coverage = np.mean([100.0 * r["coverage_final"] for r in by_policy[policy]])
            axis.set_title(f"{policy}: coverage {coverage:.1f} %", fontsize=10)
            axis.set_axis_off()
            axis.legend(loc="lower right", fontsize=7)
        figure.suptitle(scene)
        figure.tight_layout()
        path = Path(out_dir) / f"trajectories_{scene}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        figure.savefig(path, dpi=110)
        plt.close(figure)
        written.append(path)
    return written
