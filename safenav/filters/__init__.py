"""Safety filters: they sit between a nominal policy and the wheels and keep the robot's clearance."""

from safenav.filters.base import BRAKING_STATUSES, FilterResult, FilterStatus, SafetyFilter
from safenav.filters.cbf import CBFConfig, CBFSafetyFilter
from safenav.filters.qp import available_solvers

__all__ = [
    "BRAKING_STATUSES",
    "CBFConfig",
    "CBFSafetyFilter",
    "FilterResult",
    "FilterStatus",
    "SafetyFilter",
    "available_solvers",
]
