"""Point clouds for the node tests: a wall ahead, as the fields of a ``sensor_msgs/PointCloud2``.

Shared by the middleware-free tests (``test_core.py``, fields on a ``SimpleNamespace``) and the
probe (``probe.py``, fields on a real rclpy or rospy message); no ROS import here.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: ``sensor_msgs/PointField.FLOAT32``.
FLOAT32 = 7
#: Where the cloud's sensor sits on the base [m, m, rad]: ahead of the ROSbot's lidar, facing forward.
CLOUD_MOUNT = (0.1, 0.0, 0.0)
#: The cloud sources' height band in the sensor frame [m]: the floor (0.25 m below) is out of it.
BAND = (-0.15, 0.3)


def wall_points(distance: float | None) -> np.ndarray:
    """``(N, 3)`` points [m] in the sensor frame (:data:`CLOUD_MOUNT`): a wall ``distance`` ahead of the base
    (``None``: no wall), 3 m wide, at three heights inside :data:`BAND`, and floor points everywhere
    (below the band, so a correct flattening ignores them; nearer than the wall, so a wrong one brakes).
    """
    y = np.arange(-1.5, 1.5001, 0.01)
    floor_x, floor_y = np.meshgrid(np.arange(0.2, 2.0, 0.05), np.arange(-1.0, 1.0001, 0.05))
    layers = [np.column_stack((floor_x.ravel(), floor_y.ravel(), np.full(floor_x.size, -0.25)))]
    if distance is not None:
        layers += [np.column_stack((np.full(y.size, distance - CLOUD_MOUNT[0]), y, np.full(y.size, z)))
                   for z in (-0.1, 0.0, 0.2)]
    return np.vstack(layers)


def cloud_fields(points: np.ndarray, frame_id: str = "camera") -> dict[str, Any]:
    """The ``PointCloud2`` fields of ``points`` (x, y, z as little-endian float32; an unordered cloud).

    ``fields`` holds ``(name, offset, datatype, count)`` tuples and ``data`` bytes: the caller
    makes ``PointField`` messages of the first and its client's byte container of the second.
    """
    xyz = np.ascontiguousarray(points, dtype="<f4")
    return {"frame_id": frame_id, "height": 1, "width": len(xyz), "is_bigendian": False, "point_step": 12,
            "row_step": 12 * len(xyz), "is_dense": True, "data": xyz.tobytes(),
            "fields": [(name, 4 * i, FLOAT32, 1) for i, name in enumerate("xyz")]}


def cloud_parameters(name: str, *, full_turn: bool) -> dict[str, Any]:
    """Node parameters of a ``pointcloud`` source ``name`` on :data:`CLOUD_MOUNT` with :data:`BAND`.

    ``full_turn``: a 3D lidar (every bearing, an empty bin is free); otherwise a depth camera
    (a 1.5 rad field of view, an empty bin is unknown).
    """
    fov = {"angle_min": -3.14159, "angle_max": 3.14159, "empty": "no_return"} if full_turn else \
        {"angle_min": -0.75, "angle_max": 0.75, "empty": "invalid"}
    return {f"{name}.{key}": value for key, value in {
        "type": "pointcloud", "mount": list(CLOUD_MOUNT), "z_min": BAND[0], "z_max": BAND[1], "range_max": 8.0,
        **fov}.items()}
