"""Train the candidate ranker of ``goal-ranker`` from measured decisions. Results:
docs/benchmarks/goal-ranker.md

The data are runs of ``benchmarks/explorer_leverage.py --decision goal`` on the train split:
at every decision each candidate was walked on a copy of the env, map and walker (the
nearest candidate taken at every later decision) and its coverage gain recorded at several
horizons. A candidate's target is its gain averaged over the next ``--horizon`` env steps
(the area under its gain curve, trapezoids over the horizons measured) minus the mean over
the decision's candidates, in coverage points
(:mod:`naruto_agent.rl.candidate_ranker`). Decisions with fewer than two candidates teach
nothing and are left out.

The curve is cross-validated by scene: in fold ``k`` of ``--folds`` the scenes whose place in
name order is ``k`` modulo ``--folds`` are held out. For each training seed and each ``n`` of
``--sizes``, a ranker is trained in every fold on the first ``n`` decisions of the seed's
shuffle of the fold's other scenes, and the curve (``curve.csv``) gives per seed and ``n``,
averaged over the folds, on the held-out decisions:

* ``gain_over_nearest``: the mean gain of the ranker's choice minus the nearest candidate's
  (coverage points over the horizon; the nearest rule, the data's own continuation, is 0);
* ``regret``: the best candidate's gain minus the choice's;
* ``explained_variance``: of the targets by the ranker's centred scores.

``levels.json`` holds the same for the untrained twin (the same network, fresh weights per
seed) and for every scripted rule of ``goal-walker``, and ``curve.png`` draws them all. The
ranker trained on every decision with the first seed is written to ``ranker.pt``.

``horizons.json`` holds the same levels at the largest training size for each of
``--compare-horizons`` beside ``--horizon``: how far ahead the gains are predictable (the
farther, the more a gain depends on the later decisions, and the less on this one).

    python benchmarks/train_goal_ranker.py --data runs/ranker/decisions.json \\
        --output-dir runs/goal_ranker
"""

from __future__ import annotations

import csv
import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from naruto_agent.cli_args import parse_dataclass_args
from naruto_agent.rl.candidate_ranker import (
    CandidateRanker,
    RankerSettings,
    ranker_inputs,
    save_ranker,
)
from naruto_agent.rl.scripted_explorer import CHOICE_RULES, choose_candidate
from naruto_gym.rl.goal_candidates import CANDIDATE_FEATURES


@dataclass
class Args:
    data: list[str] = field(
        default_factory=lambda: ["runs/ranker/decisions.json", "runs/ranker/decisions_flat.json"]
    )
    """leverage runs (``explorer_leverage.py --decision goal``) of the train split"""
    horizon: int = 20
    """env steps a candidate's gain is averaged over (at most the runs' longest horizon); 20:
    the horizon whose gains the ranker predicts best beyond the rules (``horizons.json``)"""
    compare_horizons: list[int] = field(default_factory=lambda: [10, 30, 40, 100])
    """other horizons cross-validated at the largest training size (none: skip)"""
    folds: int = 4
    """folds of the cross-validation by scene (scene k in name order is held out in fold
    k modulo folds)"""
    seeds: list[int] = field(default_factory=lambda: [0, 1, 2])
    """training seeds (shuffle of the decisions and the network's initial weights)"""
    sizes: list[int] = field(default_factory=lambda: [25, 50, 100, 200, 400, 800, 1600])
    """training decisions per point of the curve (more than the data hold: all of them)"""
    epochs: int = 200
    """full-batch Adam steps"""
    learning_rate: float = 3e-3
    """Adam's learning rate"""
    weight_decay: float = 1e-3
    """Adam's weight decay"""
    hidden: int = 16
    """width of the ranker's MLPs (small: a few hundred decisions train it)"""
    num_candidates: int = 8
    """candidate slots"""
    output_dir: str = "runs/goal_ranker"
    """output folder"""


