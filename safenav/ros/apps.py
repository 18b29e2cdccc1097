"""The three programs of ``safenav-ros2`` and ``safenav-ros1``, without their middleware.

* ``filter`` (the default): the safety node (:class:`~safenav.ros.core.SafetyCore`).
* ``policy NAME``: a tutorial controller as a node (:class:`PolicyCore`): each scan gives one
  nominal command on ``cmd_vel_in``, as the tutorials' scan callbacks do.
* ``sim``: the PyBullet simulator as a robot (:class:`SimBridge`): it publishes ``scan`` and
  ``odom`` every control period and drives from ``cmd_vel``, in real time or, with
  ``--sim-time``, on its own clock published on ``/clock``.

Both transports parse their command line with :func:`parse_args` and fill messages with the
helpers of :mod:`safenav.ros.messages`.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from safenav import _checks
from safenav.errors import SafeNavError
from safenav.geometry import Pose2D
from safenav.reference import POLICY_NAMES, make_policy
from safenav.robot import PRESET_NAMES, RobotSpec, preset
from safenav.ros.core import CauseLog, Timed
from safenav.ros.messages import fill_odometry, fill_scan, pose_of, twist_of
from safenav.scan import LaserScan

__all__ = ["ROS1_DEBIAN_PACKAGES", "BridgeReport", "PolicyCore", "SimBridge", "parse_args", "policy_kwargs", "robot_of"]

ROS1_DEBIAN_PACKAGES = ("ros-core", "python3-rospy", "python3-sensor-msgs", "python3-geometry-msgs", "python3-nav-msgs",
                        "python3-std-srvs", "python3-diagnostic-msgs", "python3-visualization-msgs")
"""Debian's packages of ROS 1 that ``safenav-ros1`` needs (ROS 1 is not on pip)."""

COMMAND_TIMEOUT = 0.5
"""The simulated base stops when its last ``cmd_vel`` is older than this [s], as a base controller does."""


class PolicyCore:
    """A reference policy (:func:`safenav.reference.make_policy`) driven by scan messages.

    Args:
        name: one of :data:`safenav.reference.POLICY_NAMES`.
        robot: the robot (its lidar mount turns messages into scans).
        warn: logs a warning line (each cause once).
        info: logs an information line.
        **kwargs: the policy's own arguments (``goal=(x, y)`` for ``go_to_goal``, ``seed=``).
    """

    def __init__(self, name: str, robot: RobotSpec, *, warn: Any = print, info: Any = print, **kwargs: Any) -> None:
        self.robot = robot
        self.policy = make_policy(name, robot, **kwargs)
        self.causes = CauseLog(warn, info)
        self._pose: Pose2D | None = None

    def on_odometry(self, msg: Any) -> None:
        """Keep the latest pose (for goal-seeking policies)."""
        try:
            self._pose = pose_of(msg)
        except (AttributeError, TypeError, ValueError) as error:
            self.causes.report("bad odometry", f"malformed odometry ignored: {error}")

    def on_scan(self, msg: Any) -> tuple[float, float]:
        """The nominal command for one scan message; zero (logged once) for a malformed one."""
        try:
            scan = LaserScan.from_msg(msg, mount=self.robot.lidar.mount)
            command = self.policy(scan, self._pose)
        except (SafeNavError, ValueError, TypeError) as error:
            self.causes.report("bad scan", f"policy stops: {error}")
            return 0.0, 0.0
        self.causes.clear("bad scan")
        return float(command[0]), float(command[1])


@dataclass(frozen=True)
class BridgeReport:
    """What the simulated robot went through, as truth (never seen by the nodes).

    Attributes:
        world: the world's name.
        robot: the robot's name.
        time: simulated time at the end [s].
        steps: control periods simulated.
        first_collision_time: simulated time of the first contact [s], ``None`` without contact.
        min_clearance: smallest body clearance over the run [m].
        final_pose: pose at the end [m, m, rad].
        distance: path length driven [m].
        commands: ``cmd_vel`` messages received.
    """

    world: str
    robot: str
    time: float
    steps: int
    first_collision_time: float | None
    min_clearance: float
    final_pose: tuple[float, float, float]
    distance: float
    commands: int

    def to_json(self) -> str:
        """The report as one JSON object."""
        return json.dumps(self.__dict__)


