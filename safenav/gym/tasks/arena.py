"""What the tasks in random arenas share: the arena's settings and a new arena every episode."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from safenav._checks import integer, pair
from safenav.errors import InvalidConfig
from safenav.gym.tasks.base import Task, draw_seed
from safenav.robot import RobotSpec
from safenav.worlds import World, random_world

__all__ = ["ARENA_DRAWS", "RandomArena"]

#: World seeds a task tries, from its stream, before it gives up drawing an arena.
ARENA_DRAWS = 10


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
        """An arena drawn from ``rng``. A dense arena cannot always be drawn (:func:`random_world` gives up
        placing an obstacle after its tries: the m2wr's GoToGoal, one world seed in 300): then the next seed of
        the same stream is tried, so the same episode seed still gives the same arena, up to
        :data:`ARENA_DRAWS` times."""
        failure: InvalidConfig | None = None
        for _ in range(ARENA_DRAWS):
            try:
                return random_world(draw_seed(rng), robot, n_obstacles=self.n_obstacles, size=self.size,
                                    goal=self.has_goal)
            except InvalidConfig as error:
                failure = error
        raise InvalidConfig(f"{type(self).__name__}: no arena of {self.n_obstacles} obstacles in "
                            f"{self.size[0]:g} x {self.size[1]:g} m for the robot {robot.name!r} in {ARENA_DRAWS} "
                            f"draws ({failure}); expected fewer obstacles or a larger size") from failure
