"""Obstacle sources: what turns one sensor message into something the filter reads.

A source subscribes to one topic of one message type and converts each message into a
:class:`~safenav.scan.LaserScan` carrying the sensor's mount pose on the base. The node
keeps the latest converted message per source, with its age, and brakes when any source is
stale. :data:`SOURCE_TYPES` maps a ``<source>.type`` parameter to its class:

==============  ============================  =======================================
type            message                       conversion
==============  ============================  =======================================
``scan``        ``sensor_msgs/LaserScan``     :meth:`LaserScan.from_msg <safenav.scan.LaserScan.from_msg>`
``pointcloud``  ``sensor_msgs/PointCloud2``   :func:`safenav.pointcloud.scan_from_cloud` with the
                                              source's :attr:`~safenav.ros.params.SourceConfig.lidar`
==============  ============================  =======================================

Either way the result is a scan on the source's mount whose ``frame_id`` is the source's name,
so the node's robot holds one lidar per source and the filter merges them like several lidars.
Transports look a source's message class up by :attr:`Source.message`, so a new type is one
subclass here and one row of the table.
"""

from __future__ import annotations

import abc
from collections.abc import Mapping
from types import MappingProxyType, SimpleNamespace
from typing import TYPE_CHECKING, Any

from safenav.errors import InvalidConfig
from safenav.pointcloud import scan_from_cloud
from safenav.scan import LaserScan

if TYPE_CHECKING:
    from safenav.ros.params import SourceConfig

__all__ = ["SOURCE_TYPES", "PointCloudSource", "ScanSource", "Source"]


class Source(abc.ABC):
    """One obstacle source (a topic of one sensor), converting its messages for the filter.

    Args:
        config: the source's topic, mount pose and timeout.
    """

    message: tuple[str, str]
    """ROS package and message name the source subscribes to, e.g. ``("sensor_msgs", "LaserScan")``."""

    cloud: bool = False
    """The messages are point clouds: the sensor is described by :attr:`SourceConfig.lidar
    <safenav.ros.params.SourceConfig.lidar>` (field of view, ranges, height band), not by the message."""

    def __init__(self, config: SourceConfig) -> None:
        self.config = config
        self._views: dict[type, type[_Renamed]] = {}

    def renamed(self, msg: Any) -> Any:
        """``msg`` seen with ``header.frame_id`` set to the source's name (its stamp and data kept, not copied).

        The view's type has the message type's name, so a conversion error still names the
        message (``message PointCloud2 has no field 'height'``).
        """
        kind = type(msg)
        view = self._views.get(kind)
        if view is None:
            view = self._views[kind] = type(kind.__name__, (_Renamed,), {})
        return view(msg, self.config.name)

    @abc.abstractmethod
    def convert(self, msg: Any) -> LaserScan:
        """The message as a scan in the sensor frame, with the source's mount.

        Raises:
            InvalidScan: the message is malformed (the error names the field).
        """


class ScanSource(Source):
    """A ``sensor_msgs/LaserScan`` topic (REP-117 readings; the mount from the parameters).

    The scan's ``frame_id`` is the source's name: the node's robot describes each source as
    the lidar of that frame (:meth:`safenav.robot.RobotSpec.match_scan`).
    """

    message = ("sensor_msgs", "LaserScan")

    def convert(self, msg: Any) -> LaserScan:
        return LaserScan.from_msg(self.renamed(msg), mount=self.config.mount)


class PointCloudSource(Source):
    """A ``sensor_msgs/PointCloud2`` topic (a depth camera or a 3D lidar) flattened to a planar scan.

    The points in the source's height band are binned by bearing over its field of view; each
    beam reads its nearest point (:mod:`safenav.pointcloud`). Like a scan source's, the result's
    ``frame_id`` is the source's name and its mount the source's.
    """

    message = ("sensor_msgs", "PointCloud2")
    cloud = True

    def __init__(self, config: SourceConfig) -> None:
        super().__init__(config)
        if config.lidar is None or config.lidar.cloud is None:
            raise InvalidConfig(f"pointcloud source {config.name!r} needs SourceConfig.lidar with a CloudSlice, "
                                f"got {config.lidar!r}")
        self.lidar = config.lidar

    def convert(self, msg: Any) -> LaserScan:
        return scan_from_cloud(self.renamed(msg), self.lidar)


class _Renamed:
    """``msg`` seen with ``header.frame_id`` replaced, its stamp and data kept (:meth:`Source.renamed`)."""

    def __init__(self, msg: Any, frame_id: str) -> None:
        self._msg = msg
        header = getattr(msg, "header", None)
        self.header = SimpleNamespace(stamp=getattr(header, "stamp", None), frame_id=frame_id)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._msg, name)


SOURCE_TYPES: Mapping[str, type[Source]] = MappingProxyType({"scan": ScanSource, "pointcloud": PointCloudSource})
"""Source classes by the ``<source>.type`` parameter."""
