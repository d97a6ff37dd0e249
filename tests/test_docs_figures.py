"""Every headline figure of the README and the benchmarks index agrees with the result file it
comes from: a figure that drifts from its source fails here, naming page, source and value.

Each row of FIGURES is (page, pattern, source, key, format):

- ``pattern``: a regular expression whose first group is the figure as the page prints it;
- ``source``: a file under ``benchmarks/results/`` (JSON), or a generated page (Markdown);
- ``key``: for JSON, the path to the value: names joined by dots, ``[2]`` for a list index,
  ``[name=value]`` (or ``[a=x,b=y]``) for the list item whose fields have those values; for
  Markdown, a regular expression whose first group is the figure there;
- ``format``: how the page prints the value, a ``str.format`` pattern (``{:,.0f}``); a value
  that is a dict (a mean with its spread) is formatted by its keys (``{mean:.1f} ± {std:.1f}``).
  ``scale`` multiplies a number before formatting (seconds to minutes).
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
RESULTS = "benchmarks/results"


@dataclass(frozen=True)
class Figure:
    """One printed figure and where it comes from (see the module docstring)."""

    page: str
    pattern: str
    source: str
    key: str
    format: str = "{}"
    scale: float = 1.0

    @property
    def id(self) -> str:
        return f"{self.page}:{self.source}:{self.key[:60]}"


_README = "README.md"
_INDEX = "docs/benchmarks/index.md"
_RENDER = f"{RESULTS}/render_speed.json"
_RRT = f"{RESULTS}/rrt_ablation_fast_rows.json"
_NEURAL = f"{RESULTS}/naruto_neural_office0/naruto_episode_office0_neural_2000steps.json"
_MAPPING = f"{RESULTS}/mapping_quality_neural_2000frames.json"
_VECTOR = f"{RESULTS}/vector_throughput.json"
_PPO = f"{RESULTS}/ppo_rooms_map"
_GPU_ITERATION = f"{RESULTS}/gpu_h200/mapping_iteration.json"
_GPU_EPISODE = f"{RESULTS}/gpu_h200/naruto_episode_office0_neural_triton_400steps.json"
_GPU_SCALING = f"{RESULTS}/gpu_h200/vector_scaling_16cpu.json"
_EXPLORER = f"{RESULTS}/explorer_candidates"
_EXPLORER_PAGE = "docs/benchmarks/explorer.md"
_OPEN_SCANS_PAGE = "docs/benchmarks/open-scans.md"
_BOARD = "docs/benchmarks/leaderboard.md"  # generated from the suite run's folder
_MEAN_STD = "{mean:.1f} ± {std:.1f}"
_ROOM = "rows[scene=replica_like_room]"
_ERRT = "rows[variant=E-RRT].mean_ms"


def _board(section: str, policy: str, interval: bool = True) -> str:
    """The AUC-steps cell of a policy's row in a section of the leaderboard page: the mean
    and its interval, or the mean alone."""
    cell = r"([\d.]+ \[[\d.]+, [\d.]+\])" if interval else r"([\d.]+) \["
    return rf"(?s)\n## {re.escape(section)}\n.*?\n\| {policy} \| \d+ \| \d+ \| [^|]+ \| {cell}"


def _readme_board(lead: str, section: str, policy: str, interval: bool = True) -> Figure:
    """The README's AUC-steps figure of ``policy`` printed after ``lead`` (a regular
    expression), against its cell in ``section`` of the leaderboard page."""
    cell = r"([\d.]+ \[[\d.]+, [\d.]+\])" if interval else r"([\d.]+)"
    return Figure(_README, f"{lead} {cell}", _BOARD, _board(section, policy, interval))


def _explorer_figures(label: str, result: str) -> tuple[Figure, ...]:
    """The explorer page's table row ``label`` (final coverage / area for each policy, the
    paired differences with their intervals) against ``evaluation_{result}.json``."""
    source = f"{_EXPLORER}/evaluation_{result}.json"
    row = rf"\| {re.escape(label)} \| "
    number = r"[-+\d.]+"
    cells = [
        (rf"{row}([\d.]+) / ", "table.explorer.mean_final", "{:.1f}", 100.0),
        (rf"{row}[\d.]+ / ([\d.]+) \|", "table.explorer.mean_auc", "{:.3f}", 1.0),
        (
            rf"{row}(?:[^|]*\| ){{3}}\**\+([\d.]+)",
            "paired.frontier.mean_auc_difference",
            "{:.3f}",
            1.0,
        ),
        (
            rf"{row}(?:[^|]*\| ){{3}}[^[]*\[({number}),",
            "paired.frontier.interval_95[0]",
            "{:.3f}",
            1.0,
        ),
        (
            rf"{row}(?:[^|]*\| ){{4}}\**\+([\d.]+)",
            "paired.random.mean_auc_difference",
            "{:.3f}",
            1.0,
        ),
    ]
    return tuple(
        Figure(_EXPLORER_PAGE, pattern, source, key, fmt, scale)
        for pattern, key, fmt, scale in cells
    )


def _escape_timing_figures() -> tuple[Figure, ...]:
    """The open-scans page's table of what the escape check costs per move, against
    ``open_scans/escape_timing.json``."""
    source = f"{RESULTS}/open_scans/escape_timing.json"
    cells = [
        (r"\| published \(a 32 x 64 panorama every move\) \| (\d+) µs", "published_escape_us"),
        (r"lattice not yet filled around the agent \| (\d+) µs", "scanned_space_cold_escape_us"),
        (r"lattice known around the agent \| \*\*(\d+) µs", "scanned_space_warm_escape_us"),
    ]
    rows = [Figure(_OPEN_SCANS_PAGE, pattern, source, key, "{:.0f}") for pattern, key in cells]
    ratio = Figure(
        _OPEN_SCANS_PAGE,
        r"\(([\d.]+)x less than published\)",
        source,
        "published_over_scanned_warm_escape",
        "{:.1f}",
    )
    return (*rows, ratio)


FIGURES: tuple[Figure, ...] = (
    # README: headline results
    Figure(
        _README, r"\| ([\d.]+) ms rasterized", _RENDER, f"{_ROOM}.raster_rgbd_frame_ms", "{:.1f}"
    ),
    Figure(
        _README, r"rasterized, ([\d.]+) ms ray-cast", _RENDER, f"{_ROOM}.rgbd_frame_ms", "{:.1f}"
    ),
    Figure(
        _README, r"bare Open3D cast: ([\d.]+) ms", _RENDER, f"{_ROOM}.bare_open3d_cast_ms", "{:.1f}"
    ),
    Figure(
        _README,
        r"Replica sample\) \| ([\d.]+) s \|",
        f"{RESULTS}/metrics_speed.json",
        "metrics_mesh_to_mesh_s",
        "{:.2f}",
    ),
    Figure(
        _README,
        r"\| ([\d.]+) ms / [\d.]+ ms mean",
        _RRT,
        f"scenes[scene=replica_office0].{_ERRT}",
        "{:.2f}",
    ),
    Figure(
        _README,
        r"\| [\d.]+ ms / ([\d.]+) ms mean",
        _RRT,
        f"scenes[scene=apartment].{_ERRT}",
        "{:.2f}",
    ),
    Figure(
        _README,
        r"\| (\d+) ms per iteration",
        _MAPPING,
        "variants.neural.ms_per_iteration",
        "{:.0f}",
    ),
    Figure(
        _README,
        r"per iteration, ([\d.]+) min for 2000 frames",
        _MAPPING,
        "variants.neural.mapping_s",
        "{:.1f}",
        1 / 60,
    ),
    Figure(
        _README,
        r"own mesh ([\d.]+) cm accuracy",
        _NEURAL,
        "agent_mesh_metrics.accuracy_cm",
        "{:.2f}",
    ),
    Figure(
        _README,
        r"accuracy, ([\d.]+) cm completion",
        _NEURAL,
        "agent_mesh_metrics.completion_cm",
        "{:.2f}",
    ),
    Figure(
        _README,
        r"completion, ([\d.]+) % completion ratio \(published",
        _NEURAL,
        "agent_mesh_metrics.completion_ratio_pct",
        "{:.2f}",
    ),
    Figure(
        _README,
        r"([\d.]+)x the time of passively mapping",
        _NEURAL,
        "passive_reference.episode_to_passive_wall",
        "{:.2f}",
    ),
    Figure(
        _README,
        r"`apartment`, 5000 steps, 3 seeds \| NARUTO ([\d.]+ ± [\d.]+) %",
        f"{RESULTS}/apartment_5000/summary.json",
        "rows[policy=naruto].metrics.observable_completion_ratio_pct",
        _MEAN_STD,
    ),
    Figure(
        _README,
        r"`apartment`, 5000 steps.*?frontier ([\d.]+ ± [\d.]+)",
        f"{RESULTS}/apartment_5000/summary.json",
        "rows[policy=frontier].metrics.observable_completion_ratio_pct",
        _MEAN_STD,
    ),
    Figure(
        _README,
        r"2000 steps, 3 seeds \| random ([\d.]+ ± [\d.]+) %",
        f"{RESULTS}/replica_2000/summary.json",
        "rows[policy=random].metrics.completion_ratio_pct",
        _MEAN_STD,
    ),
    Figure(
        _README,
        r"2000 steps, 3 seeds \|.*?NARUTO ([\d.]+ ± [\d.]+)",
        f"{RESULTS}/replica_2000/summary.json",
        "rows[policy=naruto].metrics.completion_ratio_pct",
        _MEAN_STD,
    ),
    _readme_board(r"small: explorer \(map-and-goal\)", "small", "explorer"),
    _readme_board(r"small: [^;]*?NARUTO", "small", "naruto"),
    _readme_board(r"small: [^;]*?frontier", "small", "frontier", interval=False),
    _readme_board(r"flats: explorer", "flat", "explorer"),
    _readme_board(r"flats: [^;]*?NARUTO", "flat", "naruto"),
    _readme_board(r"flats: [^;]*?frontier", "flat", "frontier", interval=False),
    _readme_board(r"houses: [^;]*?NARUTO", "house", "naruto"),
    _readme_board(r"houses: [^;]*?explorer", "house", "explorer"),
    _readme_board(r"external [^:]*: NARUTO", "external", "naruto"),
    _readme_board(r"external [^;]*?explorer", "external", "explorer", interval=False),
    Figure(
        _README,
        r"first in small \(([\d.]+)\)",
        _BOARD,
        _board("small (open)", "explorer", False),
    ),
    Figure(
        _README,
        r"and flats \(([\d.]+)\)",
        _BOARD,
        _board("flat (open)", "explorer", False),
    ),
    Figure(
        _README,
        r"no panorama \| ([\d,]+) steps/s \|",
        _VECTOR,
        "goals.single_env_auto_frames_steps_per_s",
        "{:,.0f}",
    ),
    Figure(
        _README,
        r"\| ([\d,]+) / [\d,]+ steps/s",
        _VECTOR,
        "goals.batched_64_envs_steps_per_s",
        "{:,.0f}",
    ),
    Figure(
        _README,
        r"\| [\d,]+ / ([\d,]+) steps/s",
        _VECTOR,
        "scaling.points[cores=2].batched_default_steps_per_s",
        "{:,.0f}",
    ),
    Figure(
        _README,
        r"steps/s, ([\d.]+)x / [\d.]+x the best",
        _VECTOR,
        "goals.ratio_vs_best_async",
        "{:.1f}",
    ),
    Figure(
        _README,
        r"steps/s, [\d.]+x / ([\d.]+)x the best",
        _VECTOR,
        "scaling.points[cores=2].ratio_default_vs_best_async",
        "{:.1f}",
    ),
    Figure(
        _README,
        r"top-down map, ([\d.]+) M steps",
        f"{_PPO}/summary.json",
        "timesteps",
        "{:.2f}",
        1e-6,
    ),
    Figure(_README, r"M steps in ([\d.]+) h", f"{_PPO}/summary.json", "hours", "{:.1f}"),
    Figure(
        _README,
        r"\| ([\d.]+) / [\d.]+ / [\d.]+ % coverage in 250",
        f"{_PPO}/evaluation_summary.json",
        "rows[scene=procedural_room_1000000,policy=PPOExplorer].coverage_pct.mean",
        "{:.1f}",
    ),
    # The benchmarks index: one headline per page
    Figure(
        _INDEX,
        r"raster RGB-D frame ([\d.]+)-[\d.]+x faster",
        _RENDER,
        "rows[scene=replica_office0].raster_speedup_vs_bare",
        "{:.1f}",
    ),
    Figure(
        _INDEX,
        r"raster RGB-D frame [\d.]+-([\d.]+)x faster",
        _RENDER,
        f"{_ROOM}.raster_speedup_vs_bare",
        "{:.1f}",
    ),
    Figure(
        _INDEX,
        r"200k-sample metrics in ([\d.]+) s",
        f"{RESULTS}/metrics_speed.json",
        "metrics_mesh_to_mesh_s",
        "{:.2f}",
    ),
    Figure(
        _INDEX,
        r"culling (\d+)x the per-pose loop",
        f"{RESULTS}/culling_speed_apartment.json",
        "cull_reference_over_fast",
        "{:.0f}",
    ),
    Figure(
        _INDEX,
        r"E-RRT ([\d.]+) ms \(Replica\)",
        _RRT,
        f"scenes[scene=replica_office0].{_ERRT}",
        "{:.2f}",
    ),
    Figure(
        _INDEX, r"and ([\d.]+) ms \(apartment\)", _RRT, f"scenes[scene=apartment].{_ERRT}", "{:.2f}"
    ),
    Figure(
        _INDEX,
        r"(\d+) ms per neural mapping iteration",
        _MAPPING,
        "variants.neural.ms_per_iteration",
        "{:.0f}",
    ),
    Figure(
        _INDEX,
        r"Replica: ([\d.]+) % completion ratio",
        _NEURAL,
        "agent_mesh_metrics.completion_ratio_pct",
        "{:.2f}",
    ),
    Figure(
        _INDEX,
        r"([\d.]+)x the passive mapping's time",
        _NEURAL,
        "passive_reference.episode_to_passive_wall",
        "{:.2f}",
    ),
    Figure(
        _INDEX,
        r"([\d,]+) steps/s with 64 agents",
        _VECTOR,
        "goals.batched_64_envs_steps_per_s",
        "{:,.0f}",
    ),
    Figure(
        _INDEX, r"64 agents, ([\d.]+)x the best", _VECTOR, "goals.ratio_vs_best_async", "{:.2f}"
    ),
    Figure(
        _INDEX, r"([\d.]+) M steps in [\d.]+ h", f"{_PPO}/summary.json", "timesteps", "{:.2f}", 1e-6
    ),
    Figure(
        _INDEX,
        r"; ([\d.]+)-[\d.]+ % coverage in 250 steps",
        f"{_PPO}/evaluation_summary.json",
        "rows[scene=replica_like_room,policy=PPOExplorer].coverage_pct.mean",
        "{:.1f}",
    ),
    Figure(
        _INDEX,
        r"; [\d.]+-([\d.]+) % coverage in 250 steps",
        f"{_PPO}/evaluation_summary.json",
        "rows[scene=procedural_room_1000000,policy=PPOExplorer].coverage_pct.mean",
        "{:.1f}",
    ),
    # The GPU and 16-core figures (one H200 machine)
    Figure(
        "docs/benchmarks/mapping.md",
        r"\| fast path, Triton, CUDA graph \(published 43 samples\) \| \*\*([\d.]+)\*\*",
        _GPU_ITERATION,
        "iteration_speed_s.fast path, Triton, CUDA graph (published 43 samples)",
        "{:.1f}",
        1e3,
    ),
    Figure(
        "docs/benchmarks/mapping.md",
        r"\| batched hash grid, the PyTorch reference \(published 43 samples\) \| ([\d.]+)",
        _GPU_ITERATION,
        "iteration_speed_s.batched hash grid (published 43 samples)",
        "{:.1f}",
        1e3,
    ),
    Figure(
        "docs/benchmarks/mapping.md",
        r"\*\*episode wall time per step\*\* \| \*\*([\d.]+)\*\*",
        _GPU_EPISODE,
        "episode_s",
        "{:.1f}",
        1e3 / 400,  # seconds of the 400-step episode to ms per step
    ),
    Figure(
        "docs/replica.md",
        r"took ([\d.]+) ms\s+per step at 680 x 1200",
        _GPU_EPISODE,
        "episode_s",
        "{:.0f}",
        1e3 / 400,
    ),
    Figure(
        "docs/benchmarks/throughput.md",
        r"\| 16 \| \*\*([\d,]+)\*\* \(8 workers\)",
        _GPU_SCALING,
        "scaling.points[cores=16].batched_default_steps_per_s",
        "{:,.0f}",
    ),
    Figure(
        "docs/benchmarks/throughput.md",
        r"\| 16 \| [^\n]*\| \*\*([\d.]+)x\*\* \|",
        _GPU_SCALING,
        "scaling.points[cores=16].ratio_default_vs_best_async",
        "{:.2f}",
    ),
    Figure(
        _INDEX,
        r"\+([\d.]+) \[[-\d.]+, [\d.]+\] over frontier on the closed small",
        f"{_EXPLORER}/evaluation_closed_small.json",
        "paired.frontier.mean_auc_difference",
        "{:.3f}",
    ),
    Figure(
        _INDEX,
        r"over frontier on the closed small class, \+([\d.]+) \[",
        f"{_EXPLORER}/evaluation_closed_apartment.json",
        "paired.frontier.mean_auc_difference",
        "{:.3f}",
    ),
    Figure(
        _EXPLORER_PAGE,
        r"\| and the update's CNNs in bfloat16 \| \| \*\*([\d,]+)\*\* \|",
        f"{_EXPLORER}/env_configs.json",
        "training_env_steps_per_s.and the update in bfloat16",
        "{:,.0f}",
    ),
    Figure(
        _INDEX,
        r"trains at ([\d,]+) env steps/s end to end \(64 agents\)",
        f"{_EXPLORER}/env_configs_64_agents.json",
        "training_env_steps_per_s.and the update in bfloat16",
        "{:,.0f}",
    ),
    Figure(
        _EXPLORER_PAGE,
        r"So training runs ([\d,]+) env steps/s end to end with 64 agents",
        f"{_EXPLORER}/env_configs_64_agents.json",
        "training_env_steps_per_s.and the update in bfloat16",
        "{:,.0f}",
    ),
    Figure(
        _EXPLORER_PAGE,
        r"\| shared scenes, panorama rows within 30 degrees, one process \| [\d,]+ \| "
        r"[\d,]+ \| [\d,]+ \| ([\d,]+) \|",
        f"{_EXPLORER}/env_configs_64_agents.json",
        "training_env_steps_per_s.after: shared scenes, panorama rows within 30 deg, one process",
        "{:,.0f}",
    ),
    *_escape_timing_figures(),
    *_explorer_figures("small, closed (24)", "closed_small"),
    *_explorer_figures("apartment, closed (24)", "closed_apartment"),
    *_explorer_figures("small, open (24)", "open_small"),
    *_explorer_figures("apartment, open (8)", "open_apartment"),
)

_STEP = re.compile(r"(?P<name>[^.\[\]]+)|\[(?P<index>\d+)\]|\[(?P<match>[^\]]+)\]|\.")


def lookup(data: Any, key: str) -> Any:
    """The value at ``key`` in parsed JSON (see the module docstring for the path syntax). A
    dict key that holds a dot itself (``"metrics.completion_ratio_pct"``) is found too.

    Raises:
        KeyError: a step of the path finds nothing (the message names the step).
    """
    steps = [step for step in _STEP.finditer(key) if step[0] != "."]
    value = data
    i = 0
    while i < len(steps):
        step = steps[i]
        if step["name"] is not None:
            names = [step["name"]]
            while (
                isinstance(value, dict)
                and ".".join(names) not in value
                and i + 1 < len(steps)
                and steps[i + 1]["name"] is not None
            ):
                i += 1
                names.append(steps[i]["name"])
            name = ".".join(names)
            if not isinstance(value, dict) or name not in value:
                raise KeyError(f"no {step['name']!r} in {key!r}")
            value = value[name]
        elif step["index"] is not None:
            value = value[int(step["index"])]
        else:
            wanted = dict(part.split("=", 1) for part in step["match"].split(","))
            found = [
                item for item in value if all(str(item.get(k)) == v for k, v in wanted.items())
            ]
            if len(found) != 1:
                raise KeyError(f"{len(found)} items match [{step['match']}] in {key!r}")
            value = found[0]
        i += 1
    return value


def source_figure(figure: Figure, root: Path = ROOT) -> str:
    """The figure as its source gives it, formatted as the page should print it."""
    path = root / figure.source
    text = path.read_text(encoding="utf-8")
    if path.suffix == ".md":
        match = re.search(figure.key, text)
        if match is None:
            raise KeyError(f"{figure.source} has nothing matching {figure.key!r}")
        return match[1]
    value = lookup(json.loads(text), figure.key)
    if isinstance(value, dict):
        return figure.format.format(**value)
    if figure.scale != 1.0:
        value = value * figure.scale
    return figure.format.format(value)


def check_figure(figure: Figure, root: Path = ROOT) -> str | None:
    """None when the page prints the source's figure, else what is wrong."""
    page = (root / figure.page).read_text(encoding="utf-8")
    match = re.search(figure.pattern, page, re.S)
    if match is None:
        return f"{figure.page}: no text matches {figure.pattern!r} (reworded? update FIGURES)"
    expected = source_figure(figure, root)
    if match[1] != expected:
        return (
            f"{figure.page} prints {match[1]!r} where {figure.source} ({figure.key}) gives "
            f"{expected!r}: update the page from the result file"
        )
    return None


