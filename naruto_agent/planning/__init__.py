"""Motion planning for the NARUTO agent, usable on its own.

* :class:`SdfVolume`: values on a regular voxel grid with trilinear lookup (the planner's SDF,
  and the uncertainty volume), built from a map, a function or a ground-truth mesh.
* :func:`free_steps_along_segment`: NARUTO's segment collision check (2 cm samples, 5 cm
  agent radius), counted from the start side.
* :func:`plan_path` with :class:`PlannerConfig`: RRT and E-RRT ("direct line" and "fast tree"
  switchable), and :func:`reachable_voxels`; :func:`shortcut_path` shortens a planned path;
  :class:`FreeSpaceComponents`: which parts of the free space are connected.
* :func:`plan_rotations`, :func:`slerp_rotations`, :func:`order_views_greedily`: in-place
  turns towards target views in steps of at most ``max_rotation_deg``.
"""

from naruto_agent.mapping.sdf_volume import SdfVolume
from naruto_agent.planning.collision import (
    free_steps_along_segment,
    guaranteed_margin_m,
    segment_is_free,
)
from naruto_agent.planning.free_space import FreeSpaceComponents
from naruto_agent.planning.rotation import (
    RotationPlan,
    look_at_rotation,
    order_views_greedily,
    plan_rotations,
    slerp_rotations,
)
from naruto_agent.planning.rrt import PlannerConfig, PlanResult, plan_path, reachable_voxels
from naruto_agent.planning.shortcut import shortcut_path

__all__ = [
    "FreeSpaceComponents",
    "PlanResult",
    "PlannerConfig",
    "RotationPlan",
    "SdfVolume",
    "free_steps_along_segment",
    "guaranteed_margin_m",
    "look_at_rotation",
    "order_views_greedily",
    "plan_path",
    "plan_rotations",
    "reachable_voxels",
    "segment_is_free",
    "shortcut_path",
    "slerp_rotations",
]
