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
from naruto_gym.utils.threads import available_cpus

MAX_POOL_RESTARTS_PER_EPISODE = 1


def pending_specs(specs: Iterable[EpisodeSpec], output_dir: str | Path) -> list[EpisodeSpec]:
    """The episodes without a successful record of the same settings under ``output_dir``."""
    return [spec for spec in specs if not is_done(spec.record_path(output_dir), spec.config_hash)]


class _Progress:
    """Writes records as they come and keeps a progress bar."""

    def __init__(self, output_dir: Path, total: int, show: bool) -> None:
        self.output_dir = output_dir
        self.bar = tqdm(total=total, desc="episodes", disable=not show, unit="ep")
        self.failed = 0

    def done(self, spec: EpisodeSpec, record: dict[str, Any]) -> None:
        write_json_atomic(spec.record_path(self.output_dir), record)
        if record.get("status") != STATUS_OK:
            self.failed += 1
        self.bar.update(1)
        status = record.get("status")
        self.bar.set_postfix_str(f"{spec.episode_id}: {status}; failed {self.failed}")

    def close(self) -> None:
        self.bar.close()


def stop_with_parent(parent_pid: int, interval_s: float = 1.0) -> None:
    """In a worker process: exit as soon as the run that started it is gone (killed), since
    the episode it is running can no longer be recorded (the run records episodes itself)."""

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(interval_s)
        os.kill(os.getpid(), signal.SIGKILL)

    threading.Thread(target=watch, name="naruto-stop-with-parent", daemon=True).start()


def start_worker(parent_pid: int, threads: int) -> None:
    """Initializer of a local worker process: it stops with its parent
    (:func:`stop_with_parent`) and takes its share of the CPUs.

    The libraries an episode loads after this (torch, Open3D's OpenMP loops, the env's compiled
    loops in a worker process) size their thread pools from ``OMP_NUM_THREADS``. Unset, each
    of N workers starts a pool of every CPU, and pools that contend for the same cores wait on
    one another: some operations (a QR factorisation of a policy's weights, for one) then take
    a hundred times longer. A value the user set is kept (the workers inherit it).
    """
    os.environ.setdefault("OMP_NUM_THREADS", str(threads))
    stop_with_parent(parent_pid)


def run_local(
    specs: list[EpisodeSpec],
    output_dir: str | Path,
    workers: int = 2,
    progress: bool = True,
    episode_fn: Callable[[dict[str, Any]], dict[str, Any]] = run_episode_safe,
) -> int:
    """Run episodes in ``workers`` spawned processes (in this process when ``workers`` is 0).

    Args:
        specs: the episodes to run (see :func:`pending_specs` to skip finished ones).
        output_dir: output folder; records go to ``output_dir/records/...``.
        workers: worker processes (spawn start method: Open3D/Embree are not fork-safe), each
            with an equal share of the CPUs for its thread pools (:func:`start_worker`).
        progress: show a progress bar.
        episode_fn: picklable function from a spec dict to a record (for tests).

    Returns:
        The number of failed episodes.
    """
    output_dir = Path(output_dir)
    reporter = _Progress(output_dir, len(specs), progress)
    try:
        if workers <= 0:
            for spec in specs:
                reporter.done(spec, episode_fn(spec.as_dict()))
            return reporter.failed
        attempts = dict.fromkeys(range(len(specs)), 0)
        remaining = list(range(len(specs)))
        context = multiprocessing.get_context("spawn")
        share = max(1, available_cpus() // workers)
        while remaining:
            pool = ProcessPoolExecutor(
                max_workers=workers,
                mp_context=context,
                initializer=start_worker,
                initargs=(os.getpid(), share),
            )
            try:
                futures: dict[Future, int] = {
                    pool.submit(episode_fn, specs[index].as_dict()): index for index in remaining
                }
                remaining = []
                outstanding = set(futures)
                while outstanding:
                    finished, outstanding = wait(outstanding, return_when=FIRST_COMPLETED)
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
        progress: show a progress bar.
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
    reporter = _Progress(Path(output_dir), len(specs), progress)
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
