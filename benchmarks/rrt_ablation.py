"""The paper's Table 3, RRT against E-RRT. Results: docs/benchmarks/planning.md

RRT, E-RRT and its two ablations on the same start/goal pairs. NARUTO (Feng et al., CVPR 2024)
Table 3 reports, per planning request on Replica room0 (on a V100 GPU):

    RRT                 19 x 10^3 ms   19 x 10^3 nodes   28 x 10^3 iterations
    without direct line 17 x 10^3 ms   20 x 10^3 nodes   21 x 10^3 iterations
    without fast tree       16.00 ms       44.17 nodes        2.56 iterations
    E-RRT                    5.77 ms       16.70 nodes        1.19 iterations

This script plans with the four variants of ``naruto_agent.planning.plan_path`` (the same code
with the "direct line" and "fast tree" switches) on ground-truth SDF volumes (0.1 m voxels)
of the Replica office0 sample and of the shipped apartment scene, for the same seeded set of
start/goal pairs in free space. Goals: E-RRT at most 5.77 ms mean per request on the 2-core
CPU, and at least 1000x faster than plain RRT in the same run.

The slow variants run on the first ``--slow-pairs`` pairs of the same set (about 15 minutes
in all) and are capped (``--slow-time-limit-s`` per request). A capped request counts
as a failure with the cap as its time, so their means, and the speed-up over them, are lower
bounds; the output says how many requests hit the cap.

Times are wall-clock per request (what the paper reports), plus the planning thread's CPU
time: on a shared machine the wall time also counts waiting for a core, so the load average
before and after the run is printed and stored.

The free-space connectivity labelling (which makes unreachable goals fail at once) is built
once per map and shared by all requests, as an agent would; its cost is printed separately.

    python benchmarks/rrt_ablation.py
    python benchmarks/rrt_ablation.py --slow-pairs 0 --slow-time-limit-s 5  # all pairs, 5 s cap
"""

from __future__ import annotations

import json
import os
import platform
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from naruto_agent.cli_args import parse_dataclass_args
from naruto_agent.planning import FreeSpaceComponents, PlannerConfig, SdfVolume, plan_path

REPO = Path(__file__).resolve().parents[1]
REPLICA_MESH = REPO.parent / "shared" / "scenes" / "replica_office0" / "mesh.ply"
GOAL_MEAN_MS = 5.77
GOAL_SPEEDUP = 1000.0

# Paper rows: (time ms, nodes, iterations).
PAPER = {
    "RRT": (19e3, 19e3, 28e3),
    "without direct line": (17e3, 20e3, 21e3),
    "without fast tree": (16.00, 44.17, 2.56),
    "E-RRT": (5.77, 16.70, 1.19),
}
VARIANTS = {
    "RRT": dict(direct_line=False, fast_tree=False),
    "without direct line": dict(direct_line=False, fast_tree=True),
    "without fast tree": dict(direct_line=True, fast_tree=False),
    "E-RRT": dict(direct_line=True, fast_tree=True),
}
SLOW = {"RRT", "without direct line"}


@dataclass
class Args:
    pairs: int = 50
    """start/goal pairs per scene (the same for every variant)"""
    slow_pairs: int = 20
    """first pairs of the same set for the two slow variants (0: all)"""
    seed: int = 0
    """seed of the start/goal pairs"""
    scenes: str = "replica_office0,apartment"
    """comma-separated scenes: replica_office0 (the sample) and catalogue names"""
    voxel_size: float = 0.1
    """voxel size of the planner's SDF grid in metres"""
    min_clearance_m: float = 0.15
    """start and goal keep this SDF"""
    min_pair_distance_m: float = 1.0
    """straight-line distance between start and goal"""
    slow_time_limit_s: float = 20.0
    """cap per request for RRT and 'without direct line'"""
    time_limit_s: float = 5.0
    """cap per request for the fast variants"""
    max_iterations: int = 1_000_000
    """iteration cap per request"""
    device: str = "cpu"
    """nearest-neighbour search: cpu (numpy), auto, cuda"""
    variants: str = "RRT,without direct line,without fast tree,E-RRT"
    """comma-separated rows to run"""
    output_file: str = "benchmarks/results/rrt_ablation.json"
    """the JSON report"""