@pytest.mark.parametrize("figure", [pytest.param(f, id=f.id) for f in FIGURES])
def test_the_page_prints_the_figure_of_its_result_file(figure: Figure) -> None:
    problem = check_figure(figure)
    assert problem is None, problem


def test_every_headline_source_is_a_kept_result() -> None:
    for source in sorted({figure.source for figure in FIGURES}):
        assert (ROOT / source).is_file(), f"{source} is gone: a page still quotes it"


def test_a_drifted_figure_fails(tmp_path: Path) -> None:
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "run.json").write_text(
        json.dumps(
            {
                "rows": [{"scene": "a", "ms": 1.234}, {"scene": "b", "ms": 9.87}],
                "hours": {"mean": 2.0, "std": 0.25},
            }
        ),
        encoding="utf-8",
    )
    (tmp_path / "page.md").write_text(
        "b takes 9.9 ms; a takes 1.3 ms; 2.0 ± 0.2 h\n", encoding="utf-8"
    )
    agrees = Figure(
        "page.md", r"b takes ([\d.]+) ms", "results/run.json", "rows[scene=b].ms", "{:.1f}"
    )
    drifted = Figure(
        "page.md", r"a takes ([\d.]+) ms", "results/run.json", "rows[scene=a].ms", "{:.2f}"
    )
    spread = Figure("page.md", r"; ([\d.]+ ± [\d.]+) h", "results/run.json", "hours", _MEAN_STD)
    assert check_figure(agrees, tmp_path) is None
    assert "prints '1.3' where results/run.json (rows[scene=a].ms) gives '1.23'" in (
        check_figure(drifted, tmp_path) or ""
    )
    assert check_figure(spread, tmp_path) is None
    with pytest.raises(KeyError, match=r"0 items match \[scene=c\]"):
        lookup({"rows": [{"scene": "a"}]}, "rows[scene=c].ms")


