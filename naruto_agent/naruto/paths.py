"""The paths the NARUTO agent follows: E-RRT paths cut short where straight segments allow.

E-RRT's chain of tree nodes zigzags and, where the tree grew around a room before it found
the door, can run many times the needed length. With ``shortcut_paths`` on, every stretch
that a straight free segment covers is cut short
(:func:`~naruto_agent.planning.shortcut_path`, keeping the planner's clearance plus
``shortcut_margin_m``), and the result is split into nodes a planner step apart again.
"""

from __future__ import annotations

import numpy as np

from naruto_agent.mapping import SdfVolume
from naruto_agent.naruto.config import NarutoConfig
from naruto_agent.naruto.recovery import densify
from naruto_agent.planning import shortcut_path


def shorten_path(sdf: SdfVolume, path: np.ndarray, config: NarutoConfig) -> np.ndarray:
    """``path`` shortcut on ``sdf`` (``shortcut_paths``; unchanged when it is off).

    Args:
        sdf: the planner view the path was planned on.
        path: (K, 3) nodes a planner step apart.
        config: the agent's settings.

    Returns:
        (K', 3) nodes, consecutive ones at most ``planner.step_m`` apart.
    """
    if not config.shortcut_paths:
        return path
    planner = config.planner
    clearance = planner.clearance_m + config.shortcut_margin_m
    return densify(shortcut_path(sdf, path, clearance, planner.collision_sample_m),
                   planner.step_m)
