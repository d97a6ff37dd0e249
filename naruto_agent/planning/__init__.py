"""Motion planning for the NARUTO agent: SDF volumes, segment checks, E-RRT, rotations."""

from naruto_agent.planning.sdf_volume import SdfVolume

__all__ = ["SdfVolume"]
