"""NARUTO's scan checks on the shared guard: the panorama move check, held moves (one count
for the surface and the edge readings), the open scan's top and edges."""

from __future__ import annotations

import numpy as np
import pytest

from naruto_agent.mapping.observed_space import ObservedSpace
from naruto_agent.naruto import NarutoConfig, build_config
from naruto_agent.naruto.scan_checks import MIN_CLIMB_M
from tests.agent.naruto.agent_parts import BOUNDS, context, make_parts, walls_up_to
from tests.agent.synthetic_panoramas import floor_panorama, wall_panorama

AGENT = np.array([1.5, 1.5, 1.0])


def test_a_move_the_panorama_shows_blocked_is_held_and_its_surface_blocked() -> None:
    """The agent stands 7 cm from a surface that its 0.1 m map does not show in the way: the
    panorama taken where it stands shows it, so the move towards it is held before the env
    sees it, the surface point is blocked in the map, and the goal stays."""
    parts = make_parts(panorama=wall_panorama(-0.07), where=AGENT)  # a wall at y = 1.43 m
    guard, checks, blocked = parts.guard, parts.checks, parts.agent_map.blocked
    assert parts.checker.is_free(AGENT, AGENT + [0.1, 0.0, 0.0])  # along the wall
    assert len(blocked.points) == 0
    assert not parts.checker.is_free(AGENT, AGENT + [0.06, -0.05, 0.07])
    assert len(blocked.points) == 1
    assert blocked.points[0][1] == pytest.approx(1.43, abs=1e-3)
    assert parts.agent_map.sdf.sample(blocked.points[0][None])[0] < 0
    assert parts.failed_goals == []
    # Taken elsewhere, the panorama says nothing about this move.
    assert guard.panorama_at(AGENT + [1.0, 0.0, 0.0]) is None
    assert checks.panorama_shows_way_clear(AGENT + [1.0, 0.02, 0.0], AGENT + [1.0, -0.03, 0.0])
    off = make_parts(panorama=wall_panorama(-0.07), where=AGENT,
                     config=build_config(panorama_check=False))
    assert off.checker.is_free(AGENT, AGENT + [0.06, -0.05, 0.07])


def test_in_a_tight_spot_a_held_move_goes_to_the_env_after_max_held_moves() -> None:
    """7 cm from a wall, within the panorama's margin of it: moves towards it are held (the
    surface blocked, the goal kept), but after ``max_held_moves`` holds in a row at one spot
    the next is sent and the env decides, then the count starts again."""
    parts = make_parts(panorama=wall_panorama(-0.07), where=AGENT)
    towards_wall = AGENT + [0.06, -0.05, 0.07]
    for _ in range(parts.config.guard.max_held_moves):
        assert not parts.checker.is_free(AGENT, towards_wall)
    assert len(parts.agent_map.blocked.points) == parts.config.guard.max_held_moves
    assert parts.checker.is_free(AGENT, towards_wall)
    assert not parts.checker.is_free(AGENT, towards_wall)


def test_on_an_open_scan_a_move_the_panorama_shows_leaving_the_scan_is_held() -> None:
    """The floor under the agent ends 0.3 m ahead (+x): once the scan is known open, a move
    to 5 cm before that edge is held on the panorama and the space past it blocked; a move
    back inside passes, and on a closed scan the check does not run."""
    towards_edge = AGENT + [0.25, 0.0, 0.0]
    closed = make_parts(panorama=floor_panorama(edge_x_m=0.3), where=AGENT)
    assert not closed.guard.scan_open
    assert closed.checker.is_free(AGENT, towards_edge)  # closed: no cone check
    parts = make_parts(panorama=floor_panorama(edge_x_m=0.3), where=AGENT, scan_open=True)
    blocked = parts.agent_map.blocked
    assert parts.checks.panorama_keeps_to_scan(AGENT, AGENT + [-0.1, 0.0, 0.0])
    assert len(blocked.points) == 0
    assert not parts.checks.panorama_keeps_to_scan(AGENT, towards_edge)
    assert len(blocked.points) == 1 and blocked.points[0][0] > towards_edge[0]
    assert blocked.guessed == [True] and parts.failed_goals == []


