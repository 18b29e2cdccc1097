"""What every nominal policy shares.

A nominal policy maps the latest :class:`~safenav.scan.LaserScan` (and, for
goal-seeking policies, the robot's pose) to a command ``(v [m/s], omega [rad/s])``.
It knows nothing about safety filters. It finds directions by angle through the
scan's mount pose, never by a fixed beam index, so it works with any lidar
convention.
"""

from __future__ import annotations

import abc

from safenav.geometry import Pose2D
from safenav.robot import Command
from safenav.scan import LaserScan

__all__ = ["Policy"]


class Policy(abc.ABC):
    """A nominal policy: ``policy(scan, pose) -> Command``.

    Subclasses implement :meth:`__call__` and, when they keep state, :meth:`reset`
    and :attr:`state`.
    """

    @abc.abstractmethod
    def __call__(self, scan: LaserScan, pose: Pose2D | None = None) -> Command:
        """The nominal command for this scan.

        Args:
            scan: the latest scan, in the robot's current base frame.
            pose: the robot's pose in the world (odometry) [m, m, rad]; only goal-seeking
                policies need it.
        """

    def reset(self, seed: int | None = None) -> None:
        """Forget internal state before a new episode; ``seed`` reseeds random policies."""

    @property
    def state(self) -> str:
        """Name of the internal state, for logging (e.g. the wall follower's ``"follow the wall"``)."""
        return ""