@dataclass
class Decisions:
    """Decisions as arrays: inputs ``(D, N, F)``, valid ``(D, N)``, gains ``(D, N)`` (coverage
    points, mean over the horizon; 0 in empty slots), tables ``(D, N, C)``, scene names."""

    inputs: np.ndarray
    valid: np.ndarray
    gains: np.ndarray
    tables: np.ndarray
    scenes: list[str]

    def take(self, index: np.ndarray) -> Decisions:
        return Decisions(
            self.inputs[index],
            self.valid[index],
            self.gains[index],
            self.tables[index],
            [self.scenes[i] for i in index],
        )

    def __len__(self) -> int:
        return len(self.scenes)


def mean_gain(gains: dict[str, list[float]], horizon: int, count: int) -> np.ndarray:
    """Each candidate's gain averaged over the first ``horizon`` steps: trapezoids over the
    measured horizons, from 0 gain at the decision, in coverage points.

    Raises:
        ValueError: ``horizon`` is not among the horizons measured.
    """
    steps = sorted(int(h) for h in gains if h.isdigit())
    if horizon not in steps:
        raise ValueError(f"horizon {horizon} was not measured (the runs have {steps})")
    steps = [0, *[h for h in steps if h <= horizon]]
    curve = np.zeros((len(steps), count))
    for row, h in enumerate(steps[1:], start=1):
        curve[row] = gains[str(h)][:count]
    return 100.0 * np.trapezoid(curve, steps, axis=0) / horizon


def load_decisions(paths: list[str], horizon: int, slots: int) -> Decisions:
    """Every decision with two or more candidates of the runs at ``paths``.

    Raises:
        ValueError: a run without the candidate tables and surroundings (measured before
            they were recorded).
    """
    inputs, valid, gains, tables, scenes = [], [], [], [], []
    for path in paths:
        run = json.loads(Path(path).read_text())
        for key, episode in run["episodes"].items():
            for decision in episode["decisions"]:
                count = int(decision["candidates"])
                if count < 2:
                    continue
                if "surroundings" not in decision:
                    raise ValueError(
                        f"{path} has no candidate tables and surroundings: measure it again "
                        f"with this version of benchmarks/explorer_leverage.py"
                    )
                table = np.zeros((slots, len(CANDIDATE_FEATURES)), np.float32)
                table[:count] = decision["table"]
                inputs.append(ranker_inputs(table, np.asarray(decision["surroundings"])))
                valid.append(table[:, 0] > 0)
                row = np.zeros(slots)
                row[:count] = mean_gain(decision["gains"], horizon, count)
                gains.append(row)
                tables.append(table)
                scenes.append(key.rpartition("/")[0])
    return Decisions(
        np.asarray(inputs), np.asarray(valid), np.asarray(gains), np.asarray(tables), scenes
    )


def advantages(data: Decisions) -> np.ndarray:
    """Gains minus each decision's mean over its candidates (0 in empty slots)."""
    count = data.valid.sum(1, keepdims=True)
    mean = (data.gains * data.valid).sum(1, keepdims=True) / count
    return (data.gains - mean) * data.valid


def centred_scores(ranker: CandidateRanker, data: Decisions) -> np.ndarray:
    """The ranker's scores minus each decision's mean over its candidates (0 in empty
    slots)."""
    with torch.no_grad():
        scores = ranker(torch.from_numpy(data.inputs), torch.from_numpy(data.valid))
    valid = torch.from_numpy(data.valid)
    scores = scores.masked_fill(~valid, 0.0)
    mean = scores.sum(1, keepdim=True) / valid.sum(1, keepdim=True)
    return ((scores - mean) * valid).numpy()


def fit(data: Decisions, args: Args, seed: int, horizon: int | None = None) -> CandidateRanker:
    """A ranker trained on ``data`` (full-batch Adam on the squared error of its centred
    scores against the advantages over ``horizon``, by default ``args.horizon``)."""
    torch.manual_seed(seed)
    ranker = CandidateRanker(
        RankerSettings(args.hidden, args.num_candidates, horizon or args.horizon)
    )
    optimiser = torch.optim.Adam(
        ranker.parameters(), lr=args.learning_rate, weight_decay=args.weight_decay
    )
    inputs, valid = torch.from_numpy(data.inputs), torch.from_numpy(data.valid)
    target = torch.from_numpy(advantages(data)).float()
    count = valid.sum(1, keepdim=True)
    for _ in range(args.epochs):
        scores = ranker(inputs, valid).masked_fill(~valid, 0.0)
        centred = (scores - scores.sum(1, keepdim=True) / count) * valid
        loss = ((centred - target) ** 2).sum() / valid.sum()
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    ranker.eval()
    return ranker


