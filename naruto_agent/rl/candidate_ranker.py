"""A learned ranking of the explorer's candidate goals: a small network that scores every
candidate of a decision with the same weights, trained to predict how much coverage choosing
it adds over the decision's other candidates.

The ranker reads the candidate feature table of a decision
(:data:`~naruto_gym.rl.goal_candidates.CANDIDATE_FEATURES`, valid rows first, nearest first)
and what lies around each candidate on the walker's map
(:func:`~naruto_gym.rl.goal_candidates.candidate_surroundings`: the shares of targets and of
unknown cells within 1.2 and 2.4 m of its cluster). Each valid row becomes the inputs of
:data:`RANKER_INPUTS`: the row's own columns, its path beyond the nearest candidate's, its
rank, the number of candidates, its size against the largest and its surroundings. An MLP
embeds every row; a second MLP scores each embedding beside the mean embedding of the
decision's rows, so the score of a candidate depends on the others and permuting the rows
permutes the scores.

Its target (``benchmarks/train_goal_ranker.py``) is a measured *advantage*: at decisions of
the train split, every candidate was walked on a copy of the env, map and walker (the nearest
candidate taken at every later decision) and its coverage gain averaged over the next
``horizon`` env steps (``benchmarks/explorer_leverage.py``); a candidate's advantage is that
mean gain minus the mean over the decision's candidates, in coverage points. The ranker
regresses the advantages (its scores centred per decision) and the policy walks the
candidate of the highest score: one step of policy improvement over the nearest choice, the
rule its data were measured with.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from naruto_gym.rl.goal_candidates import (
    CANDIDATE_FEATURES,
    SURROUNDING_RADII_M,
    candidate_surroundings,
)
from naruto_gym.rl.goal_walker import GoalWalker

__all__ = [
    "RANKER_INPUTS",
    "CandidateRanker",
    "RankerSettings",
    "load_ranker",
    "ranker_inputs",
    "save_ranker",
    "walker_surroundings",
]

#: The inputs of one candidate (:func:`ranker_inputs`).
RANKER_INPUTS = (
    *CANDIDATE_FEATURES[1:],
    "path_beyond_nearest",
    "rank",
    "count",
    "size_of_largest",
    *(
        f"{kind}_within_{radius:g}_m"
        for radius in SURROUNDING_RADII_M
        for kind in ("targets", "unknown")
    ),
)
_SURROUNDINGS = 2 * len(SURROUNDING_RADII_M)
_PATH = CANDIDATE_FEATURES.index("path_m")
_SIZE = CANDIDATE_FEATURES.index("size")
_VALID = CANDIDATE_FEATURES.index("valid")
#: Version of the saved file's layout.
FORMAT = 1


def ranker_inputs(table: np.ndarray, surroundings: np.ndarray) -> np.ndarray:
    """The inputs of every slot of one decision.

    Args:
        table: ``(N, len(CANDIDATE_FEATURES))`` rows, valid ones first (zeros in empty
            slots), as the goal actions' ``candidates`` observation.
        surroundings: ``(count, 4)`` what lies around each valid candidate
            (:func:`~naruto_gym.rl.goal_candidates.candidate_surroundings`).

    Returns:
        ``(N, len(RANKER_INPUTS))`` float32; zeros in the empty slots.
    """
    table = np.asarray(table, np.float32)
    slots = table.shape[0]
    out = np.zeros((slots, len(RANKER_INPUTS)), np.float32)
    count = int((table[:, _VALID] > 0).sum())
    if count == 0:
        return out
    rows = table[:count]
    own = len(CANDIDATE_FEATURES) - 1
    out[:count, :own] = rows[:, 1:]
    out[:count, own] = rows[:, _PATH] - rows[:, _PATH].min()
    out[:count, own + 1] = np.arange(count) / max(slots - 1, 1)
    out[:count, own + 2] = count / slots
    out[:count, own + 3] = rows[:, _SIZE] / max(float(rows[:, _SIZE].max()), 1e-6)
    out[:count, own + 4 :] = np.asarray(surroundings, np.float32)[:count, :_SURROUNDINGS]
    return out


def walker_surroundings(walker: GoalWalker, i: int, count: int) -> np.ndarray:
    """What lies around the first ``count`` candidates of agent ``i`` of a walker, on its map
    (:func:`~naruto_gym.rl.goal_candidates.candidate_surroundings`)."""
    world = walker.map
    return candidate_surroundings(
        world.coarse[i], world.origins[i], world.far_cell_m, walker.centres[i][:count]
    )


@dataclass(frozen=True)
class RankerSettings:
    """What a saved ranker was built and trained with."""

    hidden: int = 64
    """width of both MLPs"""
    num_candidates: int = 8
    """candidate slots of the table it reads"""
    horizon: int = 100
    """env steps its target's gain is averaged over"""


