"""The planner state machine with a scripted planner and a perfect mover (no env, no map)."""

from __future__ import annotations

import numpy as np
import pytest

from naruto_agent.naruto import TRANSITIONS, NarutoStateMachine, Plan, State
from naruto_gym.geometry.transforms import look_at_rotation, make_pose, rotation_angle_between

START = make_pose(look_at_rotation(np.zeros(3), np.array([0.0, 1.0, 0.0])), np.zeros(3))


def straight_plan(position: np.ndarray, rotation: np.ndarray) -> Plan:
    """1 m along +x in 0.1 m nodes; target 0 ahead-left, more views around the goal."""
    path = position + np.linspace(0.0, 1.0, 11)[:, None] * np.array([1.0, 0.0, 0.0])
    goal = path[-1]
    views = goal + np.array([[1.0, 1.0, 0.0], [-1.0, 0.5, 0.3], [0.0, -1.0, -0.5]])
    return Plan(path, views, goal)


def run(machine, steps, plan=straight_plan, new_map_every=5, blocked=lambda a, b: False,
        env_blocks_at=None):
    """Drive the machine: the 'env' applies every commanded pose, except moves beyond
    x = ``env_blocks_at``, which it refuses (reporting a collision)."""
    pose = START.copy()
    collided = False
    poses = []
    for step in range(steps):
        command = machine.step(
            pose, new_map=step % new_map_every == 0, collided=collided, plan=plan,
            move_is_free=lambda a, b: not blocked(a, b),
        )
        collided = env_blocks_at is not None and command[0, 3] > env_blocks_at
        if not collided:
            pose = command
        poses.append(pose.copy())
    return poses


def test_states_follow_the_published_order_and_table():
    machine = NarutoStateMachine()
    run(machine, 60)
    first_seen = list(dict.fromkeys(machine.history))
    assert first_seen == [State.ROTATING_AT_START, State.MOVING, State.ROTATING_AT_GOAL]
    changes = [(a, b) for a, b in machine.transitions]
    assert changes[:5] == [
        (State.STAYING, State.PLANNING),
        (State.PLANNING, State.ROTATING_AT_START),
        (State.ROTATING_AT_START, State.MOVING),
        (State.MOVING, State.ROTATING_AT_GOAL),
        (State.ROTATING_AT_GOAL, State.PLANNING),
    ]
    assert all(b in TRANSITIONS[a] for a, b in changes)
    # Moving took exactly the 10 path nodes, 0.1 m each.
    assert machine.history.count(State.MOVING) >= 10


def test_no_turn_exceeds_10_degrees_and_moves_are_single_nodes():
    machine = NarutoStateMachine(max_rotation_step_deg=10.0)
    poses = [START] + run(machine, 80)
    for before, after in zip(poses[:-1], poses[1:], strict=True):
        assert rotation_angle_between(before[:3, :3], after[:3, :3]) <= np.deg2rad(10.0) + 1e-9
        assert np.linalg.norm(after[:3, 3] - before[:3, 3]) <= 0.1 + 1e-9
    # While moving the camera ends up looking at target 0.
    first_plan = straight_plan(START[:3, 3], START[:3, :3])
    last_move = max(i for i, s in enumerate(machine.history[:40]) if s == State.MOVING)
    view = poses[last_move + 1]
    expected = look_at_rotation(view[:3, 3], first_plan.views[0])
    assert rotation_angle_between(view[:3, :3], expected) < np.deg2rad(1.0)
    # At the goal every view is visited exactly.
    begin = machine.history.index(State.ROTATING_AT_GOAL)
    end = machine.history.index(State.ROTATING_AT_START, begin)
    assert all(s == State.ROTATING_AT_GOAL for s in machine.history[begin:end])
    arrivals = poses[begin + 1 : end + 1]
    for target in first_plan.views:
        wanted = look_at_rotation(first_plan.goal, target)
        assert min(rotation_angle_between(p[:3, :3], wanted) for p in arrivals) < 1e-6


def test_staying_until_a_map_arrives_and_when_planning_fails():
    machine = NarutoStateMachine()
    pose = machine.step(START, new_map=False, collided=False, plan=straight_plan,
                        move_is_free=lambda a, b: True)
    assert machine.state == State.STAYING and np.allclose(pose, START)
    calls = []

    def no_plan(position, rotation):
        calls.append(position)
        return None

    pose = machine.step(START, new_map=True, collided=False, plan=no_plan,
                        move_is_free=lambda a, b: True)
    assert len(calls) == 1 and machine.state == State.STAYING and np.allclose(pose, START)
    # No new map: no new attempt.
    machine.step(START, new_map=False, collided=False, plan=no_plan,
                 move_is_free=lambda a, b: True)
    assert len(calls) == 1


def test_a_move_blocked_on_the_map_or_by_the_env_sends_it_staying():
    machine = NarutoStateMachine()
    run(machine, 40, blocked=lambda a, b: b[0] > 0.45)
    assert State.STAYING in machine.history and machine.collisions >= 1
    assert (State.MOVING, State.STAYING) in machine.transitions

    machine = NarutoStateMachine()
    poses = run(machine, 40, env_blocks_at=0.35)
    assert max(p[0, 3] for p in poses) <= 0.35 + 1e-9
    assert (State.MOVING, State.STAYING) in machine.transitions and machine.collisions >= 1


def test_bad_settings():
    with pytest.raises(ValueError, match="max_rotation_step_deg"):
        NarutoStateMachine(max_rotation_step_deg=0)
    with pytest.raises(ValueError, match="arrival_tolerance_m"):
        NarutoStateMachine(arrival_tolerance_m=-1)
