"""Named scenarios: a robot, a world drawn from a seed, the nominal policies that make sense there.

============================  ==========  =================================  ============================
scenario                      robot       world                              policies
============================  ==========  =================================  ============================
``stop_at_wall``              rosbot      tutorial 1: a wall 3 m ahead       stop_at_wall, stop_at_wall_buggy
``obstacle_avoidance``        puzzlebot   tutorial 2: a 6 x 6 m arena        obstacle_avoidance
``wall_follower``             m2wr        tutorial 3: an L-shaped room       wall_follower
``clutter_<robot>``           each        random 10 x 10 m, 30 obstacles     random_walk, the robot's tutorial policy
``goal_<robot>``              each        random 10 x 10 m with a goal       go_to_goal
``door_<robot>``              each        6 x 5 m room split by a wall with  go_to_goal
                                          one door 2 (R + margin) + 5 cm
                                          wide, the goal behind it
``dead_end_<robot>``          each        8 x 6 m room, a U-shaped trap      go_to_goal
                                          whose mouth faces the start, the
                                          goal behind its closed end
============================  ==========  =================================  ============================

:data:`SCENARIOS` is the one table, built once from the tutorials
(:data:`~safenav.worlds.TUTORIALS`) and the presets; the command line, the experiments and
the benchmarks read it. In the tutorial scenarios the seed jitters the start pose by a few
centimetres and degrees, so seeds give different episodes of the same task; in the random
ones it draws the world (:func:`~safenav.worlds.random_world`); in the door and dead-end
ones it draws the start and the goal (:func:`~safenav.worlds.generator.door_world`,
:func:`~safenav.worlds.generator.dead_end_world`). In the door scenarios R is the robot's
circumscribed radius and margin the filters' default margin for it
(:func:`~safenav.filters.defaults.default_margin`): the door is 5 cm wider than the
narrowest one the filters let the body through (:func:`door_width`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

from safenav._checks import choice
from safenav.errors import InvalidConfig
from safenav.filters.defaults import default_margin
from safenav.reference import POLICY_NAMES, Policy, make_policy
from safenav.robot import PRESET_NAMES, RobotSpec, preset
from safenav.worlds import TUTORIALS, World, random_world
from safenav.worlds.generator import dead_end_world, door_world

__all__ = ["DOOR_SLACK", "GOAL_WORLDS", "RANDOM_WORLDS", "SCENARIOS", "SCENARIO_NAMES", "Scenario", "door_width",
           "scenario", "scenario_for", "scenario_name"]

RANDOM_WORLDS = ("clutter", "goal", "door", "dead_end")
"""Kinds of world drawn from the seed, one scenario per preset: ``clutter`` (30 obstacles), ``goal`` (the
same with a goal), ``door`` (a wall with one door, the goal behind it), ``dead_end`` (a U-shaped trap, the
goal behind it)."""

GOAL_WORLDS = ("goal", "door", "dead_end")
"""The kinds of world that have a goal."""

DOOR_SLACK = 0.05
"""How much wider the door of the door scenarios is than ``2 (R + margin)`` [m]."""

RANDOM_OBSTACLES = 30
"""Obstacles in the random 10 x 10 m arenas."""

RANDOM_WALK_HOLD = 20
"""Control periods the random walk holds each command in the scenarios (1 s at 0.05 s)."""


@dataclass(frozen=True)
class Scenario:
    """A task: which robot, which world for a seed, which nominal policies, how long.

    Attributes:
        name: the scenario's name.
        robot_name: the preset that runs it.
        policies: policy names that make sense here (the first is the default).
        duration: episode length [s].
        description: one line for tables and help.
        world_kind: a tutorial's name, or one of :data:`RANDOM_WORLDS`.
    """

    name: str
    robot_name: str
    policies: tuple[str, ...]
    duration: float
    description: str
    world_kind: str

    @property
    def robot(self) -> RobotSpec:
        """The robot preset."""
        return preset(self.robot_name)

    @property
    def has_goal(self) -> bool:
        """Whether its worlds have a goal (``go_to_goal`` needs one)."""
        return self.world_kind in GOAL_WORLDS

    def world(self, seed: int) -> World:
        """The world of episode ``seed`` (same seed, same world; see :mod:`safenav.seeding`)."""
        if self.world_kind in TUTORIALS:
            return TUTORIALS[self.world_kind].world(seed)
        if self.world_kind == "door":
            return door_world(seed, self.robot, door_width(self.robot))
        if self.world_kind == "dead_end":
            return dead_end_world(seed, self.robot)
        return random_world(seed, self.robot, n_obstacles=RANDOM_OBSTACLES, goal=self.has_goal)

    def policy(self, name: str, world: World, seed: int) -> Policy:
        """The nominal policy ``name`` for this scenario's robot in ``world``, for episode ``seed``.

        Raises:
            UnknownName: ``name`` is not one of :attr:`policies`.
        """
        choice(f"policy for scenario {self.name!r}", name, self.policies)
        if name == "go_to_goal":
            return make_policy(name, self.robot, goal=world.goal)
        if name == "random_walk":
            return make_policy(name, self.robot, seed=seed, hold_steps=RANDOM_WALK_HOLD)
        return make_policy(name, self.robot)


def _scenarios() -> dict[str, Scenario]:
    """Every scenario, in table order: the tutorials, then clutter, goal, door and dead end for each preset."""
    tutorial_policy = {tutorial.robot: tutorial.policy for tutorial in TUTORIALS.values()}
    items = [Scenario(tutorial.name, tutorial.robot, tuple(dict.fromkeys((tutorial.policy, tutorial.published_policy))),
                      tutorial.duration, tutorial.description, tutorial.name)
             for tutorial in TUTORIALS.values()]
    items += [Scenario(f"clutter_{name}", name, ("random_walk", tutorial_policy[name]), 30.0,
                       f"{name} in a random 10 x 10 m arena with {RANDOM_OBSTACLES} obstacles", "clutter")
              for name in PRESET_NAMES]
    items += [Scenario(f"goal_{name}", name, ("go_to_goal",), 40.0,
                       f"{name} drives straight for a goal across a random cluttered arena", "goal")
              for name in PRESET_NAMES]
    items += [Scenario(f"door_{name}", name, ("go_to_goal",), 40.0,
                       f"{name} drives for a goal behind a wall with one door 2 (R + margin) + "
                       f"{100 * DOOR_SLACK:g} cm wide", "door")
              for name in PRESET_NAMES]
    items += [Scenario(f"dead_end_{name}", name, ("go_to_goal",), 40.0,
                       f"{name} drives for a goal behind a U-shaped trap whose mouth faces it", "dead_end")
              for name in PRESET_NAMES]
    return {item.name: item for item in items}


def door_width(robot: RobotSpec) -> float:
    """The door of the door scenarios: ``2 (R + margin) + DOOR_SLACK`` [m].

    ``R`` is the robot's circumscribed radius and ``margin`` the filters' default clearance
    margin for it (:func:`~safenav.filters.defaults.default_margin`), so the door leaves
    :data:`DOOR_SLACK` / 2 on either side of the widest body the filters let through.
    """
    return 2.0 * (robot.radius + default_margin(robot)) + DOOR_SLACK


SCENARIOS: Mapping[str, Scenario] = MappingProxyType(_scenarios())
"""Every scenario by name (read-only, built once)."""

SCENARIO_NAMES = tuple(SCENARIOS)
"""Every scenario name, in table order."""


def scenario(name: str) -> Scenario:
    """The scenario called ``name``.

    Raises:
        UnknownName: ``name`` is not a scenario (the message lists them).
    """
    return SCENARIOS[choice("scenario", name, SCENARIO_NAMES)]


def scenario_for(name: str, robot: str | None = None, policy: str | None = None) -> Scenario:
    """The scenario ``name``, optionally with another robot or a policy it does not list.

    Args:
        name: a scenario name.
        robot: a preset that replaces the scenario's robot (``None``: keep it).
        policy: a policy to allow besides the scenario's own (``None``: only those).

    Raises:
        UnknownName: an unknown scenario, robot or policy (the message lists the known names).
        InvalidConfig: ``go_to_goal`` in a scenario whose worlds have no goal.
    """
    base = scenario(name)
    if robot is not None:
        choice("robot", robot, PRESET_NAMES)
    if policy is not None:
        choice("policy", policy, POLICY_NAMES)
    if policy == "go_to_goal" and not base.has_goal:
        raise InvalidConfig(f"policy 'go_to_goal' needs a world with a goal, and scenario {name!r} has none")
    changes: dict[str, object] = {}
    if robot is not None and robot != base.robot_name:
        changes["robot_name"] = robot
    if policy is not None and policy not in base.policies:
        changes["policies"] = (*base.policies, policy)
    return dataclasses.replace(base, **changes) if changes else base


def scenario_name(world: str, robot: str | None = None) -> str:
    """The scenario of a world as the command line names it: a tutorial, or a random kind on a robot.

    Args:
        world: a tutorial world (its scenario has the same name) or one of :data:`RANDOM_WORLDS`.
        robot: the preset of a random world (``None``: the first preset); ignored for tutorials.

    Raises:
        UnknownName: ``world`` is neither (the message lists both).
    """
    choice("world", world, (*TUTORIALS, *RANDOM_WORLDS))
    return world if world in TUTORIALS else f"{world}_{robot or PRESET_NAMES[0]}"
