"""Safety filters: they sit between a nominal policy and the wheels and keep the robot's clearance.

=============  ==========================================================================
name           filter
=============  ==========================================================================
``cbf``        :class:`CBFSafetyFilter`: control-barrier-function QP from lidar points
``mpc``        :class:`MPCSafetyFilter`: predictive, braking-safe plan (casadi)
``zones``      :class:`ZonesFilter`: stop/slowdown polygons, like ROS 2's collision monitor
``none``       no filter (``make_filter`` returns ``None``)
``*+escape``   the filter wrapped in :class:`~safenav.filters.escape.Escape` (deadlock escape),
               with :data:`ESCAPE_PRESETS` (the MPC then tracks the CBF's answer)
=============  ==========================================================================

One concept per module: ``base`` (the call template, results, statuses and reasons),
``defaults`` (settings derived from the robot), ``body`` (disk or footprint cover),
``perception`` (points, unknown region, memory), ``rows`` (constraint families), ``qp``
(QP back-ends), ``deadline`` (a call's compute budget), ``cbf``, ``mpc/`` (config, plan model, NLP,
filter), ``zones``, ``contract`` (:func:`check_filter`, the contract every filter meets).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from types import MappingProxyType
from typing import Any

from safenav import _checks
from safenav.filters.base import BRAKING_STATUSES, FilterResult, FilterStatus, Reason, SafetyFilter
from safenav.filters.body import BodyModel
from safenav.filters.cbf import CBFConfig, CBFSafetyFilter
from safenav.filters.contract import FilterContractError, check_filter
from safenav.filters.defaults import default_margin
from safenav.filters.escape import Escape, EscapeConfig
from safenav.filters.mpc import MPCConfig, MPCSafetyFilter
from safenav.filters.qp import available_solvers
from safenav.filters.zones import ZonesConfig, ZonesFilter
from safenav.robot import RobotSpec

__all__ = [
    "BRAKING_STATUSES",
    "ESCAPE_PRESETS",
    "ESCAPE_SUFFIX",
    "FILTERS",
    "FILTER_NAMES",
    "BodyModel",
    "CBFConfig",
    "CBFSafetyFilter",
    "Escape",
    "EscapeConfig",
    "FilterContractError",
    "FilterResult",
    "FilterStatus",
    "MPCConfig",
    "MPCSafetyFilter",
    "Reason",
    "SafetyFilter",
    "ZonesConfig",
    "ZonesFilter",
    "available_solvers",
    "check_filter",
    "default_margin",
    "escaped",
    "filter_settings",
    "make_filter",
    "unescaped",
]

FILTERS: MappingProxyType[str, str | None] = MappingProxyType({
    "none": None,
    "zones": "safenav.filters.zones:ZonesFilter",
    "cbf": "safenav.filters.cbf:CBFSafetyFilter",
    "mpc": "safenav.filters.mpc:MPCSafetyFilter",
})
"""The one table of filters: name -> ``module:class`` (``None`` for no filter)."""

ESCAPE_SUFFIX = "+escape"
FILTER_NAMES = (*FILTERS, *(f"{name}{ESCAPE_SUFFIX}" for name, target in FILTERS.items() if target is not None))
"""Names :func:`make_filter` accepts: every filter, and every filter with the deadlock escape."""

ESCAPE_PRESETS: MappingProxyType[str, MappingProxyType[str, Any]] = MappingProxyType({
    "mpc": MappingProxyType({"reference": "cbf"}),
})
"""Settings a filter takes inside the escape (``"<name>+escape"``) unless the caller gives them.

The MPC's plan tracks the CBF's answer there (``reference="cbf"``): tracking the nominal, it brakes in
front of an obstacle the nominal aims at, and the escape starts where a steering filter would have
gone round; tracking the CBF, it steers round it as the CBF does, and keeps its own guarantee (a
verified plan within the acceleration limits that ends stopped). BENCHMARKS.md, "The MPC + escape
tracks the CBF": goals through clutter 50 -> 58 of 60 (the m2wr's 14 -> 19 of 20). Each call then
includes a CBF call. Without the escape the MPC tracks the nominal: the CBF alone stands in front of
a door the MPC's braking plans drive through."""


def filter_settings(name: str, **given: Any) -> dict[str, Any]:
    """The settings the filter ``name`` is built with: ``given``, over :data:`ESCAPE_PRESETS` for
    ``"<filter>+escape"`` (``filter_settings("mpc+escape")`` is ``{"reference": "cbf"}``).

    Raises:
        UnknownName: ``name`` is not a filter (the message lists them).
    """
    _checks.choice("filter", name, FILTER_NAMES)
    preset = ESCAPE_PRESETS.get(unescaped(name), {}) if name.endswith(ESCAPE_SUFFIX) else {}
    return {**preset, **given}


def escaped(name: str) -> str:
    """The name of ``name`` wrapped in the deadlock escape: ``"mpc+escape"`` for ``"mpc"``; a name that
    carries the escape already, and ``"none"`` (no filter to wrap), as they are.

    Raises:
        UnknownName: ``name`` is not a filter (the message lists them).
    """
    _checks.choice("filter", name, FILTER_NAMES)
    return name if name.endswith(ESCAPE_SUFFIX) or FILTERS[name] is None else f"{name}{ESCAPE_SUFFIX}"


def unescaped(name: str) -> str:
    """The filter a name builds inside the escape: ``"mpc"`` for ``"mpc+escape"`` (and for ``"mpc"``)."""
    return name.removesuffix(ESCAPE_SUFFIX)


def filter_class(name: str) -> Callable[..., SafetyFilter] | None:
    """The class registered as ``name`` (``None`` for ``"none"``; the inner filter's for ``"<name>+escape"``).

    Raises:
        UnknownName: ``name`` is not a filter (the message lists them).
    """
    target = FILTERS[unescaped(_checks.choice("filter", name, FILTER_NAMES))]
    if target is None:
        return None
    module, _, attribute = target.partition(":")
    return getattr(importlib.import_module(module), attribute)


def make_filter(name: str, robot: RobotSpec, dt: float = 0.05, **kwargs: Any) -> SafetyFilter | Escape | None:
    """A safety filter by name (``None`` for ``"none"``).

    Args:
        name: one of :data:`FILTER_NAMES`; ``"<filter>+escape"`` wraps the filter in :class:`Escape`,
            with the settings of :data:`ESCAPE_PRESETS` unless ``kwargs`` gives them.
        robot: the robot to protect.
        dt: control period [s].
        **kwargs: the filter's settings (fields of its config class).

    Raises:
        UnknownName: ``name`` is not a filter (the message lists them).
    """
    cls = filter_class(name)
    if cls is None:
        return None
    safety = cls(robot, dt, **filter_settings(name, **kwargs))
    return Escape(safety) if name.endswith(ESCAPE_SUFFIX) else safety
