"""Process checks the tests of worker processes share."""

from __future__ import annotations


def alive(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie, not yet reaped, counts as gone)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().split(") ")[-1][0] != "Z"
    except FileNotFoundError:
        return False
