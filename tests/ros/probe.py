"""Drives a running safety node over real middleware and reports what came out, as JSON.

Run as a separate process (ROS 1 and ROS 2 message packages share module names, so one
process holds one of them)::

    python tests/ros/probe.py ros2 OUT.json [SCENARIO]   # or ros1, with ROS_MASTER_URI set

It plays a scenario (:data:`SCENARIOS`; default ``node``) against the node ``/safenav_filter``
(robot ``rosbot``, no odometry) and writes every phase's outputs and states; ``test_node.py``
asserts on them. The ``cloud`` scenario also watches a second node, ``/cloud_only``, whose
output is ``cmd_vel_cloud_only``; the ``escape`` scenario a node ``/no_escape`` started with
``escape: false``, whose output is ``cmd_vel_no_escape``.
"""

from __future__ import annotations

import array
import json
import math
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from safenav import preset  # noqa: E402
from safenav.ros.messages import fill_scan, fill_twist  # noqa: E402
from safenav.synthetic import Scene, synthetic_scan, wall  # noqa: E402
from tests.ros.clouds import cloud_fields, wall_points  # noqa: E402

RATE = 20.0          # [Hz] of the probe's scans and commands
NOMINAL = (0.5, 0.0)  # the tutorial's forward command [m/s, rad/s]
NODE = "/safenav_filter"
#: Nodes the probe watches: label -> (node name, output topic).
WATCHED = {"node": (NODE, "cmd_vel"), "cloud_only": ("/cloud_only", "cmd_vel_cloud_only"),
           "no_escape": ("/no_escape", "cmd_vel_no_escape")}


