"""The contract every safety filter meets, as a check users can run on their own filters.

Like Gymnasium's ``check_env``: give :func:`check_filter` a factory that builds your filter
for a robot and a period, and it exercises the filter the way safenav's loop, the ROS node and
the Gymnasium shield use it::

    from safenav.filters import check_filter, CBFSafetyFilter
    check_filter(lambda robot, dt: CBFSafetyFilter(robot, dt))

It raises :class:`FilterContractError` listing every clause that failed, and returns the
clauses checked otherwise. The clauses:

1. **Types.** ``filter()`` returns a :class:`~safenav.filters.FilterResult` whose ``status``
   is a :class:`~safenav.filters.FilterStatus`, and ``explain()`` is a non-empty line naming it.
2. **Finite and within the limits.** On every scan of a battery (free space, walls, clutter,
   a robot inside the margin) and every nominal (including ones beyond the limits), ``u`` is
   finite and inside the velocity limits, and, with ``velocity`` given, reachable within one
   period under the acceleration limits.
3. **Minimal intervention when safe.** In free space, with the base already moving as asked
   (``velocity = u_nom``) towards a side some lidar sees, ``u`` is ``u_nom`` bit for bit, with
   status ``OK`` and no reason.
4. **It says why.** Whenever ``u`` differs from ``u_nom`` or the status is not ``OK``, the
   result carries a :class:`~safenav.filters.Reason` and a non-empty message.
5. **Hostile input.** Readings of NaN, +-inf and out-of-range values never give NaN; a scan
   with no informative beam brakes with ``NO_DATA``; a non-finite nominal brakes with
   ``BAD_INPUT``; a stale scan brakes with ``STALE``; braking statuses report ``braked``.
6. **Structural mistakes raise** an error that is both a ``SafeNavError`` and the matching
   built-in, and survives pickling (it can cross a process boundary).
7. **Reset.** After ``reset()`` the same inputs give the same command.
"""

from __future__ import annotations

import math
import pickle
from collections.abc import Callable, Sequence

import numpy as np

from safenav.errors import InvalidCommand, SafeNavError
from safenav.filters.base import BRAKING_STATUSES, FilterResult, FilterStatus, SafetyFilter
from safenav.robot import RobotSpec, preset
from safenav.scan import LaserScan

__all__ = ["FilterContractError", "check_filter"]

FilterFactory = Callable[[RobotSpec, float], SafetyFilter]


class FilterContractError(SafeNavError, AssertionError):
    """A filter broke its contract; the message lists the failed clauses (all of them in :attr:`failures`)."""

    def __init__(self, failures: Sequence[str]) -> None:
        self.failures = tuple(failures)
        shown = "\n  ".join(self.failures[:30])
        more = f"\n  ... and {len(self.failures) - 30} more" if len(self.failures) > 30 else ""
        super().__init__(f"{len(self.failures)} contract clauses failed:\n  {shown}{more}")

    def __reduce__(self) -> tuple[type, tuple[tuple[str, ...]]]:
        return type(self), (self.failures,)


def _scans(robot: RobotSpec) -> dict[str, LaserScan]:
    """A battery of scans: free space, walls, clutter, a robot inside its margin, hostile readings."""
    template = robot.scan()
    n = template.n_beams
    directions = template.base_angles
    rng = np.random.default_rng(0)
    wall_ahead = np.where(np.cos(directions) > 0.2, (robot.radius + 0.3) / np.maximum(np.cos(directions), 0.2),
                          math.inf)
    hostile = rng.uniform(0.0, 2.0 * template.range_max, n)
    hostile[rng.random(n) < 0.2] = math.nan
    hostile[rng.random(n) < 0.1] = math.inf
    hostile[rng.random(n) < 0.05] = -math.inf
    scans = {
        "free space": template,
        "wall ahead": template.with_ranges(np.minimum(wall_ahead, template.range_max * 2)),
        "clutter": template.with_ranges(rng.uniform(robot.radius + 0.05, 3.0, n)),
        "inside the margin": template.with_ranges(np.full(n, robot.radius + 0.005)),
        "hostile readings": template.with_ranges(hostile),
    }
    return {name: scan.with_ranges(np.where(np.isfinite(scan.ranges) & (scan.ranges > scan.range_max), math.inf,
                                            scan.ranges)) if name != "hostile readings" else scan
            for name, scan in scans.items()}


def _nominals(robot: RobotSpec) -> list[np.ndarray]:
    return [np.array(value, dtype=float) for value in (
        (0.0, 0.0), (robot.v_max, 0.0), (robot.v_min, 0.0), (0.5 * robot.v_max, robot.omega_max),
        (1.5 * robot.v_max, -1.5 * robot.omega_max))]


