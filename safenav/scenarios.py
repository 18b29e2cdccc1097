"""Named scenarios: a robot, a world drawn from a seed, the nominal policies that make sense there.

============================  ==========  =================================  ============================
scenario                      robot       world                              policies
============================  ==========  =================================  ============================
``stop_at_wall``              rosbot      tutorial 1: a wall 3 m ahead       stop_at_wall, stop_at_wall_buggy
``obstacle_avoidance``        puzzlebot   tutorial 2: a 6 x 6 m arena        obstacle_avoidance
``wall_follower``             m2wr        tutorial 3: an L-shaped room       wall_follower
``clutter_<robot>``           each        random 10 x 10 m, 30 obstacles     random_walk, the robot's tutorial policy
``goal_<robot>``              each        random 10 x 10 m with a goal       go_to_goal
============================  ==========  =================================  ============================

In the tutorial scenarios the seed perturbs the start pose by a few centimetres and
degrees, so seeds give different episodes of the same task.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from safenav.errors import UnknownName
from safenav.geometry import Pose2D
from safenav.reference import Policy, make_policy
from safenav.robot import PRESET_NAMES, RobotSpec, preset
from safenav.worlds import World, random_world, tutorial_world

__all__ = ["SCENARIO_NAMES", "TUTORIAL_POLICY", "Scenario", "scenario"]

TUTORIAL_POLICY = {"rosbot": "stop_at_wall", "puzzlebot": "obstacle_avoidance", "m2wr": "wall_follower"}
"""The tutorial controller of each preset."""


@dataclass(frozen=True)
class Scenario:
    """A task: which robot, which world for a seed, which nominal policies, how long.

    Attributes:
        name: the scenario's name.
        robot_name: the preset that runs it.
        policies: policy names that make sense here (the first is the default).
        duration: episode length [s].
        description: one line for tables and help.
    """

    name: str
    robot_name: str
    policies: tuple[str, ...]
    duration: float
    description: str
    _world: Callable[[int, RobotSpec], World]

    @property
    def robot(self) -> RobotSpec:
        """The robot preset."""
        return preset(self.robot_name)

    def world(self, seed: int) -> World:
        """The world of episode ``seed`` (same seed, same world)."""
        return self._world(seed, self.robot)

    def policy(self, name: str, world: World, seed: int) -> Policy:
        """The nominal policy ``name`` for this scenario's robot in ``world``.

        Raises:
            UnknownName: ``name`` is not one of :attr:`policies`.
        """
        if name not in self.policies:
            raise UnknownName(f"policy for scenario {self.name!r}", name, self.policies)
        robot = self.robot
        if name == "go_to_goal":
            return make_policy(name, robot, goal=world.goal)
        if name == "random_walk":
            return make_policy(name, robot, seed=seed, hold_steps=20)
        return make_policy(name, robot)


def _perturbed(world_name: str, position: float, heading: float) -> Callable[[int, RobotSpec], World]:
    """The tutorial world with its start moved by up to ``position`` [m] and turned by up to ``heading`` [rad]."""

    def build(seed: int, robot: RobotSpec) -> World:
        world = tutorial_world(world_name)
        rng = np.random.default_rng(seed)
        dx, dy = rng.uniform(-position, position, 2)
        start = world.start
        return world.replace(start=Pose2D(start.x + dx, start.y + dy, start.yaw + rng.uniform(-heading, heading)))

    return build


def _random(goal: bool) -> Callable[[int, RobotSpec], World]:
    def build(seed: int, robot: RobotSpec) -> World:
        return random_world(seed, robot, n_obstacles=30, goal=goal)

    return build


def _registry() -> dict[str, Scenario]:
    scenarios = [
        Scenario("stop_at_wall", "rosbot", ("stop_at_wall", "stop_at_wall_buggy"), 12.0,
                 "tutorial 1: drive at a wall 3 m ahead and stop before it", _perturbed("stop_at_wall", 0.1, 0.1)),
        Scenario("obstacle_avoidance", "puzzlebot", ("obstacle_avoidance",), 40.0,
                 "tutorial 2: wander a 6 x 6 m arena, turning away from what is ahead",
                 _perturbed("obstacle_avoidance", 0.1, 0.2)),
        Scenario("wall_follower", "m2wr", ("wall_follower",), 60.0,
                 "tutorial 3: find a wall and follow it round an L-shaped room",
                 _perturbed("wall_follower", 0.05, 0.1)),
    ]
    for name in PRESET_NAMES:
        scenarios.append(Scenario(f"clutter_{name}", name, ("random_walk", TUTORIAL_POLICY[name]), 30.0,
                                  f"{name} in a random 10 x 10 m arena with 30 obstacles", _random(goal=False)))
    for name in PRESET_NAMES:
        scenarios.append(Scenario(f"goal_{name}", name, ("go_to_goal",), 40.0,
                                  f"{name} drives straight for a goal across a random cluttered arena",
                                  _random(goal=True)))
    return {item.name: item for item in scenarios}


SCENARIO_NAMES = tuple(_registry())
"""Every scenario name."""


def scenario(name: str) -> Scenario:
    """The scenario called ``name``.

    Raises:
        UnknownName: ``name`` is not a scenario (the message lists them).
    """
    registry = _registry()
    if name not in registry:
        raise UnknownName("scenario", name, registry)
    return registry[name]
