"""safenav: optimisation-based safety filters that keep lidar-driven mobile robots from hitting things.

A nominal policy maps a :class:`~safenav.scan.LaserScan` to a command ``(v, omega)``;
a safety filter (:mod:`safenav.filters`) changes that command as little as possible
so that the robot keeps its clearance, and says what it did.
"""

from safenav.errors import (
    InvalidCommand,
    InvalidCommandType,
    InvalidConfig,
    InvalidScan,
    InvalidScanType,
    LidarMismatch,
    LidarMismatchWarning,
    MissingDependency,
    SafeNavError,
    SafeNavWarning,
    SimulatorError,
    UnknownName,
)
from safenav.geometry import Pose2D, unicycle_rollout, unicycle_step, wrap_angle
from safenav.pointcloud import CloudSlice
from safenav.robot import PRESET_NAMES, Command, LidarSpec, RobotSpec, as_command, preset
from safenav.scan import LaserScan, Reading, SectorReading, SectorState, stamp_seconds

__version__ = "0.1.0"

__all__ = [
    "PRESET_NAMES",
    "CloudSlice",
    "Command",
    "InvalidCommand",
    "InvalidCommandType",
    "InvalidConfig",
    "InvalidScan",
    "InvalidScanType",
    "LaserScan",
    "LidarMismatch",
    "LidarMismatchWarning",
    "LidarSpec",
    "MissingDependency",
    "Pose2D",
    "Reading",
    "RobotSpec",
    "SafeNavError",
    "SafeNavWarning",
    "SectorReading",
    "SectorState",
    "SimulatorError",
    "UnknownName",
    "as_command",
    "preset",
    "stamp_seconds",
    "unicycle_rollout",
    "unicycle_step",
    "wrap_angle",
]
