"""Reference nominal policies: the three ROS tutorial controllers, go-to-goal and a random walk.

Every policy is a callable ``policy(scan, pose=None) -> Command`` with a :attr:`~Policy.state`
for logging and a :meth:`~Policy.reset`. Build one by name with :func:`make_policy`:

========================  =========================================================
name                      policy
========================  =========================================================
``stop_at_wall``          :class:`StopAtWall`, tutorial 1, front found by angle
``stop_at_wall_buggy``    :meth:`StopAtWall.tutorial_bug`, tutorial 1 as published (reads beam 360)
``obstacle_avoidance``    :class:`ObstacleAvoidance`, tutorial 2
``wall_follower``         :class:`WallFollower`, tutorial 3
``go_to_goal``            :class:`GoToGoal`, needs ``goal=(x, y)``
``random_walk``           :class:`RandomWalk`
========================  =========================================================
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any

from safenav._checks import choice
from safenav.reference.base import (
    Policy,
    Proximity,
    RangeCheck,
    TutorialController,
    check_beam,
    check_sector,
    robot_spec,
)
from safenav.reference.go_to_goal import GoToGoal
from safenav.reference.obstacle_avoidance import ObstacleAvoidance
from safenav.reference.random_walk import RandomWalk
from safenav.reference.stop_at_wall import StopAtWall
from safenav.reference.wall_follower import WallFollower
from safenav.robot import RobotSpec

__all__ = [
    "POLICIES",
    "POLICY_NAMES",
    "GoToGoal",
    "ObstacleAvoidance",
    "Policy",
    "Proximity",
    "RandomWalk",
    "RangeCheck",
    "StopAtWall",
    "TutorialController",
    "WallFollower",
    "check_beam",
    "check_sector",
    "make_policy",
]

POLICIES: Mapping[str, Callable[..., Policy]] = MappingProxyType({
    "stop_at_wall": StopAtWall,
    "stop_at_wall_buggy": StopAtWall.tutorial_bug,
    "obstacle_avoidance": ObstacleAvoidance,
    "wall_follower": WallFollower,
    "go_to_goal": GoToGoal,
    "random_walk": RandomWalk,
})
"""Every reference policy by name: a callable taking ``robot=`` and the policy's own keyword arguments."""

POLICY_NAMES = tuple(POLICIES)
"""Names :func:`make_policy` accepts (the keys of :data:`POLICIES`)."""


def make_policy(name: str, robot: RobotSpec, **kwargs: Any) -> Policy:
    """A reference policy by name, for ``robot``.

    The tutorial policies clip their commands to the robot's velocity limits (on their own
    tutorial robot nothing is clipped); :class:`GoToGoal` and :class:`RandomWalk` draw their
    limits from it.

    Args:
        name: one of :data:`POLICY_NAMES`.
        robot: the robot the policy drives.
        **kwargs: the policy's own arguments (``goal=(x, y)`` for ``"go_to_goal"``,
            ``seed=`` and ``hold_steps=`` for ``"random_walk"``, ...).

    Raises:
        UnknownName: ``name`` is not registered (the message lists the names).
        InvalidConfig: ``robot`` is not a :class:`~safenav.robot.RobotSpec`, or an argument
            is out of range.
    """
    build = POLICIES[choice("policy", name, POLICY_NAMES)]
    return build(robot=robot_spec("make_policy: robot", robot), **kwargs)
