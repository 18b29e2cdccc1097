"""safenav's Gymnasium environment: one lidar-driven robot, one task, in the PyBullet simulator.

:class:`SafeNavEnv` follows the Gymnasium API (``reset(seed=...)``, ``step(action)``,
``render()``, ``close()``) and implements the shield protocol (:mod:`safenav.gym.protocol`), so
:class:`~safenav.gym.SafetyShield` can guard it::

    import gymnasium
    import safenav.gym  # registers safenav/GoToGoal-v0, safenav/StopAtWall-v0, ...

    env = gymnasium.make("safenav/GoToGoal-v0", robot="puzzlebot")
    observation, info = env.reset(seed=0)
    observation, reward, terminated, truncated, info = env.step(env.action_space.sample())

* **Action**: ``Box(robot.lower, robot.upper)``, the command ``(v [m/s], omega [rad/s])`` held
  for ``control_dt`` (``SimConfig.control_dt``, 0.05 s by default). The box is the robot's
  velocity limits, not ``[-1, 1]``: ``check_env`` says so in a warning; wrap the environment
  in ``gymnasium.wrappers.RescaleAction(env, -1, 1)`` for agents that want a normalised box.
  The base reaches a command within its acceleration limits, as a real base does.
* **Observation**: a ``Dict`` of the lidar in sectors, the goal in polar coordinates (goal
  tasks) and the measured velocity; see :mod:`safenav.gym.observation`.
* **Reward**: progress, a success bonus and a collision penalty; see :mod:`safenav.gym.tasks.base`.
* **Episode end**: ``terminated`` when the body touches an obstacle (at any physics step of
  the period) or the task succeeds; ``truncated`` when ``task.duration`` [s] has passed.
* **info**: ``time`` [s], ``pose`` ``(x [m], y [m], yaw [rad])``, ``velocity`` (measured),
  ``clearance`` (the smallest true body clearance during the step [m]; negative in contact),
  ``collision``, ``progress`` (this step's, in the task's unit), ``scan`` (the fields of the
  :class:`~safenav.scan.LaserScan` the next action will see, as a dict: ``LaserScan(**info["scan"])``
  rebuilds it; leave it out with ``info_scan=False``), ``goal_distance`` [m] for goal tasks,
  and ``is_success`` for tasks that can succeed (GoToGoal, StopAtWall). Every value is plain
  data (numbers, strings, fresh arrays), so infos compare by value and cross process
  boundaries cheaply.
* **Seeding**: only through ``reset(seed=...)``. The seed's ``SeedSequence`` spawns three
  independent streams: the world (obstacles, start and goal of every episode), the simulator's
  noise (range noise, dropout, actuation noise) and the agent (``action_space`` is seeded from
  it, so ``env.action_space.sample()`` repeats too). A reset without a seed continues the
  streams, so the episodes after one seeded reset repeat as a sequence.
* **Rendering**: ``render_mode="rgb_array"`` draws the world, the path so far, the body and the
  scan from above with :mod:`safenav.plots`.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar

import numpy as np

from safenav._checks import boolean, choice
from safenav._optional import require
from safenav.errors import InvalidConfig, SimulatorError
from safenav.gym.observation import (
    ObservationConfig,
    encode_goal,
    encode_lidar,
    encode_velocity,
    goal_polar,
    observation_space,
)
from safenav.gym.protocol import SafetyObservation
from safenav.gym.tasks import Task, Tracker, make_task
from safenav.robot import RobotSpec, as_command, preset
from safenav.scan import LaserScan
from safenav.sim_bullet import BulletSim, SimConfig, SimState
from safenav.worlds import World

gymnasium = require("gymnasium", extra="gym", purpose="safenav's Gymnasium environments")

__all__ = ["SafeNavEnv", "scan_fields"]

RENDER_MODES = ("rgb_array",)


def scan_fields(scan: LaserScan) -> dict[str, Any]:
    """The fields of ``scan`` as plain data (fresh arrays); ``LaserScan(**scan_fields(scan))`` rebuilds it."""
    fields = {field.name: getattr(scan, field.name) for field in dataclasses.fields(scan)}
    fields["ranges"] = np.array(scan.ranges)
    fields["intensities"] = np.array(scan.intensities)
    fields["mount"] = None if scan.mount is None else tuple(scan.mount)
    return fields


class SafeNavEnv(gymnasium.Env):
    """A lidar-driven differential-drive robot doing one task in PyBullet (see the module docstring).

    Args:
        task: the task, by name (``"GoToGoal"``, ``"StopAtWall"``, ``"ObstacleAvoidance"``,
            ``"WallFollowing"``, ``"Explore"``) with its defaults, or a task instance with
            settings (``GoToGoal(n_obstacles=10)``).
        robot: a preset name or a :class:`~safenav.robot.RobotSpec`; the task's default robot
            when ``None``.
        sim: simulator settings (control period, noise, latency).
        observation: how scans, goals and velocities are encoded (``ObservationConfig()`` by default).
        render_mode: ``None`` or ``"rgb_array"``.
        info_scan: put the scan in ``info`` (it costs a pickle of the scan per step in an
            ``AsyncVectorEnv``).

    Raises:
        UnknownName: an unknown task, robot preset or render mode (the message lists them).
        InvalidConfig: an argument of the wrong type.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": list(RENDER_MODES), "render_fps": 20}

    def __init__(self, task: Task | str = "GoToGoal", robot: RobotSpec | str | None = None, *,
                 sim: SimConfig = SimConfig(), observation: ObservationConfig | None = None,
                 render_mode: str | None = None, info_scan: bool = True) -> None:
        self.task = make_task(task) if isinstance(task, str) else task
        if not isinstance(self.task, Task):
            raise InvalidConfig(f"SafeNavEnv: task must be a task name or a safenav.gym.tasks.Task, got {task!r}")
        if robot is None:
            robot = self.task.default_robot
        self.robot = preset(robot) if isinstance(robot, str) else robot
        if not isinstance(self.robot, RobotSpec):
            raise InvalidConfig(f"SafeNavEnv: robot must be a preset name or a RobotSpec, got {robot!r}")
        if not isinstance(sim, SimConfig):
            raise InvalidConfig(f"SafeNavEnv: sim must be a SimConfig, got {sim!r}")
        observation = ObservationConfig() if observation is None else observation
        if not isinstance(observation, ObservationConfig):
            raise InvalidConfig(f"SafeNavEnv: observation must be an ObservationConfig, got {observation!r}")
        if render_mode is not None:
            choice("render mode", render_mode, RENDER_MODES)
        self.sim_config = sim
        self.observation_config = observation
        self.render_mode = render_mode
        self.info_scan = boolean("SafeNavEnv.info_scan", info_scan)
        self.metadata = {**type(self).metadata, "render_fps": round(1.0 / sim.control_dt)}
        self.action_space = gymnasium.spaces.Box(self.robot.lower.astype(np.float32),
                                                 self.robot.upper.astype(np.float32), dtype=np.float32)
        self.observation_space = observation_space(observation, self.robot, goal=self.task.has_goal)
        self._world_rng: np.random.Generator | None = None
        self._noise_rng: np.random.Generator | None = None
        self._sim: BulletSim | None = None
        self._world: World | None = None
        self._state: SimState | None = None
        self._tracker: Tracker | None = None
        self._path: list[tuple[float, float, float]] = []
        self._contacts: list[tuple[float, float]] = []

    # ------------------------------------------------------------------ the shield protocol

    @property
    def control_dt(self) -> float:
        """How long each action is held [s]."""
        return self.sim_config.control_dt

    def safety_observation(self) -> SafetyObservation:
        """The latest scan, the measured velocity, the pose and the simulated time (the shield protocol).

        Raises:
            SimulatorError: before the first :meth:`reset`.
        """
        state = self._current()
        return SafetyObservation(scan=state.scan, velocity=state.velocity, pose=state.pose, time=state.time)

    @property
    def world(self) -> World | None:
        """The world of the current episode (``None`` before the first reset)."""
        return self._world

    # ------------------------------------------------------------------ the Gymnasium API

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[dict, dict]:
        """Start an episode in a new world of the task.

        Args:
            seed: seed of the world, noise and agent streams (module docstring); ``None``
                continues them.
            options: unused.
        """
        super().reset(seed=seed)
        if seed is not None or self._world_rng is None:
            world_stream, noise_stream, agent_stream = np.random.SeedSequence(self.np_random_seed).spawn(3)
            self._world_rng = np.random.default_rng(world_stream)
            self._noise_rng = np.random.default_rng(noise_stream)
            self.action_space.seed(int(agent_stream.generate_state(1, np.uint64)[0]))
        world = self.task.world(self.robot, self._world_rng)
        self._build(world)
        state = self._sim.reset(seed=int(self._noise_rng.integers(2**63 - 1)), start=world.start)
        self._state = state
        self._tracker = self.task.tracker(world, self.robot, state)
        self._path = [tuple(state.pose)]
        self._contacts = [tuple(state.pose[:2])] if state.collided else []
        return self._observation(state), self._info(state, 0.0, collision=state.collided, success=False)

    def step(self, action: Any) -> tuple[dict, float, bool, bool, dict]:
        """Hold ``action = (v [m/s], omega [rad/s])`` for one control period.

        Actions outside the box are clipped to the robot's velocity limits, as the base would.

        Raises:
            InvalidCommand: ``action`` is not a pair of finite numbers.
            SimulatorError: before :meth:`reset`.
        """
        self._current()
        state = self._sim.step(as_command(action, "action"))
        self._state = state
        progress, success = self._tracker.update(state)
        collision = state.min_clearance < 0.0
        task = self.task
        reward = (task.progress_reward * progress + task.success_reward * success
                  - task.collision_penalty * collision - task.step_penalty)
        terminated = bool(collision or success)
        truncated = not terminated and state.time >= task.duration - 1e-9
        self._path.append(tuple(state.pose))
        if collision:
            self._contacts.append(tuple(state.pose[:2]))
        info = self._info(state, progress, collision=collision, success=success)
        return self._observation(state), float(reward), terminated, bool(truncated), info

    def render(self) -> np.ndarray | None:
        """The current frame as an ``(H, W, 3)`` uint8 array (``render_mode="rgb_array"``), else ``None``."""
        if self.render_mode is None:
            return None
        from safenav.plots import plot_episode

        state = self._current()
        figure = plot_episode(self._world, self.robot, self._path, collisions=self._contacts or None,
                              scan=state.scan, title=f"{self.task.name}, {self.robot.name}, t = {state.time:.2f} s",
                              dpi=64)
        figure.canvas.draw()
        return np.asarray(figure.canvas.buffer_rgba())[:, :, :3].copy()

    def close(self) -> None:
        """Release the simulator; safe to call twice."""
        if self._sim is not None:
            self._sim.close()
            self._sim = None
        super().close()

    # ------------------------------------------------------------------ internals

    def _current(self) -> SimState:
        if self._state is None or self._sim is None:
            raise SimulatorError(f"{type(self).__name__}: call reset() before step(), render() or "
                                 "safety_observation()")
        return self._state

    def _build(self, world: World) -> None:
        """A simulator for ``world``; the current one is kept when only the start or goal changed."""
        previous = self._world
        same = (self._sim is not None and previous is not None and previous.obstacles == world.obstacles
                and previous.obstacle_height == world.obstacle_height)
        if not same:
            if self._sim is not None:
                self._sim.close()
            self._sim = BulletSim(world, self.robot, self.sim_config)
        self._world = world

    def _observation(self, state: SimState) -> dict[str, np.ndarray]:
        lidar, known = encode_lidar(state.scan, self.observation_config)
        observation = {"lidar": lidar, "lidar_known": known}
        if self.task.has_goal:
            observation["goal"] = encode_goal(state.pose, self._world.goal, self.observation_config)
        observation["velocity"] = encode_velocity(state.velocity, self.robot)
        return observation

    def _info(self, state: SimState, progress: float, *, collision: bool, success: bool) -> dict[str, Any]:
        info: dict[str, Any] = {
            "time": state.time,
            "pose": np.array(state.pose, dtype=float),
            "velocity": np.array(state.velocity, dtype=float),
            "clearance": float(state.min_clearance),
            "collision": bool(collision),
            "progress": float(progress),
        }
        if self.info_scan:
            info["scan"] = scan_fields(state.scan)
        if self.task.has_goal:
            info["goal_distance"] = goal_polar(state.pose, self._world.goal)[0]
        if self.task.has_success:
            info["is_success"] = bool(success)
        return info

    def __repr__(self) -> str:
        return f"SafeNavEnv(task={self.task.name!r}, robot={self.robot.name!r})"

