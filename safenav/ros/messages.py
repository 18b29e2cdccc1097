"""Filling and reading ROS messages, the same way on rospy and rclpy.

``sensor_msgs/LaserScan``, ``nav_msgs/Odometry``, ``geometry_msgs/Twist`` and
``visualization_msgs/Marker`` have the same fields in ROS 1 and ROS 2; only headers' stamps
and ``diagnostic_msgs/DiagnosticStatus.level`` differ, and the transports set those.
"""

from __future__ import annotations

import array
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from safenav.geometry import Pose2D
from safenav.scan import LaserScan

__all__ = ["fill_markers", "fill_odometry", "fill_scan", "fill_twist", "pose_of", "twist_of"]


def twist_of(msg: Any) -> tuple[float, float]:
    """``(linear.x [m/s], angular.z [rad/s])`` of a Twist-like message (values may be non-finite).

    Raises:
        AttributeError, TypeError, ValueError: the message has no such fields.
    """
    return float(msg.linear.x), float(msg.angular.z)


def fill_twist(msg: Any, u: Sequence[float]) -> Any:
    """Set ``linear.x`` and ``angular.z`` of a Twist message to ``u = (v [m/s], omega [rad/s])``."""
    msg.linear.x = float(u[0])
    msg.angular.z = float(u[1])
    return msg


def fill_scan(msg: Any, scan: LaserScan, frame_id: str) -> Any:
    """Copy a :class:`~safenav.scan.LaserScan`'s fields into a ``sensor_msgs/LaserScan`` message."""
    msg.header.frame_id = frame_id
    for name in ("angle_min", "angle_max", "angle_increment", "time_increment", "scan_time", "range_min",
                 "range_max"):
        setattr(msg, name, float(getattr(scan, name)))
    msg.ranges = array.array("f", scan.ranges)
    msg.intensities = array.array("f", scan.intensities)
    return msg


def fill_odometry(msg: Any, pose: Pose2D, velocity: Sequence[float], *, frame_id: str = "odom",
                  child_frame_id: str = "base_link") -> Any:
    """Set a ``nav_msgs/Odometry`` message's pose [m, rad] and body-frame twist [m/s, rad/s]."""
    msg.header.frame_id = frame_id
    msg.child_frame_id = child_frame_id
    msg.pose.pose.position.x = float(pose.x)
    msg.pose.pose.position.y = float(pose.y)
    msg.pose.pose.orientation.z = math.sin(0.5 * pose.yaw)
    msg.pose.pose.orientation.w = math.cos(0.5 * pose.yaw)
    fill_twist(msg.twist.twist, velocity)
    return msg


def pose_of(msg: Any) -> Pose2D:
    """The planar pose [m, m, rad] of a ``nav_msgs/Odometry`` message."""
    pose = msg.pose.pose
    q = pose.orientation
    yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
    return Pose2D(float(pose.position.x), float(pose.position.y), yaw)


#: Marker colours (r, g, b, a): the body outline, every constraint point, the active ones.
_FOOTPRINT_RGBA = (0.1, 0.6, 0.1, 1.0)
_POINT_RGBA = (0.6, 0.6, 0.6, 0.8)
_ACTIVE_RGBA = (0.9, 0.1, 0.1, 1.0)


def fill_markers(markers: Any, marker_type: type, point_type: type, *, frame_id: str, stamp: Any,
                 footprint: np.ndarray, points: np.ndarray, active: np.ndarray) -> Any:
    """Fill a ``visualization_msgs/MarkerArray``: the body outline and the filter's constraint points.

    Args:
        markers: the ``MarkerArray`` message to fill.
        marker_type: the ``visualization_msgs/Marker`` class.
        point_type: the ``geometry_msgs/Point`` class.
        frame_id: the base frame.
        stamp: the header stamp (the transport's time type).
        footprint: ``(n, 2)`` outline vertices [m], closed by the marker.
        points: ``(m, 2)`` constraint points [m].
        active: ``(k, 2)`` active constraint points [m].
    """
    outline = np.vstack((footprint, footprint[:1]))
    shapes = ((marker_type.LINE_STRIP, outline, _FOOTPRINT_RGBA, 0.01, "footprint"),
              (marker_type.POINTS, points, _POINT_RGBA, 0.03, "constraint points"),
              (marker_type.POINTS, active, _ACTIVE_RGBA, 0.06, "active constraint points"))
    markers.markers = []
    for marker_id, (kind, xy, rgba, size, namespace) in enumerate(shapes):
        marker = marker_type()
        marker.header.frame_id = frame_id
        marker.header.stamp = stamp
        marker.ns = namespace
        marker.id = marker_id
        marker.type = kind
        marker.action = marker_type.ADD
        marker.pose.orientation.w = 1.0
        marker.scale.x = marker.scale.y = size
        marker.color.r, marker.color.g, marker.color.b, marker.color.a = rgba
        marker.points = [_point(point_type, x, y) for x, y in np.asarray(xy, dtype=float).reshape(-1, 2)]
        markers.markers.append(marker)
    return markers


def _point(point_type: type, x: float, y: float) -> Any:
    point = point_type()
    point.x, point.y = float(x), float(y)
    return point
