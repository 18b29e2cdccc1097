"""From a scan to what a filter constrains: obstacle points, unknown directions, point reduction.

Shared by the CBF and MPC filters:

* :func:`obstacle_points` gives every obstacle point of a scan in the base frame
  (REP-117: ``HIT`` at its range; ``TOO_CLOSE`` as close as it can be without having
  hit the body).
* :func:`blocked_motion` finds the directions the scan says nothing about (outside
  the field of view, or a run of invalid beams wider than ``max_gap``) and turns them
  into "no forward motion" / "no reverse motion", because unknown is never free.
* :func:`nearest_per_bin` keeps, per angular bin around a centre, the point with the
  smallest key: the working set the filters start from.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np

from safenav.geometry import TWO_PI
from safenav.robot import RobotSpec
from safenav.scan import LaserScan, Reading

__all__ = [
    "BlockedMotion",
    "blocked_motion",
    "body_clearance",
    "default_margin",
    "nearest_per_bin",
    "obstacle_beams",
    "obstacle_points",
    "unknown_arcs",
]


SAFETY_DISTANCE = 0.02
"""The part of the default margin that is a plain safety distance [m]."""


def default_margin(robot: RobotSpec) -> float:
    """The filters' default clearance margin for ``robot`` [m].

    ``0.02 m + 2 noise_std + 1 m x angle_increment``: a safety distance, twice the lidar's
    range noise, and the widest object that can hide between two beams 1 m away.
    """
    lidar = robot.lidar
    return SAFETY_DISTANCE + 2.0 * lidar.noise_std + 1.0 * lidar.angle_increment


def obstacle_beams(scan: LaserScan, body_radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Beams that give an obstacle point, and the range to put it at [m], for a body of ``body_radius``.

    ``HIT`` beams keep their range. A ``TOO_CLOSE`` beam (``-inf``) says an object is closer
    than ``range_min``, maybe touching the body: it is put where the beam leaves the body
    disk, or at ``range_min`` if that is nearer. A filter then sees the robot as inside its
    margin and backs out of the lidar's blind zone instead of trusting a clearance it cannot
    measure (a lidar whose ``range_min`` exceeds the body radius plus the margin cannot see
    the margin).
    """
    index, ranges = scan.obstacle_beams()
    too_close = scan.ranges[index] == -math.inf
    if too_close.any():
        geometry = scan.geometry
        mx, my = scan.mount.x, scan.mount.y
        cos, sin = geometry.cos_base[index[too_close]], geometry.sin_base[index[too_close]]
        along = mx * cos + my * sin
        inside = body_radius**2 - (mx * mx + my * my)
        if inside > 0.0:  # the laser is inside the body disk: every beam leaves it at one range
            exit_range = -along + np.sqrt(along**2 + inside)
            ranges[too_close] = np.minimum(ranges[too_close], exit_range)
    return index, ranges


def body_clearance(points: np.ndarray, body_radius: float) -> float:
    """Distance from the base origin to the nearest of ``points`` minus ``body_radius`` [m] (inf if none)."""
    return float(np.hypot(points[:, 0], points[:, 1]).min()) - body_radius if len(points) else math.inf


def obstacle_points(scan: LaserScan, body_radius: float) -> np.ndarray:
    """Obstacle points of ``scan`` in the base frame, ``(N, 2)`` [m], as :func:`obstacle_beams` places them."""
    return scan.beam_points(*obstacle_beams(scan, body_radius))


class BlockedMotion(NamedTuple):
    """Which motion directions an unseen part of the scan forbids."""

    forward: bool
    """An unknown direction lies within the forward cone: no ``v > 0``."""
    backward: bool
    """An unknown direction lies within the rear cone: no ``v < 0``."""
    arcs: tuple[tuple[float, float], ...]
    """The unknown arcs as ``(start, width)`` in the base frame [rad], counter-clockwise from ``start``."""


def _outside_arc(first_direction: float, angle_increment: float, n_beams: int,
                 max_gap: float) -> tuple[tuple[float, float], ...]:
    """The arc outside the field of view as an unknown arc, if it is wider than ``max_gap`` [rad]."""
    gap = max(0.0, TWO_PI - n_beams * angle_increment)
    return ((first_direction + (n_beams - 0.5) * angle_increment, gap),) if gap > max_gap else ()


