"""The NARUTO agent's map: when the planner view is read, blocked space, visits, move checks."""

from __future__ import annotations

import numpy as np
import pytest

from naruto_agent.mapping.observed_space import ObservedSpace
from naruto_agent.mapping.sdf_volume import SdfVolume
from naruto_agent.naruto import AgentMap, NarutoConfig
from tests.agent.naruto.agent_parts import BOUNDS, free_sdf, make_parts


class FakeMapper:
    """A mapper whose every ``step``-th frame is a mapping step; its view is free space
    with uncertainty 1 everywhere."""

    def __init__(self, step: int = 5) -> None:
        self.step = step
        self.observed_space = ObservedSpace(BOUNDS.copy())
        self.views = 0
        self.panoramas: list[int] = []

    def integrate(self, rgb, depth, pose, frame_index) -> bool:  # noqa: ANN001
        return frame_index % self.step == 0

    def integrate_panorama(self, panorama, position) -> None:  # noqa: ANN001
        self.panoramas.append(int(panorama))

    def planner_view(self, voxel_size: float) -> tuple[SdfVolume, SdfVolume]:
        self.views += 1
        return free_sdf(), SdfVolume(np.ones((30, 30, 30)), np.zeros(3), 0.1)


def test_the_view_is_read_once_per_mapping_step_when_needed() -> None:
    mapper = FakeMapper(step=5)
    agent_map = AgentMap(mapper, NarutoConfig(view_every_mapping_steps=2, panorama_every=5))
    stale = [agent_map.integrate(None, None, np.eye(4), frame, panorama=frame)
             for frame in range(21)]
    # Mapping steps at frames 0, 5, 10, 15, 20: every second one makes the view stale.
    assert [frame for frame, new in enumerate(stale) if new] == [0, 10, 20]
    assert mapper.panoramas == [0, 5, 10, 15, 20]
    assert mapper.views == 0 and agent_map.sdf is None  # read only when needed
    agent_map.refresh()
    agent_map.refresh()
    assert mapper.views == 1 and agent_map.sdf is not None
    assert set(agent_map.timings) == {"mapping", "planner_view"}


def test_blocked_space_applies_to_the_view_held_and_to_the_next() -> None:
    mapper = FakeMapper(step=1)
    agent_map = AgentMap(mapper, NarutoConfig())
    agent_map.block(np.array([1.0, 1.0, 1.0]))  # before any view: kept for the first
    agent_map.integrate(None, None, np.eye(4), 0)
    agent_map.refresh()
    assert agent_map.sdf.sample(np.array([[1.0, 1.0, 1.0]]))[0] < 0
    components = agent_map.components
    assert agent_map.components is components  # computed once per view
    agent_map.block_past_edge(np.array([0.5, 2.0, 1.0]), np.array([1.0, 2.0, 1.0]),
                              guessed=True)
    radius = agent_map.config.recovery.escape_blocked_radius_m
    np.testing.assert_allclose(agent_map.blocked.points[-1], [1.0 + radius, 2.0, 1.0])
    assert agent_map.sdf.sample(np.array([[1.0 + radius, 2.0, 1.0]]))[0] < 0
    assert agent_map.sdf.sample(np.array([[0.6, 2.0, 1.0]]))[0] > 0  # the agent's side
    assert agent_map.components is not components
    agent_map.lower_ceiling(2.0)
    assert agent_map.sdf.sample(np.array([[1.5, 1.5, 2.5]]))[0] < 0
    # Forgetting the guesses reads the view again without them; refusals stay.
    assert agent_map.forget_guesses(np.array([0.5, 2.0, 1.0]))
    assert mapper.views == 2 and agent_map.blocked.guessed == [False]
    assert agent_map.sdf.sample(np.array([[1.0 + radius, 2.0, 1.0]]))[0] > 0
    assert not agent_map.forget_guesses(np.array([0.5, 2.0, 1.0]))


def test_looks_of_visits_damp_the_uncertainty_where_they_were_counted() -> None:
    mapper = FakeMapper(step=1)
    agent_map = AgentMap(mapper, NarutoConfig())
    agent_map.integrate(None, None, np.eye(4), 0)
    agent_map.refresh()
    target = np.array([[1.0, 1.0, 1.0]])
    agent_map.add_looks(target, 4.0)
    agent_map.refresh()  # the looks made the view stale
    weight = mapper.observed_space.config.look_weight
    assert agent_map.uncertainty.sample(target)[0] == pytest.approx(1.0 / (1.0 + 4 * weight))
    assert agent_map.uncertainty.sample(np.array([[2.0, 2.0, 2.0]]))[0] == pytest.approx(1.0)
    raw = SdfVolume(np.ones((30, 30, 30)), np.zeros(3), 0.1)
    damped = agent_map.damp_visited(raw)
    assert np.count_nonzero(damped.values != raw.values) == 1
    other_grid = SdfVolume(np.ones((10, 10, 10)), np.zeros(3), 0.3)
    assert agent_map.damp_visited(other_grid) is other_grid


def test_a_move_must_keep_the_clearance_or_get_no_closer_to_the_surface() -> None:
    """Free space with a wall up to x = 1 m: a move into the wall's clearance is refused,
    one along it is not; from within the clearance a move away passes, one closer not."""
    values = np.full((30, 30, 30), 0.5)
    values[:10] = -0.1
    values[10] = 0.04
    parts = make_parts(sdf=SdfVolume(values, np.zeros(3), 0.1))
    checker = parts.checker
    assert checker.keeps_clearance(np.array([1.5, 1.5, 1.0]), np.array([1.4, 1.5, 1.0]))
    assert not checker.is_free(np.array([1.5, 1.5, 1.0]), np.array([1.0, 1.5, 1.0]))
    inside = np.array([1.02, 1.5, 1.0])
    assert checker.is_free(inside, inside + [0.1, 0.0, 0.0])
    assert not checker.is_free(inside, inside - [0.05, 0.0, 0.0])
    off = make_parts(sdf=SdfVolume(values, np.zeros(3), 0.1),
                     config=NarutoConfig(check_moves_on_map=False))
    assert off.checker.is_free(inside, inside - [0.5, 0.0, 0.0])
