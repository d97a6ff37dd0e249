"""A harness worker process ends when the run that started it is killed (it could not record
the episode it runs anyway), instead of running on as an orphan."""

from __future__ import annotations

import subprocess
import sys
import time

from tests.process_checks import alive

WORKER = (
    "import os, time\n"
    "from naruto_agent.benchmark.executors import stop_with_parent\n"
    "stop_with_parent(os.getppid(), 0.05)\n"
    "print('ready', flush=True)\n"
    "time.sleep(120)\n"
)
RUN = (
    "import subprocess, sys, time\n"
    f"worker = subprocess.Popen([sys.executable, '-c', {WORKER!r}], stdout=subprocess.PIPE,"
    " text=True)\n"
    "assert worker.stdout.readline().strip() == 'ready'\n"
    "print(worker.pid, flush=True)\n"
    "time.sleep(120)\n"
)


def test_a_worker_stops_when_its_run_is_killed():
    run = subprocess.Popen([sys.executable, "-c", RUN], stdout=subprocess.PIPE, text=True)
    try:
        worker_pid = int(run.stdout.readline())
        assert alive(worker_pid)
        run.kill()
        run.wait()
        deadline = time.monotonic() + 15
        while alive(worker_pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not alive(worker_pid)
    finally:
        run.kill()
