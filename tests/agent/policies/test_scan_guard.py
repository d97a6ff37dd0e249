"""The open-scan guard the policies share: its readings and its count of held moves."""

from __future__ import annotations

import numpy as np

from naruto_agent.guards import HeldMoves, ScanGuard, ScanGuardConfig
from naruto_gym.sensors.pinhole import PinholeCamera
from tests.agent.synthetic_panoramas import floor_panorama, wall_panorama

TOWARDS_WALL = np.array([0.06, -0.05, 0.0])  # into a wall 7 cm away along -y
ALONG_WALL = np.array([0.1, 0.0, 0.0])


def test_held_moves_let_one_through_after_the_limit_then_count_again():
    holds = HeldMoves(2)
    assert holds.hold() and holds.hold() and holds.exhausted
    assert not holds.hold()  # let through; the count starts again
    assert holds.count == 0 and holds.hold()


def test_held_moves_at_another_spot_count_from_the_start():
    holds = HeldMoves(2)
    here, there = np.zeros(3), np.array([0.1, 0.0, 0.0])
    assert holds.hold(here) and holds.hold(here)
    assert holds.hold(there) and holds.count == 1  # a new spot
    assert holds.hold(there) and not holds.hold(there)
    assert holds.hold(there + 1e-4) and holds.count == 1  # within SAME_SPOT_M: the same spot


def test_surface_holds_mark_the_contact_and_run_out():
    guard = ScanGuard(ScanGuardConfig(max_held_moves=2))
    panorama = wall_panorama(-0.07)
    assert guard.hold_for_surface(panorama, ALONG_WALL) is None
    contact = guard.hold_for_surface(panorama, TOWARDS_WALL)
    assert contact is not None and contact[1] < -0.06
    assert guard.hold_for_surface(panorama, TOWARDS_WALL) is not None
    assert guard.hold_for_surface(panorama, TOWARDS_WALL) is None  # the env decides
    assert guard.hold_for_surface(panorama, TOWARDS_WALL) is not None  # held again
    assert guard.hold_for_surface(None, TOWARDS_WALL) is None


def test_released_holds_stay_released_until_the_agent_moves():
    guard = ScanGuard(ScanGuardConfig(max_held_moves=1, release_held_until_moved=True))
    panorama = wall_panorama(-0.07)
    assert guard.hold_for_surface(panorama, TOWARDS_WALL) is not None
    assert guard.surface_holds_spent(panorama)
    for _ in range(3):
        assert guard.hold_for_surface(panorama, TOWARDS_WALL) is None
    guard.moved()
    assert not guard.surface_holds_spent(panorama)
    assert guard.hold_for_surface(panorama, TOWARDS_WALL) is not None


def test_panorama_check_off_reads_nothing():
    guard = ScanGuard(ScanGuardConfig(panorama_check=False))
    assert guard.panorama({"panorama": wall_panorama(-0.07)}) is None
    assert guard.hold_for_surface(wall_panorama(-0.07), TOWARDS_WALL) is None
    assert not guard.hold_for_edge(floor_panorama(edge_x_m=0.3), np.array([0.25, 0.0, 0.0]))
    assert not guard.way_blocked(wall_panorama(-0.07), TOWARDS_WALL)


def test_edge_probe_and_its_switches():
    """The floor ends 0.3 m ahead (+x): a move towards the edge leaves the scan, one away
    from it does not; the margin switch lets a move from a start by the edge through."""
    guard = ScanGuard()
    inside = floor_panorama(edge_x_m=0.3)
    towards = np.array([0.25, 0.0, 0.0])
    assert guard.leaves_scan(inside, towards) and guard.way_blocked(inside, towards)
    assert not guard.leaves_scan(inside, np.array([-0.1, 0.0, 0.0]))
    assert guard.hold_for_edge(inside, towards) and guard.edge_holds.count == 1
    margin = floor_panorama(edge_x_m=0.06)
    along_edge = np.array([0.0, 0.1, 0.0])
    assert guard.leaves_scan(margin, along_edge)
    assert not ScanGuard(ScanGuardConfig(margin_start_passes=True)).leaves_scan(margin, along_edge)
    assert not ScanGuard(ScanGuardConfig(panorama_edge_probe=False)).way_blocked(inside, towards)
    # Scanned floor all around below: the probe is skipped.
    skipping = ScanGuard(ScanGuardConfig(full_floor_polar_deg=70.0))
    assert not skipping.leaves_scan(floor_panorama(), towards)


def test_top_check_holds_a_climb_above_the_surfaces_shown():
    panorama = floor_panorama()  # a floor 1 m below, nothing above
    climb = np.array([0.0, 0.0, 0.1])
    assert not ScanGuard().way_blocked(panorama, climb)
    assert ScanGuard(ScanGuardConfig(panorama_top_check=True)).way_blocked(panorama, climb)


def test_open_scan_from_the_sky_or_an_escape():
    camera = PinholeCamera().scaled(0.1)
    looking_down = np.eye(4)
    looking_down[:3, :3] = np.diag([1.0, -1.0, -1.0])  # the optical axis (column 2) is -z
    guard = ScanGuard()
    sky = np.zeros((camera.height, camera.width), np.float32)
    assert not guard.observe_depth(np.full_like(sky, 2.0), looking_down, camera)
    assert guard.observe_depth(sky, looking_down, camera)
    guard.reset()
    assert not guard.scan_open
    guard.note_escape()
    assert guard.scan_open
    assert not ScanGuard(ScanGuardConfig(open_sky_share=None)).observe_depth(
        sky, looking_down, camera)


def test_the_kept_panorama_reads_moves_from_where_it_was_taken():
    guard = ScanGuard()
    here = np.array([1.0, 2.0, 1.0])
    assert guard.panorama_at(here) is None  # none kept yet
    panorama = wall_panorama(-0.07)
    guard.observe_panorama(panorama, here)
    assert guard.panorama_at(here + 1e-4) is panorama  # within SAME_SPOT_M
    assert guard.panorama_at(here + [0.01, 0.0, 0.0]) is None  # taken elsewhere
    guard.observe_panorama(None, here)
    assert guard.panorama_at(here) is None
    guard.observe_panorama(panorama, here)
    guard.reset()
    assert guard.panorama_at(here) is None
    off = ScanGuard(ScanGuardConfig(panorama_check=False))
    off.observe_panorama(panorama, here)
    assert off.panorama_at(here) is None
