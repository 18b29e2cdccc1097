"""``sensor_msgs/PointCloud2`` as a planar scan: depth cameras and 3D lidars for the filters, without ROS.

The filters read a :class:`~safenav.scan.LaserScan`. A point cloud becomes one in two steps:

1. :func:`read_points` parses any object with the ``PointCloud2`` attributes (``fields``
   of ``name``/``offset``/``datatype``/``count``, ``point_step``, ``row_step``, ``height``,
   ``width``, ``is_bigendian``, ``data``; rospy, rclpy and rosbags messages or a
   ``types.SimpleNamespace``) with numpy. Every malformed field raises
   :class:`~safenav.errors.InvalidScan` naming it.
2. :func:`flatten_points` keeps the points of a height band and bins them by bearing
   into the beams of a :class:`~safenav.robot.LidarSpec`; each beam reads the nearest point
   of its bin. :func:`scan_from_cloud` does both.

The lidar describes the result like any 2D lidar (``angle_min``/``angle_max``/``n_beams``:
the field of view kept; ``range_min``/``range_max``; the mount of the cloud's frame on the
base) plus a :class:`CloudSlice`: the height band and what an empty beam means. So a
robot's ``lidars`` can hold a depth camera or a 3D lidar next to its 2D lidars.

==========================================  ===========================================
points of a beam's bin (inside the band)    reading
==========================================  ===========================================
nearest planar range ``r`` in the window     ``r`` (``HIT``)
nearest closer than ``range_min``            ``-inf`` (``TOO_CLOSE``)
all beyond ``range_max``                     ``+inf`` (``NO_RETURN``): seen free up to it
none                                         ``CloudSlice.empty``: ``NaN`` (unknown, a depth
                                             camera's hole) or ``+inf`` (a 3D lidar's sky)
==========================================  ===========================================

Points with a NaN or infinite coordinate, and points exactly at the sensor origin
``(0, 0, 0)`` (the no-return marker of many lidar and depth drivers), are ignored.
Ranges are planar, ``hypot(x, y)`` in the sensor frame; beam ``i`` takes the bearings
within half an increment of ``angle_min + i * angle_increment``.
"""

from __future__ import annotations

import array
import math
from collections.abc import Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

from safenav._checks import boolean, choice, integer, number
from safenav.errors import InvalidConfig, InvalidScan, InvalidScanType
from safenav.geometry import TWO_PI
from safenav.scan import LaserScan, stamp_seconds

if TYPE_CHECKING:
    from safenav.robot import LidarSpec

__all__ = ["CLOUD_AXES", "EMPTY_BIN_READINGS", "POINT_FIELD_TYPES", "CloudSlice", "flatten_points", "read_points",
           "scan_from_cloud"]

