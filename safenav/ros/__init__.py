"""safenav on a robot: the safety filter as a ROS 2 or ROS 1 node.

============================  =================================================================
module                        what it holds
============================  =================================================================
:mod:`safenav.ros.params`     the parameter table and :class:`NodeConfig` (validated)
:mod:`safenav.ros.sources`    obstacle sources: LaserScan and PointCloud2 topics, by ``<source>.type``
:mod:`safenav.ros.core`       :class:`SafetyCore`: inputs, the timer step, state, diagnostics
:mod:`safenav.ros.apps`       the tutorial controllers and the PyBullet simulator as nodes
:mod:`safenav.ros.messages`   filling and reading messages, identical on rospy and rclpy
:mod:`safenav.ros.ros2`       the rclpy transport: ``safenav-ros2`` (``pip install "safenav[ros2]"``)
:mod:`safenav.ros.ros1`       the rospy transport: ``safenav-ros1`` (Debian: ``ros-core``, ``python3-rospy``)
============================  =================================================================

Importing this package imports no ROS: only the two transports do.
"""

from safenav.ros.core import NodeState, SafetyCore
from safenav.ros.params import PARAMETERS, NodeConfig, SourceConfig
from safenav.ros.sources import SOURCE_TYPES, PointCloudSource, ScanSource, Source

__all__ = ["PARAMETERS", "SOURCE_TYPES", "NodeConfig", "NodeState", "PointCloudSource", "SafetyCore", "ScanSource",
           "Source", "SourceConfig"]