def parse_args() -> Args:
    return parse_dataclass_args(Args, description="NARUTO Table 3: RRT / E-RRT ablation")


def load_scene_sdf(name: str, voxel_size: float) -> tuple[SdfVolume, str] | None:
    """Ground-truth SDF of a benchmark scene, or None when its mesh is absent."""
    if name == "replica_office0":
        if not REPLICA_MESH.is_file():
            print(f"skipping replica_office0: {REPLICA_MESH} is absent")
            return None
        from naruto_gym.scenes.mesh_scene import load_scene

        scene, label = load_scene(REPLICA_MESH, up_axis="z"), "Replica office0 (sample)"
    else:
        from naruto_gym.scenes.catalogue import load_catalogue_scene

        scene, label = load_catalogue_scene(name), f"{name} (shipped, envs_assets)"
    return SdfVolume.from_mesh(scene, voxel_size=voxel_size, padding=0.2), label


def sample_pairs(
    sdf: SdfVolume, components: FreeSpaceComponents, args: Args
) -> np.ndarray:
    """(pairs, 2, 3) starts and goals: uniform in the volume, clear of obstacles, inside the
    largest free component (the building's interior), at least ``min_pair_distance_m`` apart."""
    rng = np.random.default_rng(args.seed)
    sizes = np.bincount(components.labels.ravel())
    sizes[0] = 0
    interior = int(np.argmax(sizes))
    bounds = sdf.bounds
    accepted: list[np.ndarray] = []
    while len(accepted) < 2 * args.pairs:
        points = rng.uniform(bounds[0], bounds[1], size=(4096, 3))
        clear = sdf.sample(points) >= args.min_clearance_m
        for point in points[clear]:
            if interior in components.labels_near(point):
                accepted.append(point)
    points = np.asarray(accepted)
    pairs = []
    index = 0
    while len(pairs) < args.pairs:
        start = points[index % len(points)]
        others = points[np.linalg.norm(points - start, axis=1) >= args.min_pair_distance_m]
        pairs.append((start, others[rng.integers(len(others))]))
        index += 1
    return np.asarray(pairs)


def run_variant(
    sdf: SdfVolume,
    components: FreeSpaceComponents,
    pairs: np.ndarray,
    name: str,
    args: Args,
) -> dict:
    limit = args.slow_time_limit_s if name in SLOW else args.time_limit_s
    records = []
    for index, (start, goal) in enumerate(tqdm(pairs, desc=f"  {name}", leave=False)):
        config = PlannerConfig(
            seed=args.seed * 100_003 + index,
            time_limit_s=limit,
            max_iterations=args.max_iterations,
            device=args.device,
            **VARIANTS[name],
        )
        cpu_began = time.thread_time()
        result = plan_path(sdf, start, goal, config, components=components)
        cpu_ms = (time.thread_time() - cpu_began) * 1e3
        records.append(
            dict(
                time_ms=result.time_ms,
                cpu_ms=cpu_ms,
                nodes=result.nodes,
                iterations=result.iterations,
                success=result.success,
                capped="limit" in result.reason,
                reason=result.reason,
                path_length_m=float(np.linalg.norm(np.diff(result.path, axis=0), axis=1).sum())
                if result.success
                else None,
            )
        )
    times = np.array([r["time_ms"] for r in records])
    return dict(
        variant=name,
        requests=len(records),
        time_limit_s=limit,
        mean_ms=float(times.mean()),
        median_ms=float(np.median(times)),
        mean_cpu_ms=float(np.mean([r["cpu_ms"] for r in records])),
        p90_ms=float(np.percentile(times, 90)),
        max_ms=float(times.max()),
        mean_nodes=float(np.mean([r["nodes"] for r in records])),
        mean_iterations=float(np.mean([r["iterations"] for r in records])),
        success_rate=float(np.mean([r["success"] for r in records])),
        capped=int(sum(r["capped"] for r in records)),
        records=records,
    )