class Probe:
    """Publishes scans, clouds and commands; records each watched node's output and ``~/state`` with arrival times."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.outputs: dict[str, list[list[float]]] = {label: [] for label in WATCHED}
        self.states: dict[str, list[dict[str, Any]]] = {label: [] for label in WATCHED}
        self.start = time.monotonic()

    def now(self) -> float:
        return time.monotonic() - self.start

    def on_output(self, label: str) -> Callable[[Any], None]:
        def record(msg: Any) -> None:
            with self.lock:
                self.outputs[label].append([self.now(), msg.linear.x, msg.angular.z])
        return record

    def on_state(self, label: str) -> Callable[[Any], None]:
        def record(msg: Any) -> None:
            with self.lock:
                self.states[label].append({"t": self.now(), **json.loads(msg.data)})
        return record

    def drive(self, seconds: float, scan: Any, command: tuple[float, float] | None = NOMINAL,
              until: Callable[[dict[str, list[dict[str, Any]]]], bool] | None = None,
              cloud: Any = None) -> dict[str, Any]:
        """Publish ``scan`` and ``cloud`` (``None``: nothing) and ``command`` at :data:`RATE` for ``seconds``.

        Returns what came back: ``outputs`` and ``states`` of ``/safenav_filter``, and those of
        the other watched nodes under their labels. ``until`` ends the phase early: it gets the
        states received so far in the phase, by label.
        """
        with self.lock:
            first = {label: (len(self.outputs[label]), len(self.states[label])) for label in WATCHED}
        begin = self.now()
        last_scan = None
        while self.now() - begin < seconds:
            if scan is not None:
                self.publish_scan(scan)
                last_scan = self.now()
            if cloud is not None:
                self.publish_cloud(cloud)
            if command is not None:
                self.publish_command(command)
            self.wait(1.0 / RATE)
            if until is not None:
                with self.lock:
                    if until({label: self.states[label][first[label][1]:] for label in WATCHED}):
                        break
        with self.lock:
            seen = {label: {"outputs": self.outputs[label][first[label][0]:],
                            "states": self.states[label][first[label][1]:]} for label in WATCHED}
        return {"begin": begin, "end": self.now(), "last_scan": last_scan, **seen.pop("node"), **seen}


class Ros2Probe(Probe):
    def __init__(self) -> None:
        super().__init__()
        import rclpy
        from geometry_msgs.msg import Twist
        from sensor_msgs.msg import LaserScan, PointCloud2, PointField
        from std_msgs.msg import String
        from std_srvs.srv import SetBool

        rclpy.init()
        self.rclpy, self.Twist, self.LaserScan, self.SetBool = rclpy, Twist, LaserScan, SetBool
        self.PointCloud2, self.PointField = PointCloud2, PointField
        self.node = rclpy.create_node("safenav_probe")
        self.scan_out = self.node.create_publisher(LaserScan, "scan", 10)
        self.cloud_out = self.node.create_publisher(PointCloud2, "cloud", 10)
        self.command_out = self.node.create_publisher(Twist, "cmd_vel_in", 10)
        for label, (node, output) in WATCHED.items():
            self.node.create_subscription(Twist, output, self.on_output(label), 10)
            self.node.create_subscription(String, f"{node}/state", self.on_state(label), 50)
        self.enable_client = self.node.create_client(SetBool, f"{NODE}/enable")

    def scan_message(self) -> Any:
        return self.LaserScan()

    def cloud_message(self, cloud: dict[str, Any]) -> Any:
        return fill_cloud(self.PointCloud2(), self.PointField, cloud, lambda data: array.array("B", data))

    def publish_scan(self, msg: Any) -> None:
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.scan_out.publish(msg)

    def publish_cloud(self, msg: Any) -> None:
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.cloud_out.publish(msg)

    def publish_command(self, command: tuple[float, float]) -> None:
        self.command_out.publish(fill_twist(self.Twist(), command))

    def wait(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            self.rclpy.spin_once(self.node, timeout_sec=left)

    def enable(self, on: bool) -> str:
        if not self.enable_client.wait_for_service(timeout_sec=10.0):
            raise RuntimeError("~/enable service not found")
        future = self.enable_client.call_async(self.SetBool.Request(data=on))
        self.rclpy.spin_until_future_complete(self.node, future, timeout_sec=10.0)
        return future.result().message

    def close(self) -> None:
        self.node.destroy_node()
        self.rclpy.shutdown()


class Ros1Probe(Probe):
    def __init__(self) -> None:
        super().__init__()
        from safenav.ros import ros1

        rospy = ros1.rospy
        rospy.init_node("safenav_probe", disable_signals=True)
        self.rospy, self.ros1 = rospy, ros1
        sensor_msgs = ros1.msgs["sensor_msgs.msg"]
        self.PointCloud2, self.PointField = sensor_msgs.PointCloud2, sensor_msgs.PointField
        self.scan_out = rospy.Publisher("scan", ros1.LaserScanMessage, queue_size=10)
        self.cloud_out = rospy.Publisher("cloud", self.PointCloud2, queue_size=10)
        self.command_out = rospy.Publisher("cmd_vel_in", ros1.Twist, queue_size=10)
        self.subscribers = [subscriber for label, (node, output) in WATCHED.items() for subscriber in (
            rospy.Subscriber(output, ros1.Twist, self.on_output(label)),
            rospy.Subscriber(f"{node}/state", ros1.String, self.on_state(label)))]

    def scan_message(self) -> Any:
        return self.ros1.LaserScanMessage()

    def cloud_message(self, cloud: dict[str, Any]) -> Any:
        return fill_cloud(self.PointCloud2(), self.PointField, cloud, bytes)

    def publish_scan(self, msg: Any) -> None:
        msg.header.stamp = self.rospy.Time.now()
        self.scan_out.publish(msg)

    def publish_cloud(self, msg: Any) -> None:
        msg.header.stamp = self.rospy.Time.now()
        self.cloud_out.publish(msg)

    def publish_command(self, command: tuple[float, float]) -> None:
        self.command_out.publish(fill_twist(self.ros1.Twist(), command))

    def wait(self, seconds: float) -> None:
        time.sleep(seconds)

    def enable(self, on: bool) -> str:
        self.rospy.wait_for_service(f"{NODE}/enable", timeout=10.0)
        return self.rospy.ServiceProxy(f"{NODE}/enable", self.ros1.SetBool)(on).message

    def close(self) -> None:
        self.rospy.signal_shutdown("probe done")


def node_scenario(probe: Probe) -> dict[str, Any]:
    """Free space, a wall 0.4 m ahead, a scan that stops, ``~/enable`` off, malformed scans, recovery."""
    robot = preset("rosbot")
    free = fill_scan(probe.scan_message(), robot.scan(), "laser")
    near_wall = fill_scan(probe.scan_message(), synthetic_scan(robot, Scene.of(wall(distance=0.4))), "laser")
    short = fill_scan(probe.scan_message(), synthetic_scan(robot, Scene.of(wall(distance=0.4))), "laser")
    short.ranges = [1.0] * 10
    nan_angles = fill_scan(probe.scan_message(), synthetic_scan(robot, Scene.of(wall(distance=0.4))), "laser")
    nan_angles.angle_min = math.nan
    phases: dict[str, Any] = {}
    phases["discovery"] = probe.drive(30.0, free, until=lambda states: _reports(states["node"], "ok"))
    phases["free"] = probe.drive(1.0, free)
    phases["wall"] = probe.drive(1.5, near_wall)
    phases["stale"] = probe.drive(1.5, None)
    phases["enable_off_answer"] = probe.enable(False)
    phases["disabled"] = probe.drive(1.0, near_wall)
    phases["enable_on_answer"] = probe.enable(True)
    phases["wall_again"] = probe.drive(1.0, near_wall)
    phases["wrong_lengths"] = probe.drive(1.0, short)
    phases["nan_angles"] = probe.drive(1.0, nan_angles)
    phases["recovered"] = probe.drive(1.0, near_wall)
    return phases


def cloud_scenario(probe: Probe) -> dict[str, Any]:
    """Point clouds: free, a wall 0.4 m ahead that only the cloud shows (the scan stays free), a malformed
    cloud, recovery. ``/safenav_filter`` has a scan and a depth-camera cloud source, ``/cloud_only`` a
    3D-lidar cloud source alone (both clouds from the one ``cloud`` topic; see ``clouds.py``).
    """
    free_scan = fill_scan(probe.scan_message(), preset("rosbot").scan(), "laser")
    free, near_wall = probe.cloud_message(cloud_fields(wall_points(None))), \
        probe.cloud_message(cloud_fields(wall_points(0.4)))
    malformed = probe.cloud_message(cloud_fields(wall_points(0.4)))
    malformed.row_step += 12           # the data no longer holds height * row_step bytes

    def both_ok(states: dict[str, list[dict[str, Any]]]) -> bool:
        return all(_reports(states[label], "ok") for label in WATCHED)

    phases: dict[str, Any] = {}
    phases["discovery"] = probe.drive(30.0, free_scan, cloud=free, until=both_ok)
    phases["free"] = probe.drive(1.0, free_scan, cloud=free)
    phases["wall"] = probe.drive(1.5, free_scan, cloud=near_wall)
    phases["malformed"] = probe.drive(1.0, free_scan, cloud=malformed)
    phases["recovered"] = probe.drive(1.0, free_scan, cloud=near_wall)
    return phases


def escape_scenario(probe: Probe) -> dict[str, Any]:
    """A forward command into a wall at the margin, long enough for a deadlock: ``/safenav_filter`` runs
    with the default parameters (the escape on), ``/no_escape`` with ``escape: false``."""
    robot = preset("rosbot")
    free = fill_scan(probe.scan_message(), robot.scan(), "laser")
    at_margin = fill_scan(probe.scan_message(), synthetic_scan(robot, Scene.of(wall(distance=0.39))), "laser")

    def both_ok(states: dict[str, list[dict[str, Any]]]) -> bool:
        return all(_reports(states[label], "ok") for label in ("node", "no_escape"))

    phases: dict[str, Any] = {}
    phases["discovery"] = probe.drive(30.0, free, until=both_ok)
    phases["wall"] = probe.drive(3.5, at_margin)
    return phases


SCENARIOS = {"node": node_scenario, "cloud": cloud_scenario, "escape": escape_scenario}


def _reports(states: list[dict[str, Any]], status: str) -> bool:
    return any(state["status"] == status for state in states)


def fill_cloud(msg: Any, point_field: type, cloud: dict[str, Any], data: Callable[[bytes], Any]) -> Any:
    """Fill a ``sensor_msgs/PointCloud2`` from :func:`~tests.ros.clouds.cloud_fields` (``data``: the client's
    byte container)."""
    msg.header.frame_id = cloud["frame_id"]
    for name in ("height", "width", "is_bigendian", "point_step", "row_step", "is_dense"):
        setattr(msg, name, cloud[name])
    msg.fields = [point_field(name=name, offset=offset, datatype=datatype, count=count)
                  for name, offset, datatype, count in cloud["fields"]]
    msg.data = data(cloud["data"])
    return msg


def main(middleware: str, out: str, scenario: str = "node") -> None:
    probe = Ros2Probe() if middleware == "ros2" else Ros1Probe()
    try:
        Path(out).write_text(json.dumps(SCENARIOS[scenario](probe)))
    finally:
        probe.close()


if __name__ == "__main__":
    main(*sys.argv[1:])
