"""What the NARUTO agent shows of its thinking in a recording (:meth:`Policy.view_layers`).

* ``goal``, ``planned path`` and ``view targets``: the plan the agent follows now (its goal,
  the E-RRT path to it, the points it will look at there);
* ``goals chosen``: every goal a planning request returned this episode;
* ``frontier``: free voxels next to unexplored space in the agent's observed-space grid;
* ``uncertain surfaces``: the planner view's most uncertain voxels near the reconstructed
  surface, which the goal search of Feng et al. (NARUTO, CVPR 2024) aims the camera at,
  coloured from yellow (less) to red (most);
* ``observed space (%)``: the share of the observed-space grid that rays have reached.

Everything here reads the agent's state and changes nothing (the frontier it reads is the
one the goal search computes and caches anyway).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from naruto_agent.naruto.agent_map import AgentMap
from naruto_agent.naruto.state_machine import Plan
from naruto_agent.policies.layers import Layer, LinesLayer, PointsLayer, ScalarLayer, subsample

#: At most this many frontier voxels and uncertain voxels per step, so recordings stay light.
MAX_FRONTIER_POINTS = 3000
MAX_UNCERTAIN_POINTS = 400


def plan_layers(plan: Plan | None, plans: list[dict[str, Any]]) -> list[Layer]:
    """The current plan (goal, path, view targets) and the goals chosen so far."""
    layers: list[Layer] = []
    goals = [entry["goal"] for entry in plans if isinstance(entry, dict) and "goal" in entry]
    layers.append(PointsLayer("goals chosen", np.reshape(np.asarray(goals, np.float64), (-1, 3)),
                              colour=(255, 255, 255), radius_m=0.04))
    if plan is not None:
        layers.append(PointsLayer("goal", np.reshape(plan.goal, (1, 3)), colour=(255, 200, 0),
                                  radius_m=0.08))
        layers.append(LinesLayer("planned path", (np.asarray(plan.path, np.float64),),
                                 colour=(0, 200, 255)))
        layers.append(PointsLayer("view targets", np.reshape(plan.views, (-1, 3)),
                                  colour=(255, 120, 0), radius_m=0.05))
    return layers


def frontier_points(agent_map: AgentMap) -> np.ndarray:
    """(N, 3) centres of the observed-space frontier voxels (at most
    :data:`MAX_FRONTIER_POINTS`)."""
    observed = agent_map.observed_space
    cells = np.argwhere(observed.frontier())
    return subsample(observed.grid.cell_to_world(cells), MAX_FRONTIER_POINTS)


def uncertain_surfaces(agent_map: AgentMap) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) planner voxels within a voxel and a half of the surface with the highest
    uncertainty, and their (N,) uncertainty; empty before the planner view is first read."""
    sdf, uncertainty = agent_map.sdf, agent_map.uncertainty
    if sdf is None or uncertainty is None or sdf.shape != uncertainty.shape:
        return np.zeros((0, 3)), np.zeros(0)
    near = np.abs(sdf.values) <= 1.5 * sdf.voxel_size
    values = np.where(near, uncertainty.values, 0.0).reshape(-1)
    order = np.argsort(-values, kind="stable")[:MAX_UNCERTAIN_POINTS]
    order = order[values[order] > 0]
    if not len(order):
        return np.zeros((0, 3)), np.zeros(0)
    cells = np.stack(np.unravel_index(order, sdf.shape), axis=1)
    return uncertainty.voxel_to_world(cells), values[order]


def naruto_layers(plan: Plan | None, plans: list[dict[str, Any]],
                  agent_map: AgentMap | None) -> list[Layer]:
    """Every layer of the module's list (only the plan's before the first ``reset``)."""
    layers = plan_layers(plan, plans)
    if agent_map is None:
        return layers
    layers.append(PointsLayer("frontier", frontier_points(agent_map), colour=(80, 220, 120),
                              radius_m=0.03))
    points, values = uncertain_surfaces(agent_map)
    share = values / values.max() if len(values) else values
    colours = np.stack([np.full_like(share, 255), 230 * (1 - share), np.zeros_like(share)], 1)
    layers.append(PointsLayer("uncertain surfaces", points, colours=colours, radius_m=0.045))
    fraction = agent_map.observed_space.observed_fraction
    layers.append(ScalarLayer("observed space (%)", 100.0 * fraction))
    return layers
