"""Replay the recorded ROS bag (a Hokuyo URG) through the CBF filter, with the right robot description and wrong ones.

The bag ``scan_tools-laser_scan_matcher-demo.bag`` (``shared/data/lidar``) holds 360 scans of a
Hokuyo URG-04LX: 681 beams over +-2.086 rad, 0.02-5.6 m, and 0.0 where nothing returned. Its
robot is not a preset, so it is described with a :class:`LidarSpec` copied from one message
(laser at the base origin, facing forward, as the scan matcher's demo publishes it) and a small
indoor base around it. Each scan goes through ``robot.match_scan`` and
``CBFSafetyFilter(robot).filter`` with a nominal command straight ahead, and the statuses are
counted:

* ``readme-rosbot``: what the README's example did before: ``preset("rosbot")`` and
  ``from_msg(msg, mount=robot.lidar.mount)``, straight into the filter (no ``match_scan``): the
  scan is turned 180 degrees. ``robot.match_scan`` now refuses it (``LidarMismatch``).
* ``no-mount-rosbot``: ``from_msg(msg)`` on the ROSbot, straight into the filter: the scan stays at
  the identity, and the 0.0 readings are invalid (unknown directions).
* ``hokuyo-rep117``: the right description but the 0.0 readings left invalid.
* ``hokuyo``: the right description, ``no_return="zero"``.

The base's velocity is either ``held`` at the nominal speed every scan (the measurement of
issue 12: as if the base ignored the filter) or ``fed back``: the base executes each filtered
command (the velocity at the next scan is the last command), as on a robot. A ``slack`` result is
*spurious* when no recorded point lies within :data:`NEAR` = 1 m of the laser: at up to 0.5 m/s
the filter's reach is 0.55 m (body radius 0.15 m, twice the 0.1 m look-ahead since the look-ahead
barrier is conservative by up to ``2 l`` ahead, the 0.026 m margin, and 0.175 m to stop from
0.5 m/s, ``v dt + v^2 / (2 a_max)``). Spurious slack comes from the wiring, not from the scene.
``mean v`` is the mean commanded speed: a filter that stops the robot because the way ahead
looks unseen may say ``ok``.

Run it from a checkout: ``python examples/replay_rosbag.py [--bag PATH] [--json OUT]``.
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import json
import sys
from collections.abc import Callable, Sequence
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
WIRINGS = ("readme-rosbot", "no-mount-rosbot", "hokuyo-rep117", "hokuyo")
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
        spurious_slack: ``slack`` results with no recorded point within :data:`NEAR` of the laser.
        mean_speed: mean commanded forward speed [m/s].
    """

    wiring: str
    velocity: str
    speed: float
    statuses: dict[str, int]
    spurious_slack: int
    mean_speed: float

    @property
    def slack(self) -> int:
        """Number of scans answered with ``slack``."""
        return self.statuses.get("slack", 0)


def wired(wiring: str) -> tuple[RobotSpec, Callable[[LaserScan], LaserScan]]:
    """The robot of ``wiring`` and what it does to a scan read as the bag's message before the filter sees it."""
    if wiring == "readme-rosbot":
        rosbot = preset("rosbot")
        return rosbot, lambda scan: scan.with_mount(rosbot.lidar.mount)
    if wiring == "no-mount-rosbot":
        return preset("rosbot"), lambda scan: scan
    robot = HOKUYO_ROBOT
    if wiring == "hokuyo-rep117":
        robot = HOKUYO_ROBOT.replace(lidar=dataclasses.replace(HOKUYO, no_return=None))
    return robot, robot.match_scan


def replay(scans: Sequence[LaserScan], wiring: str, velocity: str, speed: float) -> Replay:
    """Every scan through a fresh CBF filter with the nominal command ``(speed, 0)``."""
    statuses: collections.Counter[str] = collections.Counter()
    spurious = 0
    commanded = []
    robot, prepare = wired(wiring)
    safety = CBFSafetyFilter(robot, dt=DT)
    current = np.array([speed, 0.0])
    for message_scan in scans:
        result = safety.filter((speed, 0.0), prepare(message_scan), velocity=current)
        statuses[result.status.value] += 1
        commanded.append(float(result.u[0]))
        if result.status.value == "slack" and _nearest_point(message_scan) > NEAR:
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
        preset("rosbot").match_scan(scans[0])
    except LidarMismatch as error:
        print(f"preset('rosbot').match_scan(scan) -> LidarMismatch: {error}\n")
    rows = [replay(scans, wiring, velocity, speed) for velocity in VELOCITIES for wiring in WIRINGS
            for speed in SPEEDS]
    print(f"{len(scans)} scans, CBF filter, dt = {DT} s, nominal (speed, 0)\n")
    print("| velocity | wiring | speed [m/s] | ok | recovering | slack | spurious slack | other | mean v [m/s] |")
    print("|---|---|---|---|---|---|---|---|---|")
    for row in rows:
        other = sum(count for status, count in row.statuses.items() if status not in ("ok", "recovering", "slack"))
        print(f"| {row.velocity} | {row.wiring} | {row.speed:.1f} | {row.statuses.get('ok', 0)} | "
              f"{row.statuses.get('recovering', 0)} | {row.slack} | {row.spurious_slack} | {other} | "
              f"{row.mean_speed:.3f} |")
    if args.json is not None:
        args.json.write_text(json.dumps([vars(row) for row in rows], indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