def choice_levels(data: Decisions, chosen: np.ndarray) -> dict[str, float]:
    """Mean gain of the ``chosen`` slots over the nearest's, and the regret (coverage points)."""
    rows = np.arange(len(data))
    picked = data.gains[rows, chosen]
    best = np.where(data.valid, data.gains, -np.inf).max(1)
    return {
        "gain_over_nearest": round(float((picked - data.gains[:, 0]).mean()), 4),
        "regret": round(float((best - picked).mean()), 4),
    }


def ranker_levels(ranker: CandidateRanker, data: Decisions) -> dict[str, float]:
    """:func:`choice_levels` of the ranker's choices, and the explained variance of the
    advantages by its centred scores."""
    scores = centred_scores(ranker, data)
    chosen = np.where(data.valid, scores, -np.inf).argmax(1)
    target = advantages(data)[data.valid]
    residual = target - scores[data.valid]
    explained = 1.0 - residual.var() / max(float(target.var()), 1e-12)
    return {**choice_levels(data, chosen), "explained_variance": round(float(explained), 4)}


def rule_levels(data: Decisions) -> dict[str, dict[str, float]]:
    """:func:`choice_levels` of every scripted rule (``random``: its expectation, the mean
    over the valid slots)."""
    out = {}
    for rule in CHOICE_RULES:
        if rule == "random":
            count = data.valid.sum(1)
            mean = (data.gains * data.valid).sum(1) / count
            best = np.where(data.valid, data.gains, -np.inf).max(1)
            out[rule] = {
                "gain_over_nearest": round(float((mean - data.gains[:, 0]).mean()), 4),
                "regret": round(float((best - mean).mean()), 4),
            }
            continue
        rng = np.random.default_rng(0)
        chosen = np.array([choose_candidate(t, rule, rng) for t in data.tables])
        out[rule] = choice_levels(data, chosen)
    return out


def split(data: Decisions, folds: int, fold: int) -> tuple[Decisions, Decisions]:
    """(training, held-out) decisions of one fold: the scenes whose place in name order is
    ``fold`` modulo ``folds`` held out."""
    names = sorted(set(data.scenes))
    held = {name for k, name in enumerate(names) if k % folds == fold}
    mask = np.array([scene in held for scene in data.scenes])
    return data.take(np.flatnonzero(~mask)), data.take(np.flatnonzero(mask))


def mean_levels(levels: list[dict[str, float]]) -> dict[str, float]:
    """Each level's mean over folds."""
    return {key: round(float(np.mean([entry[key] for entry in levels])), 4) for key in levels[0]}


