"""What every task shares: the episode length, the reward weights, and a per-episode progress tracker.

A task says which world an episode runs in and what counts as progress. The environment turns
progress into reward the same way for every task:

    reward = progress_reward * progress  +  success_reward * [success]
             - collision_penalty * [collision]  -  step_penalty

where ``progress`` is the task's measure gained during the step (metres towards the goal,
metres driven, square metres explored; see each task), ``[success]`` is 1 on the step the task
succeeds (goal tasks only) and ``[collision]`` is 1 on the step the body first touches an
obstacle (the episode then ends: ``terminated``).
"""

from __future__ import annotations

import abc
import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from safenav._checks import duration, number
from safenav.geometry import Pose2D
from safenav.robot import RobotSpec
from safenav.sim_bullet import SimState
from safenav.worlds import World

__all__ = ["Task", "Tracker", "perturbed_start"]


class Tracker(abc.ABC):
    """Progress of one episode; made by :meth:`Task.tracker` at every reset."""

    @abc.abstractmethod
    def update(self, state: SimState) -> tuple[float, bool]:
        """Progress gained since the previous state, and whether the task has succeeded.

        Args:
            state: the simulator state after the step.

        Returns:
            ``(progress, success)``: progress in the task's unit, success for goal tasks.
        """


@dataclass(frozen=True)
class Task(abc.ABC):
    """A task: its worlds, its progress measure and its reward weights; validated on construction.

    Attributes:
        duration: episode time limit [s]: the episode is ``truncated`` after it.
        progress_reward: reward per unit of progress (see the task for the unit).
        success_reward: reward on the step the task succeeds (goal tasks).
        collision_penalty: subtracted on the step the body touches an obstacle (which ends the episode).
        step_penalty: subtracted at every step (a cost of time).
    """

    name: ClassVar[str] = ""
    """The task's name, as in the environment id ``safenav/<name>-v0``."""
    default_robot: ClassVar[str] = "rosbot"
    """The robot preset the environment uses when none is given."""
    has_goal: ClassVar[bool] = False
    """Whether the task has a goal position, observed in polar coordinates."""
    has_success: ClassVar[bool] = False
    """Whether the task can succeed (which ends the episode); ``info`` then has ``is_success``."""
    progress_unit: ClassVar[str] = "m"
    """The unit of progress, for docs and tables."""

    duration: float = 30.0
    progress_reward: float = 1.0
    success_reward: float = 10.0
    collision_penalty: float = 10.0
    step_penalty: float = 0.0

    def __post_init__(self) -> None:
        owner = type(self).__name__
        object.__setattr__(self, "duration", duration(f"{owner}.duration", self.duration))
        for name in ("progress_reward", "success_reward", "collision_penalty", "step_penalty"):
            object.__setattr__(self, name, number(f"{owner}.{name}", getattr(self, name)))

    @abc.abstractmethod
    def world(self, robot: RobotSpec, rng: np.random.Generator) -> World:
        """The world of the next episode, drawn from the world stream ``rng``."""

    @abc.abstractmethod
    def tracker(self, world: World, robot: RobotSpec, state: SimState) -> Tracker:
        """A fresh progress tracker for an episode in ``world`` that starts at ``state``."""


def perturbed_start(world: World, rng: np.random.Generator, position: float, heading: float) -> World:
    """``world`` with its start moved by up to ``position`` [m] along x and y and turned by up to ``heading`` [rad]."""
    dx, dy = rng.uniform(-position, position, 2)
    start = world.start
    return world.replace(start=Pose2D(start.x + float(dx), start.y + float(dy),
                                      start.yaw + float(rng.uniform(-heading, heading))))


def forward_distance(before: Pose2D, after: Pose2D) -> float:
    """Distance driven forward from ``before`` to ``after`` along the heading at ``before`` [m] (0 if backwards)."""
    return max(0.0, (after.x - before.x) * math.cos(before.yaw) + (after.y - before.y) * math.sin(before.yaw))


def draw_seed(rng: np.random.Generator) -> int:
    """A seed for a world builder, drawn from ``rng``."""
    return int(rng.integers(2**31 - 1))
