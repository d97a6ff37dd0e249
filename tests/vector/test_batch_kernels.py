"""The batched env's compiled loops against the single env's per-move functions."""

from __future__ import annotations

import numpy as np

from naruto_gym.motion.collision import segment_fraction_inside_box
from naruto_gym.sensors.raycaster import segment_samples, sweep_stop_from_distances
from naruto_gym.vector.batch_kernels import plan_sweeps, sweep_stops


def test_sweeps_planned_and_stopped_in_one_call_match_move_by_move():
    rng = np.random.default_rng(0)
    count = 400
    box_min, box_max = np.array([0.0, 0.0, 0.0]), np.array([4.0, 3.0, 2.5])
    starts = rng.uniform(box_min + 0.1, box_max - 0.1, (count, 3))
    # Moves of the discrete actions' length (0.1 m: a whole number of samples, where a
    # rounding difference would change the count), random ones, some leaving the box and
    # some not moving at all.
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    lengths = np.where(np.arange(count) % 3 == 0, 0.1, rng.uniform(0.0, 1.5, count))
    lengths[::17] = 0.0
    targets = starts + lengths[:, None] * directions
    start_clearances = rng.uniform(0.0, 0.3, count).astype(np.float32)
    radius = 0.05
    box, ends, clearances, sweep_lengths, offsets, fractions, points = plan_sweeps(
        starts, targets, box_min, box_max, start_clearances, radius
    )
    assert (box < 1.0).any() and (sweep_lengths == 0).any()
    distances = rng.uniform(0.0, 0.2, len(points)).astype(np.float32)
    walls = np.where(rng.uniform(size=count) < 0.5, rng.uniform(0.0, 1.0, count), np.inf)
    stops, stop_clearances = sweep_stops(fractions, offsets, sweep_lengths, distances, walls,
                                         clearances)
    for i in range(count):
        expected_box = segment_fraction_inside_box(starts[i], targets[i], box_min, box_max)
        assert box[i] == expected_box
        end = starts[i] + expected_box * (targets[i] - starts[i])
        np.testing.assert_array_equal(ends[i], end)
        clearance = max(min(radius, float(start_clearances[i]) - 1e-4), 0)
        assert clearances[i] == clearance
        expected_fractions, expected_points, length = segment_samples(starts[i], end, clearance)
        mine = slice(offsets[i], offsets[i + 1])
        np.testing.assert_array_equal(fractions[mine], expected_fractions)
        np.testing.assert_array_equal(points[mine], expected_points)
        assert sweep_lengths[i] == length
        stop, stop_clearance = sweep_stop_from_distances(
            expected_fractions, length, distances[mine], float(walls[i]), clearance
        )
        assert stops[i] == stop
        assert stop_clearances[i] == stop_clearance or (
            np.isnan(stop_clearance) and np.isnan(stop_clearances[i])
        )


def test_sweeps_skip_the_distance_queries_their_start_proves_free():
    """Samples whose start clearance, less how far they lie from the start, clears the sweep
    stop where the full sweep stops, with the same distance there: moves of every length from
    starts at every distance to the surface of a real scene (the bound needs a true distance
    field), walls cast only for segments that could reach one."""
    from naruto_gym.scenes.catalogue import resolve_scene
    from naruto_gym.sensors.raycaster import RayCaster
    from naruto_gym.vector.batch_kernels import (
        PROVABLY_CLEAR_SLACK_M,
        sweep_distance_queries,
    )

    scene = resolve_scene("two_rooms")
    raycaster = RayCaster(scene.vertices, scene.faces)
    rng = np.random.default_rng(4)
    count = 3000
    low, high = scene.bounds
    starts = rng.uniform(low + 0.05, high - 0.05, (count, 3))
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    targets = starts + rng.choice([0.0, 0.1, 0.3, 1.0], count)[:, None] * directions
    start_clearances = raycaster.unsigned_distance(starts)
    box, ends, clearances, lengths, offsets, fractions, points = plan_sweeps(
        starts, targets, low, high, start_clearances, 0.05
    )
    directions = (ends - starts) / np.maximum(lengths, 1e-300)[:, None]
    all_walls = np.where(lengths > 0, raycaster.cast_distance(starts, directions), np.inf)
    full = sweep_stops(fractions, offsets, lengths, raycaster.unsigned_distance(points),
                       all_walls, clearances)

    needed, distances = sweep_distance_queries(start_clearances, offsets, fractions, lengths,
                                               clearances)
    assert 0.1 < needed.mean() < 0.9  # both kinds of samples are there
    distances[needed] = raycaster.unsigned_distance(points[needed])
    reach = start_clearances >= lengths + clearances + PROVABLY_CLEAR_SLACK_M
    walls = np.where(reach, np.inf, all_walls)
    stops, stop_clearances = sweep_stops(fractions, offsets, lengths, distances, walls,
                                         clearances)
    bounded = np.isinf(stop_clearances)
    positions = starts + stops[:, None] * (ends - starts)
    stop_clearances[bounded] = raycaster.unsigned_distance(positions[bounded])
    np.testing.assert_array_equal(stops, full[0])
    np.testing.assert_array_equal(stop_clearances, full[1])
    assert (full[0] < 1.0).sum() > 100 and bounded.any()  # blocked sweeps, bounded stops
