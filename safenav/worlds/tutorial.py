"""The three classic ROS tutorials: each one's world, robot and controller, in one table.

======================  =========  ==========================================  ============================
tutorial                robot      world                                       controller (as published)
======================  =========  ==========================================  ============================
``stop_at_wall``        rosbot     a wall 3 m ahead                            ``stop_at_wall``
                                                                               (``stop_at_wall_buggy``)
``obstacle_avoidance``  puzzlebot  a walled 6 x 6 m arena with six obstacles   ``obstacle_avoidance``
``wall_follower``       m2wr       an L-shaped room                            ``wall_follower``
======================  =========  ==========================================  ============================

The tutorial's name is also the name of its world and of its scenario.
:data:`TUTORIALS` is the one table: the scenarios (:mod:`safenav.scenarios`), the demo and
the command line read it. Robots and controllers are named, not imported (the presets are
:func:`safenav.robot.preset`, the controllers :func:`safenav.reference.make_policy`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType

from safenav._checks import choice
from safenav.geometry import Pose2D
from safenav.seeding import generator
from safenav.worlds.shapes import WALL_THICKNESS, Box, Cylinder, Wall, room
from safenav.worlds.world import World

__all__ = ["TUTORIALS", "TUTORIAL_WORLDS", "Tutorial", "tutorial_world"]


@dataclass(frozen=True)
class Tutorial:
    """One classic tutorial.

    Attributes:
        name: the tutorial's name; also the name of its world and of its scenario.
        robot: the robot preset it was written for.
        policy: its controller, as :func:`safenav.reference.make_policy` names it (fixed where
            the published one has a bug).
        published_policy: the controller exactly as published (``safenav demo`` runs it).
        duration: how long an episode of the tutorial runs [s].
        start_jitter: how far a seeded episode moves the start: up to ``[0]`` [m] along each
            axis and ``[1]`` [rad] in heading, so seeds give different runs of the same task.
        description: one line for tables and help.
        build: makes the world.
    """

    name: str
    robot: str
    policy: str
    published_policy: str
    duration: float
    start_jitter: tuple[float, float]
    description: str
    build: Callable[[], World]

    def world(self, seed: int | None = None) -> World:
        """The tutorial's world; with a ``seed``, the start jittered by the seed's world stream.

        Args:
            seed: the episode's seed (see :mod:`safenav.seeding`); ``None`` keeps the start as built.
        """
        world = self.build()
        if seed is None:
            return world
        rng = generator(seed, "world")
        position, heading = self.start_jitter
        dx, dy = rng.uniform(-position, position, 2)
        start = world.start
        return world.replace(start=Pose2D(start.x + dx, start.y + dy, start.yaw + rng.uniform(-heading, heading)))


def _stop_at_wall() -> World:
    """The robot at the origin faces +x; the near face of a 4 m wide wall is 3 m ahead, nothing else in range."""
    face = 3.0
    wall = Wall((face + 0.5 * WALL_THICKNESS, -2.0), (face + 0.5 * WALL_THICKNESS, 2.0))
    return World("stop_at_wall", (wall,), start=Pose2D(0.0, 0.0, 0.0), bounds=(-1.0, -2.5, 3.6, 2.5))


def _obstacle_avoidance() -> World:
    """A walled 6 x 6 m arena, interior ``[-3, 3]^2``, three boxes and three posts; the start faces the middle."""
    half = 3.0 + 0.5 * WALL_THICKNESS
    arena = room((-half, -half), (half, -half), (half, half), (-half, half))
    obstacles = (
        Cylinder((0.0, 0.0), 0.35),
        Box((1.6, 1.1), (0.6, 0.4), yaw=0.4),
        Box((-1.3, 1.5), (0.5, 0.5)),
        Cylinder((1.3, -1.6), 0.25),
        Cylinder((-1.6, -0.2), 0.2),
        Box((0.3, 2.1), (1.0, 0.3)),
    )
    return World("obstacle_avoidance", arena + obstacles, start=Pose2D(-2.2, -2.2, math.pi / 4),
                 bounds=(-3.4, -3.4, 3.4, 3.4))


def _wall_follower() -> World:
    """An L-shaped room: 10 x 10 m with the 5 x 5 m top-right quarter cut away."""
    walls = room((0.0, 0.0), (10.0, 0.0), (10.0, 5.0), (5.0, 5.0), (5.0, 10.0), (0.0, 10.0))
    return World("wall_follower", walls, start=Pose2D(2.0, 0.8, 0.0), bounds=(-0.6, -0.6, 10.6, 10.6))


TUTORIALS: Mapping[str, Tutorial] = MappingProxyType({tutorial.name: tutorial for tutorial in (
    Tutorial("stop_at_wall", "rosbot", "stop_at_wall", "stop_at_wall_buggy", 12.0, (0.1, 0.1),
             "tutorial 1: drive at a wall 3 m ahead and stop before it", _stop_at_wall),
    Tutorial("obstacle_avoidance", "puzzlebot", "obstacle_avoidance", "obstacle_avoidance", 40.0, (0.1, 0.2),
             "tutorial 2: wander a 6 x 6 m arena, turning away from what is ahead", _obstacle_avoidance),
    Tutorial("wall_follower", "m2wr", "wall_follower", "wall_follower", 60.0, (0.05, 0.1),
             "tutorial 3: find a wall and follow it round an L-shaped room", _wall_follower),
)})
"""Every tutorial by name, in the order of the presets ``rosbot``, ``puzzlebot``, ``m2wr``."""

TUTORIAL_WORLDS = tuple(TUTORIALS)
"""Names of the tutorial worlds (the keys of :data:`TUTORIALS`)."""


def tutorial_world(name: str) -> World:
    """The world of one of the three classic tutorials, with its start as built.

    * ``"stop_at_wall"`` (ROSbot): the robot at the origin faces +x; the near face of a
      4 m wide wall is 3 m ahead. Nothing else is in range, so side and rear beams read ``+inf``.
    * ``"obstacle_avoidance"`` (Puzzlebot): a walled 6 x 6 m arena, interior ``[-3, 3]^2``,
      with three boxes and three cylinders; the robot starts in a corner facing the middle.
    * ``"wall_follower"`` (m2wr): an L-shaped room (10 x 10 m with the 5 x 5 m top-right
      quarter cut away). Following the wall on its right, the robot turns left at the five
      inside corners and right round the outside corner at (5, 5), about 16 m along the
      wall from the start. It starts 0.8 m from the bottom wall, heading +x with that wall
      on its right.

    ``TUTORIALS[name].robot`` names the robot of each world.

    Raises:
        UnknownName: ``name`` is not a tutorial world (the message lists them).
    """
    return TUTORIALS[choice("tutorial world", name, TUTORIAL_WORLDS)].world()
