"""Environment ids: ``safenav/<Task>-v0``, registered with Gymnasium when :mod:`safenav.gym` is imported."""

from __future__ import annotations

from safenav._optional import require
from safenav.gym.tasks import TASKS

__all__ = ["ENV_IDS", "register_envs"]

ENV_IDS: tuple[str, ...] = tuple(f"safenav/{task.name}-v0" for task in TASKS)
"""Every registered id, one per task: GoToGoal, StopAtWall, ObstacleAvoidance, WallFollowing, Explore."""


def register_envs() -> None:
    """Register every id of :data:`ENV_IDS` with Gymnasium (ids already registered are left alone).

    Each id makes a :class:`~safenav.gym.SafeNavEnv` of its task; keyword arguments of
    ``gymnasium.make`` go to its constructor (``robot=``, ``sim=``, ``observation=``,
    ``render_mode=``, ``info_scan=``, or ``task=`` with settings).
    """
    gymnasium = require("gymnasium", extra="gym", purpose="safenav's Gymnasium environments")
    for task, env_id in zip(TASKS, ENV_IDS, strict=True):
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point="safenav.gym.env:SafeNavEnv", kwargs={"task": task.name})
