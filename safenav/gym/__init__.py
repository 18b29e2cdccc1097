"""Gymnasium environments and a safety shield any agent can use (``pip install "safenav[gym]"``).

Importing this package registers one environment per task with Gymnasium:

==================================  ==========  ==================================================
id                                  robot       task
==================================  ==========  ==================================================
``safenav/GoToGoal-v0``             rosbot      reach a goal across a random cluttered arena
``safenav/StopAtWall-v0``           rosbot      tutorial 1: stop at a set distance from a wall
``safenav/ObstacleAvoidance-v0``    puzzlebot   tutorial 2: wander an arena with obstacles
``safenav/WallFollowing-v0``        m2wr        tutorial 3: follow the walls of an L-shaped room
``safenav/Explore-v0``              puzzlebot   random walk: cover a random cluttered arena
==================================  ==========  ==================================================

Shield your agent::

    import gymnasium
    from safenav.gym import SafetyShield

    env = SafetyShield(gymnasium.make("safenav/GoToGoal-v0", robot="puzzlebot"))
    observation, info = env.reset(seed=0)
    observation, reward, terminated, truncated, info = env.step(env.action_space.sample())

:class:`SafeNavEnv` documents the spaces, rewards, seeding and ``info``;
:class:`SafetyShield` the wrapper; :mod:`safenav.gym.protocol` what another environment
implements to be shielded.
"""

from safenav._optional import require

require("gymnasium", extra="gym", purpose="safenav's Gymnasium environments")
require("pybullet", extra="sim", purpose="the simulator behind safenav's Gymnasium environments")

from safenav.gym.env import SafeNavEnv  # noqa: E402 - after the dependency check, which names the extra
from safenav.gym.errors import UnsupportedEnv  # noqa: E402
from safenav.gym.observation import ObservationConfig, encode_lidar  # noqa: E402
from safenav.gym.protocol import SafetyObservable, SafetyObservation  # noqa: E402
from safenav.gym.registration import ENV_IDS, register_envs  # noqa: E402
from safenav.gym.shield import SafetyShield, shield_info  # noqa: E402
from safenav.gym.tasks import TASKS, Explore, GoToGoal, ObstacleAvoidance, StopAtWall, Task, WallFollowing  # noqa: E402

__all__ = [
    "ENV_IDS",
    "TASKS",
    "Explore",
    "GoToGoal",
    "ObservationConfig",
    "ObstacleAvoidance",
    "SafeNavEnv",
    "SafetyObservable",
    "SafetyObservation",
    "SafetyShield",
    "StopAtWall",
    "Task",
    "UnsupportedEnv",
    "WallFollowing",
    "encode_lidar",
    "register_envs",
    "shield_info",
]

register_envs()