def test_on_an_open_scan_a_climb_above_the_scans_top_is_refused_and_lowers_the_ceiling() -> None:
    """Walls measured up to about 2.6 m and no ceiling: once the scan is known open, a climb
    that ends above the measured top less the agent's radius is refused (the map alone let
    such nodes through) and sets the flight ceiling there; level and descending moves pass,
    and on a closed scan the check does not run."""
    agent = np.array([1.5, 1.5, 2.0])
    closed = make_parts(observed=walls_up_to(2.6), panorama=floor_panorama(height_m=2.0),
                        where=agent)
    limit = closed.agent_map.observed_space.scan_top_z() - closed.guard.agent_radius_m
    assert 2.5 < limit < 2.7
    below, above = agent + [0.0, 0.0, limit - 2.01], agent + [0.0, 0.0, limit - 1.95]
    assert closed.checker.is_free(agent, above)  # closed: the top is the ceiling the map shows
    parts = make_parts(observed=walls_up_to(2.6), panorama=floor_panorama(height_m=2.0),
                       where=agent, scan_open=True)
    checks = parts.checks
    assert checks.stays_below_top(agent, below)
    assert not checks.stays_below_top(agent, above)
    assert parts.agent_map.blocked.ceiling_z == pytest.approx(limit)
    assert parts.agent_map.sdf.sample(above[None])[0] < 0  # the next plan stays under it
    assert checks.stays_below_top(above, above + [0.1, 0.0, 0.0])  # level, already above
    assert checks.stays_below_top(above, below)


def test_at_the_scans_edge_a_held_move_goes_to_the_env_when_no_climb_is_possible() -> None:
    """Low over a floor hole every way out can look like leaving the scan on the panorama:
    after ``max_held_moves`` moves held back in a row at one spot the next is sent (the env
    decides) when the agent cannot climb out of the margin (``margin_climb_m=0`` here), and
    a new spot starts counting again. A held move blocks the space past the edge but keeps
    the plan's goal (the env never refused it)."""
    parts = make_parts(panorama=floor_panorama(edge_x_m=0.3), where=AGENT, scan_open=True,
                       config=NarutoConfig(margin_climb_m=0.0))
    guard, checks = parts.guard, parts.checks
    towards_edge = AGENT + [0.25, 0.0, 0.0]
    for _ in range(parts.config.guard.max_held_moves):
        assert not checks.panorama_keeps_to_scan(AGENT, towards_edge)
    assert checks.panorama_keeps_to_scan(AGENT, towards_edge)
    assert checks.pending_climb is None
    assert len(parts.agent_map.blocked.points) == parts.config.guard.max_held_moves
    assert parts.failed_goals == []
    # The count starts again: the next move from here is checked (and held) again.
    assert not checks.panorama_keeps_to_scan(AGENT, towards_edge)
    elsewhere = AGENT + [0.0, 0.05, 0.0]
    guard.observe_panorama(floor_panorama(edge_x_m=0.3), elsewhere)
    assert not checks.panorama_keeps_to_scan(elsewhere, elsewhere + [0.25, 0.0, 0.0])


