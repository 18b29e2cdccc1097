"""StopAtWall: tutorial 1, drive up to a wall and stop at a set distance from it."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from safenav._checks import pair, positive
from safenav.errors import InvalidConfig
from safenav.geometry import Pose2D
from safenav.gym.tasks.base import Task, Tracker
from safenav.robot import RobotSpec
from safenav.sim_bullet import SimState
from safenav.worlds import World, tutorial_world

__all__ = ["StopAtWall"]


class _StopError(Tracker):
    def __init__(self, task: StopAtWall, state: SimState) -> None:
        self._task = task
        self._error = abs(state.clearance - task.stop_clearance)

    def update(self, state: SimState) -> tuple[float, bool]:
        task = self._task
        error = abs(state.clearance - task.stop_clearance)
        gained, self._error = self._error - error, error
        stopped = abs(state.velocity[0]) <= task.stop_speed and abs(state.velocity[1]) <= task.stop_turn
        return gained, error <= task.tolerance and stopped


@dataclass(frozen=True)
class StopAtWall(Task):
    """The first tutorial: a wall ahead; drive up to it and stop ``stop_clearance`` from it.

    The world is :func:`~safenav.worlds.tutorial_world` ``("stop_at_wall")`` with the start
    drawn from the world stream: the body's clearance to the wall uniform in ``start_clearance``
    [m], before or beyond the stopping distance (the tutorial starts 3 m from the wall), moved
    sideways by up to 0.5 m and turned by up to 1.2 rad, so an agent has to read the wall's
    distance from the lidar. Progress is the decrease
    of ``|clearance - stop_clearance|`` [m], the body's distance to the wall against the target;
    the task succeeds within ``tolerance`` of the target with the robot stopped. The default
    target, 0.85 m, is the tutorial's "stop when the front beam reads 1 m" on the ROSbot.
    There is no goal in the observation: the wall is in the lidar.

    Attributes:
        stop_clearance: body clearance to the wall to stop at [m].
        tolerance: accepted error of the stopping distance [m].
        stop_speed: largest ``|v|`` that counts as stopped [m/s].
        stop_turn: largest ``|omega|`` that counts as stopped [rad/s].
        start_clearance: ``(nearest, farthest)`` body clearance to the wall at the start [m].
    """

    name = "StopAtWall"
    default_robot = "rosbot"
    has_success = True

    duration: float = 15.0
    stop_clearance: float = 0.85
    tolerance: float = 0.1
    stop_speed: float = 0.05
    stop_turn: float = 0.1
    start_clearance: tuple[float, float] = (0.1, 1.5)

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("stop_clearance", "tolerance", "stop_speed", "stop_turn"):
            object.__setattr__(self, name, positive(f"StopAtWall.{name}", getattr(self, name)))
        nearest, farthest = pair("StopAtWall.start_clearance", self.start_clearance, low=0.0, low_open=True)
        if farthest < nearest:
            raise InvalidConfig(f"StopAtWall.start_clearance must be (nearest, farthest) with nearest <= farthest "
                                f"[m], got {self.start_clearance!r}")
        object.__setattr__(self, "start_clearance", (nearest, farthest))

    def world(self, robot: RobotSpec, rng: np.random.Generator) -> World:
        tutorial = tutorial_world("stop_at_wall")
        start = tutorial.start   # faces the wall, the only obstacle
        closer = tutorial.clearance(start, robot.radius) - rng.uniform(*self.start_clearance)
        sideways = rng.uniform(-0.5, 0.5)
        moved = Pose2D(start.x + closer * math.cos(start.yaw) - sideways * math.sin(start.yaw),
                       start.y + closer * math.sin(start.yaw) + sideways * math.cos(start.yaw),
                       start.yaw + rng.uniform(-1.2, 1.2))
        return tutorial.replace(start=moved)

    def tracker(self, world: World, robot: RobotSpec, state: SimState) -> Tracker:
        return _StopError(self, state)