def unknown_arcs(scan: LaserScan, max_gap: float) -> tuple[tuple[float, float], ...]:
    """Arcs of base-frame directions (seen from the laser) the scan says nothing about.

    An arc is unknown when it is outside the field of view, or when consecutive
    ``INVALID`` beams span more than ``max_gap`` [rad] (an object narrower than such a
    gap could hide there; smaller gaps are bridged by their neighbours, like the gap
    between any two beams). Each beam covers half an increment either side.

    Returns:
        ``(start, width)`` pairs [rad], ``start`` in the base frame, counter-clockwise.
    """
    increment = scan.angle_increment
    n = scan.n_beams
    yaw0 = scan.mount.yaw + scan.angle_min  # base-frame direction of beam 0
    if scan.n_informative == n:
        return _outside_arc(yaw0, increment, n, max_gap)
    gap = TWO_PI - scan.field_of_view
    informative = scan.readings != Reading.INVALID
    if not informative.any():
        return ((0.0, TWO_PI),)
    # Walk the circle starting at an informative beam, so no unknown run wraps around the start.
    first = int(np.argmax(informative))
    unknown = ~np.concatenate((informative[first:], informative[:first]))
    widths = np.full(n, increment)
    if gap > 0.0:
        # The uncovered arc sits between beam n-1 and beam 0: insert it there as one element.
        split = n - first
        unknown = np.insert(unknown, split, True)
        widths = np.insert(widths, split, gap)
    edges = np.diff(np.concatenate(([False], unknown, [False])).astype(np.int8))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    cumulative = np.concatenate(([0.0], np.cumsum(widths)))
    start_angle = yaw0 + (first - 0.5) * increment
    arcs = []
    for begin, end in zip(starts, stops, strict=True):
        width = cumulative[end] - cumulative[begin]
        if width > max_gap:
            arcs.append((float(start_angle + cumulative[begin]), float(width)))
    return tuple(arcs)


def _arc_meets_cone(start: float, width: float, centre: float, half_angle: float) -> bool:
    """Whether the arc ``[start, start + width]`` meets the open cone ``centre +- half_angle``."""
    offset = (start - (centre - half_angle)) % TWO_PI
    return offset < 2.0 * half_angle or offset + width > TWO_PI


def blocked_motion(scan: LaserScan, max_gap: float, side_tolerance: float) -> BlockedMotion:
    """Motion directions forbidden because the scan does not see where they lead.

    Forward motion moves the body towards every direction within 90 degrees of the
    heading; an unknown direction within ``90 deg - side_tolerance`` of the heading
    forbids it, and likewise for reverse. A 180-degree lidar facing forward therefore
    forbids reversing, and a 360-degree lidar with all beams informative forbids nothing.

    Args:
        scan: the scan.
        max_gap: widest run of invalid beams still bridged by its neighbours [rad].
        side_tolerance: directions this close to exactly sideways are ignored [rad].
    """
    if scan.n_informative == scan.n_beams:  # only the field of view matters: same answer for the layout
        return _blocked_by_layout(scan.mount.yaw + scan.angle_min, scan.angle_increment, scan.n_beams, max_gap,
                                  side_tolerance)
    return _blocked(unknown_arcs(scan, max_gap), side_tolerance)


def _blocked(arcs: tuple[tuple[float, float], ...], side_tolerance: float) -> BlockedMotion:
    half = 0.5 * math.pi - side_tolerance
    forward = any(_arc_meets_cone(start, width, 0.0, half) for start, width in arcs)
    backward = any(_arc_meets_cone(start, width, math.pi, half) for start, width in arcs)
    return BlockedMotion(forward, backward, arcs)


@functools.lru_cache(maxsize=64)
def _blocked_by_layout(first_direction: float, angle_increment: float, n_beams: int, max_gap: float,
                       side_tolerance: float) -> BlockedMotion:
    return _blocked(_outside_arc(first_direction, angle_increment, n_beams, max_gap), side_tolerance)


def nearest_per_bin(points: np.ndarray, keys: np.ndarray, centre: tuple[float, float], n_bins: int) -> np.ndarray:
    """Indices of the point with the smallest key in each angular bin around ``centre``.

    Args:
        points: ``(N, 2)`` points [m].
        keys: ``(N,)`` values to minimise per bin (e.g. barrier values).
        centre: the point the bins are centred on [m].
        n_bins: number of equal bins over the full turn.

    Returns:
        Indices into ``points``, in increasing key order.
    """
    if len(points) == 0:
        return np.empty(0, dtype=np.intp)
    angles = np.arctan2(points[:, 1] - centre[1], points[:, 0] - centre[0])
    bins = ((angles + math.pi) * (n_bins / TWO_PI)).astype(np.intp) % n_bins
    order = np.lexsort((keys, bins))
    sorted_bins = bins[order]
    first = np.empty(order.size, dtype=bool)
    first[0] = True
    np.not_equal(sorted_bins[1:], sorted_bins[:-1], out=first[1:])
    chosen = order[first]
    return chosen[np.argsort(keys[chosen], kind="stable")]
