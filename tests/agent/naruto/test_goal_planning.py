"""The NARUTO agent's planning step: goals and paths, escapes, climbs and recoveries."""

from __future__ import annotations

import numpy as np

from naruto_agent.mapping.sdf_volume import SdfVolume
from naruto_agent.naruto import NarutoConfig
from naruto_agent.naruto.paths import shorten_path
from naruto_agent.naruto.recovery import RecoveryKind
from tests.agent.naruto.agent_parts import make_parts, walls_up_to
from tests.agent.synthetic_panoramas import floor_panorama

#: Goals anywhere in free space (the hand-made maps measure nothing).
ANYWHERE = {"goals_in_observed_space": False, "stay_in_scanned_space": False}


def room() -> tuple[SdfVolume, SdfVolume]:
    """A 3 m cube whose walls are 0.3 m thick; the wall at x = 0.3 m is uncertain."""
    points = np.stack(np.meshgrid(*[np.arange(30) * 0.1] * 3, indexing="ij"), -1)
    distance = np.min(np.concatenate([points - 0.3, 2.7 - points], axis=-1), axis=-1)
    uncertainty = np.zeros((30, 30, 30))
    uncertainty[3, 5:25, 5:25] = 1.0
    return (SdfVolume(distance, np.zeros(3), 0.1),
            SdfVolume(uncertainty, np.zeros(3), 0.1))


def test_a_plan_goes_to_a_goal_that_sees_the_uncertain_wall() -> None:
    sdf, uncertainty = room()
    parts = make_parts(sdf=sdf, uncertainty=uncertainty,
                       config=NarutoConfig(initial_look_around=False, **ANYWHERE))
    start = np.array([2.0, 1.5, 1.5])
    plan = parts.planner.plan(start, frame=7)
    record = parts.planner.plans[-1]
    assert record["outcome"] == "planned" and record["frame"] == 7
    assert plan.info is record and np.allclose(plan.path[0], start)
    assert np.all(np.linalg.norm(np.diff(plan.path, axis=0), axis=1) <= 0.1 + 1e-9)
    np.testing.assert_allclose(plan.path[-1], plan.goal)
    assert 0.5 < plan.goal[0] - 0.3 < 2.0  # within the search's range of the wall
    assert np.allclose(plan.views[:, 0], 0.3, atol=0.05)
    assert parts.monitor.failed_plans == 0
    # Reaching the goal counts a look at every target it was chosen for.
    parts.planner.count_visit(plan.goal)
    assert parts.agent_map.visit_looks.max() == parts.config.unresolved_visit_looks
    looks = parts.agent_map.visit_looks.copy()
    parts.planner.count_visit(plan.goal)  # once per plan
    np.testing.assert_array_equal(parts.agent_map.visit_looks, looks)


def test_failed_plans_lead_to_the_recovery_steps() -> None:
    sdf, _ = room()
    parts = make_parts(sdf=sdf, config=NarutoConfig(initial_look_around=False, **ANYWHERE))
    start = np.array([1.5, 1.5, 1.5])
    for _ in range(parts.config.recovery.max_failed_plans):
        assert parts.planner.plan(start) is None
        assert parts.planner.plans[-1]["outcome"] == "no goal sees a target"
    plan = parts.planner.plan(start, frame=3)
    assert plan.info == {"recovery": "look_around"} and len(plan.path) == 1
    assert parts.planner.recoveries == [(3, "look_around")]
    assert parts.planner.plans[-1]["outcome"] == "recovery: look_around"


def test_the_recovery_steps_escalate_and_fall_back() -> None:
    sdf, _ = room()
    parts = make_parts(sdf=sdf, config=NarutoConfig(**ANYWHERE))
    recovery = parts.planner.recovery
    here = np.array([1.5, 1.5, 1.5])
    for x in np.linspace(1.0, 1.5, 6):
        parts.monitor.record(np.array([x, 1.5, 1.5]), 0.0)
    kind, plan = recovery.next_plan(here)
    assert kind == RecoveryKind.LOOK_AROUND and plan.info == {"recovery": "look_around"}
    kind, plan = recovery.next_plan(here)
    assert kind == RecoveryKind.WANDER and plan.info == {"recovery": "wander"}
    assert np.linalg.norm(plan.goal - here) <= parts.config.recovery.wander_max_m + 1e-9
    kind, plan = recovery.next_plan(here)
    assert kind == RecoveryKind.RETREAT and plan.info == {"recovery": "retreat", "trusted": True}
    assert plan.path[-1][0] < here[0]
    # Inside a clearance the wander finds no way and retreats instead.
    assert parts.monitor.next_recovery() == RecoveryKind.LOOK_AROUND
    kind, plan = recovery.next_plan(np.array([0.35, 1.5, 1.5]))
    assert kind == RecoveryKind.WANDER and plan.info["recovery"] == "retreat"


