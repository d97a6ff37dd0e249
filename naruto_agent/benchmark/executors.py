"""Run many episodes: in local worker processes (spawn) or as Ray tasks, resumably.

Either way the driver process writes each record atomically as soon as its episode finishes
(workers, possibly on other machines, only return records), skips episodes whose record is
already there with the same settings, and records a crashed episode as ``failed`` without
stopping the others. A worker process that dies outright (a segfault) breaks a local pool:
the pool is rebuilt and the unfinished episodes are tried again, once, before they are
recorded as failed.
"""

from __future__ import annotations

import multiprocessing
import os
import queue
import signal
import threading
import time
from collections.abc import Callable, Iterable
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

from tqdm.auto import tqdm

from naruto_agent.benchmark.records import STATUS_OK, is_done, write_json_atomic
from naruto_agent.benchmark.runner import failed_record, run_episode_safe
from naruto_agent.benchmark.spec import EpisodeSpec
from naruto_agent.benchmark.step_progress import report_steps_to
from naruto_gym.utils.threads import available_cpus

MAX_POOL_RESTARTS_PER_EPISODE = 1
#: Seconds the driver waits for an episode to finish before it counts the steps reported.
REPORT_WAIT_S = 0.5


def pending_specs(specs: Iterable[EpisodeSpec], output_dir: str | Path) -> list[EpisodeSpec]:
    """The episodes without a successful record of the same settings under ``output_dir``."""
    return [spec for spec in specs if not is_done(spec.record_path(output_dir), spec.config_hash)]


class RunProgress:
    """Writes records as they come and keeps a progress bar of the steps taken.

    The bar counts steps of every episode to run: running episodes move it as they step
    (:meth:`steps`, fed by :mod:`naruto_agent.benchmark.step_progress`), and a finished one
    adds the steps it did not report (all of them where its steps are not reported: Ray tasks,
    an episode that failed or ended early).

    Args:
        output_dir: the run's output folder.
        specs: the episodes to run.
        show: show the bar.

    Attributes:
        failed: episodes recorded as failed so far.
        finished: episodes recorded so far.
        total_steps: the steps of all episodes (the bar's total).
        steps_counted: the steps counted on the bar so far.
        steps_reported: per episode id, the steps counted on the bar.
        steps_while_running: steps counted on the bar before their episode's record came.
    """

    def __init__(self, output_dir: Path, specs: list[EpisodeSpec], show: bool) -> None:
        self.output_dir = output_dir
        self.total_episodes = len(specs)
        self.total_steps = sum(spec.steps for spec in specs)
        self.steps_counted = 0
        self.bar = tqdm(total=self.total_steps, desc="steps", disable=not show, unit="step")
        self.failed = 0
        self.finished = 0
        self.steps_reported: dict[str, int] = {}
        self.steps_while_running = 0
        self._steps_of = {spec.episode_id: spec.steps for spec in specs}

    def steps(self, episode_id: str, count: int) -> None:
        """Count ``count`` more steps of a running episode (never beyond its length)."""
        done = self.steps_reported.get(episode_id, 0)
        count = max(0, min(count, self._steps_of.get(episode_id, 0) - done))
        if count:
            self.steps_reported[episode_id] = done + count
            self.steps_while_running += count
            self._count(count)

    def done(self, spec: EpisodeSpec, record: dict[str, Any]) -> None:
        """Write ``spec``'s record and count the steps of it the bar has not counted."""
        write_json_atomic(spec.record_path(self.output_dir), record)
        self.finished += 1
        if record.get("status") != STATUS_OK:
            self.failed += 1
        self._count(spec.steps - self.steps_reported.get(spec.episode_id, 0))
        self.steps_reported[spec.episode_id] = spec.steps
        status = record.get("status")
        self.bar.set_postfix_str(
            f"episodes {self.finished}/{self.total_episodes}, failed {self.failed}; "
            f"{spec.episode_id}: {status}"
        )

    def drain(self, reports: Any) -> None:
        """Count the steps waiting in a queue of ``(episode_id, steps)`` reports."""
        while True:
            try:
                episode_id, count = reports.get_nowait()
            except queue.Empty:
                return
            self.steps(episode_id, count)

    def close(self) -> None:
        self.bar.close()

    def _count(self, steps: int) -> None:
        self.steps_counted += steps
        self.bar.update(steps)


def stop_with_parent(parent_pid: int, interval_s: float = 1.0) -> None:
    """In a worker process: exit as soon as the run that started it is gone (killed), since
    the episode it is running can no longer be recorded (the run records episodes itself)."""

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(interval_s)
        os.kill(os.getpid(), signal.SIGKILL)

    threading.Thread(target=watch, name="naruto-stop-with-parent", daemon=True).start()


def start_worker(parent_pid: int, threads: int, step_reports: Any = None) -> None:
    """Initializer of a local worker process: it stops with its parent
    (:func:`stop_with_parent`), takes its share of the CPUs and reports the steps of its
    episodes to ``step_reports`` (a queue of ``(episode_id, steps)``; None: no reports).

    The libraries an episode loads after this (torch, Open3D's OpenMP loops, the env's compiled
    loops in a worker process) size their thread pools from ``OMP_NUM_THREADS``. Unset, each
    of N workers starts a pool of every CPU, and pools that contend for the same cores wait on
    one another: some operations (a QR factorisation of a policy's weights, for one) then take
    a hundred times longer. A value the user set is kept (the workers inherit it).
    """
    os.environ.setdefault("OMP_NUM_THREADS", str(threads))
    stop_with_parent(parent_pid)
    if step_reports is not None:
        report_steps_to(lambda episode_id, steps: step_reports.put((episode_id, steps)))


