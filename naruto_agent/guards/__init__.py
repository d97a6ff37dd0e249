"""What a policy reads about a move before it sends it, shared by every policy.

* :class:`ScanGuard` / :class:`ScanGuardConfig`: the open-scan guard (a surface in the move's
  way, the scan's top and edge, held moves, whether the scan is open).
* :class:`HeldMoves`: the count of moves held back in a row at one spot.
* :class:`RefusedMoves`: where the scan ends, learned from the moves the env refused.
* :mod:`naruto_agent.guards.panorama_clearance`: the readings of the depth panorama.
"""

from naruto_agent.guards.refused_moves import RefusedMoves
from naruto_agent.guards.scan_guard import HeldMoves, ScanGuard, ScanGuardConfig

__all__ = ["HeldMoves", "RefusedMoves", "ScanGuard", "ScanGuardConfig"]