def plot_curve(rows: list[dict[str, Any]], levels: dict[str, Any], path: Path) -> Path:
    """The learning curve (mean and spread over the seeds) against the untrained twin's and
    the scripted rules' levels, and the explained variance, as one figure."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sizes = sorted({row["decisions"] for row in rows})
    figure, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
    for axis, metric in ((left, "gain_over_nearest"), (right, "explained_variance")):
        values = np.array([[r[metric] for r in rows if r["decisions"] == n] for n in sizes])
        mean, spread = values.mean(1), values.std(1)
        axis.plot(sizes, mean, "o-", color="C0", label=f"ranker ({values.shape[1]} seeds)")
        axis.fill_between(sizes, mean - spread, mean + spread, color="C0", alpha=0.25)
        axis.axhline(
            float(np.mean([u[metric] for u in levels["untrained"]])),
            color="C3", linestyle="--", label="untrained twin",
        )  # fmt: skip
        axis.set_xscale("log")
        axis.set_xticks(sizes, [str(n) for n in sizes])
        axis.minorticks_off()
        axis.set_xlabel("training decisions")
    for k, (rule, level) in enumerate(levels["rules"].items()):
        left.axhline(level["gain_over_nearest"], color=f"C{k + 4}", linestyle=":", label=rule)
    left.set_ylabel(f"gain over nearest (coverage points, {levels['args']['horizon']} steps)")
    right.set_ylabel("explained variance of the advantages")
    left.legend(fontsize=7)
    right.legend(fontsize=7)
    figure.suptitle(
        f"held-out decisions, {levels['args']['folds']} folds by scene "
        f"({levels['decisions']} decisions, {levels['scenes']} scenes)"
    )
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path


def cross_validate(
    data: Decisions, args: Args, horizon: int, sizes: list[int]
) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """The curve's rows (per seed and training size) and the levels of the untrained twin
    and the rules, on the held-out decisions of every fold, for gains over ``horizon``."""
    folds = [split(data, args.folds, fold) for fold in range(args.folds)]
    largest = min(len(train) for train, _ in folds)
    settings = RankerSettings(args.hidden, args.num_candidates, horizon)
    rows: list[dict[str, Any]] = []
    untrained: list[dict[str, float]] = []
    for seed in args.seeds:
        twin = CandidateRanker(settings)
        twin.reinitialise(seed)
        untrained.append(mean_levels([ranker_levels(twin, held) for _, held in folds]))
        for size in sorted({min(n, largest) for n in sizes}):
            started = time.perf_counter()
            per_fold = []
            for train, held in folds:
                order = np.random.default_rng(seed).permutation(len(train))
                ranker = fit(train.take(order[:size]), args, seed, horizon)
                per_fold.append(ranker_levels(ranker, held))
            row = {"seed": seed, "decisions": size, **mean_levels(per_fold)}
            row["seconds"] = round(time.perf_counter() - started, 1)
            rows.append(row)
            print(row, flush=True)
    rules = [rule_levels(held) for _, held in folds]
    levels = {
        "decisions": len(data),
        "scenes": len(set(data.scenes)),
        "untrained": untrained,
        "rules": {rule: mean_levels([fold[rule] for fold in rules]) for rule in rules[0]},
    }
    return rows, levels


def compare_horizons(args: Args) -> dict[str, Any]:
    """The ranker's, the twin's and the rules' held-out levels at the largest training size
    for ``--horizon`` and each of ``--compare-horizons`` (means over the seeds)."""
    out: dict[str, Any] = {}
    for horizon in sorted({args.horizon, *args.compare_horizons}):
        data = load_decisions(args.data, horizon, args.num_candidates)
        rows, levels = cross_validate(data, args, horizon, [len(data)])
        out[str(horizon)] = {
            "ranker": mean_levels([{k: r[k] for k in r if k not in ("seed", "decisions",
                                                                    "seconds")} for r in rows]),
            "untrained": mean_levels(levels["untrained"]),
            "rules": levels["rules"],
        }
    return out


def main(args: Args) -> Path:
    torch.set_num_threads(1)
    out = Path(args.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    data = load_decisions(args.data, args.horizon, args.num_candidates)
    scenes = len(set(data.scenes))
    if scenes < args.folds or args.folds < 2:
        raise ValueError(
            f"{args.folds} folds need at least 2 and at most the {scenes} scenes of the data"
        )
    print(f"{len(data)} decisions of {scenes} scenes, {args.folds} folds by scene")
    rows, levels = cross_validate(data, args, args.horizon, args.sizes)
    levels["args"] = asdict(args)
    with (out / "curve.csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    (out / "levels.json").write_text(json.dumps(levels, indent=1))
    plot_curve(rows, levels, out / "curve.png")
    if args.compare_horizons:
        horizons = compare_horizons(args)
        (out / "horizons.json").write_text(json.dumps(horizons, indent=1))
        for horizon, entry in horizons.items():
            print(f"horizon {horizon}: ranker {entry['ranker']}, "
                  f"twin {entry['untrained']['gain_over_nearest']}, rules "
                  f"{ {rule: v['gain_over_nearest'] for rule, v in entry['rules'].items()} }")
    ranker = fit(data, args, args.seeds[0])
    path = save_ranker(
        ranker,
        out / "ranker.pt",
        decisions=len(data),
        scenes=scenes,
        horizon=args.horizon,
        data=args.data,
    )
    print(f"rules on the held-out decisions: {levels['rules']}")
    print(f"untrained twin: {levels['untrained']}")
    print(f"wrote {path} ({path.stat().st_size / 1024:.0f} kB)")
    return path


if __name__ == "__main__":
    main(parse_dataclass_args(Args))