def stall_check_rows(stall_check: dict[str, Any]) -> dict[str, tuple[str, str, str]]:
    """Per policy of ``stall_check.json``: its longest stay, mean coverage (%) and mean path
    (m) over its episodes, as the open-scans page's summary table prints them."""
    episodes: dict[str, list[dict[str, Any]]] = {}
    for episode in stall_check["episodes"]:
        episodes.setdefault(episode["policy"], []).append(episode)
    return {
        policy: (
            str(max(e["longest_stay_steps"] for e in rows)),
            f"{100.0 * sum(e['coverage'] for e in rows) / len(rows):.1f}",
            f"{sum(e['path_m'] for e in rows) / len(rows):.1f}",
        )
        for policy, rows in episodes.items()
    }


def test_the_open_scans_page_prints_the_stall_checks_summary() -> None:
    """The stall check's summary table (longest stay, mean coverage and path per policy) is
    the one ``open_scans/stall_check.json`` gives, with a row for every policy it ran."""
    source = ROOT / RESULTS / "open_scans" / "stall_check.json"
    expected = stall_check_rows(json.loads(source.read_text(encoding="utf-8")))
    page = (ROOT / _OPEN_SCANS_PAGE).read_text(encoding="utf-8")
    printed = {
        policy: (stay, coverage, path)
        for policy, stay, coverage, path in re.findall(
            r"^\| (\w[\w-]*) \| (\d+) \| ([\d.]+) \| ([\d.]+) \|$", page, re.M
        )
    }
    assert printed == expected, (
        f"{_OPEN_SCANS_PAGE}'s stall-check summary {printed} differs from {source.name}'s "
        f"{expected}: update the page's table from the result file"
    )
