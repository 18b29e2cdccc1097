"""Safety filters: they sit between a nominal policy and the wheels and keep the robot's clearance."""

from safenav.filters.base import BRAKING_STATUSES, FilterResult, FilterStatus, SafetyFilter

__all__ = ["BRAKING_STATUSES", "FilterResult", "FilterStatus", "SafetyFilter"]
