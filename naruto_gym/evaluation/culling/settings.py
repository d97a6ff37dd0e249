"""Culling's parameters: the literature's rule, and how the fast culling applies it.

The rule's parameters (which poses, the occlusion margin, how the occlusion depth is found)
decide which vertices are kept; they are arguments of :func:`~.mask.visible_vertex_mask` and
:func:`~.mask.cull_mesh`, with the literature's values as defaults. :class:`CullingSettings`
holds the rest: block sizes, guide images and batch sizes that decide only how many rays are
cast and in what order, never the result (the verdict is an OR over (vertex, pose) pairs).
"""

from __future__ import annotations

from dataclasses import dataclass

# The rule (Feng et al., NARUTO, CVPR 2024, after the Co-SLAM evaluation): every 2nd pose,
# a 3 cm occlusion margin, the ground-truth depth along each vertex's own line of sight.
DEFAULT_CULL_EVERY = 2
DEFAULT_DEPTH_MARGIN_M = 0.03
DEFAULT_CULL_DEPTH_SCALE: float | None = None


@dataclass(frozen=True)
class CullingSettings:
    """How the fast culling tries (vertex, pose) pairs; none of these changes its result.

    Attributes:
        block_size_m: side of the spatial blocks of vertices that share one list of the poses
            whose frustum can reach them (metres).
        guide_width_px: width of the coarse guide depth images that tell which pairs are
            likely unoccluded (never more than the camera's).
        guide_slack_m: a pair is likely unoccluded when its z-depth is at most the guide
            depth plus the occlusion margin plus this (metres) ...
        guide_slack_share: ... plus this share of its z-depth.
        order_poses_by_distance: each block lists its poses nearest first (a near pose is the
            likeliest to be in the same room); False keeps pose order.
        max_rays_per_cast: rays cast together at most (``1 << 21``: 48 MiB of float32 rays).
        max_likely_per_round: the likely pairs a vertex may try per round double from 1 up to
            this.
        max_unlikely_per_round: the unlikely pairs (a hidden vertex has to try them all) double
            from 8 up to this.
    """

    block_size_m: float = 0.5
    guide_width_px: int = 48
    guide_slack_m: float = 0.05
    guide_slack_share: float = 0.05
    order_poses_by_distance: bool = True
    max_rays_per_cast: int = 1 << 21
    max_likely_per_round: int = 8
    max_unlikely_per_round: int = 512

    def __post_init__(self) -> None:
        if not self.block_size_m > 0.0:
            raise ValueError(f"block_size_m must be positive, got {self.block_size_m}")
        for name in (
            "guide_width_px", "max_rays_per_cast", "max_likely_per_round",
            "max_unlikely_per_round",
        ):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1, got {getattr(self, name)}")
        if self.guide_slack_m < 0.0 or self.guide_slack_share < 0.0:
            raise ValueError(
                "the guide slacks must be >= 0, got "
                f"{self.guide_slack_m} m and a share of {self.guide_slack_share}"
            )


#: The settings of every culling that is given none.
DEFAULT_SETTINGS = CullingSettings()
