"""Drives a running safety node over real middleware and reports what came out, as JSON.

Run as a separate process (ROS 1 and ROS 2 message packages share module names, so one
process holds one of them)::

    python tests/ros/probe.py ros2 OUT.json     # or ros1, with ROS_MASTER_URI set

It plays :func:`node_scenario` against the node ``/safenav_filter`` (robot ``rosbot``, no
odometry) and writes every phase's outputs and states; ``test_node.py`` asserts on them.
"""

from __future__ import annotations

import json
import math
import sys
import threading
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from safenav import preset  # noqa: E402
from safenav.ros.messages import fill_scan, fill_twist  # noqa: E402
from safenav.synthetic import Scene, synthetic_scan, wall  # noqa: E402

RATE = 20.0          # [Hz] of the probe's scans and commands
NOMINAL = (0.5, 0.0)  # the tutorial's forward command [m/s, rad/s]
NODE = "/safenav_filter"


class Probe:
    """Publishes scans and commands, records ``cmd_vel`` and ``~/state`` with their arrival times."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.outputs: list[list[float]] = []
        self.states: list[dict[str, Any]] = []
        self.start = time.monotonic()

    def now(self) -> float:
        return time.monotonic() - self.start

    def on_output(self, msg: Any) -> None:
        with self.lock:
            self.outputs.append([self.now(), msg.linear.x, msg.angular.z])

    def on_state(self, msg: Any) -> None:
        with self.lock:
            self.states.append({"t": self.now(), **json.loads(msg.data)})

    def drive(self, seconds: float, scan: Any, command: tuple[float, float] | None = NOMINAL,
              until: Any = None) -> dict[str, Any]:
        """Publish ``scan`` (``None``: nothing) and ``command`` at :data:`RATE` for ``seconds``; what came back."""
        with self.lock:
            first_output, first_state = len(self.outputs), len(self.states)
        begin = self.now()
        last_scan = None
        while self.now() - begin < seconds:
            if scan is not None:
                self.publish_scan(scan)
                last_scan = self.now()
            if command is not None:
                self.publish_command(command)
            self.wait(1.0 / RATE)
            if until is not None:
                with self.lock:
                    if any(until(state) for state in self.states[first_state:]):
                        break
        with self.lock:
            return {"begin": begin, "end": self.now(), "last_scan": last_scan,
                    "outputs": self.outputs[first_output:], "states": self.states[first_state:]}


class Ros2Probe(Probe):
    def __init__(self) -> None:
        super().__init__()
        import rclpy
        from geometry_msgs.msg import Twist
        from sensor_msgs.msg import LaserScan
        from std_msgs.msg import String
        from std_srvs.srv import SetBool

        rclpy.init()
        self.rclpy, self.Twist, self.LaserScan, self.SetBool = rclpy, Twist, LaserScan, SetBool
        self.node = rclpy.create_node("safenav_probe")
        self.scan_out = self.node.create_publisher(LaserScan, "scan", 10)
        self.command_out = self.node.create_publisher(Twist, "cmd_vel_in", 10)
        self.node.create_subscription(Twist, "cmd_vel", self.on_output, 10)
        self.node.create_subscription(String, f"{NODE}/state", self.on_state, 50)
        self.enable_client = self.node.create_client(SetBool, f"{NODE}/enable")

    def scan_message(self) -> Any:
        return self.LaserScan()

    def publish_scan(self, msg: Any) -> None:
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.scan_out.publish(msg)

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
        self.scan_out = rospy.Publisher("scan", ros1.LaserScanMessage, queue_size=10)
        self.command_out = rospy.Publisher("cmd_vel_in", ros1.Twist, queue_size=10)
        self.subscribers = [rospy.Subscriber("cmd_vel", ros1.Twist, self.on_output),
                            rospy.Subscriber(f"{NODE}/state", ros1.String, self.on_state)]

    def scan_message(self) -> Any:
        return self.ros1.LaserScanMessage()

    def publish_scan(self, msg: Any) -> None:
        msg.header.stamp = self.rospy.Time.now()
        self.scan_out.publish(msg)

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
    phases["discovery"] = probe.drive(30.0, free, until=lambda state: state["status"] == "ok")
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


def main(middleware: str, out: str) -> None:
    probe = Ros2Probe() if middleware == "ros2" else Ros1Probe()
    try:
        Path(out).write_text(json.dumps(node_scenario(probe)))
    finally:
        probe.close()


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