class CandidateRanker(nn.Module):
    """Scores every candidate of a batch of decisions with shared weights (module docstring).

    Args:
        settings: the network's width and the table it reads.
    """

    def __init__(self, settings: RankerSettings | None = None) -> None:
        super().__init__()
        self.settings = settings or RankerSettings()
        width = self.settings.hidden
        self.embed = nn.Sequential(
            nn.Linear(len(RANKER_INPUTS), width), nn.ReLU(), nn.Linear(width, width), nn.ReLU()
        )
        self.score = nn.Sequential(nn.Linear(2 * width, width), nn.ReLU(), nn.Linear(width, 1))

    def forward(self, inputs: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
        """Scores ``(B, N)`` of ``inputs`` ``(B, N, len(RANKER_INPUTS))``; ``valid`` ``(B, N)``
        masks the empty slots (their scores are ``-inf``)."""
        embedded = self.embed(inputs)
        weights = valid.float().unsqueeze(-1)
        pooled = (embedded * weights).sum(1) / weights.sum(1).clamp(min=1.0)
        pooled = pooled.unsqueeze(1).expand_as(embedded)
        scores = self.score(torch.cat([embedded, pooled], dim=-1)).squeeze(-1)
        return scores.masked_fill(~valid, float("-inf"))

    def reinitialise(self, seed: int) -> None:
        """Fresh weights drawn from ``seed`` (PyTorch's default initialisation of each
        layer), the global random state left as it was: the untrained twin."""
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(int(seed))
            for layer in self.modules():
                if isinstance(layer, nn.Linear):
                    layer.reset_parameters()

    @torch.no_grad()
    def choose(self, table: np.ndarray, surroundings: np.ndarray) -> int:
        """The slot of the highest score in one decision (:func:`ranker_inputs`' arguments);
        0, the nearest, with no valid candidate."""
        inputs = torch.from_numpy(ranker_inputs(table, surroundings))[None]
        valid = torch.from_numpy(np.asarray(table)[:, _VALID] > 0)[None]
        if not bool(valid.any()):
            return 0
        return int(torch.argmax(self(inputs, valid)[0]))


def save_ranker(ranker: CandidateRanker, path: str | Path, **record: Any) -> Path:
    """Write the ranker's weights and settings (and any JSON-able ``record``: how it was
    trained) to one file that :func:`load_ranker` reads."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "format": FORMAT,
        "inputs": list(RANKER_INPUTS),
        "settings": json.dumps(asdict(ranker.settings)),
        "record": json.dumps(record),
        "state": ranker.state_dict(),
    }
    torch.save(payload, path)
    return path


def load_ranker(path: str | Path) -> tuple[CandidateRanker, dict[str, Any]]:
    """The ranker saved at ``path`` and its training record.

    Raises:
        FileNotFoundError: no file at ``path`` (the message says how to train one).
        ValueError: a file that is not a ranker of this version's inputs.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(
            f"ranker {path} not found: train one with benchmarks/train_goal_ranker.py, or "
            f"leave model_path out for the packaged one"
        )
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:  # a zip of another kind, a truncated file ...
        raise ValueError(f"{path} is not a ranker file ({error})") from error
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise ValueError(f"{path} is not a ranker file of format {FORMAT}")
    if tuple(payload["inputs"]) != RANKER_INPUTS:
        raise ValueError(
            f"{path} reads the inputs {payload['inputs']}, this version gives "
            f"{list(RANKER_INPUTS)}: train it again with benchmarks/train_goal_ranker.py"
        )
    ranker = CandidateRanker(RankerSettings(**json.loads(payload["settings"])))
    ranker.load_state_dict(payload["state"])
    ranker.eval()
    return ranker, json.loads(payload["record"])