def check_filter(make: FilterFactory, robots: Sequence[RobotSpec] | None = None, dt: float = 0.05) -> list[str]:
    """Check that the filters ``make(robot, dt)`` builds meet the contract (see the module docstring).

    Args:
        make: builds a fresh filter for a robot and a control period.
        robots: the robots to try (default: the three presets).
        dt: the control period [s].

    Returns:
        The clauses checked (one line each).

    Raises:
        FilterContractError: some clause failed; the message lists every failure.
    """
    robots = list(robots) if robots is not None else [preset(name) for name in ("rosbot", "puzzlebot", "m2wr")]
    failures: list[str] = []
    checked: list[str] = []

    def expect(condition: bool, clause: str) -> None:
        if not condition:
            failures.append(clause)

    for robot in robots:
        label = robot.name
        safety = make(robot, dt)
        rear_seen = any(lidar.scan().covers(math.pi) for lidar in getattr(robot, "lidars", (robot.lidar,)))
        for scan_name, scan in _scans(robot).items():
            for velocity in (None, np.zeros(2), np.array([0.5 * robot.v_max, 0.5 * robot.omega_max])):
                for u_nom in _nominals(robot):
                    safety.reset()
                    result = safety.filter(u_nom, scan, velocity=velocity)
                    where = f"{label}, {scan_name}, u_nom={u_nom.tolist()}, velocity={velocity}"
                    expect(isinstance(result, FilterResult) and isinstance(result.status, FilterStatus),
                           f"1 types: {where}: not a FilterResult with a FilterStatus")
                    expect(isinstance(result.explain(), str) and result.status.value in result.explain(),
                           f"1 types: {where}: explain() does not name the status")
                    u = np.asarray(result.u, dtype=float)
                    expect(bool(np.all(np.isfinite(u))), f"2 finite: {where}: u={u.tolist()}")
                    lower, upper = robot.velocity_bounds(velocity, dt if velocity is not None else None)
                    expect(bool(np.all(u >= lower - 1e-9) and np.all(u <= upper + 1e-9)),
                           f"2 limits: {where}: u={u.tolist()} outside {lower.tolist()}..{upper.tolist()}")
                    if not np.array_equal(u, u_nom) or result.status is not FilterStatus.OK:
                        expect(result.reason is not None and bool(result.message),
                               f"4 says why: {where}: status {result.status.value}, u={u.tolist()} without a reason")
                    if result.status in BRAKING_STATUSES:
                        expect(result.braked, f"5 braked: {where}: status {result.status.value} not braked")
        for u_nom in _nominals(robot):
            inside = bool(np.all(u_nom >= robot.lower) and np.all(u_nom <= robot.upper))
            if not inside or (u_nom[0] < 0.0 and not rear_seen):
                continue
            safety.reset()
            result = safety.filter(u_nom, _scans(robot)["free space"], velocity=u_nom)
            expect(np.array_equal(result.u, u_nom) and result.status is FilterStatus.OK and result.reason is None,
                   f"3 minimal: {label}, free space, u_nom={u_nom.tolist()}: gave u={result.u.tolist()}, "
                   f"{result.status.value}")
        blind = robot.scan(np.full(robot.lidar.n_beams, math.nan))
        safety.reset()
        expect(safety.filter((0.1, 0.0), blind).status is FilterStatus.NO_DATA, f"5 no data: {label}")
        safety.reset()
        expect(safety.filter((math.nan, 0.0), robot.scan()).status is FilterStatus.BAD_INPUT, f"5 bad input: {label}")
        safety.reset()
        stale = safety.filter((0.1, 0.0), robot.scan(), scan_age=10.0)
        expect(stale.status is FilterStatus.STALE and stale.braked, f"5 stale: {label}")
        safety.reset()
        try:
            safety.filter((0.1, 0.2, 0.3), robot.scan())
            failures.append(f"6 raises: {label}: a u_nom of three numbers was accepted")
        except InvalidCommand as error:
            expect(isinstance(error, ValueError), f"6 raises: {label}: InvalidCommand is not a ValueError")
            again = pickle.loads(pickle.dumps(error))
            expect(type(again) is type(error) and str(again) == str(error), f"6 pickles: {label}")
        scan = _scans(robot)["clutter"]
        safety.reset()
        first = safety.filter((0.5 * robot.v_max, 0.3), scan, velocity=(0.1, 0.0)).u
        safety.filter((robot.v_max, -robot.omega_max), scan, velocity=(0.3, 0.1))
        safety.reset()
        again = safety.filter((0.5 * robot.v_max, 0.3), scan, velocity=(0.1, 0.0)).u
        expect(np.array_equal(first, again), f"7 reset: {label}: {first.tolist()} then {again.tolist()}")
        checked.append(f"{label}: clauses 1-7 on {len(_scans(robot))} scans x 3 velocities x 5 nominals")
    if failures:
        raise FilterContractError(failures)
    return checked
