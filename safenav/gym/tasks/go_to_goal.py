"""GoToGoal: reach a goal across a random cluttered arena."""

from __future__ import annotations

import math
from dataclasses import dataclass

from safenav._checks import positive
from safenav.errors import InvalidConfig
from safenav.gym.tasks.arena import RandomArena
from safenav.gym.tasks.base import Tracker
from safenav.robot import RobotSpec
from safenav.sim_bullet import SimState
from safenav.worlds import World

__all__ = ["GoToGoal"]


class _GoalDistance(Tracker):
    def __init__(self, goal: tuple[float, float], tolerance: float, state: SimState) -> None:
        self._goal = goal
        self._tolerance = tolerance
        self._distance = self._to_goal(state)

    def _to_goal(self, state: SimState) -> float:
        return math.hypot(state.pose.x - self._goal[0], state.pose.y - self._goal[1])

    def update(self, state: SimState) -> tuple[float, bool]:
        distance = self._to_goal(state)
        gained, self._distance = self._distance - distance, distance
        return gained, distance <= self._tolerance


@dataclass(frozen=True)
class GoToGoal(RandomArena):
    """Drive to a goal through a walled arena of random boxes and cylinders.

    Every episode draws a new :func:`~safenav.worlds.random_world` (``goal=True``: the goal is at
    least half the arena's shorter side from the start, and reachable by the body) from the
    world stream. Progress is the decrease of the distance from the base to the goal [m]; the
    task succeeds (and the episode ends) within ``goal_tolerance`` of the goal.

    Attributes:
        n_obstacles: free-standing obstacles per arena (fewer than :class:`Explore`'s).
        size: free interior of the arena ``(w, h)`` [m] (smaller than :class:`Explore`'s).
        goal_tolerance: distance from the base to the goal that counts as arrived [m].
    """

    name = "GoToGoal"
    default_robot = "rosbot"
    has_goal = True
    has_success = True

    n_obstacles: int = 20
    size: tuple[float, float] = (8.0, 8.0)
    goal_tolerance: float = 0.3

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "goal_tolerance", positive("GoToGoal.goal_tolerance", self.goal_tolerance))

    def tracker(self, world: World, robot: RobotSpec, state: SimState) -> Tracker:
        if world.goal is None:
            raise InvalidConfig(f"GoToGoal needs a world with a goal, got world {world.name!r} without one")
        return _GoalDistance(world.goal, self.goal_tolerance, state)