def plot_scene(
    sdf: SdfVolume,
    components: FreeSpaceComponents,
    pair: np.ndarray,
    rows: list[dict],
    label: str,
    path: Path,
    args: Args,
) -> None:
    """Mean time per variant beside the paper's, and the RRT and E-RRT trees of one pair."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, 3, figsize=(17, 5.2))
    names = [row["variant"] for row in rows]
    position = np.arange(len(names))
    axes[0].bar(position - 0.2, [row["mean_ms"] for row in rows], 0.4,
                label="this run (2-core CPU)")
    axes[0].bar(position + 0.2, [PAPER[name][0] for name in names], 0.4,
                label="paper (V100, Replica room0)")
    axes[0].set_yscale("log")
    axes[0].set_xticks(position, names, rotation=15)
    axes[0].set_ylabel("mean planning time per request (ms)")
    axes[0].set_title(label)
    axes[0].legend()
    start, goal = pair
    level = int(round((start[2] - sdf.origin[2]) / sdf.voxel_size))
    level = int(np.clip(level, 0, sdf.shape[2] - 1))
    extent = (sdf.bounds[0, 0], sdf.bounds[1, 0], sdf.bounds[0, 1], sdf.bounds[1, 1])
    for axis, name in zip(axes[1:], ["RRT", "E-RRT"], strict=True):
        config = PlannerConfig(seed=0, time_limit_s=args.slow_time_limit_s, device=args.device,
                               max_iterations=args.max_iterations, **VARIANTS[name])
        result = plan_path(sdf, start, goal, config, components=components)
        axis.imshow(sdf.values[:, :, level].T > PlannerConfig().clearance_m, origin="lower",
                    extent=extent, cmap="gray", vmin=-0.5, vmax=1.5)
        # At most 8000 nodes drawn: enough to show the coverage, small enough a PNG.
        shown = result.tree[:: max(1, len(result.tree) // 8000)]
        axis.scatter(shown[:, 0], shown[:, 1], s=1, c="tab:blue", alpha=0.4,
                     label=f"tree ({result.nodes} nodes)")
        if result.success:
            axis.plot(result.path[:, 0], result.path[:, 1], c="tab:orange", lw=2, label="path")
        axis.scatter(*start[:2], c="tab:green", s=60, marker="o", label="start")
        axis.scatter(*goal[:2], c="tab:red", s=80, marker="*", label="goal")
        axis.set_title(f"{name}: {result.time_ms:.1f} ms, {result.iterations} iterations, "
                       f"{result.reason}", fontsize=9)
        axis.set_xlabel("x (m), top view; free space (light) at the start's height")
        axis.set_ylabel("y (m)")
        axis.legend(loc="upper right", fontsize=7)
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=90)
    plt.close(figure)


def fmt(value: float) -> str:
    if value >= 1000:
        return f"{value / 1000:.1f} x 10^3"
    return f"{value:.2f}"


def markdown_table(label: str, rows: list[dict]) -> str:
    lines = [
        f"**{label}**",
        "",
        "| variant | requests | mean (ms) | median (ms) | mean CPU (ms) | nodes | iterations "
        "| success | capped | paper: ms / nodes / iterations |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        paper = " / ".join(fmt(v) for v in PAPER[row["variant"]])
        bound = ">= " if row["capped"] else ""
        lines.append(
            f"| {row['variant']} | {row['requests']} | {bound}{fmt(row['mean_ms'])} "
            f"| {bound}{fmt(row['median_ms'])} | {bound}{fmt(row['mean_cpu_ms'])} "
            f"| {fmt(row['mean_nodes'])} "
            f"| {fmt(row['mean_iterations'])} | {100 * row['success_rate']:.0f} % "
            f"| {row['capped']} (cap {row['time_limit_s']:g} s) | {paper} |"
        )
    return "\n".join(lines)


def main() -> None:
    args = parse_args()
    print(f"NARUTO Table 3 ablation on {platform.processor() or platform.machine()}, "
          f"{args.pairs} pairs per scene, device={args.device}")
    # Other work on the machine slows every row alike; the load average is kept as context.
    load_before = os.getloadavg()
    print(f"cpus {os.cpu_count()}, load average {load_before[0]:.2f} before the run")
    output: dict = dict(args=asdict(args), paper=PAPER, scenes=[], cpus=os.cpu_count(),
                        load_average_before=load_before)
    tables = []
    for scene_name in [name.strip() for name in args.scenes.split(",") if name.strip()]:
        began = time.perf_counter()
        loaded = load_scene_sdf(scene_name, args.voxel_size)
        if loaded is None:
            continue
        sdf, label = loaded
        sdf_s = time.perf_counter() - began
        clearance = PlannerConfig().clearance_m
        began = time.perf_counter()
        for _ in range(5):
            components = FreeSpaceComponents.from_sdf(sdf, clearance)
        components_ms = (time.perf_counter() - began) / 5 * 1e3
        pairs = sample_pairs(sdf, components, args)
        print(f"\n{label}: SDF {sdf.shape} voxels built in {sdf_s:.1f} s; connectivity "
              f"labelling {components_ms:.2f} ms per map (shared by all requests, not in "
              "the per-request times)")
        # Warm-up: first-call costs (imports, allocator) are not planning time.
        plan_path(sdf, pairs[0, 0], pairs[0, 1], PlannerConfig(device=args.device),
                  components=components)
        rows = []
        chosen = [name.strip() for name in args.variants.split(",") if name.strip()]
        unknown = sorted(set(chosen) - set(VARIANTS))
        if unknown or "E-RRT" not in chosen:
            raise SystemExit(f"--variants must include E-RRT and name only {list(VARIANTS)}")
        for name in [name for name in VARIANTS if name in chosen]:
            subset = pairs
            if name in SLOW and args.slow_pairs > 0:
                subset = pairs[: args.slow_pairs]
            row = run_variant(sdf, components, subset, name, args)
            rows.append(row)
            print(f"  {name:20s} mean {row['mean_ms']:10.2f} ms (CPU {row['mean_cpu_ms']:9.2f} ms)"
                  f"  median {row['median_ms']:9.2f}"
                  f" ms  nodes {row['mean_nodes']:9.1f}  iterations {row['mean_iterations']:9.1f}"
                  f"  success {100 * row['success_rate']:5.1f} %  capped {row['capped']}")
        by_name = {row["variant"]: row for row in rows}
        e_rrt, rrt = by_name["E-RRT"], by_name.get("RRT")
        summary = (
            f"E-RRT mean {e_rrt['mean_ms']:.2f} ms wall, {e_rrt['mean_cpu_ms']:.2f} ms CPU "
            f"(goal <= {GOAL_MEAN_MS} ms wall: "
            f"{'met' if e_rrt['mean_ms'] <= GOAL_MEAN_MS else 'NOT met'})"
        )
        speedup = None
        if rrt is not None:
            # Compare on the pairs both ran (the slow rows may use a prefix of the pair set).
            shared = rrt["requests"]
            e_rrt_shared_ms = float(np.mean([r["time_ms"] for r in e_rrt["records"][:shared]]))
            speedup = rrt["mean_ms"] / e_rrt_shared_ms
            lower = " (lower bound: capped RRT requests)" if rrt["capped"] else ""
            summary += (
                f"; {speedup:,.0f}x faster than RRT on the same {shared} pairs{lower} "
                f"(goal >= {GOAL_SPEEDUP:,.0f}x: "
                f"{'met' if speedup >= GOAL_SPEEDUP else 'NOT met'})"
            )
        print("  " + summary)
        if rrt is not None:
            plot_path = (REPO / args.output_file).with_name(f"rrt_ablation_{scene_name}.png")
            # The pair with the longest E-RRT search shows the difference best.
            hardest = int(np.argmax([r["iterations"] for r in e_rrt["records"]]))
            plot_scene(sdf, components, pairs[hardest], rows, label, plot_path, args)
            print(f"  plot: {plot_path}")
        table = markdown_table(label, rows) + "\n\n" + summary + "\n"
        tables.append(table)
        output["scenes"].append(
            dict(
                scene=scene_name,
                label=label,
                sdf_shape=list(sdf.shape),
                sdf_build_s=sdf_s,
                connectivity_ms_per_map=components_ms,
                pairs=pairs.tolist(),
                rows=rows,
                e_rrt_speedup_over_rrt=speedup,
                speedup_is_lower_bound=bool(rrt["capped"]) if rrt is not None else None,
                e_rrt_goal_met=e_rrt["mean_ms"] <= GOAL_MEAN_MS,
            )
        )
    output["load_average_after"] = os.getloadavg()
    print(f"load average {output['load_average_after'][0]:.2f} after the run")
    print("\n" + "\n".join(tables))
    out = REPO / args.output_file
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(output, indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
