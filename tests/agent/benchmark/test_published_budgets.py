"""The published-budgets report: aggregation of harness records, references, the best policy."""

from __future__ import annotations

from pathlib import Path

import pytest

from naruto_agent.benchmark import write_json_atomic
from tests.scripts import load_script

SCRIPT = Path(__file__).resolve().parents[3] / "benchmarks" / "published_budgets.py"


def _script():
    return load_script(SCRIPT, "published_budgets")


def _record(policy: str, seed: int, ratio: float, status: str = "ok") -> dict:
    return {
        "episode_id": f"apartment/{policy}/seed{seed}",
        "status": status,
        "scene": "apartment",
        "policy": policy,
        "seed": seed,
        "steps_run": 5000,
        "coverage_final": ratio / 100.0,
        "metrics": {
            "completion_ratio_pct": ratio / 2.0,
            "observable_completion_ratio_pct": ratio,
            "accuracy_cm": 1.3,
            "completion_cm": 6.0,
            "mad_cm": 2.0 + seed,
        },
        "path_length_m": 100.0,
        "collisions": 2,
        "time_per_step_ms": {"policy": 10.0, "env": 20.0, "mapping": 30.0},
    }


def test_report_has_every_policy_the_published_rows_and_the_best_policy(tmp_path):
    module = _script()
    records = [_record("naruto", seed, 97.0 + seed) for seed in range(3)]
    records += [_record("frontier", seed, 96.0 + seed) for seed in range(2)]
    records.append({**_record("frontier", 2, 0.0), "status": "failed", "error": "boom"})
    for record in records:
        write_json_atomic(tmp_path / "records" / f"{record['episode_id']}.json", record)
    section, summary = module.scene_report(tmp_path, neural=[])
    assert summary["best"]["metrics.observable_completion_ratio_pct"] == {
        "policy": "naruto", "mean": pytest.approx(98.0)}
    lines = {line.split(" | ")[0].strip("| "): line for line in section.splitlines()}
    assert "| 3 | 0 |" in lines["naruto"] and "| 2 | 1 |" in lines["frontier"]
    assert "3.00 ± 1.00" in lines["naruto"]  # MAD, mean ± std over seeds
    assert not any("MP3D" in line for line in lines)  # other houses: not set beside it
    with pytest.raises(FileNotFoundError, match="naruto-benchmark"):
        module.scene_report(tmp_path / "empty", neural=[])


def test_checkpoint_verdict_compares_the_mean_and_every_seed(tmp_path):
    """Coverage at ten checkpoints; NARUTO against frontier after step 500, in the mean over
    seeds and per seed, with the lowest margin and where it falls."""
    module = _script()
    steps = 1000
    ramp = [min(1.0, step / 600) for step in range(steps + 1)]
    records = []
    for seed in range(2):
        # NARUTO: the ramp, except seed 1, which trails by 2 points at step 800.
        naruto = [value - (0.02 if seed == 1 and step == 800 else 0.0)
                  for step, value in enumerate(ramp)]
        records.append({**_record("naruto", seed, 97.0), "coverage_curve": naruto})
        records.append({**_record("frontier", seed, 96.0),
                        "coverage_curve": [0.99 * value for value in ramp]})
    records.append({**_record("frontier", 2, 0.0), "status": "failed", "coverage_curve": None})
    marks, curves = module.coverage_at_checkpoints(records)
    assert marks == list(range(100, 1001, 100)) and set(curves) == {"naruto", "frontier"}
    assert curves["frontier"][0][9] == pytest.approx(99.0)
    verdict = module.checkpoint_verdict(marks, curves)
    assert verdict["seeds"] == [0, 1] and verdict["mean"]["checkpoints"] == 5  # 600 ... 1000
    assert verdict["mean"]["at_least_as_high"] == 5  # the mean still leads at 800
    seed1 = verdict["per_seed"][1]
    assert seed1["at_least_as_high"] == 4 and seed1["lowest_at_step"] == 800
    assert seed1["lowest_margin_pct"] == pytest.approx(-1.0)
    assert module.checkpoint_verdict(marks, {"naruto": curves["naruto"]}) is None
    lines, summary = module.checkpoint_lines(records)
    assert any("in the mean over seeds 5 of 5" in line and "seed 1: 4 of 5" in line
               for line in lines)
    assert summary["verdict"]["mean"]["at_least_as_high"] == 5