def test_when_the_holds_run_out_at_the_scans_edge_the_guard_plans_a_climb() -> None:
    """Every way from a spot 1 m over a floor whose edge is 0.3 m ahead reads as leaving the
    scan: after ``max_held_moves`` holds the flagged move is not sent and a climb of
    ``margin_climb_m`` straight up is pending (the env's support cone reaches further from
    higher up). Under a surface or the scan's top the climb is cut short, and with less
    than 2 cm left the move goes to the env."""
    towards_edge = AGENT + [0.25, 0.0, 0.0]
    parts = make_parts(observed=walls_up_to(2.6), panorama=floor_panorama(edge_x_m=0.3),
                       where=AGENT, scan_open=True)
    checks = parts.checks
    for _ in range(parts.config.guard.max_held_moves + 1):
        assert not checks.panorama_keeps_to_scan(AGENT, towards_edge)
    climb = checks.pending_climb
    np.testing.assert_allclose(climb[0], AGENT)
    np.testing.assert_allclose(climb[-1], AGENT + [0.0, 0.0, parts.config.margin_climb_m])
    assert np.all(np.diff(climb[:, 2]) > 0) and np.allclose(climb[:, :2], AGENT[:2])
    assert checks.take_climb(AGENT + [0.1, 0.0, 0.0]) is None  # planned elsewhere: dropped
    assert checks.pending_climb is None

    # A surface 0.2 m overhead (under a table): the climb stops short of it.
    overhead = np.flipud(floor_panorama(height_m=0.2))
    floor = floor_panorama(edge_x_m=0.3)
    parts = make_parts(observed=walls_up_to(2.6), where=AGENT, scan_open=True,
                       panorama=np.where(overhead > 0, overhead, floor))
    for _ in range(parts.config.guard.max_held_moves + 1):
        assert not parts.checks.panorama_keeps_to_scan(AGENT, towards_edge)
    rise = parts.checks.pending_climb[-1][2] - AGENT[2]
    assert 0.1 < rise < 0.2 - parts.guard.agent_radius_m

    # The scan's top (measured top 2.6 m less scan_top_margin_m) leaves 0.12 m: cut short.
    high = np.array([1.5, 1.5, 2.18])
    parts = make_parts(observed=walls_up_to(2.6), where=high, scan_open=True,
                       panorama=floor_panorama(height_m=2.18, edge_x_m=0.3))
    top = parts.agent_map.observed_space.scan_top_z() - parts.config.scan_top_margin_m
    for _ in range(parts.config.guard.max_held_moves + 1):
        assert not parts.checks.panorama_keeps_to_scan(high, high + [0.25, 0.0, 0.0])
    assert parts.checks.pending_climb[-1][2] == pytest.approx(top)

    # No room left to climb: the move is sent and the env decides.
    start = np.array([1.5, 1.5, top - MIN_CLIMB_M / 2])
    parts = make_parts(observed=walls_up_to(2.6), where=start, scan_open=True,
                       panorama=floor_panorama(height_m=start[2], edge_x_m=0.3))
    for _ in range(parts.config.guard.max_held_moves):
        assert not parts.checks.panorama_keeps_to_scan(start, start + [0.25, 0.0, 0.0])
    assert parts.checks.panorama_keeps_to_scan(start, start + [0.25, 0.0, 0.0])
    assert parts.checks.pending_climb is None


def test_a_move_across_the_edge_of_the_measured_floor_fails_the_goal() -> None:
    """On an open scan, a move whose probe lies past the measured floor's edge is refused on
    the agent's grid, the space past it blocked and the plan's goal failed; from a point
    the test already fails the agent may move (it has to get back in)."""
    observed = ObservedSpace(BOUNDS.copy())
    xs = np.arange(0.05, 2.0, 0.1)
    observed.grid.mark_occupied(np.array([[x, y, 0.05] for x in xs for y in xs]))
    parts = make_parts(observed=observed, scan_open=True)
    checks = parts.checks
    assert checks.stays_in_scan(np.array([1.0, 1.0, 1.0]), np.array([1.1, 1.0, 1.0]))
    end = np.array([1.9, 1.0, 1.0])
    assert not checks.stays_in_scan(np.array([1.8, 1.0, 1.0]), end)
    assert parts.agent_map.blocked.points[-1][0] > end[0]
    assert parts.failed_goals == [1]
    assert checks.stays_in_scan(np.array([2.5, 1.0, 1.0]), np.array([2.6, 1.0, 1.0]))


