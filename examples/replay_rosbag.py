"""Replay the recorded ROS bag (a Hokuyo URG) through the CBF filter, with the right robot description and wrong ones.

The bag ``scan_tools-laser_scan_matcher-demo.bag`` (``shared/data/lidar``) holds 360 scans of a
Hokuyo URG-04LX: 681 beams over +-2.086 rad, 0.02-5.6 m, and 0.0 where nothing returned. Its
robot is not a preset, so it is described with a :class:`LidarSpec` copied from one message
(laser at the base origin, facing forward, as the scan matcher's demo publishes it) and a small
indoor base around it. Each scan, as ``LaserScan.from_msg`` reads it (no mount), goes through
``CBFSafetyFilter(robot).filter`` (which puts it on the robot's lidar with
``robot.match_scan``) with a nominal command straight ahead, and the statuses are counted.

What the README's example did before, ``preset("rosbot")`` with
``from_msg(msg, mount=robot.lidar.mount)`` or ``from_msg(msg)``, is now refused by the filter
(``LidarMismatch``: 681 beams vs 720, ...). What it amounted to is replayed with robots that
describe the Hokuyo wrongly but consistently, which no check can catch:

* ``turned``: the Hokuyo mounted backwards (yaw pi, the ROSbot's mount), zeros invalid: the
  README's old wiring.
* ``zeros-invalid``: the right mount, zeros invalid (``no_return`` not set): ``from_msg(msg)``.
* ``right``: the right description, ``no_return="zero"``.

The base's velocity is either ``held`` at the nominal speed every scan (the measurement of
issue 12: as if the base ignored the filter) or ``fed back``: the base executes each filtered
command (the velocity at the next scan is the last command), as on a robot. An intervention
(a command other than the nominal, or the nearest to it the acceleration limits allow) is
*spurious* when no recorded point lies within :data:`NEAR` = 1 m of the laser: at up to 0.5 m/s
the filter's reach is 0.55 m (body radius 0.15 m, twice the 0.1 m look-ahead since the look-ahead
barrier is conservative by up to ``2 l`` ahead, the 0.026 m margin, and 0.175 m to stop from
0.5 m/s, ``v dt + v^2 / (2 a_max)``). Spurious interventions come from the description, not from
the scene. ``mean v`` is the mean commanded speed.

Run it from a checkout: ``python examples/replay_rosbag.py [--bag PATH] [--json OUT]``.
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from safenav import LaserScan, LidarMismatch, LidarSpec, Pose2D, RobotSpec, preset
from safenav.datasets import RECORDING_FILES, lidar_data_dir, load_rosbag
from safenav.filters import CBFSafetyFilter

#: The Hokuyo URG-04LX of the bag, as its messages describe it.
HOKUYO = LidarSpec(
    n_beams=681,
    angle_min=-2.0862138271331787,      # msg.angle_min [rad]
    angle_max=2.0862138271331787,       # msg.angle_max: the last beam [rad]
    range_min=0.02,                     # msg.range_min [m]
    range_max=5.6,                      # msg.range_max [m]
    mount=Pose2D(0.0, 0.0, 0.0),        # base_link -> laser: at the origin, facing forward
    scan_time=0.1,                      # 10 Hz
    frame_id="laser",                   # msg.header.frame_id
    no_return="zero",                   # the URG reports 0.0 when nothing returns
)
#: A small indoor base carrying the URG at its centre.
HOKUYO_ROBOT = RobotSpec(name="urg_base", radius=0.15, v_max=0.5, v_min=-0.3, omega_max=1.5, a_max=1.0,
                         alpha_max=3.0, lidar=HOKUYO, source="examples/replay_rosbag.py")
WIRINGS = ("turned", "zeros-invalid", "right")
VELOCITIES = ("held", "fed back")
SPEEDS = (0.1, 0.3, 0.5)
#: Slack on a scan with no recorded point this close to the laser [m] is spurious (see above).
NEAR = 1.0
#: Control period of the replay: the scan period, as the filter runs in the scan callback [s].
DT = 0.1


@dataclass(frozen=True)
class Replay:
    """Statuses of one replay of the bag.

    Attributes:
        wiring: one of :data:`WIRINGS`.
        velocity: ``"held"`` or ``"fed back"``.
        speed: nominal forward speed [m/s].
        statuses: status value -> number of scans.
        spurious: interventions with no recorded point within :data:`NEAR` of the laser.
        mean_speed: mean commanded forward speed [m/s].
    """

    wiring: str
    velocity: str
    speed: float
    statuses: dict[str, int]
    spurious: int
    mean_speed: float

    @property
    def slack(self) -> int:
        """Number of scans answered with ``slack``."""
        return self.statuses.get("slack", 0)


def described(wiring: str) -> RobotSpec:
    """The robot of ``wiring`` (one of :data:`WIRINGS`)."""
    if wiring == "turned":
        return HOKUYO_ROBOT.replace(lidar=dataclasses.replace(HOKUYO, mount=preset("rosbot").lidar.mount,
                                                              no_return=None))
    if wiring == "zeros-invalid":
        return HOKUYO_ROBOT.replace(lidar=dataclasses.replace(HOKUYO, no_return=None))
    return HOKUYO_ROBOT


def replay(scans: Sequence[LaserScan], wiring: str, velocity: str, speed: float) -> Replay:
    """Every scan through a fresh CBF filter with the nominal command ``(speed, 0)``."""
    statuses: collections.Counter[str] = collections.Counter()
    spurious = 0
    commanded = []
    robot = described(wiring)
    safety = CBFSafetyFilter(robot, dt=DT)
    current = np.array([speed, 0.0])
    for message_scan in scans:
        result = safety.filter((speed, 0.0), message_scan, velocity=current)
        statuses[result.status.value] += 1
        commanded.append(float(result.u[0]))
        reachable = robot.clip((speed, 0.0), current, DT)
        if not np.allclose(result.u, reachable, atol=1e-9) and _nearest_point(message_scan) > NEAR:
            spurious += 1
        if velocity == "fed back":
            current = result.u
    return Replay(wiring, velocity, speed, dict(statuses), spurious, float(np.mean(commanded)))


def _nearest_point(message_scan: LaserScan) -> float:
    """Distance from the laser to the nearest point the URG recorded [m] (``inf`` when none)."""
    _, ranges = message_scan.obstacle_beams()
    return float(ranges.min()) if ranges.size else float("inf")


def bag_scans(path: Path) -> list[LaserScan]:
    """The bag's scans as :meth:`LaserScan.from_msg` reads the messages (no mount, plain REP-117)."""
    return [recorded.scan for recorded in load_rosbag(path)]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--bag", type=Path, help="the bag (default: shared/data/lidar)")
    parser.add_argument("--json", type=Path, help="write the counts as JSON")
    args = parser.parse_args(argv)
    bag = args.bag
    if bag is None:
        folder = lidar_data_dir()
        if folder is None:
            parser.error("recordings not found: pass --bag or set SAFENAV_LIDAR_DATA")
        bag = folder / RECORDING_FILES["laser-scan-matcher-bag"]
    scans = bag_scans(bag)
    try:
        CBFSafetyFilter(preset("rosbot"), dt=DT).filter((0.3, 0.0), scans[0])
    except LidarMismatch as error:
        print(f"CBFSafetyFilter(preset('rosbot')).filter(u, scan) -> LidarMismatch: {error}\n")
    rows = [replay(scans, wiring, velocity, speed) for velocity in VELOCITIES for wiring in WIRINGS
            for speed in SPEEDS]
    print(f"{len(scans)} scans, CBF filter, dt = {DT} s, nominal (speed, 0)\n")
    print("| velocity | wiring | speed [m/s] | statuses | spurious interventions | mean v [m/s] |")
    print("|---|---|---|---|---|---|")
    for row in rows:
        statuses = ", ".join(f"{status} {count}" for status, count in sorted(row.statuses.items()))
        print(f"| {row.velocity} | {row.wiring} | {row.speed:.1f} | {statuses} | {row.spurious} | "
              f"{row.mean_speed:.3f} |")
    if args.json is not None:
        args.json.write_text(json.dumps([vars(row) for row in rows], indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
