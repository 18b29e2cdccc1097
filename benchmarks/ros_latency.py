"""ROS 2 latency of the safety node: from a scan arriving to the filtered ``cmd_vel`` leaving.

The node (``safenav-ros2``, its own process, real rclpy over Fast DDS on the loopback
interface) filters a forward-turning nominal command against 720-beam ROSbot scans of
cluttered scenes, published at 20 Hz by this process. With ``step_on_scan`` (the default) each
scan triggers one filter step at once. Two latencies per scan:

* **in the node**: from the scan callback's entry to the command's ``publish()`` returning,
  measured by the node itself (``latency`` in ``~/state``): conversion, filter and publish;
* **round trip**: from this process publishing the scan to it receiving the ``cmd_vel`` that
  followed: adds DDS delivery both ways and both executors.

Median, p99 and max over ``--messages`` scans (default 2000) per filter; the filter's own compute
time (``filter_time`` in ``~/state``) for comparison, and the node's share outside the filter
(in-node latency minus filter time, per scan: conversion, checks and publishing). The ROS 2 Navigation collision monitor
reports about 4.5 ms per 360-point scan.

Run ``python -m benchmarks.ros_latency`` or ``python benchmarks/ros_latency.py`` (``--help``);
it needs ``pip install "safenav[ros2]"``. Run it under ``nice`` on a shared machine.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import json
import os
import random
import signal
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

if __package__ in (None, ""):   # run as a script: python benchmarks/ros_latency.py
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import markdown_table, write_json
from safenav import preset
from safenav.robot import RobotSpec
from safenav.ros.messages import fill_scan, fill_twist
from safenav.synthetic import Circle, Scene, synthetic_scan, wall

ROOT = Path(__file__).resolve().parents[1]
RATE = 20.0                  # [Hz] scans and commands
NOMINAL = (0.5, 0.3)         # [m/s, rad/s] forward and turning: the filter has work to do
NODE = "/safenav_filter"
DEADLINE = 0.05              # [s] the control period: a command later than this is late


def scenes(robot: RobotSpec, count: int, seed: int) -> list[Any]:
    """``count`` cluttered scans: a wall 0.6-1.5 m away within 60 degrees of the heading, and posts."""
    rng = np.random.default_rng(seed)
    scans = []
    for _ in range(count):
        posts = tuple(Circle((float(r * np.cos(a)), float(r * np.sin(a))), float(rng.uniform(0.05, 0.2)))
                      for r, a in zip(rng.uniform(0.7, 3.0, 8), rng.uniform(-np.pi, np.pi, 8), strict=True))
        scene = Scene.of(wall(distance=float(rng.uniform(0.6, 1.5)), direction=float(rng.uniform(-1.0, 1.0))),
                         *posts)
        scans.append(synthetic_scan(robot, scene))
    return scans


GOAL_P99 = 3.0               # [ms] the goal for the CBF's p99 in the node (p50: 1 ms)


def summary_ms(samples: Sequence[float]) -> dict[str, float]:
    """Median, p90, p99 and max [ms] of durations in seconds, and the share above :data:`GOAL_P99`."""
    values = np.asarray(samples, dtype=float) * 1e3
    if values.size == 0:
        return {"n": 0, **dict.fromkeys(("p50_ms", "p90_ms", "p99_ms", "max_ms", "over_goal"), float("nan"))}
    return {"n": int(values.size), "p50_ms": float(np.median(values)), "p90_ms": float(np.percentile(values, 90)),
            "p99_ms": float(np.percentile(values, 99)), "max_ms": float(values.max()),
            "over_goal": float(np.mean(values > GOAL_P99))}


@contextlib.contextmanager
def node_process(filter_name: str, env: dict[str, str], log: Path) -> Iterator[subprocess.Popen]:
    command = [sys.executable, "-m", "safenav.ros.ros2", "--ros-args", "-p", "robot:=rosbot",
               "-p", f"filter:={filter_name}", "-p", "odom_topic:=''", "-p", f"control_period:={DEADLINE}"]
    with log.open("wb") as output:
        process = subprocess.Popen(command, cwd=ROOT, env=env, stdout=output, stderr=subprocess.STDOUT,
                                   start_new_session=True)
        try:
            yield process
        finally:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.pid, signal.SIGINT)
            try:
                process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()


def measure(filter_name: str, messages: int, scans: list[Any], env: dict[str, str], log: Path) -> dict[str, Any]:
    """Publish ``messages`` scans at 20 Hz to a fresh node running ``filter_name``; the latencies."""
    import rclpy
    from geometry_msgs.msg import Twist
    from sensor_msgs.msg import LaserScan
    from std_msgs.msg import String

    published: list[float] = []
    replies: list[float] = []
    states: list[dict[str, Any]] = []
    with node_process(filter_name, env, log) as process:
        context = rclpy.Context()
        rclpy.init(context=context)
        node = rclpy.create_node("ros_latency_driver", context=context)
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        scan_out = node.create_publisher(LaserScan, "scan", 10)
        command_out = node.create_publisher(Twist, "cmd_vel_in", 10)
        node.create_subscription(Twist, "cmd_vel", lambda msg: replies.append(time.monotonic()), 100)
        node.create_subscription(String, f"{NODE}/state", lambda msg: states.append(json.loads(msg.data)), 100)
        messages_out = [fill_scan(LaserScan(), scan, "laser") for scan in scans]
        command = fill_twist(Twist(), NOMINAL)
        deadline = time.monotonic() + 60.0
        while not states or states[-1]["status"] != "ok":   # discovery: until the node filters
            if time.monotonic() > deadline or process.poll() is not None:
                raise RuntimeError(f"the node did not start filtering; see {log}")
            command_out.publish(command)
            scan_out.publish(messages_out[0])
            executor.spin_once(timeout_sec=1.0 / RATE)
        states.clear()
        replies.clear()
        start, wall_start = time.monotonic(), time.time()
        for k in range(messages):
            due = start + k / RATE
            while (left := due - time.monotonic()) > 0:
                executor.spin_once(timeout_sec=left)
            command_out.publish(command)
            msg = messages_out[k % len(messages_out)]
            msg.header.stamp = node.get_clock().now().to_msg()
            published.append(time.monotonic())
            scan_out.publish(msg)
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
    round_trips = []
    replies_array = np.asarray(replies)
    for k, sent in enumerate(published):
        until = published[k + 1] if k + 1 < len(published) else sent + 1.0 / RATE
        index = np.searchsorted(replies_array, sent)
        if index < len(replies_array) and replies_array[index] < until:
            round_trips.append(replies_array[index] - sent)
    states = [s for s in states if s["time"] >= wall_start]     # the node's clock is the system clock
    scan_steps = [s for s in states if s["trigger"] == "scan"]
    answered = [s for s in scan_steps if s["latency"] is not None]
    return {"filter": filter_name, "scans": messages, "in_node": summary_ms([s["latency"] for s in answered]),
            "round_trip": summary_ms(round_trips), "filter_time": summary_ms([s["filter_time"] for s in scan_steps]),
            "outside_filter": summary_ms([s["latency"] - s["filter_time"] for s in answered]),
            "late_round_trips": int(sum(r > DEADLINE for r in round_trips)),
            "missing_replies": messages - len(round_trips),
            "timer_steps": sum(s["trigger"] == "timer" for s in states),
            "statuses": dict(collections.Counter(s["status"] for s in states))}


def main(argv: Sequence[str] | None = None, prog: str = "ros_latency") -> int:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--messages", type=int, default=2000, help="scans per filter at 20 Hz (default: 2000)")
    parser.add_argument("--filters", default="cbf,mpc", help="comma-separated filters (default: cbf,mpc)")
    parser.add_argument("--scenes", type=int, default=50, help="distinct cluttered scans, cycled (default: 50)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--domain", type=int, default=None, help="ROS_DOMAIN_ID (default: a random one in 1..101)")
    parser.add_argument("--logs", type=Path, default=Path("/tmp"), help="where the node's log goes")
    parser.add_argument("--json", metavar="PATH", help="write the results as JSON")
    args = parser.parse_args(argv)

    domain = args.domain if args.domain is not None else random.Random().randint(1, 101)
    os.environ.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    robot = preset("rosbot")
    scans = scenes(robot, args.scenes, args.seed)
    print(f"{args.messages} scans of {robot.lidar.n_beams} beams at {RATE:g} Hz per filter, ROS 2 domain {domain}, "
          f"nominal {NOMINAL}")
    results = [measure(name, args.messages, scans, env, args.logs / f"ros_latency_{name}.log")
               for name in args.filters.split(",")]
    rows = []
    for result in results:
        node, trip, compute = result["in_node"], result["round_trip"], result["filter_time"]
        outside = result["outside_filter"]
        rows.append([result["filter"], node["n"], node["p50_ms"], node["p90_ms"], node["p99_ms"], node["max_ms"],
                     f"{100 * node['over_goal']:.1f}%", trip["p50_ms"], trip["p99_ms"], trip["max_ms"],
                     compute["p50_ms"], compute["p99_ms"], outside["p50_ms"], outside["p99_ms"],
                     result["missing_replies"], result["late_round_trips"]])
    print()
    print(markdown_table(["filter", "scans", "in node p50 ms", "p90 ms", "p99 ms", "max ms", f"> {GOAL_P99:g} ms",
                          "round trip p50 ms", "p99 ms", "max ms", "filter p50 ms", "filter p99 ms",
                          "outside filter p50 ms", "p99 ms", "no reply", f"round trip > {DEADLINE:g} s"], rows))
    load = os.getloadavg()
    print(f"load average during the run (1, 5, 15 min): {load[0]:.2f}, {load[1]:.2f}, {load[2]:.2f} on "
          f"{os.cpu_count()} cores")
    write_json(args.json, {"config": {**vars(args), "logs": str(args.logs), "domain": domain}, "results": results,
                           "load_average": load})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
