"""Efficiency metrics on hand-made curves, seeded bootstrap intervals, paired comparisons."""

from __future__ import annotations

import numpy as np
import pytest

from naruto_agent.benchmark.efficiency import (
    area_under_curve,
    completion_points,
    cumulative_path,
    episode_efficiency,
    first_reach,
    mean_over_steps,
)
from naruto_agent.benchmark.statistics import bootstrap_ci, excludes_zero, paired_comparison
from naruto_agent.benchmark.suite import ordered_groups
from naruto_agent.benchmark.suite_report import class_summary, paired_summary, statistics_markdown


def _record(points, positions, budget, scene="s0", policy="p", seed=0, translation=None):
    env_kwargs = {} if translation is None else {"max_translation_m": translation}
    return {
        "status": "ok",
        "scene": scene,
        "policy": policy,
        "seed": seed,
        "config": {"steps": budget, "env_kwargs": env_kwargs},
        "completion_curve": [{"step": s, "completion_ratio_pct": c} for s, c in points],
        "trajectory": positions,
        "metrics": {"completion_ratio_pct": points[-1][1], "accuracy_cm": 1.0},
        "collisions": 2,
    }


def test_area_under_a_linear_and_a_step_curve():
    # linear from 0 to 100 % over the horizon: area 1/2
    assert area_under_curve(np.array([0.0, 10.0]), np.array([0.0, 100.0]), 10.0) == 0.5
    # reaches 100 % at half the horizon, then holds: 1/4 + 1/2
    assert area_under_curve(np.array([0.0, 5.0]), np.array([0.0, 100.0]), 10.0) == 0.75
    # points beyond the horizon are cut: 0..4 rises to 40 % at x=4 -> area 0.2*4/4 ... /100
    assert area_under_curve(np.array([0.0, 10.0]), np.array([0.0, 100.0]), 4.0) == pytest.approx(
        0.2
    )
    with pytest.raises(ValueError, match="horizon"):
        area_under_curve(np.array([0.0]), np.array([0.0]), 0.0)


def test_first_reach_interpolates_and_gives_none_when_never_reached():
    x, y = np.array([0.0, 10.0, 20.0]), np.array([0.0, 60.0, 90.0])
    assert first_reach(x, y, 30.0) == pytest.approx(5.0)
    assert first_reach(x, y, 80.0) == pytest.approx(10.0 + 10.0 * 20.0 / 30.0)
    assert first_reach(x, y, 95.0) is None


def test_cumulative_path_and_points():
    path = cumulative_path([[0, 0, 0], [3, 4, 0], [3, 4, 0], [3, 4, 1]])
    assert path.tolist() == [0.0, 5.0, 5.0, 6.0]
    steps, ratios = completion_points({"completion_curve": [
        {"step": 2, "completion_ratio_pct": 50.0}, {"step": 3, "completion_ratio_pct": None}]})
    assert steps.tolist() == [0.0, 2.0] and ratios.tolist() == [0.0, 50.0]


def test_episode_efficiency_of_a_hand_made_episode():
    # 10-step budget, 1 m per step along x; 80 % at step 4, 100 % at step 8 (then held).
    positions = [[float(t), 0.0, 0.0] for t in range(11)]
    record = _record([(4, 80.0), (8, 100.0), (10, 100.0)], positions, 10, translation=1.0)
    out = episode_efficiency(record)
    # area: 0..4 rises to 80 (160), 4..8 from 80 to 100 (360), 8..10 at 100 (200) -> 720/1000
    assert out["auc_steps"] == pytest.approx(0.72)
    # path horizon = 10 steps x 1 m, and metres equal steps here
    assert out["auc_path"] == pytest.approx(0.72)
    assert out["steps_to_80"] == 4 and out["metres_to_80"] == 4.0
    assert out["steps_to_90"] == 6 and out["metres_to_90"] == 6.0
    assert out["steps_to_95"] == 7  # 7.0 exactly: 80 + 15/20 * 4 steps after step 4
    assert out["path_m"] == 10.0


def test_a_policy_that_stands_still_while_mapping_keeps_its_ratio_per_metre():
    positions = [[0.0, 0.0, 0.0]] * 5 + [[float(t), 0.0, 0.0] for t in range(1, 6)]
    record = _record([(4, 60.0), (9, 60.0)], positions, 9, translation=1.0)
    out = episode_efficiency(record)
    # 60 % at 0 m (the camera turned on the spot), held over the 9 m horizon
    assert out["auc_path"] == pytest.approx(0.6)
    assert out["steps_to_80"] is None and out["metres_to_80"] is None


def test_a_record_without_a_completion_curve_has_no_areas():
    out = episode_efficiency({"config": {"steps": 5}, "trajectory": [[0, 0, 0], [1, 0, 0]]})
    assert out["auc_steps"] is None and out["steps_to_90"] is None and out["path_m"] == 1.0


def test_bootstrap_interval_is_seeded_and_covers_the_mean():
    values = np.arange(20, dtype=float)
    first = bootstrap_ci(values, seed=3)
    assert first == bootstrap_ci(values, seed=3)
    assert first["mean"] == pytest.approx(9.5)
    assert first["low"] < 9.5 < first["high"]
    # the standard error of the mean is std/sqrt(n) ~ 1.29: a 95 % interval ~ +-2.5
    assert 1.8 < 9.5 - first["low"] < 3.2 and 1.8 < first["high"] - 9.5 < 3.2
    assert bootstrap_ci([4.0])["low"] == 4.0
    assert bootstrap_ci([])["mean"] is None
    with pytest.raises(ValueError, match="confidence"):
        bootstrap_ci(values, confidence=1.5)


