"""The explorer, its untrained twin and goal-walker run side by side from naruto-benchmark,
each under its own label, and the statistics pair the explorer with each of the other two."""

from __future__ import annotations

import pytest

pytest.importorskip("stable_baselines3")

from naruto_agent.benchmark.cli import main  # noqa: E402
from naruto_agent.benchmark.records import load_records  # noqa: E402
from naruto_agent.benchmark.suite_report import paired_summary  # noqa: E402
from naruto_agent.rl.explorer_policy import PACKAGED_MODEL  # noqa: E402

if not PACKAGED_MODEL.exists():
    pytest.skip("no explorer checkpoint is shipped", allow_module_level=True)

TINY = [
    "--scenes", "procedural:room:7", "--seeds", "0", "1", "--max-episode-steps", "4",
    "--image-scale", "0.1", "--eval-points", "1", "--eval-samples", "2000",
    "--checkpoint-samples", "2000", "--eval-samples-per-m2", "0",
    "--env-kwargs", '{"coverage_samples": 2000}', "--no-plots", "--no-progress", "--workers", "0",
]  # fmt: skip


@pytest.mark.slow
def test_the_three_rows_are_kept_apart_and_the_explorer_is_paired_with_each(tmp_path):
    policies = ["explorer", "explorer-untrained", "goal-walker"]
    assert main([*TINY, "--policies", *policies, "--output-dir", str(tmp_path)]) == 0
    records = load_records(tmp_path)
    assert sorted((r["policy"], r["seed"]) for r in records) == sorted(
        (policy, seed) for policy in policies for seed in (0, 1)
    )
    entries = next(iter(paired_summary(records, resamples=200).values()))
    pairs = {(e["a"], e["b"]) for e in entries if e["metric"] == "auc_steps"}
    assert {("explorer", "explorer-untrained"), ("explorer", "goal-walker")} <= pairs
    for entry in entries:
        if entry["metric"] == "auc_steps":
            assert entry["overall"]["n"] == 2
