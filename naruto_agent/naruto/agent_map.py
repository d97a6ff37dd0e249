"""The NARUTO agent's map of one episode, as its planner and move checks read it.

:class:`AgentMap` wraps the mapper (TSDF, neural or one's own: a
:class:`~naruto_agent.mapping.Mapper`) and holds the *planner view*: the SDF and uncertainty
volumes on the planner's grid (0.1 m voxels over the scene's bounding box), with
the space the agent learned to avoid (:class:`~naruto_agent.naruto.recovery.BlockedSpace`)
blocked in the SDF and the targets of reached goals damped in the uncertainty. The view is
read from the mapper only when a mapping step made it stale and someone needs it.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from naruto_agent.mapping import Mapper, SdfVolume, make_mapper
from naruto_agent.mapping.observed_space import ObservedSpace
from naruto_agent.naruto.config import MAPPERS, NarutoConfig
from naruto_agent.naruto.recovery import BlockedSpace
from naruto_agent.planning import FreeSpaceComponents
from naruto_agent.policies.base import EnvContext


def build_mapper(
    name: str, context: EnvContext, config: NarutoConfig, device: str, rng: np.random.Generator,
    settings: dict[str, Any] | None = None,
) -> Mapper:
    """The mapper of a new episode (:func:`~naruto_agent.mapping.make_mapper`).

    Args:
        name: ``"tsdf"``, ``"neural"``, another registered name or an import path.
        context: the env's context (bounds and camera).
        config: the agent's settings: ``"tsdf"`` and ``"neural"`` take their own section.
        device: the mapper's device.
        rng: the agent's randomness; a mapper with a seed (the neural one) draws it from it.
        settings: keyword arguments of any other mapper.

    Raises:
        ValueError: the mapper cannot be built, or lacks what the agent reads.
    """
    if name in MAPPERS:
        settings = {"config": getattr(config, name)}
    return make_mapper(name, context.bounds, context.camera, device=device, rng=rng,
                       settings=settings)


class AgentMap:
    """The mapper and the planner view of one episode, with the blocked space applied.

    Args:
        mapper: the episode's mapper (a :class:`~naruto_agent.mapping.Mapper`).
        config: the agent's settings.
        timings: the dict the ``"mapping"`` and ``"planner_view"`` seconds are added to (a
            new one when None).

    Attributes:
        mapper: the mapper.
        config: the agent's settings.
        blocked: the space the agent learned to avoid.
        sdf: the planner view's SDF, blocked space applied (None before the first read).
        uncertainty: the planner view's uncertainty, reached goals' targets damped.
        visit_looks: looks per planner voxel added by reached goals (None before the first).
        timings: seconds spent by phase.
    """

    def __init__(self, mapper: Mapper, config: NarutoConfig,
                 timings: dict[str, float] | None = None) -> None:
        self.mapper = mapper
        self.config = config
        self.timings = timings if timings is not None else {"mapping": 0.0,
                                                            "planner_view": 0.0}
        self.blocked = BlockedSpace(config.recovery.blocked_radius_m)
        self.sdf: SdfVolume | None = None
        self.uncertainty: SdfVolume | None = None
        self.visit_looks: np.ndarray | None = None
        self._components: FreeSpaceComponents | None = None
        self._stale = False
        self._mapping_steps = 0

    @property
    def observed_space(self) -> ObservedSpace:
        """The mapper's measure of explored space."""
        return self.mapper.observed_space

    @property
    def clearance_m(self) -> float:
        """The planner's clearance from surfaces."""
        return self.config.planner.clearance_m

    def keeps_clearance(self, position: np.ndarray) -> bool:
        """Whether ``position`` keeps the planner's clearance on the planner view held (where
        a path may set off without an escape first)."""
        return float(self.sdf.sample(np.asarray(position, np.float64))[0]) > self.clearance_m

    # -- mapping -----------------------------------------------------------------------------
    def integrate(self, rgb: np.ndarray, depth: np.ndarray, pose: np.ndarray, frame_index: int,
                  panorama: np.ndarray | None = None) -> bool:
        """Hand one frame to the mapper (it keeps its own keyframe and mapping schedule).

        Args:
            rgb: the frame's colour image.
            depth: its depth image.
            pose: its 4x4 camera-to-world pose.
            frame_index: the frame's index in the episode.
            panorama: the depth panorama taken where the agent stands, if any; integrated
                every ``panorama_every``-th frame (``use_panorama``).

        Returns:
            Whether the planner view went stale: a mapping step ran and it is the
            ``view_every_mapping_steps``-th.
        """
        changed = self.mapper.integrate(rgb, depth, pose, frame_index)
        if (self.config.use_panorama and panorama is not None
                and frame_index % self.config.panorama_every == 0):
            self.mapper.integrate_panorama(panorama, pose[:3, 3])
        if not changed:
            return False
        self._mapping_steps += 1
        if (self._mapping_steps - 1) % self.config.view_every_mapping_steps != 0:
            return False
        self._stale = True
        return True

    def refresh(self) -> None:
        """Read the planner view from the mapper if a mapping step made the one held stale."""
        if not self._stale:
            return
        clock = time.perf_counter()
        sdf, uncertainty = self.mapper.planner_view(self.config.planner_voxel_m)
        self._take_view(sdf, uncertainty)
        self.timings["planner_view"] += time.perf_counter() - clock

    def use_view(self, sdf: SdfVolume, uncertainty: SdfVolume | None = None) -> None:
        """Take a given planner view instead of the mapper's (blocked space applied,
        uncertainty damped as a read view is); it holds until the next mapping step."""
        self._take_view(sdf, uncertainty)

    def _take_view(self, sdf: SdfVolume, uncertainty: SdfVolume | None) -> None:
        self.uncertainty = None if uncertainty is None else self.damp_visited(uncertainty)
        self.sdf = self.blocked.apply(sdf)
        self._components = None
        self._stale = False

    @property
    def components(self) -> FreeSpaceComponents:
        """The connected components of the planner view's free space (at the planner's
        clearance), computed once per view."""
        if self._components is None:
            self._components = FreeSpaceComponents.from_sdf(self.sdf, self.clearance_m)
        return self._components

    # -- blocked space -----------------------------------------------------------------------
    def block(self, centre: np.ndarray, radius_m: float | None = None,
              guessed: bool = False) -> None:
        """Block a ball in the map.

        Args:
            centre: the ball's centre.
            radius_m: its radius (the blocked space's own when None).
            guessed: blocked on the agent's own reading, not on a move the env refused (see
                :meth:`forget_guesses`).
        """
        self.blocked.add(centre, radius_m, guessed)
        self.apply_blocked()

    def block_past_edge(self, position: np.ndarray, target: np.ndarray,
                        guessed: bool = False) -> None:
        """The scan ends at ``target`` (seen from ``position``): block the space beyond it, a
        ball of ``recovery.escape_blocked_radius_m`` that touches the target and leaves the
        agent's side alone (just the target, as a surface, when that radius is 0)."""
        radius = self.config.recovery.escape_blocked_radius_m
        if radius <= 0:
            self.block(target, None, guessed)
            return
        direction = target - position
        self.block(target + radius * direction / np.linalg.norm(direction), radius, guessed)

    def lower_ceiling(self, z: float) -> None:
        """Block everything above height ``z`` (an open scan's top)."""
        self.blocked.lower_ceiling(z)
        self.apply_blocked()

    def apply_blocked(self) -> None:
        """Apply the blocked space to the planner view held (after a change to it)."""
        if self.sdf is not None:
            self.sdf = self.blocked.apply(self.sdf)
            self._components = None

    def forget_guesses(self, position: np.ndarray, reach_m: float = math.inf) -> bool:
        """Unblock the space blocked on the agent's own readings within ``reach_m`` of
        ``position`` (everywhere by default) and read the planner view again.

        Beside a floor hole's rim the panorama's edge test can hold moves that the env would
        let pass, and the balls blocked past them can hem the agent in until no plan starts
        or reaches a goal. Without them the next plan may try the same way, and after
        ``max_held_moves`` holds the env decides: what it refuses stays blocked.

        Returns:
            False when there was no such guess.
        """
        if not self.blocked.forget_guesses_near(position, reach_m):
            return False
        self._stale = True
        self.refresh()
        return True

    # -- visits ------------------------------------------------------------------------------
    def add_looks(self, targets: np.ndarray, looks: float) -> None:
        """Count ``looks`` looks at every planner voxel of ``targets`` ((N, 3) points); the
        view is read again (damped) when next needed. Needs a planner view."""
        if self.visit_looks is None:
            self.visit_looks = np.zeros(self.sdf.shape, np.float32)
        cells = np.rint(self.sdf.world_to_voxel(np.asarray(targets, np.float64).reshape(-1, 3))
                        ).astype(np.int64)
        cells = cells[np.all((cells >= 0) & (cells < np.asarray(self.sdf.shape)), axis=1)]
        np.add.at(self.visit_looks, tuple(cells.T), np.float32(looks))
        self._stale = True

    def damp_visited(self, uncertainty: SdfVolume) -> SdfVolume:
        """``uncertainty`` divided by ``1 + look_weight * looks`` where reached goals counted
        looks (see ``NarutoConfig.unresolved_visit_looks``)."""
        if self.visit_looks is None or self.visit_looks.shape != uncertainty.shape:
            return uncertainty
        weight = self.observed_space.config.look_weight
        return SdfVolume(uncertainty.values / (1.0 + weight * self.visit_looks),
                         uncertainty.origin, uncertainty.voxel_size)