def run_local(
    specs: list[EpisodeSpec],
    output_dir: str | Path,
    workers: int = 2,
    progress: bool = True,
    episode_fn: Callable[[dict[str, Any]], dict[str, Any]] = run_episode_safe,
    reporter: RunProgress | None = None,
) -> int:
    """Run episodes in ``workers`` spawned processes (in this process when ``workers`` is 0).

    Args:
        specs: the episodes to run (see :func:`pending_specs` to skip finished ones).
        output_dir: output folder; records go to ``output_dir/records/...``.
        workers: worker processes (spawn start method: Open3D/Embree are not fork-safe), each
            with an equal share of the CPUs for its thread pools (:func:`start_worker`).
        progress: show a progress bar of the steps taken, moved by running episodes.
        episode_fn: picklable function from a spec dict to a record (for tests).
        reporter: the records' writer and progress bar (default: a :class:`RunProgress`
            of ``specs`` that shows its bar when ``progress``).

    Returns:
        The number of failed episodes.
    """
    output_dir = Path(output_dir)
    reporter = reporter or RunProgress(output_dir, specs, progress)
    try:
        if workers <= 0:
            report_steps_to(reporter.steps)
            for spec in specs:
                reporter.done(spec, episode_fn(spec.as_dict()))
            return reporter.failed
        attempts = dict.fromkeys(range(len(specs)), 0)
        remaining = list(range(len(specs)))
        context = multiprocessing.get_context("spawn")
        step_reports = context.Queue()
        share = max(1, available_cpus() // workers)
        while remaining:
            pool = ProcessPoolExecutor(
                max_workers=workers,
                mp_context=context,
                initializer=start_worker,
                initargs=(os.getpid(), share, step_reports),
            )
            try:
                futures: dict[Future, int] = {
                    pool.submit(episode_fn, specs[index].as_dict()): index for index in remaining
                }
                remaining = []
                outstanding = set(futures)
                while outstanding:
                    finished, outstanding = wait(
                        outstanding, timeout=REPORT_WAIT_S, return_when=FIRST_COMPLETED
                    )
                    reporter.drain(step_reports)
                    for future in finished:
                        index = futures[future]
                        try:
                            record = future.result()
                        except BrokenProcessPool as error:
                            attempts[index] += 1
                            if attempts[index] > MAX_POOL_RESTARTS_PER_EPISODE:
                                record = failed_record(
                                    specs[index],
                                    f"worker process died ({error}); the episode was tried "
                                    f"{attempts[index]} times",
                                )
                            else:
                                remaining.append(index)
                                continue
                        except Exception as error:  # noqa: BLE001 (e.g. an unpicklable result)
                            record = failed_record(specs[index], error)
                        reporter.done(specs[index], record)
            except BaseException:
                # Ctrl-C or a driver error: drop queued episodes, do not wait for running ones
                # (finished records are already on disk; a rerun does the rest).
                pool.shutdown(wait=False, cancel_futures=True)
                raise
            pool.shutdown(wait=True)
        return reporter.failed
    finally:
        report_steps_to(None)
        reporter.close()


def run_ray(
    specs: list[EpisodeSpec],
    output_dir: str | Path,
    address: str = "auto",
    progress: bool = True,
    num_cpus_per_episode: float = 1.0,
    local_cpus: int | None = None,
) -> int:
    """Run episodes as Ray tasks (one env per task); the driver writes the records.

    Args:
        specs: the episodes to run.
        output_dir: output folder on the driver's machine.
        address: ``"auto"`` (a running cluster), ``"HOST:PORT"``, or ``"local"`` to start a
            local Ray instance. An already initialised Ray (``ray.init`` called by the user) is
            used as it is.
        progress: show a progress bar of the steps taken (moved as each episode finishes).
        num_cpus_per_episode: CPUs Ray reserves for each episode.
        local_cpus: CPUs of a ``"local"`` instance (default: all).

    Returns:
        The number of failed episodes.

    The workers must have ``naruto-gym`` installed (same version) and the scenes at the same
    paths; Ray is an optional extra: ``pip install "naruto-gym[ray]"``.
    """
    try:
        import ray
    except ImportError as error:
        raise ValueError(
            "the Ray backend needs Ray: pip install 'naruto-gym[ray]' (or 'ray[default]')"
        ) from error
    if not ray.is_initialized():
        if address == "local":
            ray.init(num_cpus=local_cpus, include_dashboard=False, log_to_driver=False)
        else:
            ray.init(address=address, log_to_driver=False)
    remote_episode = ray.remote(num_cpus=num_cpus_per_episode, max_retries=1)(run_episode_safe)
    reporter = RunProgress(Path(output_dir), specs, progress)
    try:
        refs = {remote_episode.remote(spec.as_dict()): spec for spec in specs}
        outstanding = list(refs)
        while outstanding:
            finished, outstanding = ray.wait(outstanding, num_returns=1)
            for ref in finished:
                spec = refs[ref]
                try:
                    record = ray.get(ref)
                except Exception as error:  # noqa: BLE001 (a task or its node died)
                    record = failed_record(spec, error)
                reporter.done(spec, record)
        return reporter.failed
    finally:
        reporter.close()
