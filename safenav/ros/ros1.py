"""``safenav-ros1``: the same safety node, controllers and simulator on ROS 1 (rospy).

Only transport lives here; the logic is :class:`~safenav.ros.core.SafetyCore`, shared with
:mod:`safenav.ros.ros2`. Parameters are private (``_filter:=mpc`` on the command line, or
``<param>``/``<rosparam>`` in a launch file; nested names such as ``scan/mount`` read as
``scan.mount``)::

    sudo apt-get install ros-core python3-rospy python3-sensor-msgs python3-geometry-msgs \\
        python3-nav-msgs python3-std-srvs python3-diagnostic-msgs python3-visualization-msgs
    roscore &
    safenav-ros1 _robot:=rosbot _filter:=cbf                            # the safety node
    safenav-ros1 policy stop_at_wall_buggy --robot rosbot               # a tutorial controller
    safenav-ros1 sim --world stop_at_wall --robot rosbot                # PyBullet as the robot

ROS 1 comes from the operating system, not from pip. When ``rospy`` is not importable (a
virtual environment), the node imports it and the ROS 1 messages from Debian's
``/usr/lib/python3/dist-packages`` (or ``$SAFENAV_ROS1_PYTHONPATH``), ahead of any
same-named ROS 2 message packages, after numpy and safenav's own dependencies are loaded.
That needs the Python minor version Debian's packages were built for (3.11 on bookworm).

rospy runs every subscriber in its own thread: one lock serialises the core. The control
timer is a deadline loop on the wall clock that a scan tick pushes back by one period.
"""

from __future__ import annotations

import contextlib
import importlib
import os
import sys
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

from safenav.errors import MissingDependency, SafeNavError
from safenav.ros import apps
from safenav.ros.core import SafetyCore
from safenav.ros.messages import fill_twist
from safenav.ros.outputs import MessageTypes, TopicOutputs
from safenav.ros.params import NodeConfig

__all__ = ["DEBIAN_ROS1_PATH", "PolicyNode", "SafetyNode", "SimNode", "import_ros1", "main"]

DEBIAN_ROS1_PATH = "/usr/lib/python3/dist-packages"
"""Where Debian installs rospy and the ROS 1 messages (``SAFENAV_ROS1_PYTHONPATH`` overrides it)."""

#: The ROS 1 modules the nodes use, imported together so that none comes from ROS 2.
_ROS1_MODULES = ("rospy", "std_msgs.msg", "sensor_msgs.msg", "geometry_msgs.msg", "nav_msgs.msg", "std_srvs.srv",
                 "diagnostic_msgs.msg", "visualization_msgs.msg", "rosgraph_msgs.msg")
_APT_LINE = f"sudo apt-get install {' '.join(apps.ROS1_DEBIAN_PACKAGES)}"
_QUEUE = 10


class MissingROS1(MissingDependency):
    """rospy is not installed; the message gives the ``apt-get`` line (ROS 1 is not on pip)."""

    def __init__(self, searched: str) -> None:
        super().__init__("rospy", "safenav-ros1 (the ROS 1 node)")
        self.searched = searched
        text = (f"safenav-ros1 (the ROS 1 node) needs rospy, from the operating system (Debian: {_APT_LINE}); "
                f"not importable, and not found in {searched}")
        self.msg, self.args = text, (text,)   # ImportError prints .msg

    def __reduce__(self) -> tuple[type, tuple[str]]:
        return type(self), (self.searched,)


@contextlib.contextmanager
def _first_on_path(directory: str) -> Iterator[None]:
    sys.path.insert(0, directory)
    try:
        yield
    finally:
        sys.path.remove(directory)
        sys.path.append(directory)  # rospy imports some modules lazily (rosgraph.network, ...)


def import_ros1() -> dict[str, ModuleType]:
    """rospy and the ROS 1 message modules, by module name.

    Raises:
        MissingROS1: rospy is neither importable nor in Debian's (or the configured) directory.
    """
    try:
        return {name: importlib.import_module(name) for name in _ROS1_MODULES}
    except ImportError:
        for name in [m for m in sys.modules if m.split(".")[0] in {n.split(".")[0] for n in _ROS1_MODULES}]:
            del sys.modules[name]  # ROS 2 packages of the same names, imported by the failed attempt
    directory = os.environ.get("SAFENAV_ROS1_PYTHONPATH", DEBIAN_ROS1_PATH)
    if not (Path(directory) / "rospy" / "__init__.py").is_file():
        raise MissingROS1(directory)
    with _first_on_path(directory):
        return {name: importlib.import_module(name) for name in _ROS1_MODULES}


