"""The NARUTO agent as a policy: map every frame, search goals by uncertainty, move by E-RRT.

One :meth:`NarutoPolicy.act` call is one iteration of NARUTO's loop (NARUTO_NOTES.md
section 1):

1. The observation's RGB-D frame and ground-truth pose go to the mapper, which applies its
   own schedule (a keyframe and a mapping step every 5 frames).
2. After a mapping step (every ``view_every_mapping_steps``-th) the agent reads the map on
   the planner grid (0.1 m voxels over the scene's bounding box): an SDF volume and an
   uncertainty volume that is zero off the surface.
3. The :class:`~naruto_agent.naruto.state_machine.NarutoStateMachine` picks the next pose.
   Its planning step runs the uncertainty-aware goal search
   (:func:`~naruto_agent.naruto.goal_search.uncertainty_aware_goal_search`) and E-RRT
   (:func:`~naruto_agent.planning.plan_path`) to the best goal.

Mappers (``mapper=``):

* ``"tsdf"`` (default): :class:`~naruto_agent.mapping.TsdfUncertaintyMapper`, TSDF fusion with
  an uncertainty derived from observation counts. Tens of milliseconds per frame on a CPU.
* ``"neural"``: :class:`~naruto_agent.mapping.NeuralMapper`, the published system (neural
  field + NLL-trained uncertainty grid + active ray sampling). On this project's 2-core CPU a
  mapping step costs seconds (the first frame's 200 iterations tens of seconds, and reading
  the planner view evaluates the field on every voxel), so a 2000-frame episode takes hours;
  use it with a GPU (``device="auto"`` picks CUDA).

Choices of this implementation beyond the published description (all switchable):

* Candidate goals must lie in free space connected to the agent (the E-RRT's own
  connectivity check would reject the others after the search).
* When the best goal cannot be reached, the next best (``goal_attempts``, 3) are tried
  before giving up (the published system gives up at once and stays).
* The E-RRT path is shortcut (``shortcut_paths``): the tree's zigzag chain of nodes, which
  can run many times the needed length, becomes the straight free segments it allows.
* Candidate goals lie every 0.5 m in height (published: 1 m), so low viewpoints that see
  under furniture are candidates.
* Of two goals that see about as much, the nearer by the way through free space wins
  (``goal_search.distance_discount_m`` 3 m with ``discount_by_travel``), not the nearer in a
  straight line through a wall.
* When the newest map puts the agent itself inside the clearance of a surface (the map
  sharpened since the path was planned), the path starts with a short straight move to the
  nearest free voxel within ``escape_radius_m``; otherwise the planner could never start.
* Unexplored space is uncertain (the mappers' ``unknown_space``): the frontier of what the
  frames have measured is a target at the initial variance, so the agent heads into rooms
  it has not seen. Goals must lie in measured free space (``goals_in_observed_space``), so
  the agent stands where it knows it can stand when it looks into the unknown.
* Unexplored space first (``goal_search.explore_first_share``): while enough voxels are
  nearly as uncertain as the most uncertain one, the targets are drawn from them only, so
  the agent finishes the rooms it has not seen before it polishes surfaces seen once or
  twice. A goal reached counts as a look at every target it was chosen for
  (``unresolved_visit_looks``): what is still unresolved after the visit (frontier under
  furniture) fades instead of calling the agent back.
* The depth panorama, when the env gives one, adds the free space all around the agent to
  that measure (``use_panorama``), and every move is checked against it before it is sent
  (``check_moves_on_panorama``), as a robot checks its range sensor: the 0.1 m map misses
  surfaces by a few centimetres, the panorama does not. On an open scan the same check
  reads the env's scanned-space test from the panorama's points below the move's end.
* Never stuck (:mod:`naruto_agent.naruto.recovery`): a refused move (``collided`` /
  ``collision_reason`` in the step info) blocks its target in the agent's own map (a move
  refused for leaving an open scan: the space past the edge, or, for a climb at the open
  top, everything above the agent), goals that
  failed are not tried again for a while, and when plans keep failing or the agent neither
  moves nor measures anything new it looks around, moves to reachable space away from where
  it has been, or retreats along its own trajectory. Space blocked on the agent's own
  reading of an open scan's edge (a move the panorama or its map held back, which the env
  never refused) is forgotten when a plan fails, and near the agent when it leaves no way
  out: beside a floor hole's rim those guesses can hem the agent in.

What the agent knows: the observations (RGB-D, pose, panorama), the env's step info
(``collided``, ``collision_reason``) and the scene's bounding box from the
:class:`~naruto_agent.policies.EnvContext`; never the mesh.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, fields, replace
from typing import Any, Literal

import numpy as np
import trimesh

from naruto_agent.mapping import (
    NeuralMapper,
    NeuralMapperConfig,
    TsdfMapperConfig,
    TsdfUncertaintyMapper,
)
from naruto_agent.naruto.goal_search import GoalSearchConfig, uncertainty_aware_goal_search
from naruto_agent.naruto.recovery import (
    BlockedSpace,
    ProgressMonitor,
    RecoveryConfig,
    RecoveryKind,
    densify,
    look_around_targets,
)
from naruto_agent.naruto.state_machine import NarutoStateMachine, Plan, State
from naruto_agent.planning import (
    FreeSpaceComponents,
    PlannerConfig,
    SdfVolume,
    plan_path,
    shortcut_path,
)
from naruto_agent.planning.rotation import image_view_test
from naruto_agent.planning.rrt import reachable_voxels
from naruto_agent.policies.base import (
    EnvContext,
    Info,
    Observation,
    OwnReconstruction,
    Policy,
    clip_pose_action,
    pose_action,
)
from naruto_agent.policies.panorama_clearance import (
    clear_part_of_move,
    first_contact,
    move_leaves_scan,
    refused_at_top,
    steep_miss_share,
)

MAPPERS = ("tsdf", "neural")
"""Names of the mappers the agent can run on (``NarutoPolicy(mapper=...)``)."""
_MIN_CLIMB_M = 0.02  # a climb out of an open scan's margin shorter than this is not worth it


@dataclass
class NarutoConfig:
    """Settings of the NARUTO agent; defaults follow the published system.

    Attributes:
        planner_voxel_m: voxel of the planner's SDF and uncertainty volumes (0.1 m).
        view_every_mapping_steps: read the planner view after every n-th mapping step (1:
            after each, as published).
        lazy_planner_view: read it only when the state machine needs it (planning, or a
            move to check), not while the agent turns in place. The same decisions for a
            mapper whose map changes only at mapping steps; a TSDF fuses every frame, so
            a view read later holds a few more frames. Saves about half the reads.
        max_rotation_step_deg: largest turn per frame: 20 degrees, what the env allows and
            what the frontier and random policies use (published: 10). On the apartment,
            5000 steps, seed 0: coverage 64.8 / 88.2 / 94.3 / 98.2 % at steps 500 / 1000 /
            2000 / 5000 against 36.5 / 81.4 / 93.2 / 97.5 % with 10 degrees, observable
            completion ratio 97.7 % against 96.1 %.
        skip_views_in_image: at the goal, do not turn to a view whose target is already in
            the image (inside its central 80 %) of the current rotation or of one the
            camera turned through. The published agent turns to all 10 views in 10-degree
            steps, which took 70 % of the frames of a 200-step apartment episode; the
            targets the skipped turns would centre are in the frames anyway. False:
            published.
        goal_attempts: best goals tried in turn with E-RRT before staying (published: 1).
        shortcut_paths: follow the E-RRT path with every stretch that a straight free
            segment covers cut short (:func:`~naruto_agent.planning.shortcut_path`; the
            segments keep the planner's clearance). The published agent follows the tree's
            chain of nodes, which zigzags and, where the tree grew around a room before it
            found the door, can be many times longer than needed (apartment, seed 1: a
            442-node path to a goal 2.2 m away). False: published.
        shortcut_margin_m: extra clearance a shortcut segment keeps on top of the
            planner's (the tree's own edges keep the planner's). The trilinear SDF of the
            0.1 m planner grid overestimates the distance to convex corners and thin edges
            by up to a few centimetres, and a long straight segment passes close to many
            of them: with the shortcuts the env refused 30 moves per 5000-step apartment
            episode, against 11 before (13.7 once the TSDF planner view was bounded from
            behind surfaces). 0 (default): the planner's clearance. 0.05 m (apartment, 2500
            steps, seeds 0-2, before that bound): 9 / 10 / 17 refused moves (seed 1 without
            it: 26), but coverage at step 2500 of 97.4 / 95.7 / 97.2 % against 97.5 / 97.7 /
            98.2 %: the safer shortcuts are fewer and the ways longer.
        reachable_iterations: extensions of the goal search's fallback tree.
        check_moves_on_map: check every move against the agent's newest map before sending
            it (2 cm samples, agent radius 5 cm); a blocked move is a detected collision.
        check_moves_on_panorama: also check every move against the env's depth panorama
            where the agent stands (when the observation has one), as a robot checks its
            range sensor before it moves: the 0.1 m map's distance field misses a surface
            by a few centimetres here and there, and the env refused those moves. A move
            the panorama shows blocked is not sent; the surface point is blocked in the map
            (``RecoveryConfig.blocked_radius_m``) so that the next plan goes around it, and
            the goal stays. On an open scan the move must also keep to the scanned space
            as the panorama shows it (the env's cone test on the surface points around the
            agent); one that leaves it is refused as by ``edge_probe_m``.
        panorama_margin_m: the panorama check keeps the env's agent radius plus this.
        max_held_moves: after this many moves in a row held back at one spot by the
            panorama (a surface in the way, or leaving an open scan), the next is sent and
            the env decides (its refusal teaches the map as any other): low over a floor
            hole every way can look like leaving, and in a tight spot (under a table, 7 cm
            from a leg) every way can come within the margin of a surface.
        margin_climb_m: when the count runs out on a move the panorama reads as leaving an
            open scan, the agent climbs this far straight up instead of sending the move (0.3
            m; less where the scan's top, ``scan_top_margin_m`` below the measured surfaces'
            top, or the panorama's surfaces come first; not under 2 cm), then looks around
            and plans again. Low beside a floor hole's rim the env's support cone (60 degrees
            down) reaches past the hole from higher up, so a climb takes the agent further
            in, where level moves leave the scan: on ``replica_like_room:no_ceiling+holes``,
            seed 6, the panorama had flagged every move from a spot 0.8 m high, the env
            accepted the two climbs among them and refused the level moves sent after the
            count ran out (2 escape refusals). 0: send the move, the env decides.
        escape_radius_m: how far the agent may look for free space when the map puts it
            inside a surface's clearance (0 switches the escape off).
        arrival_tolerance_m: a moving agent farther than this from its commanded node was
            stopped by the env.
        use_panorama: integrate the env's depth panorama (when the observation has one) into
            the map's measure of explored space.
        panorama_every: ... every n-th frame (5, the mapping cadence).
        goals_in_observed_space: candidate goals must lie in space the frames measured free.
        stay_in_scanned_space: candidate goals must have measured surface below them and lie
            no higher than the measured surfaces' top (:meth:`ObservedSpace.supported`,
            :meth:`ObservedSpace.scan_top_z`), and only supported frontier counts as a target:
            on an open scan (no ceiling, a missing wall) the space rays reach over a wall top
            or through a gap is outside the scan, where the env refuses moves. False: goals
            and frontier anywhere in measured free space.
        scan_top_margin_m: ... and at least this far below the measured surfaces' top (0.3
            m): from the height of a room's open wall tops the space beyond the walls is in
            view below, and the env's scanned-space rule refuses such points (with 0.5 m goal
            levels a goal at 3.0 m came up in a 3 m room without a ceiling). In a closed
            room the top is the ceiling, which the goals' 8 cm clearance keeps them from
            anyway (the highest positions of the published-budget episodes lay 0.39-0.68
            m below the scenes' top).
        sector_support_after_escape: once the scan is known to be open (the env refused a
            move for leaving the scanned space, or a depth frame saw the sky: see
            ``open_sky_share``), candidate goals must also have measured surface below
            them in every sector of the env's support cone
            (:meth:`ObservedSpace.sectors_seen_below`), not only within 0.3 m sideways: a
            point in a wall's opening or over a floor hole's edge passes the coarse test and
            the env refuses it. Moves are checked too: a move from a point that passes the
            test towards one ``edge_probe_m`` beyond its end (horizontally) that fails it is
            refused on the agent's map, as the env would refuse it, and the space past it
            blocked as after an escape refusal. Closed scenes give neither sign, so nothing
            changes there. False: the coarse test only.
        open_sky_share: the scan counts as open once this share of a depth frame's pixels
            that look at least 35 degrees up or down hit nothing within the sensor's range
            (:func:`~naruto_agent.policies.panorama_clearance.steep_miss_share`): indoors such
            a ray meets a ceiling or a floor within a few metres, so misses mean a scan
            without a ceiling or with a hole in its floor. Open scans showed it within 3
            steps; the shipped scenes and the Replica sample never did. None: only an escape
            refusal tells.
        edge_probe_m: see ``sector_support_after_escape``: the agent's 0.1 m grid blurs the
            scan's edge by up to a voxel, and the env keeps the agent's clearance from it.
        unresolved_visit_looks: when the agent reaches a goal and turns to its views, every
            target the goal search saw from that goal counts this many looks: its
            uncertainty in the planner view is divided by ``1 + look_weight * looks`` (the
            observed space's look weight, 0.25: to half with 4), whether or not the frames
            could tell it was looked at. That holds for frontier (a target under a table's
            edge, outside the image's vertical reach) and for surface voxels whose
            uncertainty the frames cannot lower (the TSDF mapper counts a view of a voxel
            when its centre lies within 5 cm of the measured depth, which a voxel beside a
            thin edge or seen at a grazing angle never does; a neural field's uncertainty
            can stay high where it extrapolates). Without it the agent kept returning to
            such targets near it (apartment, seed 0, steps 1800-2600: 23 plans that gained
            1.3 % coverage; seed 1, steps 2000-2700 with frontier only: 35 plans at its own
            position for 0.5 %). 0: off.
        initial_look_around: the first plan of an episode is a turn in place that looks all
            around, so the first goal search sees the whole surrounding (the published agent
            searches from its first view).
        seed: seed of the agent's randomness when ``reset`` gets none.
        recovery: stall detection and recovery (:class:`RecoveryConfig`).
        goal_search: the goal search's settings (published, except candidate goals every
            0.5 m in height instead of 1 m, so that low viewpoints, which see under tables
            and desks, are candidates: on the Replica sample the published levels left only
            two heights inside the room; a distance discount of
            3 m along the way through free space: of two goals that see about as much, the
            nearer by travel wins; and explore-first
            with a share of 0.75: while at least 30 voxels are at 3/4 of the largest
            uncertainty or more, targets are drawn from those).
        planner: E-RRT settings (the time limit, 2 s, is shorter than the planning module's
            default 5 s: a CPU agent should not stall; the seed is redrawn every request).
        tsdf: settings of the TSDF mapper (``mapper="tsdf"``).
        neural: settings of the neural mapper (``mapper="neural"``).
    """

    planner_voxel_m: float = 0.1
    view_every_mapping_steps: int = 1
    lazy_planner_view: bool = True
    max_rotation_step_deg: float = 20.0
    skip_views_in_image: bool = True
    goal_attempts: int = 3
    shortcut_paths: bool = True
    shortcut_margin_m: float = 0.0
    reachable_iterations: int = 2000
    check_moves_on_map: bool = True
    check_moves_on_panorama: bool = True
    panorama_margin_m: float = 0.01
    max_held_moves: int = 3
    margin_climb_m: float = 0.3
    escape_radius_m: float = 0.3
    arrival_tolerance_m: float = 0.01
    use_panorama: bool = True
    panorama_every: int = 5
    goals_in_observed_space: bool = True
    stay_in_scanned_space: bool = True
    scan_top_margin_m: float = 0.3
    sector_support_after_escape: bool = True
    open_sky_share: float | None = 0.05
    edge_probe_m: float = 0.15
    unresolved_visit_looks: float = 4.0
    initial_look_around: bool = True
    seed: int = 0
    recovery: RecoveryConfig = field(default_factory=RecoveryConfig)
    goal_search: GoalSearchConfig = field(
        default_factory=lambda: GoalSearchConfig(goal_spacing_z_m=0.5,
                                                 distance_discount_m=3.0,
                                                 discount_by_travel=True,
                                                 explore_first_share=0.75)
    )
    planner: PlannerConfig = field(default_factory=lambda: PlannerConfig(time_limit_s=2.0))
    tsdf: TsdfMapperConfig = field(default_factory=TsdfMapperConfig)
    neural: NeuralMapperConfig = field(default_factory=NeuralMapperConfig)

    def __post_init__(self) -> None:
        if not self.planner_voxel_m > 0:
            raise ValueError(f"planner_voxel_m must be positive, got {self.planner_voxel_m}")
        if (self.view_every_mapping_steps < 1 or self.goal_attempts < 1
                or self.panorama_every < 1):
            raise ValueError("view_every_mapping_steps, goal_attempts and panorama_every must "
                             "be at least 1")
        if not 0 < self.max_rotation_step_deg <= 180:
            raise ValueError(f"max_rotation_step_deg must be in (0, 180], got "
                             f"{self.max_rotation_step_deg}")
        if (self.escape_radius_m < 0 or self.arrival_tolerance_m < 0
                or self.unresolved_visit_looks < 0 or self.scan_top_margin_m < 0
                or self.shortcut_margin_m < 0 or self.margin_climb_m < 0):
            raise ValueError("escape_radius_m, arrival_tolerance_m, unresolved_visit_looks, "
                             "scan_top_margin_m, shortcut_margin_m and margin_climb_m must "
                             "be >= 0")
        if self.open_sky_share is not None and not 0 < self.open_sky_share <= 1:
            raise ValueError(f"open_sky_share must be in (0, 1] or None, got "
                             f"{self.open_sky_share}")
        if self.edge_probe_m < 0:
            raise ValueError(f"edge_probe_m must be >= 0, got {self.edge_probe_m}")
        if self.max_held_moves < 0:
            raise ValueError(f"max_held_moves must be >= 0, got {self.max_held_moves}")
        self.planner.validate()


_SECTIONS = {"goal_search": GoalSearchConfig, "planner": PlannerConfig,
             "recovery": RecoveryConfig,
             "tsdf": TsdfMapperConfig, "neural": NeuralMapperConfig}


def build_config(config: NarutoConfig | None = None, **settings: Any) -> NarutoConfig:
    """A :class:`NarutoConfig` with keyword overrides.

    Top-level fields are given by name (``goal_attempts=1``); a section takes a dict of its
    fields (``goal_search={"top_k": 1}``, ``planner={"time_limit_s": 1.0}``) or an instance.
    JSON-able, so benchmark specs can carry them.
    """
    config = config or NarutoConfig()
    known = {f.name for f in fields(NarutoConfig)}
    unknown = set(settings) - known
    if unknown:
        raise ValueError(f"unknown NARUTO settings {sorted(unknown)}; known: {sorted(known)}")
    updates: dict[str, Any] = {}
    for name, value in settings.items():
        if name in _SECTIONS and isinstance(value, dict):
            section = getattr(config, name)
            section_fields = {f.name for f in fields(_SECTIONS[name])}
            bad = set(value) - section_fields
            if bad:
                raise ValueError(f"unknown {name} settings {sorted(bad)}; known: "
                                 f"{sorted(section_fields)}")
            value = replace(section, **value)
        updates[name] = value
    return replace(config, **updates)


class NarutoPolicy(Policy):
    """NARUTO: uncertainty-aware goal search + E-RRT on the agent's own map ("pose" actions).

    Args:
        mapper: ``"tsdf"`` (fast, default) or ``"neural"`` (the published mapper; slow on a
            CPU, see the module docstring).
        config: full settings; ``settings`` override its fields (see :func:`build_config`).
        device: device of the mapper and the planner's nearest-neighbour search ("auto":
            CUDA when present).
        **settings: :class:`NarutoConfig` fields.

    Attributes:
        mapper: the map of the current episode (after ``reset``).
        machine: the state machine (``machine.history`` holds the state of every action).
        plans: one dict of diagnostics per planning request.
        monitor: progress, failed plans and goals of the episode.
        blocked: points where the env refused a move.
        recoveries: (frame, kind) of every recovery this episode.
        visit_looks: looks per planner voxel counted by visits (``unresolved_visit_looks``),
            None before the first.
        timings: seconds spent per phase (``mapping``, ``planner_view``, ``goal_search``,
            ``rrt``, ``control``) this episode.
    """

    action_modes = ("pose",)
    required_observations = ("rgb", "depth", "pose")

    def __init__(
        self,
        mapper: Literal["tsdf", "neural"] = "tsdf",
        config: NarutoConfig | None = None,
        device: str = "auto",
        **settings: Any,
    ) -> None:
        super().__init__()
        if mapper not in MAPPERS:
            raise ValueError(f"mapper must be one of {MAPPERS}, got {mapper!r}")
        self.mapper_name = mapper
        self.device = device
        self.config = build_config(config, **settings)
        self.mapper: TsdfUncertaintyMapper | NeuralMapper | None = None
        self.machine = NarutoStateMachine(self.config.max_rotation_step_deg,
                                          self.config.arrival_tolerance_m)
        self.plans: list[dict[str, Any]] = []
        self.timings: dict[str, float] = {}
        self.sdf: SdfVolume | None = None
        self.uncertainty: SdfVolume | None = None
        self._components: FreeSpaceComponents | None = None
        self._rng = np.random.default_rng(self.config.seed)
        self._frame_index = 0
        self._mapping_steps = 0
        self._new_map = False
        self._view_stale = False
        self.monitor = ProgressMonitor(self.config.recovery)
        self.blocked = BlockedSpace(self.config.recovery.blocked_radius_m)
        self.recoveries: list[tuple[int, str]] = []
        self._commanded: np.ndarray | None = None
        self._visit: tuple[np.ndarray, np.ndarray] | None = None  # (goal, targets it sees)
        self.visit_looks: np.ndarray | None = None  # looks per planner voxel from visits
        self._scan_open = False  # an escape refusal or the sky: the scan is open
        self._panorama: tuple[np.ndarray, np.ndarray] | None = None  # (panorama, where)
        self._held: tuple[np.ndarray, int] | None = None  # where moves were held, how many
        self._climb: np.ndarray | None = None  # a climb out of an open scan's margin, next

    # -- mapping -----------------------------------------------------------------------------
    def bind(self, context: EnvContext) -> None:
        super().bind(context)
        camera = context.camera
        self.machine.in_view = (
            image_view_test(camera.width, camera.height, camera.fx, camera.fy, camera.cx,
                            camera.cy, margin=0.1)
            if self.config.skip_views_in_image else None
        )

    def _make_mapper(self) -> TsdfUncertaintyMapper | NeuralMapper:
        context = self.context
        if self.mapper_name == "tsdf":
            return TsdfUncertaintyMapper(context.bounds, context.camera,
                                         replace(self.config.tsdf, device=self.device))
        neural = replace(self.config.neural, device=self.device,
                         seed=int(self._rng.integers(2**31 - 1)))
        return NeuralMapper(context.bounds, context.camera, neural)

    def _integrate(self, observation: Observation) -> None:
        clock = time.perf_counter()
        pose = np.asarray(observation["pose"], dtype=np.float64)
        changed = self.mapper.integrate(
            observation["rgb"], observation["depth"], pose, self._frame_index,
        )
        if not self._scan_open and self.config.open_sky_share is not None:
            miss = steep_miss_share(observation["depth"], pose, self.context.camera)
            self._scan_open = miss >= self.config.open_sky_share
        panorama = observation.get("panorama")
        self._panorama = None if panorama is None else (np.asarray(panorama), pose[:3, 3].copy())
        if (self.config.use_panorama and panorama is not None
                and self._frame_index % self.config.panorama_every == 0):
            self.mapper.integrate_panorama(panorama, pose[:3, 3])
        self.timings["mapping"] += time.perf_counter() - clock
        if changed:
            self._mapping_steps += 1
            if (self._mapping_steps - 1) % self.config.view_every_mapping_steps == 0:
                self._view_stale = True
                self._new_map = True
                if not self.config.lazy_planner_view:
                    self._read_view()

    def _read_view(self) -> None:
        """Read the planner view if a mapping step made the one held stale."""
        if not self._view_stale:
            return
        clock = time.perf_counter()
        sdf, uncertainty = self.mapper.planner_view(self.config.planner_voxel_m)
        self.uncertainty = self._damp_visited(uncertainty)
        self.sdf = self.blocked.apply(sdf)
        self._components = None
        self._view_stale = False
        self.timings["planner_view"] += time.perf_counter() - clock

    # -- episode -----------------------------------------------------------------------------
    def reset(self, observation: Observation, info: Info, seed: int | None = None) -> None:
        super().reset(observation, info, seed)
        self._rng = np.random.default_rng(self.config.seed if seed is None else seed)
        self.mapper = self._make_mapper()
        if not self.config.stay_in_scanned_space:
            self.mapper.observed_space.configure(support_below_m=None)
        self.machine.reset()
        self.plans = []
        self.timings = dict.fromkeys(
            ("mapping", "planner_view", "goal_search", "rrt", "control"), 0.0
        )
        self.sdf = self.uncertainty = None
        self._components = None
        self._frame_index = 0
        self._mapping_steps = 0
        self._new_map = False
        self._view_stale = False
        self.monitor = ProgressMonitor(self.config.recovery)
        self.blocked = BlockedSpace(self.config.recovery.blocked_radius_m)
        self.recoveries = []
        self._commanded = None
        self._visit = None
        self.visit_looks = None
        self._scan_open = False  # an escape refusal or the sky: the scan is open
        self._panorama = None
        self._held = None
        self._climb = None
        self._integrate(observation)

    def _note_refused_move(self, position: np.ndarray, info: Info) -> None:
        """A refused move blocks its target in the agent's map (an escape refusal: the space
        past the scan's edge; a refused climb at an open top: everything above the agent);
        the plan's goal failed."""
        if self._commanded is None or not info.get("collided", False):
            return
        if np.linalg.norm(self._commanded - position) <= self.config.arrival_tolerance_m:
            return
        if info.get("collision_reason") == "escape":
            self._scan_open = True
            if self._refused_climb(position, self._commanded):
                self.blocked.lower_ceiling(position[2])
                self._blocked_space_changed()
            else:
                self._block_past_edge(position, self._commanded)
        else:
            self._block(self._commanded, None)

    def _refused_climb(self, position: np.ndarray, target: np.ndarray) -> bool:
        """An escape refusal at the scan's open top rather than at its side
        (:func:`refused_at_top`, with "all around below" judged by the env's cone test on the
        agent's own grid)."""
        supported = self.mapper.observed_space.sectors_seen_below(position[None])[0]
        return refused_at_top(position, target, bool(supported))

    def _block_past_edge(
        self, position: np.ndarray, target: np.ndarray, goal_failed: bool = True,
        guessed: bool = False,
    ) -> None:
        """The scan ends at ``target``: block the space beyond it, in a ball that touches
        the target and leaves the agent's side alone (the plan's goal failed unless
        ``goal_failed`` is False; ``guessed``: the agent's own reading, not the env's
        refusal, see :meth:`_forget_guesses`)."""
        radius = self.config.recovery.escape_blocked_radius_m
        if radius <= 0:
            self._block(target, None, goal_failed, guessed)
            return
        direction = target - position
        self._block(target + radius * direction / np.linalg.norm(direction), radius, goal_failed,
                    guessed)

    def _block(self, centre: np.ndarray, radius: float | None, goal_failed: bool = True,
               guessed: bool = False) -> None:
        """Block a ball in the agent's map (the blocked space's own radius when None); the
        plan's goal failed (unless ``goal_failed`` is False)."""
        self.blocked.add(centre, radius, guessed)
        self._blocked_space_changed(goal_failed)

    def _forget_guesses(self, position: np.ndarray, reach_m: float = math.inf) -> bool:
        """Unblock the space the agent blocked on its own readings within ``reach_m`` of
        ``position`` (everywhere by default) and read the planner view again; False when
        there was none. Beside a floor hole's rim the panorama's edge test can hold moves
        that the env would let pass, and the balls blocked past them can hem the agent in
        until no plan starts or reaches a goal (``replica_like_room:no_ceiling+holes``,
        seed 6: 0.4 m in 300 steps). Without them the next plan may try the same way, and
        after ``max_held_moves`` holds the env decides: what it refuses stays blocked."""
        if not self.blocked.forget_guesses_near(position, reach_m):
            return False
        self._view_stale = True
        self._read_view()
        return True

    def _plan_failed(self, position: np.ndarray, record: dict[str, Any], outcome: str) -> None:
        """A plan that found no goal or no path: the monitor counts it, and the agent's own
        guesses of the scan's edge are forgotten for the next plan (:meth:`_forget_guesses`)."""
        record["outcome"] = outcome
        self.monitor.plan_failed()
        if self._forget_guesses(position):
            record["forgot_guesses"] = True

    def _blocked_space_changed(self, goal_failed: bool = True) -> None:
        """Apply the blocked space to the agent's map; the plan's goal failed (unless
        ``goal_failed`` is False)."""
        if self.sdf is not None:
            self.sdf = self.blocked.apply(self.sdf)
            self._components = None
        plan = self.machine.plan
        if goal_failed and plan is not None and not plan.info.get("recovery"):
            self.monitor.goal_failed(plan.goal)

    def act(self, observation: Observation, info: Info | None = None) -> np.ndarray:
        if self.mapper is None:
            raise RuntimeError("call reset() with the first observation before act()")
        self._frame_index += 1
        self._integrate(observation)
        clock = time.perf_counter()
        position = np.asarray(observation["pose"], dtype=np.float64)[:3, 3]
        self._note_refused_move(position, info or {})
        self.monitor.record(position, self.mapper.observed_space.observed_fraction)
        inner = ("goal_search", "rrt", "planner_view")
        before = sum(self.timings[name] for name in inner)
        new_map, self._new_map = self._new_map, False
        pose = self.machine.step(
            np.asarray(observation["pose"], dtype=np.float64),
            new_map=new_map,
            collided=bool((info or {}).get("collided", False)),
            plan=self._plan,
            move_is_free=self._move_is_free,
        )
        # Control is the state machine's own work; the phases it called are timed apart.
        called = sum(self.timings[name] for name in inner) - before
        self.timings["control"] += time.perf_counter() - clock - called
        moved = np.linalg.norm(pose[:3, 3] - position) > 1e-9
        self._commanded = pose[:3, 3].copy() if moved else None
        return clip_pose_action(pose_action(pose), self.context.action_space)

    @property
    def state(self) -> State:
        """The state machine's current state."""
        return self.machine.state

    def mesh(self, voxel_size: float = 0.02) -> trimesh.Trimesh:
        """The agent's reconstruction (for ``env.unwrapped.evaluate(policy.mesh())``)."""
        if self.mapper is None:
            raise RuntimeError("the agent has no map yet: call reset() first")
        return self.mapper.extract_mesh(voxel_size)

    def reconstruction(self) -> OwnReconstruction | None:
        """The agent's map (mesh and SDF) for the benchmark harness; None before reset()."""
        if self.mapper is None:
            return None
        return OwnReconstruction(self.mesh(), self.mapper.sdf)

    # -- planning ----------------------------------------------------------------------------
    @property
    def _clearance(self) -> float:
        return self.config.planner.clearance_m

    def _move_is_free(self, start: np.ndarray, end: np.ndarray) -> bool:
        """The move's samples (every 2 cm, the start excluded) keep the agent's clearance.

        When a sharper map has put the agent itself within a surface's clearance, the move
        only has to get no closer to the surface than the agent already is, so that it can
        move away.
        """
        plan = self.machine.plan
        if not self.config.check_moves_on_map or (plan is not None and plan.info.get("trusted")):
            return True  # a retreat goes back through space the agent has been in
        self._read_view()
        if not self._keeps_clearance(start, end):
            return False
        if not self._panorama_shows_way_clear(start, end):
            return False
        if self._scan_open and self.config.sector_support_after_escape:
            return (self._stays_below_top(start, end) and self._panorama_keeps_to_scan(start, end)
                    and self._stays_in_scan(start, end))
        return True

    def _stays_below_top(self, start: np.ndarray, end: np.ndarray) -> bool:
        """On an open scan a climb may not end above the scan's top: the flight ceiling a
        refused climb taught, or the measured surfaces' top (:meth:`ObservedSpace.scan_top_z`,
        voxel tops, so up to a voxel above the surfaces) less the agent's radius. The map
        alone let a path's node a few centimetres above either through (the SDF blends
        blocked voxels with free ones). A refused climb lowers the flight ceiling, so the
        next plan stays under it; the goal stays. Level and descending moves always pass."""
        if end[2] <= start[2]:
            return True
        top = self.mapper.observed_space.scan_top_z() - self.context.agent_radius_m
        if end[2] <= min(top, self.blocked.ceiling_z):
            return True
        if top < self.blocked.ceiling_z:
            self.blocked.lower_ceiling(max(top, float(start[2])))
            self._blocked_space_changed(goal_failed=False)
        return False

    def _panorama_from(self, start: np.ndarray) -> np.ndarray | None:
        """The newest panorama when it was taken at ``start`` and the panorama checks are on
        (``check_moves_on_panorama``); None otherwise."""
        if not self.config.check_moves_on_panorama or self._panorama is None:
            return None
        panorama, centre = self._panorama
        return panorama if np.linalg.norm(start - centre) <= 1e-3 else None

    def _panorama_shows_way_clear(self, start: np.ndarray, end: np.ndarray) -> bool:
        """The move checked against the depth panorama taken where it starts
        (``check_moves_on_panorama``); a blocked move blocks the surface point in the map."""
        panorama = self._panorama_from(start)
        if panorama is None:
            return True
        radius = self.context.agent_radius_m + self.config.panorama_margin_m
        contact = first_contact(panorama, end - start, radius)
        if contact is None or not self._hold_here(start):
            return True
        self.blocked.add(start + contact)
        self._blocked_space_changed(goal_failed=False)
        return False

    def _hold_here(self, start: np.ndarray) -> bool:
        """Count a move held back by the panorama at ``start``; False (send it, the env
        decides) after ``max_held_moves`` moves in a row were held at this spot, and the
        count starts again (a move the env refuses teaches the map, and the next ones are
        checked again)."""
        held_here = self._held is not None and np.linalg.norm(start - self._held[0]) <= 1e-3
        count = self._held[1] + 1 if held_here else 1
        if count > self.config.max_held_moves:
            self._held = (start.copy(), 0)
            return False
        self._held = (start.copy(), count)
        return True

    def _panorama_keeps_to_scan(self, start: np.ndarray, end: np.ndarray) -> bool:
        """On an open scan, the env's cone test read from the panorama where the move starts
        (``check_moves_on_panorama``, :func:`move_leaves_scan`): a move that leaves the
        scanned space there is refused, and the space past it blocked, as after an escape
        refusal; after ``max_held_moves`` moves held in a row at one spot (:meth:`_hold_here`)
        the agent climbs out of the margin instead (:meth:`_margin_climb`), or when it cannot
        the move passes and the env decides."""
        panorama = self._panorama_from(start)
        radius = self.context.agent_radius_m
        if panorama is None or not move_leaves_scan(panorama, end - start, radius):
            return True
        if not self._hold_here(start):
            self._climb = self._margin_climb(start, panorama)
            if self._climb is None:
                return True  # the env decides
            return False  # the next plan is the climb
        # Held before the env saw it: the goal may still be reached another way.
        self._block_past_edge(start, end, goal_failed=False, guessed=True)
        return False

    def _margin_climb(self, start: np.ndarray, panorama: np.ndarray) -> np.ndarray | None:
        """Nodes (a planner step apart) of a climb of up to ``margin_climb_m`` straight up
        from ``start``: below the scan's top (``scan_top_margin_m`` under the measured
        surfaces' top, and the flight ceiling refused climbs taught) and as far as the
        panorama shows it clear of surfaces; None when less than 2 cm is left."""
        height = self.config.margin_climb_m
        if height <= 0:
            return None
        top = min(self.mapper.observed_space.scan_top_z() - self.config.scan_top_margin_m,
                  self.blocked.ceiling_z)
        rise = min(height, top - float(start[2]))
        if rise < _MIN_CLIMB_M:
            return None
        radius = self.context.agent_radius_m + self.config.panorama_margin_m
        part = clear_part_of_move(panorama, np.array([0.0, 0.0, rise]), radius)
        if part is None or part[2] < _MIN_CLIMB_M:
            return None
        rise = float(part[2])  # cut short below a surface (a slide sideways is not a climb)
        steps = max(1, math.ceil(rise / self.config.planner.step_m - 1e-9))
        heights = np.arange(0, steps + 1) / steps * rise
        return start + heights[:, None] * np.array([0.0, 0.0, 1.0])

    def _stays_in_scan(self, start: np.ndarray, end: np.ndarray) -> bool:
        """On an open scan a path may cross a floor hole's edge or a wall's opening where
        the goal search's test never looked: a move from a point that passes the env's cone
        test on the agent's map towards one that fails it (probed ``edge_probe_m`` beyond
        the move's end, horizontally) is refused here, and the space past it blocked so the
        next plan goes elsewhere."""
        grid = self.mapper.observed_space.grid
        if grid.move_leaves_support(start, end, self.config.edge_probe_m):
            self._block_past_edge(start, end, guessed=True)
            return False
        return True

    def _keeps_clearance(self, start: np.ndarray, end: np.ndarray) -> bool:
        """The move check itself, on the current planner view (see :meth:`_move_is_free`)."""
        sample = self.config.planner.collision_sample_m
        count = max(1, math.ceil(float(np.linalg.norm(end - start)) / sample - 1e-9))
        fractions = np.arange(0, count + 1) / count
        values = self.sdf.sample(start + fractions[:, None] * (end - start))
        threshold = min(self._clearance, float(values[0]) - 1e-3)
        return bool(np.all(values[1:] > threshold))

    def _escape(self, position: np.ndarray) -> np.ndarray | None:
        """Straight nodes (0.1 m apart) to the nearest voxel well inside free space whose
        every node the move check accepts (it never gets deeper into the surface than the
        agent is; a nearer voxel across a blocked point would be refused at every try), or
        None."""
        sdf = self.sdf
        radius = self.config.escape_radius_m
        if radius <= 0:
            return None
        span = math.ceil(radius / sdf.voxel_size)
        centre = np.rint(sdf.world_to_voxel(position)).astype(np.int64)
        axis = np.arange(-span, span + 1)
        block = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
        voxels = centre + block
        inside = np.all((voxels >= 0) & (voxels < np.asarray(sdf.shape)), axis=1)
        voxels = voxels[inside]
        points = sdf.voxel_to_world(voxels)
        distance = np.linalg.norm(points - position, axis=1)
        # Well inside: clearance plus one collision sample, so the planner accepts the start.
        free = (sdf.values[voxels[:, 0], voxels[:, 1], voxels[:, 2]]
                > self._clearance + self.config.planner.collision_sample_m)
        candidates = np.flatnonzero(free & (distance <= radius) & (distance > 1e-9))
        # Nearest first; the first whose nodes all pass the move check (as they will be
        # checked when the agent moves).
        for index in candidates[np.lexsort((candidates, distance[candidates]))]:
            target = points[index]
            steps = max(1, math.ceil(float(np.linalg.norm(target - position)) / 0.1 - 1e-9))
            path = position + (np.arange(0, steps + 1) / steps)[:, None] * (target - position)
            if all(self._keeps_clearance(a, b) for a, b in zip(path[:-1], path[1:],
                                                                strict=True)):
                return path
        return None

    def _count_visit(self, position: np.ndarray) -> None:
        """The targets of the plan just finished count as looked at, if its goal was reached
        (see ``NarutoConfig.unresolved_visit_looks``)."""
        visit, self._visit = self._visit, None
        if visit is None or self.config.unresolved_visit_looks <= 0:
            return
        goal, targets = visit
        if np.linalg.norm(position - goal) > self.config.planner.step_m or self.sdf is None:
            return  # stopped on the way: nothing was refuted
        if self.visit_looks is None:
            self.visit_looks = np.zeros(self.sdf.shape, np.float32)
        cells = np.rint(self.sdf.world_to_voxel(np.asarray(targets, np.float64).reshape(-1, 3))
                        ).astype(np.int64)
        cells = cells[np.all((cells >= 0) & (cells < np.asarray(self.sdf.shape)), axis=1)]
        np.add.at(self.visit_looks, tuple(cells.T), np.float32(self.config.unresolved_visit_looks))
        self._view_stale = True

    def _damp_visited(self, uncertainty: SdfVolume) -> SdfVolume:
        """The planner view's uncertainty lowered by the looks of visits (see
        ``NarutoConfig.unresolved_visit_looks``)."""
        if self.visit_looks is None or self.visit_looks.shape != uncertainty.shape:
            return uncertainty
        weight = self.mapper.observed_space.config.look_weight
        return SdfVolume(uncertainty.values / (1.0 + weight * self.visit_looks),
                         uncertainty.origin, uncertainty.voxel_size)

    def _plan(self, position: np.ndarray, rotation: np.ndarray) -> Plan | None:
        """Goal search + E-RRT from ``position`` on the newest planner view."""
        self._count_visit(position)
        self._read_view()
        sdf, uncertainty = self.sdf, self.uncertainty
        record: dict[str, Any] = {"frame": self._frame_index, "position": position.tolist()}
        self.plans.append(record)
        if self.config.initial_look_around and len(self.plans) == 1:
            record.update(outcome="initial look-around", path_nodes=1)
            return Plan(position[None].copy(), self._look_around(position), position.copy(),
                        {"recovery": "look_around"})
        climb, self._climb = self._climb, None
        if climb is not None and np.linalg.norm(climb[0] - position) <= 1e-3:
            # Checked on the panorama already; the edge test held every way from here.
            record.update(outcome="climb out of the scan's margin", path_nodes=int(len(climb)))
            self.recoveries.append((self._frame_index, "climb"))
            return Plan(climb, self._look_around(climb[-1]), climb[-1].copy(),
                        {"recovery": "climb", "trusted": True})
        if self.monitor.needs_recovery():
            return self._recover(position, record)
        prefix = position[None]
        start = position
        if sdf.sample(position)[0] <= self._clearance:
            escape = self._escape(position)
            reach = self._clearance + self.config.escape_radius_m
            if escape is None and self._forget_guesses(position, reach):
                # Hemmed in by its own guesses: try again without those around it.
                sdf, uncertainty = self.sdf, self.uncertainty
                record["forgot_guesses"] = True
                escape = (position[None].copy() if sdf.sample(position)[0] > self._clearance
                          else self._escape(position))
            record["escape"] = escape is not None
            if escape is None:
                self._plan_failed(position, record, "start not free")
                return None
            prefix, start = escape, escape[-1]
        if self._components is None:
            self._components = FreeSpaceComponents.from_sdf(sdf, self._clearance)
        goal_mask = self._goal_mask(start)

        clock = time.perf_counter()
        travel = (self._components.travel_distances(start)
                  if self.config.goal_search.discount_by_travel else None)
        search = uncertainty_aware_goal_search(
            sdf, uncertainty, start, self._rng,
            replace(self.config.goal_search, top_k=self.config.goal_attempts),
            goal_mask=goal_mask,
            planner_config=replace(self.config.planner, device=str(self.device)),
            reachable_iterations=self.config.reachable_iterations,
            travel=travel,
        )
        self.timings["goal_search"] += time.perf_counter() - clock
        record.update(
            search_ms=search.diagnostics.get("time_ms", 0.0),
            fallback=search.used_reachable_mask,
            targets=int(len(search.targets)),
            goal_scores=[round(float(s), 4) for s in search.goal_scores],
        )
        if not search.found:
            self._plan_failed(position, record, "no goal sees a target")
            return None
        clock = time.perf_counter()
        try:
            for rank, (goal, views) in enumerate(zip(search.goals, search.goal_views, strict=True)):
                planner = replace(self.config.planner, seed=int(self._rng.integers(2**31 - 1)),
                                  device=str(self.device))
                result = plan_path(sdf, start, goal, planner, self._components)
                if result.success:
                    path = np.vstack([prefix[:-1], self._shorten(sdf, result.path)])
                    record.update(outcome="planned", goal=goal.tolist(), rank=rank,
                                  score=float(search.goal_scores[rank]),
                                  path_nodes=int(len(path)), rrt_ms=result.time_ms)
                    self.monitor.plan_succeeded()
                    self.monitor.progress_made(position)
                    self._visit = (goal.copy(), search.goal_visible[rank])
                    return Plan(path, views, goal.copy(), record)
                self.monitor.goal_failed(goal)
            self._plan_failed(position, record, f"no goal reachable ({result.reason})")
            return None
        finally:
            self.timings["rrt"] += time.perf_counter() - clock

    def _shorten(self, sdf: SdfVolume, path: np.ndarray) -> np.ndarray:
        """The planned path shortcut (``shortcut_paths``), nodes a step apart again (the
        tree's own nodes are a step apart already)."""
        if not self.config.shortcut_paths:
            return path
        planner = self.config.planner
        clearance = self._clearance + self.config.shortcut_margin_m
        return densify(shortcut_path(sdf, path, clearance, planner.collision_sample_m),
                       planner.step_m)

    def _goal_mask(self, start: np.ndarray) -> np.ndarray | None:
        """Candidate goals: free space connected to ``start``, measured free (when
        ``goals_in_observed_space``), away from goals that failed recently."""
        sdf = self.sdf
        labels = self._components.labels_near(start)
        mask = np.isin(self._components.labels, sorted(labels)) if labels else None
        observed = self.mapper.observed_space
        if self.config.goals_in_observed_space:
            free = observed.sample(observed.grid.free, sdf.grid_points()).reshape(sdf.shape)
            mask = free if mask is None else mask & free
        if self.config.stay_in_scanned_space:
            inside = self._inside_scan(sdf.grid_points(), start).reshape(sdf.shape)
            mask = inside if mask is None else mask & inside
        failed = self.monitor.recent_failed_goals()
        if len(failed):
            radius = self.config.recovery.failed_goal_radius_m
            points = sdf.grid_points()
            near = np.zeros(len(points), dtype=bool)
            for goal in failed:
                near |= np.linalg.norm(points - goal, axis=1) <= radius
            near = near.reshape(sdf.shape)
            mask = ~near if mask is None else mask & ~near
        return mask

    def _inside_scan(self, points: np.ndarray, position: np.ndarray) -> np.ndarray:
        """(N,) bool: points over measured surface and ``scan_top_margin_m`` below the
        measured surfaces' top, or no higher than the agent stands (where the env let it be:
        over a scan that is mostly floor the measured top can lie below the agent)."""
        observed = self.mapper.observed_space
        top = max(observed.scan_top_z() - self.config.scan_top_margin_m, float(position[2]))
        inside = observed.sample(observed.supported(), points) & (points[:, 2] <= top)
        if self._scan_open and self.config.sector_support_after_escape:
            candidates = np.flatnonzero(inside)
            inside[candidates] = observed.sectors_seen_below(points[candidates])
        return inside

    # -- recovery ----------------------------------------------------------------------------
    def _recover(self, position: np.ndarray, record: dict[str, Any]) -> Plan | None:
        """The next recovery step (look around, wander, retreat) as a plan."""
        kind = self.monitor.next_recovery()
        self.recoveries.append((self._frame_index, kind.value))
        record.update(recovery=kind.value)
        plan = None
        if kind == RecoveryKind.WANDER:
            plan = self._wander(position)
            if plan is None:
                kind = RecoveryKind.RETREAT
        if kind == RecoveryKind.RETREAT:
            path = self.monitor.retreat_path(position)
            if len(path) > 1:
                plan = Plan(path, self._look_around(path[-1]), path[-1].copy(),
                            {"recovery": "retreat", "trusted": True})
            else:
                kind = RecoveryKind.LOOK_AROUND
        if kind == RecoveryKind.LOOK_AROUND:
            plan = Plan(position[None].copy(), self._look_around(position), position.copy(),
                        {"recovery": "look_around"})
        record.update(outcome=f"recovery: {plan.info['recovery']}",
                      path_nodes=int(len(plan.path)))
        return plan

    def _look_around(self, position: np.ndarray) -> np.ndarray:
        recovery = self.config.recovery
        return look_around_targets(position, recovery.look_around_views,
                                   recovery.look_around_pitch_deg)

    def _wander(self, position: np.ndarray) -> Plan | None:
        """A path to reachable space within ``wander_max_m``, as far as possible from where
        the agent has been."""
        sdf = self.sdf
        if sdf.sample(position)[0] <= self._clearance:
            return None
        planner = replace(self.config.planner, seed=int(self._rng.integers(2**31 - 1)),
                          device=str(self.device))
        clock = time.perf_counter()
        try:
            reachable = reachable_voxels(sdf, position, planner,
                                         iterations=self.config.reachable_iterations)
            points = sdf.grid_points()[reachable.reshape(-1)]
            points = points[np.linalg.norm(points - position, axis=1)
                            <= self.config.recovery.wander_max_m]
            if self.config.stay_in_scanned_space:
                points = points[self._inside_scan(points, position)]
            if len(points) == 0:
                return None
            history = np.asarray(self.monitor.trajectory[-300:])
            novelty = np.full(len(points), np.inf)
            for chunk in np.array_split(history, max(1, len(history) // 64)):
                novelty = np.minimum(novelty, np.min(
                    np.linalg.norm(points[:, None, :] - chunk[None, :, :], axis=2), axis=1))
            order = np.argsort(-novelty, kind="stable")[:5]
            if self._components is None:
                self._components = FreeSpaceComponents.from_sdf(sdf, self._clearance)
            for goal in points[order]:
                result = plan_path(sdf, position, goal, planner, self._components)
                if result.success:
                    path = self._shorten(sdf, result.path)
                    return Plan(path, self._look_around(goal), goal.copy(),
                                {"recovery": "wander"})
            return None
        finally:
            self.timings["rrt"] += time.perf_counter() - clock
