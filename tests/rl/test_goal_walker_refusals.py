"""A move the env refused is never sent again from where it was refused: the goal walker
takes the refusal as evidence of what its map cannot show (a hole in the floor, the top of a
partial scan, a fragmented surface), for every kind of move, so that it does not repeat one
refused move until a stall watchdog notices."""

from __future__ import annotations

import numpy as np
import pytest

from naruto_gym.rl.egocentric_map_kernels import FREE, OCCUPIED
from naruto_gym.rl.goal_planner import MOVE_BACKWARD, MOVE_FORWARD, MOVE_LEFT, MOVE_RIGHT
from naruto_gym.rl.goal_walker import MOVE_DOWN, MOVE_UP, WALK
from tests.rl.test_goal_actions import _level_walker, _observe, _turn

#: World x-y offset of each step from a camera looking along +x (``_level_walker``).
STEP_OFFSETS = {
    MOVE_FORWARD: (1, 0),
    MOVE_BACKWARD: (-1, 0),
    MOVE_LEFT: (0, 1),
    MOVE_RIGHT: (0, -1),
}


@pytest.mark.parametrize("move", list(STEP_OFFSETS))
def test_a_refused_step_of_any_direction_blocks_the_cell_it_led_into(move):
    """Forward, backward and sideways steps alike (the way out of a stay steps sideways and
    backward): the cell the refused step led into is an obstacle on the map from then on."""
    builder, walker, pose = _level_walker([5.0, 5.0, 1.3])
    pose[:2, 3] += 0.05  # the middle of a cell (the map's cells have corners at the start)
    builder.grids[0, FREE] = 255
    _observe(builder, pose, np.zeros((32, 64), np.float32))
    own = np.floor((pose[:2, 3] - builder.origins[0]) / builder.cell_m).astype(int)
    walker.last_moves[0], walker.last_positions[0] = move, pose[:3, 3]
    walker.phases[0] = WALK
    walker.next_moves()  # sees the step refused (the agent did not move)
    ahead = own + np.array(STEP_OFFSETS[move])
    assert builder.grids[0, OCCUPIED, ahead[0], ahead[1]] == 255
    assert np.count_nonzero(builder.grids[0, OCCUPIED]) == 1


def test_a_climb_refused_under_a_measured_ceiling_is_not_tried_again():
    """The panorama's top row hits something 1.5 m up (a lamp, a stray fragment over a scan
    without a ceiling), so there looks to be room to climb towards the walking height; the
    env refuses the climb (the agent would rise above the partial scan). The walker keeps
    the height it has instead of sending the same climb at every step."""
    builder, walker, pose = _level_walker([1.0, 1.0, 0.6])
    panorama = np.zeros((32, 64), np.float32)
    moves = []
    for _ in range(12):
        panorama[0], panorama[-1] = 2.1 - pose[2, 3], pose[2, 3]  # a ceiling hit, the floor
        _observe(builder, pose, panorama)
        move = int(walker.next_moves()[0])
        moves.append(move)
        if move == MOVE_UP and pose[2, 3] < 0.75:  # the env refuses climbs from 0.8 m
            pose[2, 3] += 0.1
        elif move not in (MOVE_UP, MOVE_DOWN):
            _turn(pose, move) if move not in STEP_OFFSETS else None
    assert moves[:3] == [MOVE_UP] * 3  # 0.6 -> 0.8, then the refused one
    assert MOVE_UP not in moves[3:] and walker.climb_ceilings[0] == pytest.approx(0.8)


def test_a_refused_descent_is_not_tried_again():
    """An idle walker over furniture steps down after a full turn; where the env refuses the
    descent (the agent would sink into a hole of the scan) it steps down no more there."""
    builder, walker, pose = _level_walker([1.0, 1.0, 2.3])
    panorama = np.zeros((32, 64), np.float32)
    moves = []
    for _ in range(40):
        panorama[0], panorama[-1] = 2.65 - pose[2, 3], pose[2, 3] - 1.2  # ceiling, table top
        _observe(builder, pose, panorama)
        move = int(walker.next_moves()[0])
        moves.append(move)
        if move == MOVE_DOWN and pose[2, 3] > 2.25:  # the env refuses descents from 2.2 m
            pose[2, 3] -= 0.1
        elif move not in (MOVE_UP, MOVE_DOWN):
            _turn(pose, move)
    first_down = moves.index(MOVE_DOWN)
    assert moves[first_down : first_down + 2] == [MOVE_DOWN] * 2  # 2.3 -> 2.2, then refused
    assert MOVE_DOWN not in moves[first_down + 2 :]
    assert walker.descent_floors[0] == pytest.approx(2.2)


def test_a_refused_primitive_step_is_not_repeated_for_the_rest_of_its_macro_step():
    """A learner's primitive move that the env refuses (its map showed free space there)
    turns instead for the rest of the macro-step, rather than being refused at every step."""
    builder, walker, pose = _level_walker([5.0, 5.0, 1.3])
    pose[:2, 3] += 0.05  # the middle of a cell (the map's cells have corners at the start)
    builder.grids[0, FREE] = 255
    _observe(builder, pose, np.zeros((32, 64), np.float32))
    walker.set_actions(np.array([walker.num_candidates + MOVE_FORWARD]))
    assert int(walker.next_moves()[0]) == MOVE_FORWARD
    moves = [int(walker.next_moves()[0]) for _ in range(5)]  # the agent never moved
    assert MOVE_FORWARD not in moves