ros = import_ros1()
rospy = ros["rospy"]
msgs = {name: module for name, module in ros.items() if name != "rospy"}
String = msgs["std_msgs.msg"].String
LaserScanMessage = msgs["sensor_msgs.msg"].LaserScan
Twist, TwistStamped, Point = (getattr(msgs["geometry_msgs.msg"], n) for n in ("Twist", "TwistStamped", "Point"))
Odometry = msgs["nav_msgs.msg"].Odometry
SetBool, SetBoolResponse = msgs["std_srvs.srv"].SetBool, msgs["std_srvs.srv"].SetBoolResponse
DiagnosticArray, DiagnosticStatus, KeyValue = (getattr(msgs["diagnostic_msgs.msg"], n)
                                               for n in ("DiagnosticArray", "DiagnosticStatus", "KeyValue"))
Marker, MarkerArray = msgs["visualization_msgs.msg"].Marker, msgs["visualization_msgs.msg"].MarkerArray
ClockMessage = msgs["rosgraph_msgs.msg"].Clock
SIM_TYPES = {"scan": LaserScanMessage, "odom": Odometry, "clock": ClockMessage}
MESSAGE_TYPES = MessageTypes(Twist, TwistStamped, String, DiagnosticArray, DiagnosticStatus, KeyValue, MarkerArray,
                             Marker, Point)