#: ``sensor_msgs/PointField`` datatype codes -> numpy type codes (without byte order).
POINT_FIELD_TYPES = MappingProxyType({1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"})

#: What a beam whose bin holds no point reads: ``"invalid"`` (NaN) or ``"no_return"`` (``+inf``).
EMPTY_BIN_READINGS = ("invalid", "no_return")

#: Axis conventions of a cloud's frame: ``"rep103"`` (x forward, y left, z up) or ``"optical"``
#: (z forward, x right, y down: the ``*_optical_frame`` of cameras, REP-103's camera convention).
CLOUD_AXES = ("rep103", "optical")


@dataclass(frozen=True)
class CloudSlice:
    """How a point cloud becomes a planar scan: the height band kept and what an empty beam means.

    Heights are in the cloud's frame after turning it into REP-103 axes (z up): choose the band
    so that it holds every obstacle the body can hit and neither the floor nor overhangs the
    robot passes under. A tilted sensor is not levelled.

    Attributes:
        z_min: lowest point kept [m], sensor frame, z up.
        z_max: highest point kept [m].
        empty: reading of a beam with no point in its bin (:data:`EMPTY_BIN_READINGS`):
            ``"invalid"`` (unknown: a depth camera's hole may be a black or shiny obstacle) or
            ``"no_return"`` (free up to ``range_max``: a 3D lidar that returns every hit).
            No default: it decides whether a hole is driven into.
        axes: the cloud frame's axes (:data:`CLOUD_AXES`); ``"optical"`` clouds
            (z forward, x right, y down) are turned to x forward, y left, z up first.
    """

    z_min: float
    z_max: float
    empty: str
    axes: str = "rep103"

    def __post_init__(self) -> None:
        z_min = number("CloudSlice.z_min", self.z_min)
        z_max = number("CloudSlice.z_max", self.z_max)
        if z_max <= z_min:
            raise InvalidConfig(f"CloudSlice.z_max must be > z_min = {z_min!r}, got {self.z_max!r}")
        object.__setattr__(self, "z_min", z_min)
        object.__setattr__(self, "z_max", z_max)
        choice("CloudSlice.empty reading", self.empty, EMPTY_BIN_READINGS)
        choice("CloudSlice.axes convention", self.axes, CLOUD_AXES)


def scan_from_cloud(msg: Any, lidar: LidarSpec, *, stamp: Any = None) -> LaserScan:
    """A planar scan of ``lidar``'s layout from a ``PointCloud2``-like message.

    The scan carries the lidar's mount (given), ``header.stamp`` (or ``stamp``) and
    ``header.frame_id`` (else the lidar's), so :meth:`safenav.robot.RobotSpec.match_scan`
    can check it against the robot's lidar of that frame.

    Args:
        msg: the message-like object (see :func:`read_points`).
        lidar: the source's description; ``lidar.cloud`` says how to flatten it.
        stamp: acquisition time overriding the header (any form of
            :func:`~safenav.scan.stamp_seconds`).

    Raises:
        InvalidConfig: ``lidar.cloud`` is ``None`` (a 2D lidar's description).
        InvalidScan: a field of the message is missing or malformed (the message names it).
    """
    if lidar.cloud is None:
        raise InvalidConfig(
            f"lidar {lidar.frame_id!r} has no CloudSlice; describe a point-cloud source with "
            "LidarSpec(..., cloud=CloudSlice(z_min=..., z_max=..., empty=...))"
        )
    ranges = flatten_points(read_points(msg), lidar)
    header = getattr(msg, "header", None)
    if stamp is None and header is not None:
        stamp = getattr(header, "stamp", None)
    scan = lidar.scan(ranges, stamp=stamp_seconds(stamp, "header.stamp" if header is not None else "stamp"))
    frame_id = getattr(header, "frame_id", None)
    if isinstance(frame_id, str) and frame_id and frame_id != scan.frame_id:
        scan = scan.replace(frame_id=frame_id)
    return scan


def flatten_points(points: np.ndarray, lidar: LidarSpec) -> np.ndarray:
    """Ranges [m] of ``lidar``'s beams from ``(N, 3)`` points [m] in the cloud's frame.

    See the module docstring for the readings; ``lidar.cloud`` gives the band, the empty-bin
    reading and the axes.

    Raises:
        InvalidConfig: ``lidar.cloud`` is ``None``.
        InvalidScan: ``points`` is not an ``(N, 3)`` array of numbers.
    """
    cloud = lidar.cloud
    if cloud is None:
        raise InvalidConfig(f"lidar {lidar.frame_id!r} has no CloudSlice to flatten points with")
    xyz = np.asarray(points, dtype=float)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise InvalidScan(f"points must be an (N, 3) array of x, y, z [m], got shape {xyz.shape}")
    if cloud.axes == "optical":
        x, y, z = xyz[:, 2], -xyz[:, 0], -xyz[:, 1]
    else:
        x, y, z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    with np.errstate(invalid="ignore", over="ignore"):   # column by column: (N, 3) row reductions are slow
        usable = (np.isfinite(x + y + z) & ((x != 0.0) | (y != 0.0) | (z != 0.0))
                  & (z >= cloud.z_min) & (z <= cloud.z_max))
    x, y = x[usable], y[usable]
    increment = lidar.angle_increment
    offset = (np.arctan2(y, x) - lidar.angle_min + 0.5 * increment) % TWO_PI
    beam = np.floor(offset / increment).astype(np.intp)
    in_view = beam < lidar.n_beams
    nearest = np.full(lidar.n_beams, math.inf)
    np.minimum.at(nearest, beam[in_view], np.hypot(x[in_view], y[in_view]))
    seen = np.zeros(lidar.n_beams, dtype=bool)
    seen[beam[in_view]] = True
    ranges = np.where(seen, nearest, math.nan if cloud.empty == "invalid" else math.inf)
    ranges[seen & (nearest < lidar.range_min)] = -math.inf
    ranges[seen & (nearest > lidar.range_max)] = math.inf
    return ranges


def read_points(msg: Any, fields: Sequence[str] = ("x", "y", "z")) -> np.ndarray:
    """The values of ``fields`` of every point of a ``PointCloud2``-like message, ``(N, len(fields))`` floats.

    Rows are in the message's order (row by row, ``N = height * width``); NaN and infinite
    values are kept (:func:`flatten_points` drops them). Row padding (``row_step`` larger
    than ``width * point_step``) is skipped; a field with ``count > 1`` gives its first value.

    Args:
        msg: an object with ``fields``, ``point_step``, ``row_step``, ``height``, ``width``,
            ``is_bigendian`` and ``data`` (bytes, bytearray, ``array('B')``, a uint8 array or
            a sequence of byte values).
        fields: names of the fields to read.

    Raises:
        InvalidScan: a required attribute is missing, or a field, a size or ``data`` is
            malformed (the message names it and the value).
    """
    def attribute(name: str) -> Any:
        try:
            return getattr(msg, name)
        except AttributeError:
            raise InvalidScan(
                f"message {type(msg).__name__} has no field {name!r}; expected a sensor_msgs/PointCloud2-like object"
            ) from None

    height = integer("PointCloud2.height", attribute("height"), low=0, error=InvalidScan)
    width = integer("PointCloud2.width", attribute("width"), low=0, error=InvalidScan)
    point_step = integer("PointCloud2.point_step", attribute("point_step"), low=1, error=InvalidScan)
    row_step = integer("PointCloud2.row_step", attribute("row_step"), low=0, error=InvalidScan)
    big_endian = boolean("PointCloud2.is_bigendian", attribute("is_bigendian"), error=InvalidScan)
    layout = _field_layout(attribute("fields"), point_step)
    missing = [name for name in fields if name not in layout]
    if missing:
        raise InvalidScan(
            f"PointCloud2 has no field {missing[0]!r}; its fields are {', '.join(layout) or 'none'}"
        )
    if row_step < width * point_step:
        raise InvalidScan(
            f"PointCloud2.row_step={row_step} is less than width * point_step = {width} * {point_step}"
        )
    data = _bytes(attribute("data"))
    if data.size != height * row_step:
        raise InvalidScan(
            f"PointCloud2.data has {data.size} bytes; expected height * row_step = {height} * {row_step}"
        )
    order = ">" if big_endian else "<"
    dtype = np.dtype({
        "names": list(fields),
        "formats": [order + layout[name][1] for name in fields],
        "offsets": [layout[name][0] for name in fields],
        "itemsize": point_step,
    })
    rows = data.reshape(height, row_step)[:, :width * point_step]
    records = np.ascontiguousarray(rows).reshape(-1).view(dtype)
    return np.column_stack([records[name].astype(float) for name in fields]) if len(fields) else np.empty((0, 0))


def _field_layout(fields: Any, point_step: int) -> dict[str, tuple[int, str]]:
    """Field name -> (byte offset, numpy type code) of ``PointCloud2.fields``, every entry checked."""
    if isinstance(fields, (str, bytes)) or not isinstance(fields, Sequence):
        raise InvalidScanType(f"PointCloud2.fields must be a sequence of PointField, got {fields!r}")
    layout: dict[str, tuple[int, str]] = {}
    for position, field in enumerate(fields):
        where = f"PointCloud2.fields[{position}]"
        values = {}
        for name in ("name", "offset", "datatype", "count"):
            if not hasattr(field, name):
                raise InvalidScan(f"{where} has no {name!r}; expected a PointField (name, offset, datatype, count)")
            values[name] = getattr(field, name)
        label = values["name"]
        if not isinstance(label, str) or not label:
            raise InvalidScan(f"{where}.name must be a non-empty string, got {label!r}")
        where = f"PointCloud2 field {label!r}"
        offset = integer(f"{where} offset", values["offset"], low=0, error=InvalidScan)
        count = integer(f"{where} count", values["count"], low=1, error=InvalidScan)
        datatype = values["datatype"]
        if isinstance(datatype, bool) or datatype not in POINT_FIELD_TYPES:
            raise InvalidScan(
                f"{where} datatype={datatype!r}; expected a PointField code 1-8 (INT8 ... FLOAT64)"
            )
        code = POINT_FIELD_TYPES[datatype]
        end = offset + count * np.dtype(code).itemsize
        if end > point_step:
            raise InvalidScan(
                f"{where} offset={offset} with {count} x {np.dtype(code).itemsize} bytes ends at byte {end}, "
                f"beyond point_step={point_step}"
            )
        if label in layout:
            raise InvalidScan(f"{where} appears twice in PointCloud2.fields")
        layout[label] = (offset, code)
    return layout


def _bytes(data: Any) -> np.ndarray:
    """``PointCloud2.data`` as a 1-D uint8 array (no copy for bytes-like data)."""
    if isinstance(data, (bytes, bytearray, memoryview)):
        return np.frombuffer(data, dtype=np.uint8)
    if isinstance(data, array.array):
        if data.typecode not in ("B", "b"):
            raise InvalidScanType(f"PointCloud2.data must hold bytes, got array('{data.typecode}')")
        return np.frombuffer(data, dtype=np.uint8)
    if isinstance(data, np.ndarray) and data.dtype == np.uint8:
        return data.reshape(-1)
    if data is None or isinstance(data, str) or not isinstance(data, (Sequence, np.ndarray)):
        raise InvalidScanType(f"PointCloud2.data must be bytes or a sequence of byte values, got {type(data).__name__}")
    values = np.asarray(data)
    if values.ndim != 1 or values.dtype.kind not in "iu" or (values.size and (values.min() < 0 or values.max() > 255)):
        raise InvalidScanType(
            f"PointCloud2.data must be bytes or a sequence of byte values 0-255, got {values.dtype} "
            f"values of shape {values.shape}"
        )
    return values.astype(np.uint8)
