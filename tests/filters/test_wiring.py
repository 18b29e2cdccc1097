"""Wiring mistakes a new user makes, on the filter side: each gives the documented error or status, none a crash.

The scan-side table (mounts in degrees, stamps of every form, zeros) is in tests/test_scan.py
and tests/test_robot.py; here the filters meet those scans, and every mistake that gives a
status rather than an error is driven in a closed loop from 2 m at a wall.
"""

from __future__ import annotations

import dataclasses
import math
import types

import numpy as np
import pytest

from benchmarks.falsify import _clearances, _scan
from safenav import LaserScan, LidarMismatch, Pose2D, preset, unicycle_step
from safenav.errors import InvalidConfig, InvalidScanType
from safenav.filters import FilterStatus, make_filter
from safenav.synthetic import Scene, Segment

WALL = Scene.of(Segment((2.3, -3.0), (2.3, 3.0)))    # 2 m ahead of the ROSbot's body


def message_of(scan: LaserScan, stamp: object | None = None) -> types.SimpleNamespace:
    """A ROS-like LaserScan message carrying ``scan``'s readings (no mount: ROS keeps it in tf)."""
    header = types.SimpleNamespace(stamp=stamp, frame_id=scan.frame_id)
    return types.SimpleNamespace(header=header, angle_min=scan.angle_min, angle_max=scan.angle_max,
                                 angle_increment=scan.angle_increment, time_increment=scan.time_increment,
                                 scan_time=scan.scan_time, range_min=scan.range_min, range_max=scan.range_max,
                                 ranges=scan.ranges.tolist(), intensities=[])


def closed_loop(filter_name: str, wire, *, period: float = 0.05, steps: int = 120, robot=None
                ) -> tuple[float, set[str], float]:
    """From 2 m at a wall at full speed: each period the scan goes through ``wire(scan, t)`` to the filter.

    Returns the smallest body clearance, the statuses seen and the distance driven [m].
    """
    robot = robot or preset("rosbot")
    safety = make_filter(filter_name, robot, 0.05)
    pose, velocity = Pose2D(), np.zeros(2)
    rng = np.random.default_rng(0)
    lowest, statuses = math.inf, set()
    for step in range(steps):
        t = step * period
        scan, kwargs = wire(_scan(robot, WALL, pose, 0.0, rng, t), t)
        result = safety.filter((1.0, 0.0), scan, velocity=velocity, **kwargs)
        statuses.add(result.status.value)
        if result.status is not FilterStatus.OK or result.modified:
            assert result.reason is not None and result.explain().startswith(result.status.value)
        velocity = robot.clip(result.u, velocity, period)
        for _ in range(10):
            pose = unicycle_step(pose, float(velocity[0]), float(velocity[1]), period / 10)
            lowest = min(lowest, float(_clearances(WALL, np.array([[pose.x, pose.y]]), robot.radius)[0]))
    return lowest, statuses, pose.x


@pytest.mark.parametrize("filter_name", ["cbf", "mpc"])
@pytest.mark.parametrize(("mistake", "wire", "period", "status"), [
    ("no mount given (the ROSbot's lidar is mounted backwards)",
     lambda scan, t: (LaserScan.from_msg(message_of(scan)), {}), 0.05, "ok"),
    ("called every 0.1 s with dt = 0.05 s, the time given",
     lambda scan, t: (scan, dict(now=t)), 0.1, "late"),
    ("a stamp in integer nanoseconds",
     lambda scan, t: (LaserScan.from_msg(message_of(scan, stamp=round(t * 1e9) + 1_700_000_000_000_000_000)),
                      dict(now=t + 1_700_000_000.0)), 0.05, "ok"),
    ("a ROS 1 header stamp and the time",
     lambda scan, t: (LaserScan.from_msg(message_of(scan, stamp=types.SimpleNamespace(
         secs=int(t), nsecs=round((t - int(t)) * 1e9)))), dict(now=t)), 0.05, "ok"),
    ("an unstamped scan while the time is given",
     lambda scan, t: (scan.replace(stamp=None), dict(now=t)), 0.05, "stale"),
    ("a clock 2 s behind the scans' stamps",
     lambda scan, t: (scan.replace(stamp=t + 2.0), dict(now=t)), 0.05, "stale"),
])
def test_a_wiring_mistake_gives_its_status_and_never_a_contact(filter_name, mistake, wire, period, status):
    lowest, statuses, _ = closed_loop(filter_name, wire, period=period)
    assert lowest > 0.0, f"{mistake}: contact"
    assert status in statuses, (mistake, statuses)


def zeros_for_no_return(scan: LaserScan, t: float) -> tuple[LaserScan, dict]:
    """The scan as a driver that reports 0.0 where nothing returned sends it (Hokuyo's urg_node)."""
    return LaserScan.from_msg(message_of(scan.with_ranges(np.where(np.isinf(scan.ranges), 0.0, scan.ranges)))), {}


@pytest.mark.parametrize("filter_name", ["cbf", "mpc"])
def test_zeros_for_no_return_are_unknown_unless_the_lidar_says_so(filter_name):
    # Undeclared, the zeros are invalid readings: the directions behind them are unknown and the
    # robot does not drive into them. Declared (LidarSpec.no_return="zero"), they are free space.
    rosbot = preset("rosbot")
    lowest, statuses, driven = closed_loop(filter_name, zeros_for_no_return)
    assert lowest > 0.0 and driven < 0.1 and statuses & {"braking", "ok"}
    declared = rosbot.replace(lidar=dataclasses.replace(rosbot.lidar, no_return="zero"))
    lowest, statuses, driven = closed_loop(filter_name, zeros_for_no_return, robot=declared)
    assert lowest > 0.0 and driven > 1.0


@pytest.mark.parametrize("filter_name", ["cbf", "mpc", "zones"])
def test_wiring_errors_name_the_mistake(filter_name):
    rosbot, puzzlebot = preset("rosbot"), preset("puzzlebot")
    safety = make_filter(filter_name, rosbot, 0.05)
    with pytest.raises(LidarMismatch, match=r"360 .* 720|720 .* 360"):
        safety.filter((0.5, 0.0), puzzlebot.scan())                         # a Puzzlebot's scan to a ROSbot
    with pytest.raises(LidarMismatch, match="mount"):
        safety.filter((0.5, 0.0), rosbot.scan().replace(mount=Pose2D(0.0, 0.0, 0.0)))   # the tutorial's bug
    with pytest.raises(InvalidScanType, match="LaserScan"):
        safety.filter((0.5, 0.0), {"ranges": [1.0]})
    with pytest.raises(InvalidConfig, match=r"dt must be a duration in seconds in \(0, 1\], got 50 \(milliseconds\?\)"):
        make_filter(filter_name, rosbot, 50)


@pytest.mark.parametrize("filter_name", ["cbf", "mpc"])
def test_scan_ages_that_cannot_be_trusted_brake_and_say_why(filter_name):
    robot = preset("rosbot")
    scan = robot.scan(stamp=10.0)
    cases = [(dict(scan_age=-0.5), "in the future"), (dict(now=8.0), "in the future"),
             (dict(now=10.8), "old"), (dict(scan_age=math.nan), "unknown age")]
    for kwargs, fragment in cases:
        safety = make_filter(filter_name, robot, 0.05)
        result = safety.filter((0.5, 0.0), scan, velocity=(0.5, 0.0), **kwargs)
        assert result.status is FilterStatus.STALE and result.braked, kwargs
        assert fragment in result.message and result.reason.family == "stale", (kwargs, result.message)
