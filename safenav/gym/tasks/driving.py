"""ObstacleAvoidance and WallFollowing: tutorials 2 and 3, rewarded for driving forward."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from safenav._checks import pair
from safenav.errors import InvalidConfig
from safenav.gym.tasks.base import Task, Tracker, forward_distance, perturbed_start
from safenav.robot import RobotSpec
from safenav.sim_bullet import SimState
from safenav.worlds import World, tutorial_world

__all__ = ["ObstacleAvoidance", "WallFollowing"]


class _ForwardDistance(Tracker):
    """Distance driven forward, counted only while the body clearance lies in ``band`` (if any)."""

    def __init__(self, state: SimState, band: tuple[float, float] | None) -> None:
        self._pose = state.pose
        self._band = band

    def update(self, state: SimState) -> tuple[float, bool]:
        driven = forward_distance(self._pose, state.pose)
        self._pose = state.pose
        if self._band is not None and not self._band[0] <= state.clearance <= self._band[1]:
            driven = 0.0
        return driven, False


@dataclass(frozen=True)
class ObstacleAvoidance(Task):
    """The second tutorial: wander a walled 6 x 6 m arena with six obstacles, as far as possible.

    The world is :func:`~safenav.worlds.tutorial_world` ``("obstacle_avoidance")`` with the
    start moved by up to 0.1 m and turned by up to 0.2 rad (world stream). Progress is the
    distance driven forward [m] (along the heading at the start of each step; reversing earns
    nothing). No goal: the episode ends on a collision or on time.
    """

    name = "ObstacleAvoidance"
    default_robot = "puzzlebot"

    def world(self, robot: RobotSpec, rng: np.random.Generator) -> World:
        return perturbed_start(tutorial_world("obstacle_avoidance"), rng, 0.1, 0.2)

    def tracker(self, world: World, robot: RobotSpec, state: SimState) -> Tracker:
        return _ForwardDistance(state, None)


@dataclass(frozen=True)
class WallFollowing(Task):
    """The third tutorial: follow the walls of an L-shaped 10 x 10 m room.

    The world is :func:`~safenav.worlds.tutorial_world` ``("wall_follower")`` with the start
    moved by up to 0.05 m and turned by up to 0.1 rad (world stream). Progress is the distance
    driven forward [m] while the body keeps a clearance within ``band`` of the nearest wall;
    driving farther from every wall, or closer than ``band[0]``, earns nothing.

    Attributes:
        band: ``(nearest, farthest)`` body clearance to the nearest wall that counts as following it [m].
    """

    name = "WallFollowing"
    default_robot = "m2wr"

    duration: float = 60.0
    band: tuple[float, float] = (0.2, 1.2)

    def __post_init__(self) -> None:
        super().__post_init__()
        band = pair("WallFollowing.band", self.band, low=0.0)
        if band[1] <= band[0]:
            raise InvalidConfig(f"WallFollowing.band must be (nearest, farthest) with nearest < farthest [m], "
                                f"got {self.band!r}")
        object.__setattr__(self, "band", band)

    def world(self, robot: RobotSpec, rng: np.random.Generator) -> World:
        return perturbed_start(tutorial_world("wall_follower"), rng, 0.05, 0.1)

    def tracker(self, world: World, robot: RobotSpec, state: SimState) -> Tracker:
        return _ForwardDistance(state, self.band)


