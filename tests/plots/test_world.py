"""Drawing a world from above: every obstacle, within the world's bounds, at equal scale."""

import pytest

from safenav.plots import plot_world
from safenav.worlds import tutorial_world


def test_plot_world_draws_every_obstacle_within_the_bounds():
    world = tutorial_world("obstacle_avoidance")
    ax = plot_world(world)
    assert len(ax.patches) == len(world.obstacles)
    assert ax.get_xlim() == pytest.approx(world.bounds[0::2]) and ax.get_ylim() == pytest.approx(world.bounds[1::2])
    assert ax.get_aspect() == 1.0
