"""NARUTO's planner state machine (Feng et al., NARUTO, CVPR 2024), one frame per call.

| state | goes to | does |
|---|---|---|
| staying | planning when a new map arrived | keeps the pose |
| planning | rotating-at-start if a reachable goal was found, else staying | goal search + E-RRT |
| rotating-at-start | moving when its rotations are used up | SLERP towards looking at target 0 |
| moving | rotating-at-goal at the path's end; staying on a detected collision | one path node
  (0.1 m) per frame, looking at target 0 |
| rotating-at-goal | planning when done | visit up to 10 target views by SLERP |

The machine knows nothing of maps or planners: :meth:`NarutoStateMachine.step` takes the
current pose, whether a new map arrived, whether the last move collided, a ``plan`` callback
(goal search + path planning, returning a :class:`Plan` or None) and a ``move_is_free``
callback (the agent's own collision check of the next move), and returns the pose to command.
Planning takes no frame of its own: the state after it acts in the same call.

Every turn is split into SLERP steps of at most ``max_rotation_step_deg`` (10 degrees, with
``ceil``, see :func:`~naruto_agent.planning.slerp_rotations`), while moving too: the camera
turns towards target 0 by at most that much per node.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from naruto_agent.planning.rotation import InViewTest, plan_rotations, slerp_rotations
from naruto_gym.geometry.transforms import look_at_rotation, make_pose


class State(str, Enum):
    """The planner's states."""

    STAYING = "staying"
    PLANNING = "planning"
    ROTATING_AT_START = "rotating_at_start"
    MOVING = "moving"
    ROTATING_AT_GOAL = "rotating_at_goal"


TRANSITIONS: dict[State, frozenset[State]] = {
    State.STAYING: frozenset({State.STAYING, State.PLANNING}),
    State.PLANNING: frozenset({State.ROTATING_AT_START, State.STAYING}),
    State.ROTATING_AT_START: frozenset({State.ROTATING_AT_START, State.MOVING, State.STAYING}),
    State.MOVING: frozenset({State.MOVING, State.ROTATING_AT_GOAL, State.STAYING}),
    State.ROTATING_AT_GOAL: frozenset({State.ROTATING_AT_GOAL, State.PLANNING, State.STAYING}),
}
"""Allowed successors of every state (staying in a state is a successor too, where a state
lasts several frames). Every state may also go to staying when a stall watchdog cuts the
plan short (:meth:`NarutoStateMachine.interrupt`)."""

# Closer than this to target 0, a node keeps the camera's rotation (looking at a point from
# on top of it is undefined).
_MIN_LOOK_DISTANCE_M = 0.05


@dataclass
class Plan:
    """What planning hands to the state machine.

    Attributes:
        path: (K, 3) waypoints, ``path[0]`` the agent's position, consecutive ones at most a
            step (0.1 m) apart, the last the goal.
        views: (V, 3) targets to look at at the goal (V >= 1); target 0 is watched on the way.
        goal: (3,) the goal.
        info: diagnostics (scores, timings) for logs; ``move_at_once`` skips the turn
            towards target 0 before the first move (it turns on the way).
    """

    path: np.ndarray
    views: np.ndarray
    goal: np.ndarray
    info: dict = field(default_factory=dict)


PlanFunction = Callable[[np.ndarray, np.ndarray], "Plan | None"]
MoveCheck = Callable[[np.ndarray, np.ndarray], bool]


def orthonormalised(rotation: np.ndarray) -> np.ndarray:
    """The proper rotation nearest to a 3x3 matrix (float32 poses drift off orthonormal)."""
    u, _, vt = np.linalg.svd(np.asarray(rotation, dtype=np.float64))
    result = u @ vt
    if np.linalg.det(result) < 0:
        u[:, -1] *= -1
        result = u @ vt
    return result


