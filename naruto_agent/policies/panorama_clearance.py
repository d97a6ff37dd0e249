"""The panorama readings and the refusal memory under their former import path.

They live in :mod:`naruto_agent.guards.panorama_clearance` and
:mod:`naruto_agent.guards.refused_moves`, below the policies, so that every policy and the
shared :class:`~naruto_agent.guards.ScanGuard` read the panorama the same way; this module
keeps ``from naruto_agent.policies.panorama_clearance import ...`` working.
"""

from naruto_agent.guards.panorama_clearance import (
    PanoramaClearance,
    clear_part_of_move,
    cone_supported,
    first_contact,
    floor_edge_profile,
    horizontal_profile,
    move_leaves_scan,
    profile_clearance,
    sees_all_around_below,
    steep_miss_share,
    surface_top,
)
from naruto_agent.guards.refused_moves import RefusedMoves, refused_at_top

__all__ = [
    "PanoramaClearance",
    "RefusedMoves",
    "clear_part_of_move",
    "cone_supported",
    "first_contact",
    "floor_edge_profile",
    "horizontal_profile",
    "move_leaves_scan",
    "profile_clearance",
    "refused_at_top",
    "sees_all_around_below",
    "steep_miss_share",
    "surface_top",
]