class SimBridge:
    """:class:`~safenav.sim_bullet.BulletSim` as a robot on ROS: commands in, scans and odometry out.

    The base holds the latest ``cmd_vel`` for each control period, and stops (under its
    acceleration limits) when that command is older than :data:`COMMAND_TIMEOUT`.

    Args:
        world: a tutorial world name, or ``random:SEED`` for :func:`safenav.worlds.random_world`.
        robot: the robot.
        control_period: the simulator's control period [s].
        seed: seed of the simulator's noise.
    """

    def __init__(self, world: str, robot: RobotSpec, *, control_period: float = 0.05, seed: int = 0) -> None:
        from safenav.sim_bullet import BulletSim, SimConfig
        from safenav.worlds import random_world, tutorial_world

        if world.startswith("random:"):
            built = random_world(_checks.integer("--world random:SEED", _int(world[7:])), robot)
        else:
            built = tutorial_world(world)
        self.sim = BulletSim(built, robot, SimConfig(control_dt=control_period), seed=seed)
        self.robot = robot
        self.state = self.sim.reset()
        self._command: Timed | None = None
        self._min_clearance = self.state.clearance
        self._distance = 0.0
        self._commands = 0
        self._contact_logged = False

    def on_command(self, msg: Any, now: float) -> None:
        """Keep the latest command (a non-finite or malformed one stops the base)."""
        try:
            u = twist_of(msg)
        except (AttributeError, TypeError, ValueError):
            u = (0.0, 0.0)
        self._command = Timed(u if all(map(math.isfinite, u)) else (0.0, 0.0), now, time.perf_counter())
        self._commands += 1

    def step(self, now: float) -> Any:
        """Advance one control period under the latest command; the new :class:`SimState`."""
        command = self._command
        u = command.value if command is not None and now - command.time <= COMMAND_TIMEOUT else (0.0, 0.0)
        before = self.state.pose
        self.state = self.sim.step(u)
        self._min_clearance = min(self._min_clearance, self.state.min_clearance)
        self._distance += math.hypot(self.state.pose.x - before.x, self.state.pose.y - before.y)
        return self.state

    def publish_step(self, now: float, stamp: Callable[[float], Any], types: Mapping[str, type],
                     publish: Mapping[str, Callable[[Any], None]], log_error: Callable[[str], None]) -> None:
        """Advance one period and publish ``clock`` (when ``publish`` has it), ``odom`` and ``scan``.

        Args:
            now: the node's time [s] (for the command timeout).
            stamp: the header stamp of a simulated time [s].
            types: message classes ``"scan"``, ``"odom"`` and ``"clock"``.
            publish: a function per topic, by the same names.
            log_error: logs the first contact.
        """
        state = self.step(now)
        stamp_now = stamp(state.time)
        if "clock" in publish:
            publish["clock"](types["clock"](clock=stamp_now))
        odom = fill_odometry(types["odom"](), state.pose, state.velocity)
        odom.header.stamp = stamp_now
        publish["odom"](odom)   # first: a node that filters when the scan arrives then has this period's velocity
        scan = fill_scan(types["scan"](), state.scan, "laser")
        scan.header.stamp = stamp_now
        publish["scan"](scan)
        if state.first_collision_time is not None and not self._contact_logged:
            self._contact_logged = True
            log_error(f"contact at t = {state.first_collision_time:.2f} s (simulator truth)")

    def finished(self, duration: float | None, stop_on_contact: bool) -> bool:
        """Whether the run is over: ``duration`` [s] of simulated time, or a contact when asked."""
        state = self.state
        if stop_on_contact and state.first_collision_time is not None:
            return True
        return duration is not None and state.time >= duration - 1e-9

    def report(self) -> BridgeReport:
        """Truth about the run so far."""
        state = self.state
        return BridgeReport(world=self.sim.world.name, robot=self.robot.name, time=state.time, steps=state.steps,
                            first_collision_time=state.first_collision_time, min_clearance=self._min_clearance,
                            final_pose=tuple(state.pose), distance=self._distance, commands=self._commands)

    def finish(self, path: Path | None) -> BridgeReport:
        """Print the report as one JSON line, write it to ``path`` when given, and release the simulator."""
        report = self.report()
        print(report.to_json(), flush=True)
        if path is not None:
            path.write_text(report.to_json())
        self.close()
        return report

    def close(self) -> None:
        """Release the simulator."""
        self.sim.close()


