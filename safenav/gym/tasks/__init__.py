"""The tasks behind safenav's environments, one per environment id ``safenav/<name>-v0``.

=====================  ==========  ======================================================  ===========
task                   robot       world                                                   progress
=====================  ==========  ======================================================  ===========
:class:`GoToGoal`      rosbot      random 8 x 8 m arena, 20 obstacles, a reachable goal    m to goal
:class:`StopAtWall`    rosbot      tutorial 1: a wall 3 m ahead                            m of error
:class:`ObstacleAvoidance` puzzlebot  tutorial 2: a 6 x 6 m arena with 6 obstacles        m forward
:class:`WallFollowing` m2wr        tutorial 3: an L-shaped 10 x 10 m room                  m along walls
:class:`Explore`       puzzlebot   random 10 x 10 m arena, 30 obstacles                    m^2 covered
=====================  ==========  ======================================================  ===========
"""

from __future__ import annotations

from safenav._checks import choice
from safenav.gym.tasks.base import Task, Tracker
from safenav.gym.tasks.driving import ObstacleAvoidance, WallFollowing
from safenav.gym.tasks.explore import Explore
from safenav.gym.tasks.go_to_goal import GoToGoal
from safenav.gym.tasks.stop_at_wall import StopAtWall

__all__ = ["TASKS", "Explore", "GoToGoal", "ObstacleAvoidance", "StopAtWall", "Task", "Tracker", "WallFollowing",
           "make_task"]

TASKS: tuple[type[Task], ...] = (GoToGoal, StopAtWall, ObstacleAvoidance, WallFollowing, Explore)
"""Every task class, in the order of the environment ids."""


def make_task(name: str) -> Task:
    """The task called ``name`` (``"GoToGoal"``, ...) with its default settings.

    Raises:
        UnknownName: ``name`` is not a task (the message lists them).
    """
    by_name = {task.name: task for task in TASKS}
    return by_name[choice("task", name, tuple(by_name))]()
