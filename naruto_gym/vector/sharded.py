"""The batched env's agents sharded over worker processes, so that a step uses every core.

One process steps its agents with compiled loops that release the GIL, but the Python
bookkeeping of a step and Open3D's distance queries hold it: past a few threads they
serialise. :class:`ShardedAgents` splits the agents into contiguous shares, one per worker
process (started with ``spawn`` or ``forkserver``, as Embree and Open3D may deadlock after a
``fork``); each worker steps its share as an in-process batched env with its own threads and
writes the observations into shared memory (:mod:`naruto_gym.vector.shared_buffers`), and
sends rewards and infos back through its pipe. Every agent keeps its own scene, seed and
random stream, so the shares give the observations, rewards and infos one process gives.

A worker that raises sends its traceback, the caller raises it, and the workers are shut
down; so are they on ``close()``, a ``KeyboardInterrupt`` in the caller (the workers ignore
``SIGINT``: the caller stops them) and the caller's exit (they end when their pipe closes).
"""

from __future__ import annotations

import multiprocessing
import multiprocessing.connection
import os
import pickle
import signal
import time
import traceback
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

from naruto_gym.scenes.stream import is_procedural_name, parse_procedural_name
from naruto_gym.utils.threads import THREADS_ENV_VAR
from naruto_gym.vector.infos import merge_shard_infos
from naruto_gym.vector.packed_infos import InfoPacker, InfoUnpacker
from naruto_gym.vector.shared_buffers import SharedObservations
from naruto_gym.vector.shared_scenes import SharedSceneStreams

#: Fewest agents a worker process gets by default: below it the step's fixed cost per process
#: outweighs the parallelism.
MIN_AGENTS_PER_WORKER = 16
#: Fewest CPUs at which the default shards the agents over processes: on fewer, one process
#: with a thread per CPU is as fast and starts at once.
MIN_CPUS_FOR_WORKERS = 4
#: CPUs (threads) per worker process by default: two threads per process overlap a share's
#: GIL-bound bookkeeping with its compiled loops.
THREADS_PER_WORKER = 2
# Seconds a worker has to finish its close before it is terminated.
_CLOSE_TIMEOUT_S = 5.0


