"""``safenav-ros2``: the safety filter, the tutorial controllers and the simulator on ROS 2 (rclpy).

Only transport lives here: subscriptions, timers, clocks and publishers. The logic is
:class:`~safenav.ros.core.SafetyCore` (shared with :mod:`safenav.ros.ros1`)::

    pip install "safenav[ros2]"
    safenav-ros2 --ros-args -p robot:=rosbot -p filter:=cbf            # the safety node
    safenav-ros2 policy stop_at_wall_buggy --robot rosbot              # a tutorial controller
    safenav-ros2 sim --world stop_at_wall --robot rosbot               # PyBullet as the robot

(also ``python -m safenav.ros.ros2 ...``). Topics (relative, so ``--ros-args -r`` remaps them):
sources (``scan``), ``cmd_vel_in``, ``odom`` in; ``cmd_vel``, ``~/state`` (``std_msgs/String``,
JSON), ``/diagnostics``, ``~/markers`` out; service ``~/enable`` (``std_srvs/SetBool``).
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Sequence
from typing import Any

from safenav._optional import require
from safenav.errors import SafeNavError
from safenav.ros import apps
from safenav.ros.core import SafetyCore
from safenav.ros.messages import fill_twist
from safenav.ros.outputs import MessageTypes, TopicOutputs
from safenav.ros.params import NodeConfig

__all__ = ["PolicyNode", "SafetyNode", "SimNode", "main"]

_PURPOSE = "safenav-ros2 (the ROS 2 node)"
#: Parameters every rclpy node has; they are not the safety node's.
_RCLPY_PARAMETERS = ("use_sim_time", "start_type_description_service")

rclpy = require("rclpy", extra="ros2", purpose=_PURPOSE)
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue  # noqa: E402
from geometry_msgs.msg import Point, Twist, TwistStamped  # noqa: E402
from nav_msgs.msg import Odometry  # noqa: E402
from rclpy.clock import Clock, ClockType  # noqa: E402
from rclpy.executors import ExternalShutdownException  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from rclpy.task import Future  # noqa: E402
from rclpy.time import Time  # noqa: E402
from rosgraph_msgs.msg import Clock as ClockMessage  # noqa: E402
from sensor_msgs.msg import LaserScan as LaserScanMessage  # noqa: E402
from std_msgs.msg import String  # noqa: E402
from std_srvs.srv import SetBool  # noqa: E402
from visualization_msgs.msg import Marker, MarkerArray  # noqa: E402

_RELIABLE_DEPTH = 10
SIM_TYPES = {"scan": LaserScanMessage, "odom": Odometry, "clock": ClockMessage}
MESSAGE_TYPES = MessageTypes(Twist, TwistStamped, String, DiagnosticArray, DiagnosticStatus, KeyValue, MarkerArray,
                             Marker, Point)


def _message_class(package: str, name: str) -> type:
    return getattr(importlib.import_module(f"{package}.msg"), name)


def _seconds(node: Node) -> float:
    return node.get_clock().now().nanoseconds * 1e-9


class SafetyNode(Node):
    """The safety filter node (see :mod:`safenav.ros.core` for what each tick does).

    Args:
        name: node name.
        cli_args: ROS arguments (``--ros-args -p ...``).

    Raises:
        SafeNavError: a parameter is invalid (the message names it).
    """

    def __init__(self, name: str = "safenav_filter", *, cli_args: Sequence[str] | None = None) -> None:
        super().__init__(name, cli_args=list(cli_args) if cli_args else None, allow_undeclared_parameters=True,
                         automatically_declare_parameters_from_overrides=True)
        given = {name: parameter.value for name, parameter in self.get_parameters_by_prefix("").items()
                 if name not in _RCLPY_PARAMETERS and not name.startswith("qos_overrides.")}
        config = NodeConfig.from_parameters(given)
        logger = self.get_logger()
        self.core = SafetyCore(config, warn=logger.warning, info=logger.info)
        twist = TwistStamped if config.stamped else Twist
        for source in self.core.sources.values():
            self.create_subscription(_message_class(*source.message), source.config.topic,
                                     lambda msg, name=source.config.name: self._on_scan(name, msg),
                                     qos_profile_sensor_data)
        self.create_subscription(twist, config.cmd_vel_in_topic,
                                 lambda msg: self.core.on_command(msg, _seconds(self)), _RELIABLE_DEPTH)
        if config.odom_topic:
            self.create_subscription(Odometry, config.odom_topic,
                                     lambda msg: self.core.on_odometry(msg, _seconds(self)), qos_profile_sensor_data)
        publish = {"command": self.create_publisher(twist, config.cmd_vel_out_topic, _RELIABLE_DEPTH).publish,
                   "state": self.create_publisher(String, "~/state", _RELIABLE_DEPTH).publish,
                   "diagnostics": self.create_publisher(DiagnosticArray, "/diagnostics", _RELIABLE_DEPTH).publish}
        if config.markers:
            publish["markers"] = self.create_publisher(MarkerArray, "~/markers", 1).publish
        self.outputs = TopicOutputs(self.core, MESSAGE_TYPES, publish, stamp=lambda: self.get_clock().now().to_msg(),
                                    level=lambda level: bytes([level]), node_name=self.get_name())
        self.create_service(SetBool, "~/enable", self._on_enable)
        self._timer = self.create_timer(config.control_period, lambda: self.core.tick(_seconds(self), self.outputs))
        logger.info(self.core.describe())

    def _on_scan(self, source: str, msg: Any) -> None:
        if self.core.on_scan(source, msg, _seconds(self)):
            self.core.tick(_seconds(self), self.outputs, trigger="scan")
            self._timer.reset()

    def _on_enable(self, request: Any, response: Any) -> Any:
        response.message = self.core.set_enabled(request.data)
        response.success = True
        return response


class PolicyNode(Node):
    """A tutorial controller: one nominal command on the output topic per scan."""

    def __init__(self, args: Any, *, cli_args: Sequence[str] | None = None) -> None:
        super().__init__(f"safenav_policy_{args.name}", cli_args=list(cli_args) if cli_args else None)
        logger = self.get_logger()
        self.core = apps.PolicyCore(args.name, apps.robot_of(args), warn=logger.warning, info=logger.info,
                                    **apps.policy_kwargs(args))
        self._out = self.create_publisher(Twist, args.output, _RELIABLE_DEPTH)
        self.create_subscription(LaserScanMessage, "scan", self._on_scan, qos_profile_sensor_data)
        self.create_subscription(Odometry, "odom", self.core.on_odometry, qos_profile_sensor_data)
        logger.info(f"{args.name} on {args.robot}: scan -> {args.output}")

    def _on_scan(self, msg: Any) -> None:
        self._out.publish(fill_twist(Twist(), self.core.on_scan(msg)))


class SimNode(Node):
    """The PyBullet simulator as a robot: ``scan`` and ``odom`` out, ``cmd_vel`` in.

    The simulation advances one control period per tick of a steady (wall-clock) timer, at
    ``--speed`` times real time. Stamps are the node's clock, or with ``--sim-time`` the
    simulated time, also published on ``/clock``.
    """

    def __init__(self, args: Any, *, cli_args: Sequence[str] | None = None) -> None:
        super().__init__("safenav_sim", cli_args=list(cli_args) if cli_args else None)
        self.args = args
        self.bridge = apps.SimBridge(args.world, apps.robot_of(args), control_period=args.control_period,
                                     seed=args.seed)
        self.done = Future()
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._publish = {"scan": self.create_publisher(LaserScanMessage, "scan", qos_profile_sensor_data).publish,
                         "odom": self.create_publisher(Odometry, "odom", _RELIABLE_DEPTH).publish}
        if args.sim_time:
            self._publish["clock"] = self.create_publisher(ClockMessage, "/clock", _RELIABLE_DEPTH).publish
        self.create_subscription(Twist, "cmd_vel", lambda msg: self.bridge.on_command(msg, self._now()),
                                 _RELIABLE_DEPTH)
        self.create_timer(args.control_period / args.speed, self._step, clock=self._steady)
        self.get_logger().info(f"simulating {args.world} with {args.robot}: cmd_vel -> scan, odom")

    def _now(self) -> float:
        if self.args.sim_time:
            return self.bridge.state.time
        return _seconds(self)

    def _stamp(self, sim_time: float) -> Any:
        if not self.args.sim_time:
            return self.get_clock().now().to_msg()
        return Time(nanoseconds=round(sim_time * 1e9)).to_msg()

    def _step(self) -> None:
        if self.done.done():
            return
        self.bridge.publish_step(self._now(), self._stamp, SIM_TYPES, self._publish, self.get_logger().error)
        if self.bridge.finished(self.args.duration, self.args.stop_on_contact):
            self.done.set_result(self.bridge.report())


def _run(node: Node, until: Any = None) -> None:
    try:
        if until is None:
            rclpy.spin(node)
        else:
            rclpy.spin_until_future_complete(node, until)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass


def main(argv: Sequence[str] | None = None) -> int:
    """``safenav-ros2 [filter | policy NAME | sim] [options] [--ros-args ...]``; the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    from rclpy.utilities import remove_ros_args

    args = apps.parse_args(remove_ros_args(["safenav-ros2", *argv])[1:], "safenav-ros2")
    ros_args = argv[argv.index("--ros-args"):] if "--ros-args" in argv else []
    rclpy.init(args=["safenav-ros2", *ros_args])
    node: Node | None = None
    try:
        if args.command == "policy":
            node = PolicyNode(args, cli_args=ros_args)
            _run(node)
        elif args.command == "sim":
            node = SimNode(args, cli_args=ros_args)
            _run(node, node.done)
            node.bridge.finish(args.report)
        else:
            node = SafetyNode(cli_args=ros_args)
            _run(node)
    except (SafeNavError, ImportError) as error:  # a bad parameter, or a filter whose extra is missing
        print(f"safenav-ros2: {error}", file=sys.stderr)
        return 2
    finally:
        if node is not None:
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