def _int(text: str) -> Any:
    try:
        return int(text)
    except ValueError:
        return text


def parse_args(argv: Sequence[str], prog: str) -> argparse.Namespace:
    """The command line of ``safenav-ros2``/``safenav-ros1`` (middleware arguments already removed).

    ``PROG [filter]`` runs the safety node (its settings are ROS parameters);
    ``PROG policy NAME [--robot R] [--goal X Y] [--seed S]`` a tutorial controller;
    ``PROG sim [--world W] [--robot R] [--duration S] [--report FILE] [--sim-time]`` the simulator.
    Middleware arguments (``--ros-args ...``, ``name:=value``) must be removed first.
    """
    parser = argparse.ArgumentParser(prog=prog, description="safenav on ROS: the safety filter node, the "
                                     "tutorial controllers as nodes, and the PyBullet simulator as a robot.")
    commands = parser.add_subparsers(dest="command")
    commands.add_parser("filter", help="the safety filter node (default); settings are ROS parameters")
    policy = commands.add_parser("policy", help="a tutorial controller publishing nominal commands on cmd_vel_in")
    policy.add_argument("name", choices=POLICY_NAMES)
    policy.add_argument("--robot", choices=PRESET_NAMES, default="rosbot")
    policy.add_argument("--goal", type=float, nargs=2, metavar=("X", "Y"), help="go_to_goal's goal [m] (odom frame)")
    policy.add_argument("--seed", type=int, default=0, help="random_walk's seed")
    policy.add_argument("--output", default="cmd_vel_in", help="topic of the nominal commands")
    sim = commands.add_parser("sim", help="PyBullet as a robot: publishes scan and odom, drives from cmd_vel")
    sim.add_argument("--world", default="stop_at_wall", help="a tutorial world, or random:SEED")
    sim.add_argument("--robot", choices=PRESET_NAMES, default="rosbot")
    sim.add_argument("--seed", type=int, default=0)
    sim.add_argument("--control-period", type=_period, default=0.05, help="[s]")
    sim.add_argument("--duration", type=_period, default=None, help="stop after this much simulated time [s]")
    sim.add_argument("--report", type=Path, default=None, help="write the truth (contact, clearance) as JSON")
    sim.add_argument("--stop-on-contact", action="store_true", help="end the run at the first contact")
    sim.add_argument("--sim-time", action="store_true",
                     help="publish the simulator's clock on /clock and stamp with it (run the other nodes with "
                          "use_sim_time)")
    sim.add_argument("--speed", type=_period, default=1.0, help="simulated seconds per wall-clock second")
    args = parser.parse_args(list(argv))
    if args.command is None:
        args.command = "filter"
    if args.command == "policy" and args.name == "go_to_goal" and args.goal is None:
        parser.error("policy go_to_goal needs --goal X Y")
    return args


def _period(text: str) -> float:
    try:
        return _checks.duration("value", float(text), high=3600.0)
    except (SafeNavError, ValueError) as error:
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text!r}: {error}") from None


def policy_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    """The policy's own arguments from the command line."""
    if args.name == "go_to_goal":
        return {"goal": tuple(args.goal)}
    if args.name == "random_walk":
        return {"seed": args.seed}
    return {}


def robot_of(args: argparse.Namespace) -> RobotSpec:
    """The robot named on the command line."""
    return preset(args.robot)
