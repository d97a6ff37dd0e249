"""Benchmark harness: run scenes x policies x seeds, record, tabulate and plot.

* :mod:`~naruto_agent.benchmark.spec`: :class:`EpisodeSpec` and :func:`build_specs`.
* :mod:`~naruto_agent.benchmark.runner`: :func:`run_episode` (one episode -> a record).
* :mod:`~naruto_agent.benchmark.executors`: :func:`run_local` (spawned processes) and
  :func:`run_ray` (Ray tasks), both resumable, writing records atomically.
* :mod:`~naruto_agent.benchmark.tables` and :mod:`~naruto_agent.benchmark.plots`: reports.
* :mod:`~naruto_agent.benchmark.cli`: the ``naruto-benchmark`` command.
"""

from naruto_agent.benchmark.executors import pending_specs, run_local, run_ray
from naruto_agent.benchmark.records import load_records, write_json_atomic
from naruto_agent.benchmark.runner import run_episode, run_episode_safe
from naruto_agent.benchmark.spec import EpisodeSpec, build_specs, parse_scene
from naruto_agent.benchmark.tables import markdown_table, summarise

__all__ = [
    "EpisodeSpec",
    "build_specs",
    "load_records",
    "markdown_table",
    "parse_scene",
    "pending_specs",
    "run_episode",
    "run_episode_safe",
    "run_local",
    "run_ray",
    "summarise",
    "write_json_atomic",
]
