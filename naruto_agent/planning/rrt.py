"""RRT and E-RRT path planning on an SDF volume (NARUTO, CVPR 2024, Sec. 3.4 and Table 3).

One planner, two switches, so the four rows of the paper's ablation are the same code:

* ``direct_line``: every iteration first tries the straight line from the tree to the goal
  and adds a node every step along its free prefix. The line starts from whichever of the
  nodes added since the last attempt lies nearest the goal (the start, in the first
  iteration); when no node was added there is nothing new to try.
* ``fast_tree``: the extension towards a uniformly random point goes up to
  ``max_extend_steps`` (M = 10) steps instead of one, and every free intermediate node is
  added.

With both off it is a plain RRT: one node per iteration, towards a random point, no goal
bias. The goal is reached when a node lies within ``goal_tolerance_steps`` steps of it; the
path is the chain of tree nodes from the start (no smoothing), followed by the goal itself
when that last short segment is free.

Nearest neighbours are found by brute force over all nodes: numpy on the CPU, torch on a CUDA
device when one is present (``device="auto"``).
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from naruto_agent.mapping.sdf_volume import SdfVolume
from naruto_agent.planning.collision import samples_per_step, segment_is_free
from naruto_agent.planning.free_space import FreeSpaceComponents

_RANDOM_BATCH = 256


@dataclass
class PlannerConfig:
    """Settings of the planner; defaults are NARUTO's published ones (E-RRT).

    Attributes:
        step_m: tree step, metres (NARUTO: 0.1, one voxel).
        max_extend_steps: M, the most steps of one "fast tree" extension (NARUTO: 10).
        direct_line: try the straight line to the goal every iteration.
        fast_tree: extend by up to ``max_extend_steps`` steps, keeping every free node.
        collision_sample_m: spacing of collision samples along a move (NARUTO: 0.02).
        agent_radius_m: the agent is a sphere of this radius (NARUTO: 0.05).
        safety_margin_m: extra clearance on top of the radius (NARUTO: 0). See
            :func:`naruto_agent.planning.collision.guaranteed_margin_m` for the margin that
            makes the check conservative against the true geometry.
        max_iterations: give up after this many iterations.
        time_limit_s: give up after this much wall time.
        goal_tolerance_steps: the goal is reached within this many steps of it (NARUTO: 1).
        check_connectivity: before growing a tree, reject goals that no free path can reach
            (see :class:`~naruto_agent.planning.free_space.FreeSpaceComponents`).
        seed: seed of the random points; the same seed gives the same tree.
        device: where the nearest-neighbour search runs: "auto" (CUDA when available, else
            CPU), "cpu" (numpy, the fastest on a CPU), a torch device string ("cuda:0"), or
            "torch:cpu" (torch on the CPU; for testing).
    """

    step_m: float = 0.1
    max_extend_steps: int = 10
    direct_line: bool = True
    fast_tree: bool = True
    collision_sample_m: float = 0.02
    agent_radius_m: float = 0.05
    safety_margin_m: float = 0.0
    max_iterations: int = 30_000
    time_limit_s: float = 5.0
    goal_tolerance_steps: float = 1.0
    check_connectivity: bool = True
    seed: int | None = 0
    device: str = "auto"

    @property
    def clearance_m(self) -> float:
        """The SDF value a sample must exceed to be free."""
        return self.agent_radius_m + self.safety_margin_m

    def validate(self) -> None:
        """Raise a ValueError naming the first setting that is out of range."""
        positive = {
            "step_m": self.step_m,
            "collision_sample_m": self.collision_sample_m,
            "time_limit_s": self.time_limit_s,
            "goal_tolerance_steps": self.goal_tolerance_steps,
        }
        for name, value in positive.items():
            if not value > 0:
                raise ValueError(f"PlannerConfig.{name} must be positive, got {value}")
        if self.max_extend_steps < 1:
            raise ValueError(f"max_extend_steps must be >= 1, got {self.max_extend_steps}")
        if self.max_iterations < 1:
            raise ValueError(f"max_iterations must be >= 1, got {self.max_iterations}")
        if self.agent_radius_m < 0 or self.safety_margin_m < 0:
            raise ValueError("agent_radius_m and safety_margin_m must be >= 0 metres")


@dataclass
class PlanResult:
    """Outcome of one planning request.

    Attributes:
        success: whether a path to the goal was found.
        path: (K, 3) waypoints from the start (exactly) to within one step of the goal;
            (0, 3) on failure. Consecutive waypoints are at most one step apart (the goal,
            appended when its last short segment is free, at most the goal tolerance).
        nodes: number of tree nodes when planning ended (start included).
        iterations: planner iterations run.
        time_ms: wall time of the request, milliseconds.
        reason: "reached" on success, otherwise why it failed.
        tree: (nodes, 3) all tree nodes, for inspection and plots.
    """

    success: bool
    path: np.ndarray
    nodes: int
    iterations: int
    time_ms: float
    reason: str
    tree: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)), repr=False)


@functools.lru_cache(maxsize=1)
def _auto_device() -> str:
    try:
        import torch
    except ImportError:  # pragma: no cover - torch is a dependency
        return "cpu"
    return "cuda" if torch.cuda.is_available() else "cpu"


def resolve_device(device: str) -> str:
    """"auto" -> "cuda" when torch sees a GPU, else "cpu"; other strings pass through.

    The first "auto" call imports torch (about a second); the answer is cached.
    """
    return _auto_device() if device == "auto" else device


class _Tree:
    """Preallocated node storage with brute-force nearest-neighbour search."""

    def __init__(self, root: np.ndarray, capacity: int, device: str) -> None:
        """``device == "cpu"``: numpy search; any other torch device: torch search there
        ("torch:cpu" runs the torch search on the CPU, to test that path without a GPU)."""
        self.points = np.empty((capacity, 3), dtype=np.float64)
        self.parents = np.empty(capacity, dtype=np.int64)
        self.points[0] = root
        self.parents[0] = -1
        self.squared_norms = np.empty(capacity, dtype=np.float64)
        self.squared_norms[0] = float(root @ root)
        self.count = 1
        self._torch_points = None
        if device != "cpu":
            import torch

            self._torch = torch
            device = device.removeprefix("torch:")
            # float64 so that the GPU picks the same neighbour as numpy, ties included.
            self._torch_points = torch.empty((capacity, 3), dtype=torch.float64, device=device)
            self._torch_points[0] = torch.as_tensor(root, dtype=torch.float64)

    def _grow(self, needed: int) -> None:
        capacity = len(self.points)
        if needed <= capacity:
            return
        new_capacity = max(needed, 2 * capacity)
        points = np.empty((new_capacity, 3), dtype=np.float64)
        points[: self.count] = self.points[: self.count]
        parents = np.empty(new_capacity, dtype=np.int64)
        parents[: self.count] = self.parents[: self.count]
        norms = np.empty(new_capacity, dtype=np.float64)
        norms[: self.count] = self.squared_norms[: self.count]
        self.points, self.parents, self.squared_norms = points, parents, norms
        if self._torch_points is not None:
            grown = self._torch.empty(
                (new_capacity, 3), dtype=self._torch_points.dtype, device=self._torch_points.device
            )
            grown[: self.count] = self._torch_points[: self.count]
            self._torch_points = grown

    def add_chain(self, parent: int, points: np.ndarray) -> range:
        """Append ``points`` as a chain hanging from ``parent``; returns their indices."""
        added = len(points)
        begin = self.count
        self._grow(begin + added)
        self.points[begin : begin + added] = points
        self.parents[begin] = parent
        self.parents[begin + 1 : begin + added] = np.arange(begin, begin + added - 1)
        self.squared_norms[begin : begin + added] = np.einsum("ij,ij->i", points, points)
        if self._torch_points is not None:
            self._torch_points[begin : begin + added] = self._torch.as_tensor(
                points, dtype=self._torch_points.dtype
            )
        self.count += added
        return range(begin, begin + added)

    def nearest(self, query: np.ndarray) -> int:
        if self._torch_points is not None:
            query_t = self._torch.as_tensor(query, dtype=self._torch_points.dtype).to(
                self._torch_points.device
            )
            difference = self._torch_points[: self.count] - query_t
            return int(self._torch.argmin((difference * difference).sum(dim=1)).item())
        # |p - q|^2 = |p|^2 - 2 p.q + |q|^2: one matrix-vector product per query.
        count = self.count
        return int(np.argmin(self.squared_norms[:count] - 2.0 * (self.points[:count] @ query)))

    def path_to(self, index: int) -> np.ndarray:
        chain = []
        while index >= 0:
            chain.append(index)
            index = int(self.parents[index])
        return self.points[chain[::-1]].copy()


def _point(value: np.ndarray, what: str) -> np.ndarray:
    point = np.asarray(value, dtype=np.float64).reshape(-1)
    if point.shape != (3,) or not np.all(np.isfinite(point)):
        raise ValueError(f"{what} must be a finite (3,) world point in metres, got {value!r}")
    return point


class _MoveChecker:
    """The planner's hot path: the free prefix of a move, in one trilinear lookup.

    Same samples and rule as :func:`~naruto_agent.planning.collision.free_steps_along_segment`
    (every ``collision_sample_m``, free where SDF > clearance, counted from the start), with
    the sample offsets precomputed and the points built directly in voxel coordinates.
    """

    def __init__(self, sdf: SdfVolume, config: PlannerConfig) -> None:
        self.values = sdf.values
        self.origin = sdf.origin
        self.inverse_voxel = 1.0 / sdf.voxel_size
        self.step_m = config.step_m
        self.per_step = samples_per_step(config.step_m, config.collision_sample_m)
        self.clearance = config.clearance_m
        diagonal = float(np.linalg.norm(sdf.bounds[1] - sdf.bounds[0]))
        self._grow(int(diagonal / config.step_m) + 2)

    def _grow(self, steps: int) -> None:
        self.max_steps = steps
        self.along = np.arange(1, steps * self.per_step + 1, dtype=np.float64) * (
            self.step_m / self.per_step
        )
        self.buffer = np.empty(len(self.along), dtype=self.values.dtype)

    def free_steps(self, origin: np.ndarray, direction: np.ndarray, steps: int) -> int:
        if steps > self.max_steps:
            self._grow(steps)
        count = steps * self.per_step
        start = (origin - self.origin) * self.inverse_voxel
        coordinates = start[:, None] + (direction * self.inverse_voxel)[:, None] * self.along[
            None, :count
        ]
        values = self.buffer[:count]
        ndimage.map_coordinates(
            self.values, coordinates, output=values, order=1, mode="constant", cval=-1.0,
            prefilter=False,
        )
        free = values > self.clearance
        if free.all():
            return steps
        return int(free.argmin()) // self.per_step

    def steps_towards(
        self, tree: _Tree, source: int, target: np.ndarray, max_steps: int
    ) -> range:
        """Add the free prefix of up to ``max_steps`` steps from node ``source`` to ``target``.

        Takes at least one step when the target is nearer than a step (a node may overshoot
        a random point by less than a step; the goal is reached within tolerance first).
        """
        origin = tree.points[source]
        delta = target - origin
        distance = math.sqrt(float(delta @ delta))
        if distance < 1e-12:
            return range(0)
        steps = min(max_steps, max(1, int(distance / self.step_m + 1e-9)))
        direction = delta / distance
        free = self.free_steps(origin, direction, steps)
        if free == 0:
            return range(0)
        ends = self.along[self.per_step - 1 : free * self.per_step : self.per_step]
        return tree.add_chain(source, origin + ends[:, None] * direction)


def _first_within(tree: _Tree, added: range, goal: np.ndarray, tolerance: float) -> int:
    if len(added) == 0:
        return -1
    difference = tree.points[added.start : added.stop] - goal
    near = np.einsum("ij,ij->i", difference, difference) <= tolerance * tolerance + 1e-12
    return added.start + int(np.argmax(near)) if near.any() else -1


def plan_path(
    sdf: SdfVolume,
    start: np.ndarray,
    goal: np.ndarray,
    config: PlannerConfig | None = None,
    components: FreeSpaceComponents | None = None,
) -> PlanResult:
    """Plan a collision-free path from ``start`` to ``goal`` with RRT / E-RRT.

    Args:
        sdf: signed distance volume, metres, positive in free space.
        start: (3,) start position (world, metres).
        goal: (3,) goal position.
        config: planner settings (default: NARUTO's E-RRT).
        components: precomputed free-space components for ``sdf`` at the config's clearance,
            to share the connectivity check between requests; built here when needed and
            not given.

    Returns:
        A :class:`PlanResult`; failures come back with ``success=False`` and a reason
        (start or goal outside the volume or not free, goal not connected, iteration or time
        limit), never as an exception.
    """
    config = config or PlannerConfig()
    config.validate()
    start = _point(start, "start")
    goal = _point(goal, "goal")
    began = time.perf_counter()
    deadline = began + config.time_limit_s

    def finish(success: bool, reason: str, tree: _Tree | None = None, iterations: int = 0,
               path: np.ndarray | None = None) -> PlanResult:
        nodes = tree.count if tree is not None else 0
        return PlanResult(
            success=success,
            path=path if path is not None else np.zeros((0, 3)),
            nodes=nodes,
            iterations=iterations,
            time_ms=(time.perf_counter() - began) * 1e3,
            reason=reason,
            tree=tree.points[:nodes].copy() if tree is not None else np.zeros((0, 3)),
        )

    clearance = config.clearance_m
    inside = sdf.contains(np.stack([start, goal]))
    box = np.round(sdf.bounds, 3).tolist()
    if not inside[0]:
        return finish(False, f"start {start.tolist()} is outside the SDF volume {box}")
    if not inside[1]:
        return finish(False, f"goal {goal.tolist()} is outside the SDF volume {box}")
    start_sdf, goal_sdf = sdf.sample(np.stack([start, goal]))
    if start_sdf <= clearance:
        return finish(False, f"start is not in free space (SDF {start_sdf:.3f} m <= {clearance} m)")
    if goal_sdf <= clearance:
        return finish(False, f"goal is not in free space (SDF {goal_sdf:.3f} m <= {clearance} m)")
    if config.check_connectivity:
        if components is None or abs(components.clearance_m - clearance) > 1e-9:
            components = FreeSpaceComponents.from_sdf(sdf, clearance)
        if not components.connected(start, goal):
            return finish(False, "goal is not connected to the start through free space")

    tree = _Tree(start, capacity=4096, device=resolve_device(config.device))
    mover = _MoveChecker(sdf, config)
    tolerance = config.goal_tolerance_steps * config.step_m

    def success_at(index: int, iterations: int) -> PlanResult:
        path = tree.path_to(index)
        if np.linalg.norm(path[-1] - goal) > 1e-9 and segment_is_free(
            sdf, path[-1], goal, config.collision_sample_m, clearance
        ):
            path = np.vstack([path, goal])
        return finish(True, "reached", tree, iterations, path)

    if np.linalg.norm(goal - start) <= tolerance:
        return success_at(0, 0)

    rng = np.random.default_rng(config.seed)
    bounds = sdf.bounds
    randoms = rng.uniform(bounds[0], bounds[1], size=(_RANDOM_BATCH, 3))
    next_random = 0
    extend_steps = config.max_extend_steps if config.fast_tree else 1
    untried = range(0, 1)  # nodes added since the last direct-line attempt
    for iteration in range(1, config.max_iterations + 1):
        if time.perf_counter() > deadline:
            return finish(False, f"time limit of {config.time_limit_s} s reached", tree,
                          iteration - 1)
        if config.direct_line and len(untried) > 0:
            candidates = tree.points[untried.start : untried.stop] - goal
            source = untried.start + int(np.argmin(np.einsum("ij,ij->i", candidates, candidates)))
            untried = range(0)
            distance = float(np.linalg.norm(goal - tree.points[source]))
            whole_steps = int(distance / config.step_m + 1e-9)
            if whole_steps > 0:
                added = mover.steps_towards(tree, source, goal, whole_steps)
                reached = _first_within(tree, added, goal, tolerance)
                if reached >= 0:
                    return success_at(reached, iteration)

        if next_random >= len(randoms):
            randoms = rng.uniform(bounds[0], bounds[1], size=(_RANDOM_BATCH, 3))
            next_random = 0
        target = randoms[next_random]
        next_random += 1
        added = mover.steps_towards(tree, tree.nearest(target), target, extend_steps)
        if len(added) > 0:
            reached = _first_within(tree, added, goal, tolerance)
            if reached >= 0:
                return success_at(reached, iteration)
            untried = added
    return finish(False, f"iteration limit of {config.max_iterations} reached", tree,
                  config.max_iterations)


def reachable_voxels(
    sdf: SdfVolume,
    start: np.ndarray,
    config: PlannerConfig | None = None,
    iterations: int = 2000,
) -> np.ndarray:
    """Voxels within one step of a tree grown from ``start`` over the whole volume.

    NARUTO's goal search falls back to this when no goal sees a target: it grows an RRT
    with no goal (fast-tree extensions towards random points) and masks the uncertainty
    with the voxels the tree reaches.

    Args:
        sdf: signed distance volume.
        start: (3,) root of the tree (must be free, else nothing is reachable).
        config: planner settings (step, clearance, seed, time limit, device).
        iterations: number of extensions.

    Returns:
        (nx, ny, nz) bool mask of voxels whose centre lies within one step of a tree node.
    """
    config = config or PlannerConfig()
    config.validate()
    start = _point(start, "start")
    mask = np.zeros(sdf.shape, dtype=bool)
    if not sdf.contains(start)[0] or sdf.sample(start)[0] <= config.clearance_m:
        return mask
    tree = _Tree(start, capacity=4096, device=resolve_device(config.device))
    mover = _MoveChecker(sdf, config)
    rng = np.random.default_rng(config.seed)
    bounds = sdf.bounds
    deadline = time.perf_counter() + config.time_limit_s
    extend_steps = config.max_extend_steps if config.fast_tree else 1
    targets = rng.uniform(bounds[0], bounds[1], size=(iterations, 3))
    for target in targets:
        if time.perf_counter() > deadline:
            break
        mover.steps_towards(tree, tree.nearest(target), target, extend_steps)

    # Every voxel centre within one step of a node: test the block of voxels around each node.
    nodes = sdf.world_to_voxel(tree.points[: tree.count])
    reach = config.step_m / sdf.voxel_size
    span = math.ceil(reach)
    offsets = np.arange(-span, span + 2)
    block = np.stack(np.meshgrid(offsets, offsets, offsets, indexing="ij"), -1).reshape(-1, 3)
    candidates = np.floor(nodes).astype(np.int64)[:, None, :] + block[None, :, :]
    close = np.linalg.norm(candidates - nodes[:, None, :], axis=2) <= reach + 1e-9
    inside = np.all((candidates >= 0) & (candidates < np.asarray(sdf.shape)), axis=2)
    hits = candidates[close & inside]
    mask[hits[:, 0], hits[:, 1], hits[:, 2]] = True
    return mask
