"""Your own robot: a :class:`RobotSpec` and :class:`LidarSpec` for a base that is not a preset.

The robot here is shaped like a TurtleBot3 Burger with its LDS-01 lidar (numbers from its
public description; the acceleration limits are assumptions: measure your base's). Copy the
lidar's layout from one message of your driver (``rostopic echo -n 1 /scan`` or
``ros2 topic echo --once /scan``), and its mount from your URDF (``base_link`` -> laser frame).

Run it: ``python examples/your_own_robot.py``.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

from safenav import LaserScan, LidarMismatch, LidarSpec, Pose2D, RobotSpec, preset
from safenav.filters import CBFSafetyFilter

lidar = LidarSpec(
    n_beams=360,                       # len(msg.ranges)
    angle_min=0.0,                     # msg.angle_min [rad]
    angle_max=math.radians(359.0),     # the last beam: angle_min + (n_beams - 1) * angle_increment [rad]
    range_min=0.12,                    # msg.range_min [m]
    range_max=3.5,                     # msg.range_max [m]
    mount=Pose2D(-0.032, 0.0, 0.0),    # base_link -> base_scan in the URDF: x [m], y [m], yaw [rad]
    scan_time=0.2,                     # 5 Hz
    frame_id="base_scan",              # msg.header.frame_id
    no_return="zero",                  # the driver reports 0.0 when nothing returns: read it as +inf
)
robot = RobotSpec(
    name="turtlebot3_burger",
    radius=0.15,                       # a disk around base_link that holds the whole footprint [m]
    footprint=((0.041, 0.105), (-0.105, 0.105), (-0.105, -0.105), (0.041, -0.105)),
    v_max=0.22, v_min=-0.22,           # [m/s]
    omega_max=2.84,                    # [rad/s]
    a_max=1.0, alpha_max=3.0,          # what the motors can do [m/s^2, rad/s^2] (assumed here)
    lidar=lidar,
)
safety = CBFSafetyFilter(robot, dt=lidar.scan_time)   # filtering in the scan callback: dt = the scan period


def on_scan(msg, odometry_twist, u_nom):
    scan = robot.match_scan(LaserScan.from_msg(msg))  # checks the layout, puts the scan on the lidar's mount
    result = safety.filter(u_nom, scan, velocity=odometry_twist)
    return result


def lds01_message(wall_distance: float) -> SimpleNamespace:
    """A message like the LDS-01 driver's: a wall ``wall_distance`` [m] ahead of base_link, 0.0 elsewhere."""
    ranges = [0.0] * 360
    for beam in range(-30, 31):                        # beams within 30 degrees of straight ahead
        ranges[beam % 360] = (wall_distance - lidar.mount.x) / math.cos(math.radians(beam))
    header = SimpleNamespace(stamp=SimpleNamespace(sec=1_700_000_000, nanosec=0), frame_id="base_scan")
    return SimpleNamespace(header=header, angle_min=0.0, angle_max=math.radians(359.0),
                           angle_increment=math.radians(1.0), time_increment=0.0, scan_time=0.2, range_min=0.12,
                           range_max=3.5, ranges=ranges, intensities=[])


if __name__ == "__main__":
    for distance in (2.0, 0.45):
        result = on_scan(lds01_message(distance), (0.2, 0.0), (0.22, 0.0))
        print(f"wall {distance:.2f} m ahead: u = ({result.u[0]:.3f} m/s, {result.u[1]:.3f} rad/s), "
              f"status {result.status.value}")
    try:
        preset("rosbot").match_scan(LaserScan.from_msg(lds01_message(2.0)))
    except LidarMismatch as error:
        print(f"the same scan given to the ROSbot preset: LidarMismatch: {error}")
