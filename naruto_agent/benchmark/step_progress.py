"""The steps of running episodes, reported to the harness's progress bar as they are taken.

An episode of the harness adds :func:`step_hooks` to its loop: a hook that hands its steps, a
chunk at a time, to the sink this process reports to (:func:`report_steps_to`). The driver's
progress bar is the sink when episodes run in its own process; a local worker process reports
through a queue the driver drains (:mod:`naruto_agent.benchmark.executors`). Without a sink
the hook is left out.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from naruto_agent.episode_loop import EpisodeHook

#: Steps after which a running episode reports them, at the latest.
STEPS_PER_REPORT = 25
#: Seconds after which a running episode reports the steps it took since its last report,
#: at the latest (a slow policy moves the bar at least this often).
SECONDS_PER_REPORT = 0.5

#: ``sink(episode_id, steps)``: takes a running episode's steps since its last report.
StepSink = Callable[[str, int], None]

_sink: StepSink | None = None


def report_steps_to(sink: StepSink | None) -> None:
    """Make ``sink`` take the steps of the episodes this process runs from now on (None:
    no reports)."""
    global _sink
    _sink = sink


def step_hooks(episode_id: str) -> list[EpisodeHook]:
    """The hook that reports ``episode_id``'s steps to this process's sink, or none when
    there is no sink."""
    return [] if _sink is None else [StepReporter(episode_id, _sink)]


class StepReporter(EpisodeHook):
    """Hands an episode's steps to a sink every :data:`STEPS_PER_REPORT` steps or
    :data:`SECONDS_PER_REPORT` seconds, whichever comes first, and at its last step.

    Args:
        episode_id: the episode the steps are of.
        sink: takes ``(episode_id, steps)``.
    """

    def __init__(self, episode_id: str, sink: StepSink) -> None:
        self.episode_id = episode_id
        self.sink = sink
        self.reported = 0
        self.reported_at = time.monotonic()

    def on_step(self, step: int, observation: dict, info: dict, last: bool) -> None:
        now = time.monotonic()
        due = step - self.reported >= STEPS_PER_REPORT
        if step > self.reported and (last or due or now - self.reported_at >= SECONDS_PER_REPORT):
            self.sink(self.episode_id, step - self.reported)
            self.reported, self.reported_at = step, now
