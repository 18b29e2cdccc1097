"""Explore: cover as much floor as possible of a random cluttered arena (the random-walk task)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from safenav._checks import positive
from safenav.gym.tasks.arena import RandomArena
from safenav.gym.tasks.base import Tracker
from safenav.robot import RobotSpec
from safenav.sim_bullet import SimState
from safenav.worlds import World

__all__ = ["Explore"]


class _NewArea(Tracker):
    """Area of the grid cells the base enters for the first time [m^2]."""

    def __init__(self, cell: float, state: SimState) -> None:
        self._cell = cell
        self._visited = {self._index(state)}

    def _index(self, state: SimState) -> tuple[int, int]:
        return (math.floor(state.pose.x / self._cell), math.floor(state.pose.y / self._cell))

    def update(self, state: SimState) -> tuple[float, bool]:
        index = self._index(state)
        if index in self._visited:
            return 0.0, False
        self._visited.add(index)
        return self._cell * self._cell, False


@dataclass(frozen=True)
class Explore(RandomArena):
    """Explore a walled arena of random boxes and cylinders: the random-walk task.

    Every episode draws a new :func:`~safenav.worlds.random_world` (no goal) from the world
    stream (:class:`~safenav.gym.tasks.arena.RandomArena`). Progress is the floor area newly
    covered [m^2]: the base entering a square cell of ``cell`` side [m] it has not entered
    before in the episode. No goal: the episode ends on a collision or on time.

    Attributes:
        cell: side of the coverage grid's cells [m].
    """

    name = "Explore"
    default_robot = "puzzlebot"
    progress_unit = "m^2"

    n_obstacles: int = 30
    size: tuple[float, float] = (10.0, 10.0)
    cell: float = 0.5

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "cell", positive("Explore.cell", self.cell))

    def tracker(self, world: World, robot: RobotSpec, state: SimState) -> Tracker:
        return _NewArea(self.cell, state)