def test_the_first_plan_looks_around_and_a_pending_climb_comes_next() -> None:
    agent = np.array([1.5, 1.5, 1.0])
    parts = make_parts(observed=walls_up_to(2.6), panorama=floor_panorama(edge_x_m=0.3),
                       where=agent, scan_open=True)
    plan = parts.planner.plan(agent)
    assert plan.info == {"recovery": "look_around"}
    assert parts.planner.plans[-1]["outcome"] == "initial look-around"
    for _ in range(parts.config.guard.max_held_moves + 1):
        assert not parts.checks.panorama_keeps_to_scan(agent, agent + [0.25, 0.0, 0.0])
    plan = parts.planner.plan(agent, frame=9)
    assert plan.info == {"recovery": "climb", "trusted": True, "move_at_once": True}
    top = agent + [0.0, 0.0, parts.config.margin_climb_m]
    np.testing.assert_allclose(plan.path[-1], top)
    assert len(plan.views) == parts.config.recovery.look_around_views  # no heading given
    assert parts.planner.recoveries == [(9, "climb")]
    assert parts.checks.pending_climb is None  # used once
    # Given the camera's rotation, the climb keeps facing the way the camera faces (no
    # look-around at the top: the next plan comes at once).
    for _ in range(parts.config.guard.max_held_moves + 1):
        assert not parts.checks.panorama_keeps_to_scan(agent, agent + [0.25, 0.0, 0.0])
    facing_y = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # z -> +y
    plan = parts.planner.plan(agent, frame=12, rotation=facing_y)
    np.testing.assert_allclose(plan.views, [top + [0.0, 1.0, 0.0]])


def test_escape_from_inside_a_blocked_ball_takes_a_line_the_move_check_accepts() -> None:
    """The agent stands within its clearance, next to the blocked ball of a move refused a
    step ahead (+x), with a wall close behind it (-x): the escape ends well inside free
    space and every node of it passes the agent's own move check (else it is refused at
    every try and the agent never moves)."""
    values = np.full((30, 30, 30), 0.5)
    values[:10] = -0.1  # a wall up to x = 0.95 m
    values[10] = 0.04  # the voxels at x = 1.0 m: inside the agent's clearance
    agent = np.array([1.02, 1.5, 1.0])
    parts = make_parts(sdf=SdfVolume(values, np.zeros(3), 0.1))
    parts.agent_map.block(agent + [0.1, 0.0, 0.0])
    clearance = parts.config.planner.clearance_m
    assert parts.agent_map.sdf.sample(agent[None])[0] <= clearance  # trapped, as the agent was
    path = parts.planner.escape(agent)
    assert path is not None and np.allclose(path[0], agent)
    assert parts.agent_map.sdf.sample(path[-1][None])[0] > clearance
    assert all(parts.checker.is_free(a, b) for a, b in zip(path[:-1], path[1:], strict=True))
    assert make_parts(config=NarutoConfig(escape_radius_m=0.0)).planner.escape(agent) is None


def test_goal_mask_keeps_goals_away_from_failed_ones() -> None:
    sdf, _ = room()
    parts = make_parts(sdf=sdf, config=NarutoConfig(**ANYWHERE))
    start = np.array([1.5, 1.5, 1.5])
    mask = parts.planner.goal_mask(start)
    assert mask.shape == sdf.shape and mask[15, 15, 15] and not mask[1, 15, 15]
    parts.monitor.goal_failed(np.array([2.0, 2.0, 2.0]))
    masked = parts.planner.goal_mask(start)
    assert mask[20, 20, 20] and not masked[20, 20, 20] and masked[15, 15, 15]
    assert masked[20, 20, 10]  # a goal that failed on its own: lower ones stay candidates
    # A goal that failed past an open scan's edge fails at every height.
    parts.monitor.goal_failed(np.array([1.0, 1.0, 2.0]), column=True)
    masked = parts.planner.goal_mask(start)
    assert not masked[10, 10, 20] and not masked[10, 10, 5] and masked[15, 15, 5]
    assert len(parts.monitor.recent_failed_goals()) == 2
    assert len(parts.monitor.recent_failed_goals(columns=True)) == 1


def test_shortened_paths_keep_nodes_a_step_apart() -> None:
    sdf, _ = room()
    zigzag = np.array([[1.0, 1.0, 1.5], [1.1, 1.1, 1.5], [1.2, 1.0, 1.5], [1.3, 1.1, 1.5],
                       [1.4, 1.0, 1.5]])
    short = shorten_path(sdf, zigzag, NarutoConfig())
    assert np.allclose(short[0], zigzag[0]) and np.allclose(short[-1], zigzag[-1])
    assert np.sum(np.linalg.norm(np.diff(short, axis=0), axis=1)) < 0.45
    assert np.all(np.linalg.norm(np.diff(short, axis=0), axis=1) <= 0.1 + 1e-9)
    assert shorten_path(sdf, zigzag, NarutoConfig(shortcut_paths=False)) is zigzag


def test_a_plan_asked_to_leave_a_spot_goes_past_it_and_moves_at_once() -> None:
    """After a stall watchdog cut a look-around short: a goal farther than the radius from
    the spot, no turn first; the request holds while plans fail and ends with the plan."""
    sdf, uncertainty = room()
    parts = make_parts(sdf=sdf, uncertainty=uncertainty,
                       config=NarutoConfig(initial_look_around=False, **ANYWHERE))
    start = np.array([2.0, 1.5, 1.5])
    near = parts.planner.plan(start, frame=1)
    parts.planner.leave(start, 2.5)  # the whole room lies within 2.5 m of the start
    plan = parts.planner.plan(start, frame=2)
    assert np.linalg.norm(near.goal - start) < 2.5
    assert plan is None and parts.monitor.failed_plans == 1
    parts.planner.leave(start, 0.6)
    plan = parts.planner.plan(start, frame=3)
    assert np.linalg.norm(plan.goal - start) > 0.6
    assert plan.info["leaving"] and plan.info["move_at_once"]
    again = parts.planner.plan(start, frame=4)
    assert "leaving" not in again.info and "move_at_once" not in again.info
