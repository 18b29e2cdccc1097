"""Safety filters: they sit between a nominal policy and the wheels and keep the robot's clearance.

=============  ==========================================================================
name           filter
=============  ==========================================================================
``cbf``        :class:`CBFSafetyFilter`: control-barrier-function QP from lidar points
``mpc``        :class:`~safenav.filters.mpc.MPCSafetyFilter`: predictive, braking-safe plan
``zones``      :class:`ZonesFilter`: stop/slowdown polygons, like ROS 2's collision monitor
``none``       no filter (``make_filter`` returns ``None``)
=============  ==========================================================================
"""

from __future__ import annotations

from typing import Any

from safenav.errors import UnknownName
from safenav.filters.base import BRAKING_STATUSES, FilterResult, FilterStatus, SafetyFilter
from safenav.filters.cbf import CBFConfig, CBFSafetyFilter
from safenav.filters.mpc import MPCConfig, MPCSafetyFilter
from safenav.filters.qp import available_solvers
from safenav.filters.reduction import default_margin
from safenav.filters.zones import ZonesConfig, ZonesFilter
from safenav.robot import RobotSpec

__all__ = [
    "BRAKING_STATUSES",
    "FILTER_NAMES",
    "CBFConfig",
    "CBFSafetyFilter",
    "FilterResult",
    "FilterStatus",
    "MPCConfig",
    "MPCSafetyFilter",
    "SafetyFilter",
    "ZonesConfig",
    "ZonesFilter",
    "available_solvers",
    "default_margin",
    "make_filter",
]

FILTER_NAMES = ("none", "zones", "cbf", "mpc")
"""Names :func:`make_filter` accepts."""


def make_filter(name: str, robot: RobotSpec, dt: float = 0.05, **kwargs: Any) -> SafetyFilter | None:
    """A safety filter by name (``None`` for ``"none"``).

    Args:
        name: one of :data:`FILTER_NAMES`.
        robot: the robot to protect.
        dt: control period [s].
        **kwargs: the filter's settings (fields of its config class).

    Raises:
        UnknownName: ``name`` is not a filter (the message lists them).
    """
    if name == "none":
        return None
    if name == "zones":
        return ZonesFilter(robot, dt, **kwargs)
    if name == "cbf":
        return CBFSafetyFilter(robot, dt, **kwargs)
    if name == "mpc":
        from safenav.filters.mpc import MPCSafetyFilter

        return MPCSafetyFilter(robot, dt, **kwargs)
    raise UnknownName("filter", name, FILTER_NAMES)