def default_workers(num_envs: int, threads: int) -> int:
    """Worker processes a batched env of ``num_envs`` agents on ``threads`` CPUs uses by
    default: one (in-process threads) below ``MIN_CPUS_FOR_WORKERS`` CPUs, else one per
    ``THREADS_PER_WORKER`` CPUs, at most one per ``MIN_AGENTS_PER_WORKER`` agents."""
    if threads < MIN_CPUS_FOR_WORKERS:
        return 1
    return max(1, min(threads // THREADS_PER_WORKER, num_envs // MIN_AGENTS_PER_WORKER))


def resolve_workers(workers: int | None, num_envs: int, threads: int) -> int:
    """``workers`` checked (a positive integer, at most ``num_envs``), or the default."""
    if workers is None:
        return default_workers(num_envs, threads)
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1:
        raise ValueError(
            f"workers must be a positive integer (or None for the default), got {workers!r}"
        )
    if workers > num_envs:
        raise ValueError(
            f"workers={workers} is more than num_envs={num_envs}: each worker "
            "process needs at least one agent"
        )
    return int(workers)


def several_scenes(scenes: Sequence[Any] | SharedSceneStreams) -> bool:
    """Whether ``scenes`` (one entry per agent) put the agents in more than one scene: a
    procedural stream, or entries that are not all the same (names compared by value,
    other scenes by identity, as the scene pool shares runtimes)."""
    if isinstance(scenes, SharedSceneStreams):
        return True
    if any(is_procedural_name(item) and parse_procedural_name(item).is_stream for item in scenes):
        return True
    return len({item if isinstance(item, str) else id(item) for item in scenes}) > 1


class WorkerError(RuntimeError):
    """A worker process of a sharded batched env failed; the message holds its traceback.

    An exception raised in a worker is raised in the caller as the same exception (where it
    pickles) with a ``WorkerError`` as its cause, so that ``except ValueError`` works as with
    one process and the worker's traceback is printed with it; a worker that died is a
    ``WorkerError``."""


def _serve(
    connection: Any,
    make_env: Callable[..., Any],
    kwargs: dict[str, Any],
    threads: int,
    buffers: SharedObservations,
    start: int,
    stop: int,
) -> None:
    """A worker: build the share's env, then answer the caller's commands until ``close``
    (or until the caller's end of the pipe closes)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the caller handles Ctrl-C and stops us
    os.environ[THREADS_ENV_VAR] = str(threads)  # Open3D's queries and anything else here
    env = None
    packer = InfoPacker()
    try:
        env = make_env(**kwargs)
        connection.send(("ok", None))
        while True:
            try:
                command, payload = connection.recv()
            except (EOFError, OSError):  # the caller is gone
                return
            try:
                if command == "close":
                    connection.send(("ok", None))
                    return
                connection.send(
                    ("ok", _answer(env, command, payload, buffers, start, stop, packer))
                )
            except Exception as error:  # noqa: BLE001 - sent to the caller, raised there
                connection.send(("error", _failure(error)))
    except Exception as error:  # noqa: BLE001 - the env could not be built
        try:
            connection.send(("error", _failure(error)))
        except (BrokenPipeError, OSError):
            pass
    finally:
        if env is not None:
            env.close()
        connection.close()


def _failure(error: Exception) -> tuple[Exception | None, str, str, str]:
    """What a worker sends of an exception: the exception itself where it pickles (so that
    the caller raises the same type), its type's name, its message and the traceback."""
    try:
        pickle.loads(pickle.dumps(error))
        sendable: Exception | None = error
    except Exception:  # noqa: BLE001 - an exception that does not pickle: its text only
        sendable = None
    return sendable, type(error).__name__, str(error), traceback.format_exc()


def _answer(
    env: Any,
    command: str,
    payload: Any,
    buffers: SharedObservations,
    start: int,
    stop: int,
    packer: InfoPacker,
) -> Any:
    if command == "reset":
        seeds, options = payload
        observations, infos = env.reset(seed=seeds, options=options)
        buffers.write(observations, start, stop)
        return packer.pack({"infos": infos})
    if command == "step":
        started = time.perf_counter()
        observations, rewards, terminated, truncated, infos = env.step(payload)
        buffers.write(observations, start, stop)
        packed = packer.pack(
            {"rewards": rewards, "terminated": terminated, "truncated": truncated, "infos": infos}
        )
        return time.perf_counter() - started, packed
    if command == "poses":
        return env.poses
    if command == "rays_cast":
        return env.rays_cast
    if command == "spaces":
        return env.single_action_space
    raise ValueError(f"unknown command {command!r}")


@dataclass
class StepTimes:
    """Where the wall time of the sharded steps went, summed over ``steps`` steps: what
    limits scaling over processes.

    ``seconds`` is each step as the caller saw it. ``slowest_worker_s`` adds up each step's
    slowest worker's own time (stepping its share, writing its observations, packing its
    infos) and ``mean_worker_s`` the workers' mean of it: their ratio is the imbalance
    between shares. ``caller_s`` is the calling process's own work after the last answer
    came (copying that worker's observations out of shared memory, merging the infos; the
    other shares are copied while the slower workers still step). The rest,
    ``seconds - slowest_worker_s - caller_s``, is the hand-over: sending the actions,
    waking the workers, the answers through the pipes.
    """

    steps: int = 0
    seconds: float = 0.0
    slowest_worker_s: float = 0.0
    mean_worker_s: float = 0.0
    caller_s: float = 0.0

    @property
    def handover_s(self) -> float:
        """Seconds neither a worker's stepping nor the caller's merge and copy."""
        return self.seconds - self.slowest_worker_s - self.caller_s

    def per_step_ms(self) -> dict[str, float]:
        """Each part in milliseconds per step (empty before the first step)."""
        if self.steps == 0:
            return {}
        parts = {
            "step": self.seconds,
            "slowest_worker": self.slowest_worker_s,
            "mean_worker": self.mean_worker_s,
            "caller": self.caller_s,
            "handover": self.handover_s,
        }
        return {name: 1000.0 * value / self.steps for name, value in parts.items()}


class ShardedAgents:
    """``num_envs`` agents in ``workers`` processes, each stepping a contiguous share.

    Args:
        make_env: builds a share's in-process batched env from keywords (``num_envs``,
            ``scene``, ``threads``; picklable, e.g. the env class).
        num_envs: the agents.
        scenes: each agent's scene (as the env takes them), or a ``SharedSceneStreams`` (each
            share gets its groups: a share must start at a group's first agent).
        env_kwargs: every other keyword of the shares' envs.
        observation_space: one agent's observation space.
        workers: the processes (at most ``num_envs``).
        threads: CPUs to spread over the workers (each gets its share, at least one).
        start_method: ``"spawn"`` or ``"forkserver"`` (never ``"fork"``: Embree and Open3D may
            deadlock in a forked child).
    """

    def __init__(
        self,
        make_env: Callable[..., Any],
        num_envs: int,
        scenes: Sequence[Any] | SharedSceneStreams,
        env_kwargs: dict[str, Any],
        observation_space: spaces.Dict,
        workers: int,
        threads: int,
        start_method: str = "spawn",
    ) -> None:
        if start_method not in ("spawn", "forkserver"):
            raise ValueError(
                f"start_method must be 'spawn' or 'forkserver', got "
                f"{start_method!r} (Embree may deadlock in a forked child)"
            )
        context = multiprocessing.get_context(start_method)
        self.num_envs = int(num_envs)
        self.bounds = [
            (int(part[0]), int(part[-1]) + 1)
            for part in np.array_split(np.arange(self.num_envs), workers)
        ]
        # Each share's scenes, made before anything is started (a share may be refused).
        share_scenes = [
            scenes.share(start) if isinstance(scenes, SharedSceneStreams) else scenes[start:stop]
            for start, stop in self.bounds
        ]
        self.buffers = SharedObservations(observation_space, self.num_envs, context)
        self.threads = max(1, int(threads))
        self._unpacker = InfoUnpacker(workers)
        self.step_times = StepTimes()
        self._connections: list[Any] = []
        self._processes: list[Any] = []
        self.closed = False
        for k, (start, stop) in enumerate(self.bounds):
            share_threads = max(1, threads // workers + (1 if k < threads % workers else 0))
            kwargs = {
                **env_kwargs,
                "num_envs": stop - start,
                "scene": share_scenes[k]
                if isinstance(share_scenes[k], SharedSceneStreams)
                else list(share_scenes[k]),
                "threads": share_threads,
            }
            parent_end, child_end = context.Pipe()
            process = context.Process(
                target=_serve,
                name=f"naruto-vector-worker-{k}",
                daemon=True,
                args=(child_end, make_env, kwargs, share_threads, self.buffers, start, stop),
            )
            process.start()
            child_end.close()
            self._connections.append(parent_end)
            self._processes.append(process)
        self._finalizer = weakref.finalize(self, _stop, self._connections, self._processes)
        try:
            self._gather(range(workers))  # every env built
        except BaseException:  # an env that could not be built, or Ctrl-C meanwhile
            self.close()
            raise

    @property
    def workers(self) -> int:
        """The worker processes."""
        return len(self._processes)

    @property
    def pids(self) -> list[int]:
        """The worker processes' ids."""
        return [process.pid for process in self._processes]

    # -- commands --------------------------------------------------------------------------
    def call(
        self,
        command: str,
        payloads: Sequence[Any] | None = None,
        only: Sequence[int] | None = None,
        on_answer: Callable[[int], None] | None = None,
    ) -> list[Any]:
        """Send ``command`` (with each worker's payload) to the workers (all, or ``only``)
        and return their answers in order; a failure is raised (see :meth:`_raise`).
        ``on_answer(k)`` runs as soon as worker ``k`` has answered without an error, while
        the others may still be at work."""
        if self.closed:
            raise RuntimeError("the batched env's worker processes are closed: make a new env")
        chosen = list(range(self.workers)) if only is None else list(only)
        try:
            for k in chosen:
                self._connections[k].send((command, None if payloads is None else payloads[k]))
            answers, failure = self._gather(chosen, on_answer)
        except BaseException:  # a dead pipe or Ctrl-C: stop them all
            self.close()
            raise
        if failure is not None:
            self._raise(*failure)
        return answers

    def _gather(
        self, chosen: Sequence[int], on_answer: Callable[[int], None] | None = None
    ) -> tuple[list[Any], tuple | None]:
        """Every chosen worker's answer (taken in the order they come), and the first
        failure ``(worker, sent error, died)`` (all answers are read first, so that the
        pipes stay in step)."""
        answers: dict[int, Any] = {}
        failures: dict[int, tuple] = {}
        waiting = {self._connections[k]: k for k in chosen}
        while waiting:
            for connection in multiprocessing.connection.wait(list(waiting)):
                k = waiting.pop(connection)
                try:
                    status, answer = connection.recv()
                except (EOFError, OSError):
                    exit_code = self._processes[k].exitcode
                    answer = (None, "EOFError", "the worker process died", f"exit code {exit_code}")
                    failures[k] = (k, answer, True)
                else:
                    if status == "error":
                        failures[k] = (k, answer, False)
                    elif on_answer is not None and not failures:
                        on_answer(k)
                answers[k] = answer
        failure = None
        if failures:  # a dead worker first, else the lowest-numbered failure
            failure = min(failures.values(), key=lambda entry: (not entry[2], entry[0]))
        return [answers[k] for k in chosen], failure

    def _raise(self, k: int, sent: tuple, died: bool) -> None:
        """Raise a worker's failure in the caller. Bad input (a ``ValueError`` or
        ``TypeError`` a live worker sent back, such as a reset pose inside furniture) leaves
        the workers running, so the env stays usable as with one process; anything else
        stops every worker."""
        error, name, message, text = sent
        if died or not isinstance(error, (ValueError, TypeError)):
            self.close()
        cause = WorkerError(
            f"worker process {k} of the batched env raised {name}: "
            f"{message}\n\nthe worker's traceback:\n{text}"
        )
        if error is None:
            raise cause
        raise error from cause

    def reset(
        self, seeds: Sequence[int | None], mask: np.ndarray, options: dict[str, Any]
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Reset the agents ``mask`` flags with their ``seeds`` and ``options``."""
        chosen, payloads = [], []
        for k, (start, stop) in enumerate(self.bounds):
            if mask[start:stop].any():
                chosen.append(k)
            share_options = {**options, "reset_mask": mask[start:stop].copy()}
            payloads.append((list(seeds[start:stop]), share_options))
        answers = self.call("reset", payloads, chosen)
        parts = [
            (self._unpacker.unpack(k, answer)["infos"], *self.bounds[k])
            for k, answer in zip(chosen, answers, strict=True)
        ]
        return self.buffers.copy(self.threads), merge_shard_infos(parts, self.num_envs)

    def step(self, actions: np.ndarray) -> tuple[Any, ...]:
        """Step every agent with its action (timed into :attr:`step_times`)."""
        started = time.perf_counter()
        observations = self.buffers.empty()
        answered = [started]

        def copy_share(k: int) -> None:  # while the other workers still step
            answered[0] = time.perf_counter()
            self.buffers.copy_rows(observations, *self.bounds[k])

        answers = self.call(
            "step", [actions[start:stop] for start, stop in self.bounds], on_answer=copy_share
        )
        busy = [seconds for seconds, _ in answers]
        merged = self._unpacker.merge([packed for _, packed in answers], self.bounds, self.num_envs)
        finished = time.perf_counter()
        times = self.step_times
        times.steps += 1
        times.seconds += finished - started
        times.slowest_worker_s += max(busy)
        times.mean_worker_s += sum(busy) / len(busy)
        times.caller_s += finished - answered[0]
        return (
            observations,
            merged["rewards"],
            merged["terminated"],
            merged["truncated"],
            merged.get("infos", {}),
        )

    def poses(self) -> np.ndarray:
        """(N, 4, 4) every agent's pose."""
        return np.concatenate(self.call("poses"))

    def rays_cast(self) -> int:
        """Rays cast by every worker so far."""
        return int(sum(self.call("rays_cast")))

    def single_action_space(self) -> spaces.Space:
        """One agent's action space, as the first worker's env has it."""
        return self.call("spaces", only=[0])[0]

    def close(self) -> None:
        """Stop the workers (idempotent)."""
        self.closed = True
        self._finalizer()


def _stop(connections: list[Any], processes: list[Any]) -> None:
    """Ask the workers to close, terminate those that do not, and release the pipes."""
    for connection, process in zip(connections, processes, strict=True):
        if process.is_alive():
            try:
                connection.send(("close", None))
            except (BrokenPipeError, OSError):
                pass
    for process in processes:
        process.join(_CLOSE_TIMEOUT_S)
        if process.is_alive():
            process.terminate()
            process.join(_CLOSE_TIMEOUT_S)
        if process.is_alive():  # pragma: no cover - a worker stuck in native code
            process.kill()
            process.join()
    for connection in connections:
        connection.close()
