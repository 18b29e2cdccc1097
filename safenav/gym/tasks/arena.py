"""What the tasks in random arenas share: the arena's settings and a new arena every episode."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from safenav._checks import integer, pair
from safenav.gym.tasks.base import Task, draw_seed
from safenav.robot import RobotSpec
from safenav.worlds import World, random_world

__all__ = ["RandomArena"]


@dataclass(frozen=True)
class RandomArena(Task):
    """A task in a walled arena of random boxes and cylinders, a new arena every episode.

    Every episode draws a :func:`~safenav.worlds.random_world` from the world stream, with a
    reachable goal at least half the arena's shorter side from the start when the task has a
    goal.

    Attributes:
        n_obstacles: free-standing obstacles per arena.
        size: free interior of the arena ``(w, h)`` [m].
    """

    n_obstacles: int = 30
    size: tuple[float, float] = (10.0, 10.0)

    def __post_init__(self) -> None:
        super().__post_init__()
        owner = type(self).__name__
        object.__setattr__(self, "n_obstacles", integer(f"{owner}.n_obstacles", self.n_obstacles, low=0))
        object.__setattr__(self, "size", pair(f"{owner}.size", self.size, low=0.0, low_open=True))

    def world(self, robot: RobotSpec, rng: np.random.Generator) -> World:
        return random_world(draw_seed(rng), robot, n_obstacles=self.n_obstacles, size=self.size, goal=self.has_goal)
