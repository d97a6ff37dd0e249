"""The learned candidate ranker (``goal-ranker``): its inputs, its network's symmetry, its
file, its untrained twin, its training script and the policy in the harness."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from naruto_agent.cli_args import parse_dataclass_args
from naruto_agent.policies.registry import make_policy
from naruto_agent.rl.candidate_ranker import (
    RANKER_INPUTS,
    CandidateRanker,
    load_ranker,
    ranker_inputs,
    save_ranker,
)
from naruto_gym.rl.egocentric_map_kernels import FREE, OCCUPIED, SEEN
from naruto_gym.rl.goal_candidates import CANDIDATE_FEATURES, candidate_surroundings
from tests.scripts import load_script

ROOT = Path(__file__).resolve().parents[3]


def _table(rows: list[list[float]], slots: int = 8) -> np.ndarray:
    table = np.zeros((slots, len(CANDIDATE_FEATURES)), np.float32)
    for k, row in enumerate(rows):
        table[k] = [1.0, *row]
    return table


TABLE = _table(
    [
        [0.10, 0.12, 0.5, 0.8, 0.25, 1.0, 0.0],
        [0.30, 0.20, -0.6, 0.7, 1.00, 0.5, 1.0],
        [0.45, 0.40, 0.0, -1.0, 0.50, 0.0, 0.0],
    ]
)
AROUND = np.array([[0.1, 0.2, 0.05, 0.3], [0.0, 0.5, 0.1, 0.6], [0.2, 0.1, 0.2, 0.2]])


def test_inputs_of_a_decision_relate_each_candidate_to_the_others():
    inputs = ranker_inputs(TABLE, AROUND)
    assert inputs.shape == (8, len(RANKER_INPUTS))
    assert not inputs[3:].any()  # empty slots
    column = {name: k for k, name in enumerate(RANKER_INPUTS)}
    assert inputs[:3, column["path_beyond_nearest"]] == pytest.approx([0.0, 0.2, 0.35])
    assert inputs[:3, column["rank"]] == pytest.approx([0.0, 1 / 7, 2 / 7])
    assert inputs[:3, column["count"]] == pytest.approx([3 / 8] * 3)
    assert inputs[:3, column["size_of_largest"]] == pytest.approx([0.25, 1.0, 0.5])
    assert inputs[:3, column["unknown_within_2.4_m"]] == pytest.approx([0.3, 0.6, 0.2])
    assert not ranker_inputs(np.zeros_like(TABLE), np.zeros((0, 4))).any()


def test_scores_are_shared_per_candidate_and_empty_slots_are_never_chosen():
    ranker = CandidateRanker()
    ranker.reinitialise(3)
    inputs = torch.from_numpy(np.random.default_rng(0).normal(size=(2, 8, len(RANKER_INPUTS))))
    valid = torch.tensor([[True] * 5 + [False] * 3, [True] * 8])
    scores = ranker(inputs.float(), valid)
    order = torch.tensor([2, 0, 4, 1, 3, 5, 6, 7])
    permuted = ranker(inputs.float()[:, order], valid[:, order])
    assert torch.allclose(permuted, scores[:, order], atol=1e-6)
    assert torch.isinf(scores[0, 5:]).all() and torch.isfinite(scores[1]).all()
    assert ranker.choose(TABLE, AROUND) in (0, 1, 2)
    assert ranker.choose(np.zeros_like(TABLE), np.zeros((0, 4))) == 0


def test_the_untrained_twin_is_drawn_from_its_seed(tmp_path):
    trained = CandidateRanker()
    first, again, other = CandidateRanker(), CandidateRanker(), CandidateRanker()
    first.reinitialise(5), again.reinitialise(5), other.reinitialise(6)
    weights = [
        [p.detach().numpy().copy() for p in model.parameters()]
        for model in (first, again, other, trained)
    ]
    assert all(np.array_equal(a, b) for a, b in zip(weights[0], weights[1], strict=True))
    assert not any(np.array_equal(a, b) for a, b in zip(weights[0], weights[2], strict=True))
    assert not any(np.array_equal(a, b) for a, b in zip(weights[0], weights[3], strict=True))


def test_a_saved_ranker_scores_as_before_and_bad_files_are_refused(tmp_path):
    ranker = CandidateRanker()
    path = save_ranker(ranker, tmp_path / "ranker.pt", decisions=12)
    loaded, record = load_ranker(path)
    inputs = torch.from_numpy(ranker_inputs(TABLE, AROUND))[None]
    valid = torch.from_numpy(TABLE[:, 0] > 0)[None]
    assert torch.equal(loaded(inputs, valid), ranker(inputs, valid)) and record == {"decisions": 12}
    with pytest.raises(FileNotFoundError, match="train_goal_ranker.py"):
        load_ranker(tmp_path / "missing.pt")
    (tmp_path / "other.pt").write_bytes(b"not a ranker")
    with pytest.raises(ValueError, match="not a ranker file"):
        load_ranker(tmp_path / "other.pt")
    with pytest.raises(ValueError, match="weights must be one of"):
        make_policy("goal-ranker", model_path=str(path), weights="fresh")


def test_surroundings_count_targets_and_unknown_cells_around_each_cluster():
    coarse = np.zeros((4, 10, 10), np.uint8)
    coarse[FREE, :, :5] = 1  # the left half is free, the right half unknown
    coarse[OCCUPIED, 2, 2] = 1  # an obstacle the camera has not seen ...
    coarse[OCCUPIED, 6, 2] = coarse[SEEN, 6, 2] = 1  # ... and one it has
    coarse[FREE, 2, 2] = coarse[FREE, 6, 2] = 0
    centres = np.array([[2.5, 2.5], [2.5, 7.5], [0.5, 0.5]])  # world metres, 1 m cells
    around = candidate_surroundings(coarse, np.zeros(2), 1.0, centres, radii_m=(1.0,))
    # Deep in the free half: the unseen obstacle is the one target of 9 cells, none unknown.
    assert around[0] == pytest.approx([1 / 9, 0.0])
    # In the unknown half: no target inside the square, every cell unknown.
    assert around[1] == pytest.approx([0.0, 1.0])
    # At the map's corner: the 5 cells outside count as unknown; the free cells beside them
    # (the map's edge) are targets.
    assert around[2][1] == pytest.approx(5 / 9) and around[2][0] == pytest.approx(3 / 9)


@pytest.fixture(scope="module")
def trainer():
    yield load_script(ROOT / "benchmarks" / "train_goal_ranker.py", "train_goal_ranker_under_test")
    del sys.modules["train_goal_ranker_under_test"]


def test_the_target_is_the_gain_averaged_over_the_horizon(trainer):
    gains = {"10": [0.01, 0.02], "20": [0.02, 0.02], "goal": [0.5, 0.5]}
    # Trapezoids from 0 at the decision: (0 + 1) / 2 * 10 + (1 + 2) / 2 * 10 = 20 point-steps.
    assert trainer.mean_gain(gains, 20, 2) == pytest.approx([1.0, 1.5])
    with pytest.raises(ValueError, match="horizon 40 was not measured"):
        trainer.mean_gain(gains, 40, 2)


def test_fitting_learns_a_ranking_that_the_features_decide(trainer):
    """Synthetic decisions whose best candidate is decided by its size, path and what lies
    around it: a fitted ranker finds it on held-out decisions, its untrained twin does
    not."""
    rng = np.random.default_rng(0)
    tables, gains, around = [], [], []
    for _ in range(300):
        count = int(rng.integers(2, 9))
        rows = np.column_stack(
            [
                np.sort(rng.uniform(0, 0.5, count)),  # path, nearest first
                rng.uniform(0, 0.5, count),
                rng.uniform(-1, 1, (count, 2)),
                rng.uniform(0.1, 1.0, count),  # size
                rng.uniform(0, 1, (count, 2)),
            ]
        )
        tables.append(_table(rows.tolist()))
        around.append(rng.uniform(0, 1, (count, 4)))
        row = np.zeros(8)
        row[:count] = 10 * rows[:, 4] - 4 * rows[:, 0] + 3 * around[-1][:, 3]
        gains.append(row)
    tables = np.asarray(tables)
    data = trainer.Decisions(
        np.asarray([ranker_inputs(t, a) for t, a in zip(tables, around, strict=True)]),
        tables[:, :, 0] > 0,
        np.asarray(gains),
        tables,
        [f"scene{k % 10}" for k in range(len(tables))],
    )
    train, held = trainer.split(data, 5, 4)
    args = parse_dataclass_args(trainer.Args, ["--epochs", "300"])
    fitted = trainer.ranker_levels(trainer.fit(train, args, seed=0), held)
    twin = CandidateRanker()
    twin.reinitialise(0)
    untrained = trainer.ranker_levels(twin, held)
    assert fitted["explained_variance"] > 0.8
    assert fitted["regret"] < 0.25 * untrained["regret"]
    assert fitted["gain_over_nearest"] > trainer.rule_levels(held)["largest"]["gain_over_nearest"]


def test_measured_decisions_train_a_ranker_that_the_policy_and_its_twin_play(trainer, tmp_path):
    leverage = load_script(ROOT / "benchmarks" / "explorer_leverage.py", "leverage_for_ranker")
    try:
        runs = []
        for scene in ("procedural:small:0", "procedural:small:1"):
            runs.append(str(tmp_path / f"{scene.rsplit(':', 1)[1]}.json"))
            argv = ["--scenes", scene, "--max-episode-steps", "60", "--decision", "goal",
                    "--advance", "nearest", "--horizons", "5", "10",
                    "--output-file", runs[-1]]  # fmt: skip
            leverage.main(parse_dataclass_args(leverage.Args, argv))
    finally:
        del sys.modules["leverage_for_ranker"]
    out = tmp_path / "ranker"
    argv = ["--data", *runs, "--horizon", "10", "--compare-horizons", "5", "--folds", "2",
            "--sizes", "2", "100", "--seeds", "0", "1", "--epochs", "20",
            "--output-dir", str(out)]  # fmt: skip
    path = trainer.main(parse_dataclass_args(trainer.Args, argv))
    curve = (out / "curve.csv").read_text().splitlines()
    assert curve[0].startswith("seed,decisions,gain_over_nearest,regret,explained_variance")
    assert len(curve) == 1 + 2 * 2
    horizons = json.loads((out / "horizons.json").read_text())
    assert sorted(horizons) == ["10", "5"]
    assert horizons["5"]["rules"]["nearest"]["gain_over_nearest"] == 0.0
    assert set(horizons["10"]["ranker"]) == {"gain_over_nearest", "regret", "explained_variance"}
    _, record = load_ranker(path)
    assert record["horizon"] == 10 and record["decisions"] > 2

    import gymnasium as gym

    from naruto_agent.episode_loop import StepRecords, run_episode_loop

    for name in ("goal-ranker", "goal-ranker-untrained"):
        policy = make_policy(name, model_path=str(path))
        env = gym.make(
            "NarutoRecon-v0", scene="procedural:small:2", action_mode="discrete",
            image_scale=0.05, max_episode_steps=40,
        )  # fmt: skip
        records = StepRecords()
        run_episode_loop(env, policy, 40, 0, [records])
        env.close()
        assert len(records.coverage) == 41 and records.coverage[-1] > records.coverage[0]
        assert policy.settings["decision"] == "goal"
