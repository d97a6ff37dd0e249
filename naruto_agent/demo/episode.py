"""The record of one demo episode: what the loop (:mod:`.run`) produced and the writers
(:mod:`.outputs`) turn into files.

It lives in its own module so that both depend on it and neither on the other.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import trimesh


@dataclass
class Episode:
    """What one demo episode produced.

    Attributes:
        steps_run: steps taken.
        coverage: coverage (fraction of the observable surface seen) after reset and each step.
        completion_curve: ``{"step", "completion_ratio_pct", ...}`` at the evaluation points.
        poses: (steps_run + 1, 4, 4) camera-to-world poses, start included.
        goals: (G, 3) goals the policy chose.
        frames: (step, picture) of the subsampled ``rgb_array`` frames.
        collisions: refused or shortened moves, by reason.
        path_length_m: distance travelled.
        times_s: seconds per phase (``policy``, ``env``, ``mapping``, ``pictures``,
            ``eval_points``, ``recording``).
        mesh: the reconstruction scored at the end.
        map_source: where ``mesh`` comes from.
        camera_size: (height, width) of the frames, the order of the docs and of image
            arrays.
        policy_detail_s: the policy's own per-phase seconds, when it keeps them.
        stalled_steps: steps spent in a stall (the policy's stall watchdog; 0 without one).
        stall_recoveries: the watchdog's triggers (``StallEvent.as_dict()``), in order.
    """

    steps_run: int
    coverage: list[float]
    completion_curve: list[dict[str, Any]]
    poses: np.ndarray
    goals: np.ndarray
    frames: list[tuple[int, np.ndarray]]
    collisions: Counter[str]
    path_length_m: float
    times_s: dict[str, float]
    mesh: trimesh.Trimesh
    map_source: str
    camera_size: tuple[int, int]
    policy_detail_s: dict[str, float]
    stalled_steps: int = 0
    stall_recoveries: list[dict[str, Any]] = field(default_factory=list)
