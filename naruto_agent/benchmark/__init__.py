"""Benchmark harness: run scenes x policies x seeds, record, tabulate and plot.

* :mod:`~naruto_agent.benchmark.spec`: :class:`EpisodeSpec` and :func:`build_specs`.
* :mod:`~naruto_agent.benchmark.runner`: :func:`run_episode` (one episode -> a record).
* :mod:`~naruto_agent.benchmark.reference_frames`: the frames the reference map is fused from
  (the leaderboard's camera at the poses the policy reached).
* :mod:`~naruto_agent.benchmark.executors`: :func:`run_local` (spawned processes) and
  :func:`run_ray` (Ray tasks), both resumable, writing records atomically, with a progress bar
  of the steps taken (:mod:`~naruto_agent.benchmark.step_progress`).
* :mod:`~naruto_agent.benchmark.checks`: a run's checks before it starts (scene names, the
  settings that differ from the leaderboard's).
* :mod:`~naruto_agent.benchmark.tables` and :mod:`~naruto_agent.benchmark.plots`: reports.
* :mod:`~naruto_agent.benchmark.suite`: the scene suite as episodes (``--suite``).
* :mod:`~naruto_agent.benchmark.efficiency`: area under the completion-ratio curve, steps and
  metres to a level; :mod:`~naruto_agent.benchmark.statistics`: bootstrap intervals and paired
  comparisons; :mod:`~naruto_agent.benchmark.suite_report` and
  :mod:`~naruto_agent.benchmark.suite_plots`: per-class tables and plots;
  :mod:`~naruto_agent.benchmark.leaderboard`: the docs' leaderboard page, made from a run
  folder or from :mod:`~naruto_agent.benchmark.episode_archive` (compact copies of a suite
  run's episodes kept in git, for a run spread over sessions).
* :mod:`~naruto_agent.benchmark.cli`: the ``naruto-benchmark`` command.
"""

from naruto_agent.benchmark.efficiency import episode_efficiency
from naruto_agent.benchmark.executors import pending_specs, run_local, run_ray
from naruto_agent.benchmark.records import load_records, write_json_atomic
from naruto_agent.benchmark.runner import run_episode, run_episode_safe
from naruto_agent.benchmark.spec import EpisodeSpec, build_specs, parse_scene
from naruto_agent.benchmark.statistics import bootstrap_ci, paired_comparison
from naruto_agent.benchmark.suite import select_scenes, suite_specs
from naruto_agent.benchmark.suite_report import write_statistics
from naruto_agent.benchmark.tables import markdown_table, summarise

__all__ = [
    "EpisodeSpec",
    "bootstrap_ci",
    "build_specs",
    "episode_efficiency",
    "load_records",
    "markdown_table",
    "paired_comparison",
    "parse_scene",
    "pending_specs",
    "run_episode",
    "run_episode_safe",
    "run_local",
    "run_ray",
    "select_scenes",
    "suite_specs",
    "summarise",
    "write_json_atomic",
    "write_statistics",
]