def _flatten(values: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"scan": {"mount": [..]}}`` as ``{"scan.mount": [..]}``."""
    flat: dict[str, Any] = {}
    for key, value in values.items():
        if isinstance(value, Mapping):
            flat.update(_flatten(value, f"{prefix}{key}."))
        else:
            flat[f"{prefix}{key}"] = value
    return flat


class _DeadlineLoop:
    """Calls ``step`` every ``period`` [s] of wall time, on its own thread; :meth:`restart` pushes the deadline."""

    def __init__(self, period: float, step: Callable[[], None]) -> None:
        self.period = period
        self._step = step
        self._deadline = time.monotonic() + period
        self._wake = threading.Condition()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def restart(self) -> None:
        with self._wake:
            self._deadline = time.monotonic() + self.period
            self._wake.notify()

    def _run(self) -> None:
        while not rospy.is_shutdown():
            with self._wake:
                remaining = self._deadline - time.monotonic()
                if remaining > 0.0:
                    self._wake.wait(remaining)
                    continue
                self._deadline += self.period
                if self._deadline < time.monotonic():   # fell behind: do not try to catch up
                    self._deadline = time.monotonic() + self.period
            self._step()


class SafetyNode:
    """The safety filter node on rospy (see :mod:`safenav.ros.core`); call after ``rospy.init_node``.

    Raises:
        SafeNavError: a parameter is invalid (the message names it).
    """

    def __init__(self) -> None:
        config = NodeConfig.from_parameters(_flatten(rospy.get_param("~", {})))
        self.core = SafetyCore(config, warn=rospy.logwarn, info=rospy.loginfo)
        self._lock = threading.Lock()
        twist = TwistStamped if config.stamped else Twist
        self._subscribers = [
            rospy.Subscriber(source.config.topic, getattr(msgs[f"{source.message[0]}.msg"], source.message[1]),
                             self._on_scan, callback_args=source.config.name, queue_size=1)
            for source in self.core.sources.values()]
        self._subscribers.append(rospy.Subscriber(config.cmd_vel_in_topic, twist, self._locked(self.core.on_command),
                                                  queue_size=_QUEUE))
        if config.odom_topic:
            self._subscribers.append(rospy.Subscriber(config.odom_topic, Odometry,
                                                      self._locked(self.core.on_odometry), queue_size=1))
        publish = {"command": rospy.Publisher(config.cmd_vel_out_topic, twist, queue_size=_QUEUE).publish,
                   "state": rospy.Publisher("~state", String, queue_size=_QUEUE).publish,
                   "diagnostics": rospy.Publisher("/diagnostics", DiagnosticArray, queue_size=_QUEUE).publish}
        if config.markers:
            publish["markers"] = rospy.Publisher("~markers", MarkerArray, queue_size=1).publish
        self.outputs = TopicOutputs(self.core, MESSAGE_TYPES, publish, stamp=rospy.Time.now, level=int,
                                    node_name=rospy.get_name())
        self._service = rospy.Service("~enable", SetBool, self._on_enable)
        self._loop = _DeadlineLoop(config.control_period, self._on_timer)
        rospy.loginfo(self.core.describe())

    def _locked(self, handler: Callable[[Any, float], None]) -> Callable[[Any], None]:
        def call(msg: Any) -> None:
            with self._lock:
                handler(msg, rospy.get_time())
        return call

    def _on_scan(self, msg: Any, source: str) -> None:
        with self._lock:
            if self.core.on_scan(source, msg, rospy.get_time()):
                self.core.tick(rospy.get_time(), self.outputs, trigger="scan")
                self._loop.restart()

    def _on_timer(self) -> None:
        with self._lock:
            self.core.tick(rospy.get_time(), self.outputs)

    def _on_enable(self, request: Any) -> Any:
        with self._lock:
            return SetBoolResponse(success=True, message=self.core.set_enabled(request.data))


class PolicyNode:
    """A tutorial controller on rospy: one nominal command per scan."""

    def __init__(self, args: Any) -> None:
        self.core = apps.PolicyCore(args.name, apps.robot_of(args), warn=rospy.logwarn, info=rospy.loginfo,
                                    **apps.policy_kwargs(args))
        self._out = rospy.Publisher(args.output, Twist, queue_size=_QUEUE)
        self._subscribers = [rospy.Subscriber("scan", LaserScanMessage, self._on_scan, queue_size=1),
                             rospy.Subscriber("odom", Odometry, self.core.on_odometry, queue_size=1)]

    def _on_scan(self, msg: Any) -> None:
        self._out.publish(fill_twist(Twist(), self.core.on_scan(msg)))


class SimNode:
    """The PyBullet simulator as a robot on rospy (see :class:`safenav.ros.ros2.SimNode`)."""

    def __init__(self, args: Any) -> None:
        self.args = args
        self.bridge = apps.SimBridge(args.world, apps.robot_of(args), control_period=args.control_period,
                                     seed=args.seed)
        self._lock = threading.Lock()
        self._publish = {"scan": rospy.Publisher("scan", LaserScanMessage, queue_size=1).publish,
                         "odom": rospy.Publisher("odom", Odometry, queue_size=1).publish}
        if args.sim_time:
            self._publish["clock"] = rospy.Publisher("/clock", ClockMessage, queue_size=1).publish
        self._subscriber = rospy.Subscriber("cmd_vel", Twist, self._on_command, queue_size=_QUEUE)
        self._loop = _DeadlineLoop(args.control_period / args.speed, self._step)

    def _now(self) -> float:
        return self.bridge.state.time if self.args.sim_time else rospy.get_time()

    def _on_command(self, msg: Any) -> None:
        with self._lock:
            self.bridge.on_command(msg, self._now())

    def _step(self) -> None:
        with self._lock:
            self.bridge.publish_step(self._now(), self._stamp, SIM_TYPES, self._publish, rospy.logerr)
        if self.bridge.finished(self.args.duration, self.args.stop_on_contact):
            rospy.signal_shutdown("simulated duration reached")

    def _stamp(self, sim_time: float) -> Any:
        return rospy.Time.from_sec(sim_time) if self.args.sim_time else rospy.Time.now()


def main(argv: Sequence[str] | None = None) -> int:
    """``safenav-ros1 [filter | policy NAME | sim] [options] [name:=value ...]``; the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    args = apps.parse_args(rospy.myargv(["safenav-ros1", *argv])[1:], "safenav-ros1")
    names = {"policy": f"safenav_policy_{getattr(args, 'name', '')}", "sim": "safenav_sim"}
    rospy.init_node(names.get(args.command, "safenav_filter"), argv=["safenav-ros1", *argv])
    try:
        if args.command == "policy":
            PolicyNode(args)
            rospy.spin()
        elif args.command == "sim":
            node = SimNode(args)
            rospy.spin()
            node.bridge.finish(args.report)
        else:
            SafetyNode()
            rospy.spin()
    except (SafeNavError, ImportError) as error:  # a bad parameter, or a filter whose extra is missing
        print(f"safenav-ros1: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