def test_inside_scan_and_a_refused_climb() -> None:
    """Goals lie over measured surface below the measured top less the margin (or as high
    as the agent stands); once the scan is open, over surface in every sector of the env's
    support cone too (not low beside a floor hole). An escape refusal of a climb over
    measured floor came at the scan's top; a level one did not."""
    observed = walls_up_to(2.6)
    xs = np.arange(0.05, 3.0, 0.1)
    observed.grid.mark_occupied(np.array([[x, y, 0.05] for x in xs for y in xs
                                          if max(abs(x - 1.5), abs(y - 1.5)) > 0.5]))
    closed = make_parts(observed=observed)
    opened = make_parts(observed=observed, scan_open=True)
    column = np.array([[2.3, 1.5, z] for z in np.arange(0.2, 3.0, 0.1)])
    top = observed.scan_top_z() - closed.config.scan_top_margin_m
    supported = observed.sample(observed.supported(), column)
    low = closed.checks.inside_scan(column, np.array([2.3, 1.5, 0.0]))
    assert np.array_equal(low, supported & (column[:, 2] <= top)) and low.any()
    high = closed.checks.inside_scan(column, np.array([2.3, 1.5, top + 0.4]))
    assert np.array_equal(high, supported & (column[:, 2] <= top + 0.4))
    assert (high & ~low).any()  # the agent's own height admits more
    beside_hole = np.array([[1.5 + dx, 1.5, z] for dx in (0.0, 0.2, 0.4, 0.8)
                            for z in (0.2, 0.5, 1.0)])
    coarse = closed.checks.inside_scan(beside_hole, np.zeros(3))
    strict = opened.checks.inside_scan(beside_hole, np.zeros(3))
    assert np.array_equal(strict, coarse & observed.sectors_seen_below(beside_hole))
    assert (coarse & ~strict).any() and strict.any()
    position = np.array([0.6, 0.6, 1.0])
    assert observed.sectors_seen_below(position[None])[0]
    assert opened.checks.refused_climb(position, position + [0.1, 0.0, 0.05])
    assert not opened.checks.refused_climb(position, position + [0.1, 0.0, 0.0])


def test_a_depth_frame_that_sees_the_sky_opens_the_scan() -> None:
    """Steep pixels that miss mean no ceiling; only ``open_sky_share`` of them are needed,
    and with it None only an escape refusal opens the scan."""
    from naruto_gym.geometry.transforms import look_at_rotation, make_pose

    parts = make_parts()
    camera = context().camera
    eye = np.array([1.0, 1.0, 1.0])
    up = make_pose(look_at_rotation(eye, eye + [1.0, 0.0, 3.0]), eye)
    parts.guard.observe_depth(np.ones((camera.height, camera.width), np.float32), up, camera)
    assert not parts.guard.scan_open
    parts.guard.observe_depth(np.zeros((camera.height, camera.width), np.float32), up, camera)
    assert parts.guard.scan_open
    never = make_parts(config=build_config(open_sky_share=None))
    never.guard.observe_depth(np.zeros((camera.height, camera.width), np.float32), up, camera)
    assert not never.guard.scan_open
    never.guard.note_escape()
    assert never.guard.scan_open


def test_one_count_serves_the_surface_and_the_edge_readings() -> None:
    """A move held for a surface and one held for leaving the scan at the same spot count
    together (``guard.holds``): after ``max_held_moves`` of either the next goes through."""
    parts = make_parts(panorama=wall_panorama(-0.07), where=AGENT, scan_open=True,
                       config=NarutoConfig(margin_climb_m=0.0))
    checks, limit = parts.checks, parts.config.guard.max_held_moves
    assert not checks.panorama_shows_way_clear(AGENT, AGENT + [0.06, -0.05, 0.07])
    parts.guard.observe_panorama(floor_panorama(edge_x_m=0.3), AGENT)  # the next frame
    for _ in range(limit - 1):
        assert not checks.panorama_keeps_to_scan(AGENT, AGENT + [0.25, 0.0, 0.0])
    assert parts.guard.holds.count == limit and parts.guard.edge_holds.count == 0
    assert checks.panorama_keeps_to_scan(AGENT, AGENT + [0.25, 0.0, 0.0])  # the env decides


def test_the_panorama_edge_reading_follows_the_guards_switch() -> None:
    """``guard.panorama_edge_probe`` off: the panorama no longer holds a move for leaving the
    scan (the surface reading and the grid's edge probe stay)."""
    off = make_parts(panorama=floor_panorama(edge_x_m=0.3), where=AGENT, scan_open=True,
                     config=build_config(panorama_edge_probe=False))
    assert off.checks.panorama_keeps_to_scan(AGENT, AGENT + [0.25, 0.0, 0.0])
    assert off.guard.holds.count == 0 and len(off.agent_map.blocked.points) == 0