def test_grouped_bootstrap_sees_the_spread_between_scenes():
    # two scenes far apart, seeds within a scene equal: the two-level interval is wide,
    # the interval of the seeds of one scene is a point
    values = [0.0] * 5 + [10.0] * 5
    scenes = ["a"] * 5 + ["b"] * 5
    grouped = bootstrap_ci(values, scenes, seed=1)
    assert grouped["low"] == 0.0 and grouped["high"] == 10.0
    assert bootstrap_ci([10.0] * 5)["high"] == 10.0


def test_paired_comparison_removes_the_scene_difficulty():
    rng = np.random.default_rng(0)
    difficulty = {scene: 50.0 + 40.0 * rng.random() for scene in range(6)}
    a = {(s, k): difficulty[s] + 1.0 + 0.1 * rng.standard_normal() for s in range(6)
         for k in range(3)}
    b = {(s, k): difficulty[s] + 0.1 * rng.standard_normal() for s in range(6) for k in range(3)}
    b[(9, 0)] = 1.0  # not shared: left out
    result = paired_comparison(a, b, seed=0)
    overall = result["overall"]
    assert overall["n"] == 18 and overall["scenes"] == 6
    assert overall["mean"] == pytest.approx(1.0, abs=0.1)
    assert excludes_zero(overall)
    assert set(result["per_scene"]) == set(range(6))
    # unpaired, the scene spread swamps the same one-point lead
    unpaired = bootstrap_ci(list(a.values()), [key[0] for key in a], seed=0)
    assert unpaired["high"] - unpaired["low"] > 5 * (overall["high"] - overall["low"])


def test_class_summary_and_paired_summary_of_records():
    positions = [[float(t), 0.0, 0.0] for t in range(11)]
    records = []
    for scene in ("s0", "s1"):
        for seed in (0, 1):
            records.append(_record([(5, 90.0), (10, 95.0)], positions, 10, scene, "fast", seed))
            records.append(_record([(5, 40.0), (10, 85.0)], positions, 10, scene, "slow", seed))
    manifest = {"scenes": {"s0": {"size_class": "small"}, "s1": {"size_class": "small"}}}
    summary = class_summary(records, manifest, resamples=200)
    assert set(summary) == {"small"}
    fast = summary["small"]["fast"]
    assert fast["episodes"] == 4 and fast["scenes"] == 2
    assert fast["steps_to_90"]["reached"] == 4
    assert summary["small"]["slow"]["steps_to_90"]["reached"] == 0
    paired = paired_summary(records, manifest, resamples=200)
    auc = next(e for e in paired["small"] if e["metric"] == "auc_steps")
    assert auc["a"] == "fast" and auc["overall"]["mean"] > 0
    text = statistics_markdown(summary, paired)
    assert "## small" in text and "| fast | slow | auc_steps |" in text


def test_the_curve_is_the_observable_surfaces_where_the_record_has_it():
    """The whole surface's ratio counts faces no camera inside can see (it stays near half in
    a closed house), so the levels are read on the observable surface's ratio."""
    curve = [{"step": 5, "completion_ratio_pct": 40.0, "observable_completion_ratio_pct": 80.0},
             {"step": 10, "completion_ratio_pct": 48.0, "observable_completion_ratio_pct": 96.0}]
    steps, ratios = completion_points({"completion_curve": curve})
    np.testing.assert_allclose(ratios, [0.0, 80.0, 96.0])
    whole = [{key: value for key, value in point.items() if not key.startswith("observable")}
             for point in curve]
    np.testing.assert_allclose(completion_points({"completion_curve": whole})[1],
                               [0.0, 40.0, 48.0])


def test_the_open_variant_is_its_own_group_and_follows_its_closed_class():
    positions = [[float(t), 0.0, 0.0] for t in range(11)]
    records = [
        _record([(5, 90.0), (10, 95.0)], positions, 10, "h0", "p"),
        _record([(5, 20.0), (10, 30.0)], positions, 10, "h0-open", "p"),
        _record([(5, 50.0), (10, 60.0)], positions, 10, "s0", "p"),
    ]
    manifest = {"scenes": {
        "h0": {"size_class": "house", "variant": "closed"},
        "h0-open": {"size_class": "house", "variant": "open"},
        "s0": {"size_class": "small", "variant": "closed"},
    }}
    summary = class_summary(records, manifest, resamples=50)
    assert ordered_groups(summary) == ["small", "house", "house (open)"]
    closed = summary["house"]["p"]["completion_ratio_pct"]["mean"]
    opened = summary["house (open)"]["p"]["completion_ratio_pct"]["mean"]
    assert (closed, opened) == (95.0, 30.0)


def test_mean_over_steps_holds_the_last_value_and_cuts_at_the_budget():
    assert mean_over_steps([0.0, 0.5, 1.0], 3) == 0.5
    assert mean_over_steps([0.2, 0.4], 4) == (0.2 + 0.4 + 0.4 + 0.4) / 4
    assert np.isclose(mean_over_steps([0.2, 0.4, 0.9, 0.9], 2), 0.3)
