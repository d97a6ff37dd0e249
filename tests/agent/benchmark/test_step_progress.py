"""The harness's progress bar counts steps, moved by episodes while they run, in this process
and in worker processes."""

from __future__ import annotations

import pytest

from naruto_agent.benchmark import build_specs, run_local
from naruto_agent.benchmark.executors import RunProgress
from naruto_agent.benchmark.step_progress import (
    STEPS_PER_REPORT,
    StepReporter,
    report_steps_to,
    step_hooks,
)

TINY = {
    "image_scale": 0.1,
    "eval_points": 0,
    "eval_samples": 4000,
    "checkpoint_samples": 2000,
    "env_kwargs": {"panorama_shape": [16, 32], "coverage_samples": 2000},
}
STEPS = 60


def test_a_running_episode_reports_its_steps_in_chunks():
    reports: list[tuple[str, int]] = []
    reporter = StepReporter("room/random/seed0", lambda *report: reports.append(report))
    for step in range(1, STEPS + 1):
        reporter.on_step(step, {}, {}, last=step == STEPS)
    assert sum(count for _, count in reports) == STEPS
    assert all(episode == "room/random/seed0" for episode, _ in reports)
    assert len(reports) >= STEPS // STEPS_PER_REPORT + 1  # chunks, the last one at the end
    assert max(count for _, count in reports) <= STEPS_PER_REPORT


def test_no_hook_without_a_sink():
    report_steps_to(None)
    assert step_hooks("room/random/seed0") == []


def test_the_bar_never_counts_an_episode_beyond_its_length(tmp_path):
    (spec,) = build_specs(["two_rooms"], ["random"], [0], 10, **TINY)
    progress = RunProgress(tmp_path, [spec], show=False)
    progress.steps(spec.episode_id, 8)
    progress.steps(spec.episode_id, 8)  # a retried attempt reports its steps again
    assert progress.steps_counted == 10 == progress.steps_while_running
    progress.done(spec, {"status": "ok", "episode_id": spec.episode_id})
    assert progress.steps_counted == progress.total_steps == 10


@pytest.mark.parametrize("workers", [0, 1])
def test_running_episodes_move_the_bar_step_by_step(tmp_path, workers):
    specs = build_specs(["two_rooms"], ["random"], [0, 1], STEPS, **TINY)
    progress = RunProgress(tmp_path, specs, show=False)
    assert progress.total_steps == 2 * STEPS
    assert run_local(specs, tmp_path, workers=workers, progress=False, reporter=progress) == 0
    assert progress.steps_counted == 2 * STEPS and progress.finished == 2
    if workers == 0:  # every step counted while its episode ran
        assert progress.steps_while_running == 2 * STEPS
    else:  # a worker's reports reach the driver through a queue, some before the record
        assert progress.steps_while_running > 0
    assert step_hooks("after/the/run") == []  # the sink goes with the run