class NarutoStateMachine:
    """Staying -> planning -> rotating-at-start -> moving -> rotating-at-goal -> planning ...

    Args:
        max_rotation_step_deg: largest turn per frame (NARUTO: 10 degrees).
        arrival_tolerance_m: while moving, an agent farther than this from the node it was
            sent to was stopped (by the env's collision check) and counts as a collision.
        in_view: None (published) turns to every view at the goal; given (see
            :func:`~naruto_agent.planning.rotation.plan_rotations`), views already in the
            image are not turned to.

    Attributes:
        state: the current state.
        history: the state that produced each returned pose, in order.
        transitions: every state change, in order, as (from, to).
        plan: the plan being carried out (None before the first one).
    """

    def __init__(self, max_rotation_step_deg: float = 10.0, arrival_tolerance_m: float = 0.01,
                 in_view: InViewTest | None = None):
        if not max_rotation_step_deg > 0:
            raise ValueError(f"max_rotation_step_deg must be positive, got "
                             f"{max_rotation_step_deg}")
        if arrival_tolerance_m < 0:
            raise ValueError(f"arrival_tolerance_m must be >= 0, got {arrival_tolerance_m}")
        self.max_rotation_step_deg = float(max_rotation_step_deg)
        self.arrival_tolerance_m = float(arrival_tolerance_m)
        self.in_view = in_view
        self.reset()

    def reset(self) -> None:
        """Back to "staying" with nothing planned."""
        self.state = State.STAYING
        self.history: list[State] = []
        self.transitions: list[tuple[State, State]] = []
        #: indices into ``transitions`` of those :meth:`interrupt` made (not the published
        #: order's own).
        self.interruptions: list[int] = []
        self.plan: Plan | None = None
        self.collisions = 0
        self._rotations: deque[np.ndarray] = deque()
        self._path: deque[np.ndarray] = deque()
        self._commanded: np.ndarray | None = None

    def interrupt(self) -> None:
        """Drop the plan being carried out and stay (a stall watchdog's recovery): the next
        :meth:`step` with a new map plans again."""
        self._path.clear()
        self._rotations.clear()
        self._commanded = None
        if self.state != State.STAYING:
            self.interruptions.append(len(self.transitions))
        self._go(State.STAYING)

    def _go(self, state: State) -> None:
        if state not in TRANSITIONS[self.state]:  # pragma: no cover - guards the table
            raise RuntimeError(f"illegal transition {self.state.value} -> {state.value}")
        if state != self.state:
            self.transitions.append((self.state, state))
        self.state = state

    def _emit(self, position: np.ndarray, rotation: np.ndarray) -> np.ndarray:
        self.history.append(self.state)
        return make_pose(rotation, position)

    def step(
        self,
        pose: np.ndarray,
        new_map: bool,
        collided: bool,
        plan: PlanFunction,
        move_is_free: MoveCheck,
        plan_when_held: bool = False,
    ) -> np.ndarray:
        """Advance one frame and return the 4x4 camera-to-world pose to command.

        Args:
            pose: the agent's current 4x4 camera-to-world pose.
            new_map: a map newer than the last planning is available.
            collided: the env reported that the last move was blocked.
            plan: ``plan(position, rotation) -> Plan | None`` (goal search + E-RRT).
            move_is_free: ``move_is_free(from, to)``, the agent's own check of a move on its
                map.
            plan_when_held: a move ``move_is_free`` holds is planned around in this frame
                (once) instead of the frame ending standing.
        """
        pose = np.asarray(pose, dtype=np.float64)
        position = pose[:3, 3].copy()
        rotation = orthonormalised(pose[:3, :3])
        if self.state == State.MOVING and self._commanded is not None:
            stopped = np.linalg.norm(position - self._commanded) > self.arrival_tolerance_m
            if collided or stopped:
                self.collisions += 1
                self._path.clear()
                self._go(State.STAYING)
        self._commanded = None
        for _ in range(2 * (len(State) + 2)):  # every state emits or moves on; at most one
            # cycle is planned again
            if self.state == State.STAYING:
                if not new_map:
                    return self._emit(position, rotation)
                self._go(State.PLANNING)
            elif self.state == State.PLANNING:
                new_map = False
                found = plan(position, rotation)
                if found is None:
                    self._go(State.STAYING)
                    return self._emit(position, rotation)
                self.plan = found
                self._path = deque(np.asarray(found.path, dtype=np.float64)[1:])
                self._rotations = deque(
                    slerp_rotations(rotation, self._look_at(position, rotation),
                                    self.max_rotation_step_deg)
                ) if not found.info.get("move_at_once") else deque()
                self._go(State.ROTATING_AT_START)
            elif self.state == State.ROTATING_AT_START:
                if self._rotations:
                    return self._emit(position, self._rotations.popleft())
                self._go(State.MOVING)
            elif self.state == State.MOVING:
                if not self._path:
                    views = np.asarray(self.plan.views, dtype=np.float64).reshape(-1, 3)
                    far = np.linalg.norm(views - position, axis=1) > _MIN_LOOK_DISTANCE_M
                    turns = plan_rotations(rotation, position, views[far],
                                           self.max_rotation_step_deg, in_view=self.in_view)
                    self._rotations = deque(turns.rotations)
                    self._go(State.ROTATING_AT_GOAL)
                    continue
                node = self._path[0]
                if not move_is_free(position, node):
                    self.collisions += 1
                    self._path.clear()
                    self._go(State.STAYING)
                    if plan_when_held:
                        plan_when_held, new_map = False, True
                        continue
                    return self._emit(position, rotation)
                self._path.popleft()
                desired = self._look_at(node, rotation)
                turn = slerp_rotations(rotation, desired, self.max_rotation_step_deg)[0]
                self._commanded = node.copy()
                return self._emit(node, turn)
            else:  # ROTATING_AT_GOAL
                if self._rotations:
                    return self._emit(position, self._rotations.popleft())
                self._go(State.PLANNING)
        raise RuntimeError("state machine made no decision")  # pragma: no cover

    def _look_at(self, eye: np.ndarray, fallback: np.ndarray) -> np.ndarray:
        """Rotation looking from ``eye`` at target 0 of the plan (``fallback`` when on it)."""
        target = np.asarray(self.plan.views, dtype=np.float64).reshape(-1, 3)[0]
        if np.linalg.norm(target - eye) <= _MIN_LOOK_DISTANCE_M:
            return fallback
        return look_at_rotation(eye, target)
