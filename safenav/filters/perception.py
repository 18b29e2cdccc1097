"""From scans to what the filters constrain: obstacle points, the unknown region, and a memory.

Shared by every filter, so the CBF and the MPC see the same world:

* :func:`obstacle_beams` / :func:`beam_points`: every obstacle point of a scan in the base
  frame (REP-117: ``HIT`` at its range; ``TOO_CLOSE`` as close as it can be without having
  hit the body).
* :func:`unknown_region`: which parts of the body's outline face space that no current beam
  of any source covers, and which motions they forbid. Computed from the body and each
  lidar's mount, not from a laser origin: a sample of the outline is *covered* when some
  source's field of view contains it and the beams towards it are informative. Outline
  samples outside every field of view (*blind* samples: beside and behind a front-mounted
  180-degree lidar) forbid translating the body towards them unless the space ahead of them
  in that direction comes into view within the body's size (the strip beside the m2wr's
  body, which forward motion sweeps: what is in it was seen before it got there, or was
  there at the start; see :class:`PointMemory` and ``docs/safety.md``). Outline samples in
  a field of view but behind a run of invalid beams wider than ``max_gap`` (*gap* samples)
  forbid every motion of the outline towards them, turning included.
* :class:`PointMemory`: obstacle points that leave the field of view are carried in the base
  frame by odometry and stay obstacles while the body can reach them and no current beam
  contradicts them (not for a fixed time).
* :func:`nearest_per_bin`: a working set, the point with the smallest key per angular bin.

It holds the three perception steps together because the unknown region and the memory both work on
the obstacle points the first step produces.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from safenav.filters.body import BodyModel
from safenav.filters.kernels import frozen, plain
from safenav.geometry import TWO_PI, Pose2D, unicycle_step, wrap_angle
from safenav.scan import _HIT, _INVALID, _NO_RETURN, _TOO_CLOSE, LaserScan  # the reading codes as plain ints

__all__ = [
    "START_BLIND_CLEARANCE",
    "Frontier",
    "PointMemory",
    "SeenFree",
    "beam_gap",
    "beam_points",
    "blind_cells",
    "body_clearance",
    "dead_reckoning",
    "nearest_per_bin",
    "obstacle_beams",
    "resolved_range",
    "shadow_points",
    "unknown_beams",
    "unknown_region",
]

#: Distance outside the outline at which coverage is tested [m].
OUTLINE_OFFSET = 1e-3

START_BLIND_CLEARANCE = 0.5
"""The start assumption [m]: when a filter starts (or is reset), nothing lies within this distance
of the body in directions no lidar's field of view covers (the strip beside and the space behind a
front-mounted 180-degree lidar). The filter cannot know what is there until it has seen it; from
then on everything it saw is remembered. ``benchmarks/falsify.py`` starts only inside it."""


def body_clearance(points: np.ndarray, body_radius: float) -> float:
    """Distance from the base origin to the nearest of ``points`` minus ``body_radius`` [m] (inf if none)."""
    return float(np.hypot(points[:, 0], points[:, 1]).min()) - body_radius if len(points) else math.inf


def obstacle_beams(scan: LaserScan, body: BodyModel | float) -> tuple[np.ndarray, np.ndarray]:
    """Beams that give an obstacle point, and the range to put it at [m], for ``body``.

    ``HIT`` beams keep their range. A ``TOO_CLOSE`` beam (``-inf``) says an object is closer
    than ``range_min``, maybe touching the body: it is put where the beam leaves the body's
    outline (the footprint polygon, or the disk; a number is the radius of a disk around the
    base origin), or at ``range_min`` if that is nearer. A filter then sees the robot as inside
    its margin and backs out of the lidar's blind zone instead of trusting a clearance it cannot
    measure (a lidar whose ``range_min`` exceeds the distance to the body's edge plus the margin
    cannot see the margin).
    """
    index, ranges = scan.obstacle_beams()
    too_close = scan.ranges[index] == -math.inf
    if too_close.any():
        geometry = scan.geometry
        origin = np.array([scan.mount.x, scan.mount.y])
        beams = index[too_close]
        direction = np.column_stack((geometry.cos_base[beams], geometry.sin_base[beams]))
        outline = None if not isinstance(body, BodyModel) else body.outline
        if outline is None:
            radius = body if not isinstance(body, BodyModel) else float(body.radii[0])
            along = direction @ origin
            inside = radius**2 - float(origin @ origin)
            if inside > 0.0:  # the laser is inside the body disk: every beam leaves it at one range
                ranges[too_close] = np.minimum(ranges[too_close], -along + np.sqrt(along**2 + inside))
        else:
            ranges[too_close] = np.minimum(ranges[too_close], _exit_ranges(origin, direction, outline))
    return index, ranges


def _exit_ranges(origin: np.ndarray, direction: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """How far rays from ``origin`` (inside the convex ``polygon``) along ``direction`` ``(K, 2)`` leave it [m]."""
    a = polygon
    edge = np.roll(a, -1, axis=0) - a
    normal = np.column_stack((edge[:, 1], -edge[:, 0]))           # outward for a counter-clockwise polygon
    depth = np.einsum("vi,vi->v", normal, a) - normal @ origin    # >= 0 while the origin is inside
    speed = direction @ normal.T                                  # (K, V): how fast each ray nears each edge
    with np.errstate(divide="ignore", invalid="ignore"):
        reach = np.where(speed > 1e-12, depth[None, :] / speed, np.inf)
    return np.maximum(np.min(reach, axis=1), 0.0)


def classify(scans: tuple[LaserScan, ...], compiled: Any = None) -> None:
    """What each beam of each scan reads (:attr:`~safenav.scan.LaserScan.readings`, its hits and
    :attr:`~safenav.scan.LaserScan.n_informative`), by one compiled pass over the ranges when ``compiled`` holds the
    kernels of :mod:`~safenav.filters.kernels` (else the scan computes them with numpy when first asked): the same
    values, set once per scan."""
    if compiled is None:
        return
    for scan in scans:
        if "readings" not in scan.__dict__:
            scan._classified(*compiled.scan_readings(frozen(scan.ranges), scan.range_min, scan.range_max, _HIT,
                                                     _NO_RETURN, _TOO_CLOSE, _INVALID))


def beam_points(scans: tuple[LaserScan, ...], body: BodyModel | float, max_distance: float = math.inf,
                compiled: Any = None) -> np.ndarray:
    """Obstacle points of every scan in the base frame, ``(N, 2)`` [m] (``body``: see :func:`obstacle_beams`).

    With ``max_distance``, beams whose point cannot be within ``max_distance`` of the base
    origin (range beyond ``max_distance + |mount|``) are skipped before any trigonometry.
    ``compiled``: the kernels of :mod:`~safenav.filters.kernels` (the same points by one compiled loop for a scan
    taken at once without a ``TOO_CLOSE`` beam).
    """
    pieces = []
    for scan in scans:
        if compiled is not None and scan.sweep_motion is None and max_distance == math.inf:
            geometry = scan.geometry
            points, close = compiled.hit_points(frozen(scan.ranges), frozen(scan._hit_mask), geometry.cos_base,
                                                geometry.sin_base, float(scan.mount.x), float(scan.mount.y))
            if not close:
                pieces.append(points)
                continue
        index, ranges = obstacle_beams(scan, body)
        if math.isfinite(max_distance):
            keep = ranges <= max_distance + math.hypot(scan.mount.x, scan.mount.y)
            index, ranges = index[keep], ranges[keep]
        pieces.append(scan.beam_points(index, ranges))
    if len(pieces) == 1:
        return pieces[0]
    return np.vstack(pieces) if pieces else np.empty((0, 2))


def _lever(scan: LaserScan) -> float:
    """How far from the base origin [m] the lidar measured any of the scan's beams, at most: its mount's distance,
    and for a turning lidar on a moving base the sweep's extent (:attr:`~safenav.scan.LaserScan.sweep_error`)."""
    lever = math.hypot(scan.mount.x, scan.mount.y)
    return lever if scan.sweep_motion is None else lever + scan.sweep_error[0]


def beam_gap(distance: float, angle_increment: float) -> float:
    """How far apart two neighbouring beams are ``distance`` [m] from their lidar [m]: the widest obstacle that
    can stand between them there, unseen (assumption A2; :func:`resolved_range` is the inverse)."""
    return 2.0 * distance * math.sin(0.5 * angle_increment)


def resolved_range(width: float, angle_increment: float) -> float:
    """How far from its lidar [m] an obstacle ``width`` [m] wide cannot hide between two beams
    (:func:`beam_gap` is the inverse)."""
    return width / (2.0 * math.sin(0.5 * angle_increment))


def horizon_points(scans: tuple[LaserScan, ...], reach: float, width: float | None = None) -> np.ndarray:
    """Where what the lidars see ends: a point at ``range_max`` along every ``NO_RETURN`` beam, ``(N, 2)`` [m].

    A ``NO_RETURN`` beam says the space is free up to ``range_max``, and nothing beyond it: an
    obstacle there is seen only once it is within ``range_max``. A base that cannot stop within
    that distance must not drive as if it were free, so the filters treat these points as
    obstacles of the current call (never remembered). Only scans whose ``range_max`` can come
    within ``reach`` [m] of the base origin give any (the tutorial lidars' 12 m and 30 m never do).

    With ``width`` [m], an obstacle that wide is seen for sure only where two neighbouring beams are
    less than ``width`` apart, up to :func:`resolved_range` from the lidar; beyond,
    it can hide between them. That range is then the horizon when it is nearer than ``range_max``: a
    point there along every beam that reads farther (a farther hit or ``NO_RETURN``).
    """
    pieces = []
    for scan in scans:
        horizon = scan.range_max
        if width is not None:
            horizon = min(horizon, resolved_range(width, scan.angle_increment))
        if horizon - _lever(scan) > reach:
            continue
        beyond = scan.readings == _NO_RETURN
        if horizon < scan.range_max:
            beyond |= (scan.readings == _HIT) & (scan.ranges > horizon)
        index = np.flatnonzero(beyond)
        if index.size:
            pieces.append(scan.beam_points(index, np.full(index.size, horizon)))
    if not pieces:
        return np.empty((0, 2))
    return pieces[0] if len(pieces) == 1 else np.vstack(pieces)


#: Spacing [m] of the points along an occluder's shadow edge (:func:`shadow_points`): a body disk that keeps
#: its margin from each point keeps it from the edge but for the sagitta, 1.2 mm for a 0.25 m disk.
SHADOW_SPACING = 0.05


def shadow_points(scans: tuple[LaserScan, ...], reach: float, jump: float, compiled: Any = None) -> np.ndarray:
    """Points along the edges of what obstacles hide within ``reach`` of the base origin, ``(N, 2)`` [m].

    A beam that hits an obstacle says nothing about the space behind it. Where the next beam reads
    farther by more than ``jump`` [m] (a ``HIT`` farther, or ``NO_RETURN``), the first beam's hit is the
    edge of an occluder, and the space beyond it along that beam borders what the occluder hides: an
    obstacle there (a second pole behind a first) comes into view only when the robot has moved, and
    possibly nearer than it can stop from. The filters treat points every :data:`SHADOW_SPACING` along
    that beam beyond the hit, up to ``reach`` (the base's stopping reach), as obstacles of the current call
    (never remembered): a plan may go round an occluder, not into its shadow before it has seen it. Behind
    a wall they lie behind the wall; seen from a lidar at the base origin they are all farther than the
    occluder itself, so only motion towards the shadow meets them.

    ``compiled``: the kernels of :mod:`~safenav.filters.kernels` (the same points, by one compiled loop per scan).
    """
    pieces = []
    for scan in scans:
        ranges, readings = scan.ranges, scan.readings
        lever = _lever(scan)
        if compiled is not None:
            wraps = bool(scan.n_beams * scan.angle_increment >= TWO_PI - 1e-9)
            beams, distances = compiled.shadow_beams(frozen(ranges), frozen(readings), _HIT, _NO_RETURN,
                                                     float(reach + lever), SHADOW_SPACING, float(jump), wraps)
            if beams.size:
                pieces.append(scan.beam_points(beams, distances))
            continue
        hit = readings == _HIT
        near = hit & (ranges < reach + lever - SHADOW_SPACING)
        if not near.any():
            continue
        farther = np.where(hit, ranges, -math.inf)
        farther[readings == _NO_RETURN] = math.inf
        beyond = ranges + jump
        # A beam is an occluder's edge when a neighbour (the previous or the next, round the turn for a full
        # scan) reads farther by more than the jump.
        edge = np.zeros(scan.n_beams, dtype=bool)
        edge[1:] = farther[:-1] > beyond[1:]
        edge[:-1] |= farther[1:] > beyond[:-1]
        if scan.n_beams * scan.angle_increment >= TWO_PI - 1e-9:
            edge[0] |= farther[-1] > beyond[0]
            edge[-1] |= farther[0] > beyond[-1]
        index = np.flatnonzero(edge & near)
        if not index.size:
            continue
        steps = np.floor((reach + lever - ranges[index]) / SHADOW_SPACING).astype(np.intp)
        beams = np.repeat(index, steps)
        offsets = np.arange(beams.size) - np.repeat(np.cumsum(steps) - steps, steps) + 1
        pieces.append(scan.beam_points(beams, ranges[beams] + SHADOW_SPACING * offsets))
    if not pieces:
        return np.empty((0, 2))
    return pieces[0] if len(pieces) == 1 else np.vstack(pieces)


def unknown_beams(scan: LaserScan, max_gap: float) -> np.ndarray:
    """Mask of the beams inside a run of ``INVALID`` readings wider than ``max_gap`` [rad].

    Shorter runs are bridged by their neighbours, like the gap between any two beams. Each
    beam covers half an increment either side; a full-turn scan's runs wrap round.
    """
    invalid = scan.readings == _INVALID
    if not invalid.any():
        return np.zeros(scan.n_beams, dtype=bool)
    if invalid.all():
        return np.ones(scan.n_beams, dtype=bool)
    wraps = scan.field_of_view >= TWO_PI - 1e-9
    shift = int(np.argmin(invalid)) if wraps else 0   # start the walk at an informative beam
    walk = np.roll(invalid, -shift)
    edges = np.diff(np.concatenate(([False], walk, [False])).astype(np.int8))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    mask = np.zeros(scan.n_beams, dtype=bool)
    for begin, end in zip(starts, stops, strict=True):
        if (end - begin) * scan.angle_increment > max_gap:
            mask[begin:end] = True
    return np.roll(mask, shift)


class Frontier(NamedTuple):
    """What part of the outline faces unknown space, and the motions that forbids.

    Attributes:
        points: ``(K, 2)`` outline samples facing a gap (a run of invalid beams) [m].
        normals: ``(K, 2)`` their outward normals; no point of the outline may move along them.
        forward: some blind outline sample forbids translating forward (``v > 0``).
        backward: some blind outline sample forbids translating backward (``v < 0``).
        gap_forward: some gap sample (beyond the side tolerance) is approached by ``v > 0``.
        gap_backward: likewise by ``v < 0``.
        complete: every outline sample is covered by an informative beam now.
    """

    points: np.ndarray
    normals: np.ndarray
    forward: bool
    backward: bool
    gap_forward: bool
    gap_backward: bool
    complete: bool = False
    """Every outline sample is covered by an informative beam now (no blind side, no gap)."""

    @property
    def blocks_forward(self) -> bool:
        return self.forward or self.gap_forward

    @property
    def blocks_backward(self) -> bool:
        return self.backward or self.gap_backward


@dataclass(frozen=True, eq=False)
class _Layout:
    """Per source, which beam each outline sample falls on (-1 outside the field of view)."""

    beams: tuple[np.ndarray, ...]
    blind_forward: bool
    blind_backward: bool
    clear: Frontier
    """The answer when every beam of every source is informative (it depends on the layout only)."""


def _layout_key(scan: LaserScan) -> tuple[float, float, int, float, float, float]:
    return (scan.angle_min, scan.angle_increment, scan.n_beams, scan.mount.x, scan.mount.y, scan.mount.yaw)


@functools.lru_cache(maxsize=64)
def _layout(keys: tuple[tuple[float, float, int, float, float, float], ...], body_key: bytes, radius: float,
            side_tolerance: float, depth: float) -> _Layout:
    """Static coverage of the outline samples by the sources' fields of view (cached per layout)."""
    outline = np.frombuffer(body_key, dtype=float).reshape(-1, 2) if body_key else None
    body = BodyModel(np.zeros((1, 2)), np.array([radius]), outline, "key")
    points, normals = body.boundary()
    probe = points + OUTLINE_OFFSET * normals

    def beam_of(key: tuple[float, float, int, float, float, float], where: np.ndarray) -> np.ndarray:
        angle_min, increment, n_beams, mx, my, myaw = key
        bearing = np.arctan2(where[:, 1] - my, where[:, 0] - mx) - myaw - angle_min
        offset = np.mod(bearing + 0.5 * increment, TWO_PI) - 0.5 * increment
        index = np.floor(offset / increment + 0.5).astype(np.intp)
        inside = (index >= 0) & (index < n_beams) & (np.abs(offset - index * increment) <= 0.5 * increment + 1e-12)
        return np.where(inside, index, -1)

    beams = tuple(beam_of(key, probe) for key in keys)
    blind = np.all(np.stack([b < 0 for b in beams]), axis=0)
    threshold = math.sin(side_tolerance)
    steps = np.linspace(0.0, depth, 16)[1:]

    def comes_into_view(direction: float) -> np.ndarray:
        """Whether the space ahead of each blind sample (along ``direction`` x) enters a field of view."""
        # Every step at once (a layout is built at every call that moves a late scan into the current frame).
        ahead = (probe[None, :, :] + np.array([direction, 0.0]) * steps[:, None, None]).reshape(-1, 2)
        seen = np.any(np.stack([beam_of(key, ahead) >= 0 for key in keys]), axis=0)
        return seen.reshape(len(steps), len(points)).any(axis=0)

    # (Nothing outside every field of view: no side is blind, whatever comes into view.)
    forward = bool(blind.any()) and bool(np.any(blind & (normals[:, 0] > threshold) & ~comes_into_view(1.0)))
    backward = bool(blind.any()) and bool(np.any(blind & (normals[:, 0] < -threshold) & ~comes_into_view(-1.0)))
    for array in beams:
        array.flags.writeable = False
    none = np.empty((0, 2))
    return _Layout(beams, forward, backward, Frontier(none, none, forward, backward, False, False,
                                                      complete=not bool(blind.any())))


def unknown_region(scans: tuple[LaserScan, ...], body: BodyModel, max_gap: float, side_tolerance: float
                   ) -> Frontier:
    """The parts of the body's outline that face unknown space, and the motions they forbid.

    Args:
        scans: the sources, each in the base frame through its mount.
        body: the body model (its outline is sampled).
        max_gap: widest run of invalid beams bridged by its neighbours [rad].
        side_tolerance: outline samples whose outward normal is within this angle of
            sideways do not forbid translation [rad].
    """
    layout = _layout(tuple(_layout_key(scan) for scan in scans), *body.key, side_tolerance, body.reach)
    if all(scan.n_informative == scan.n_beams for scan in scans):
        return layout.clear
    points, normals = body.boundary()
    covered = np.zeros(len(points), dtype=bool)
    in_view = np.zeros(len(points), dtype=bool)
    for scan, beams in zip(scans, layout.beams, strict=True):
        seen = beams >= 0
        in_view |= seen
        if scan.n_informative == scan.n_beams:
            covered |= seen
            continue
        unknown = unknown_beams(scan, max_gap)
        covered |= seen & ~unknown[np.maximum(beams, 0)]
    gap = in_view & ~covered
    threshold = math.sin(side_tolerance)
    return Frontier(points[gap], normals[gap], layout.blind_forward, layout.blind_backward,
                    bool(np.any(normals[gap, 0] > threshold)), bool(np.any(normals[gap, 0] < -threshold)))


# ---------------------------------------------------------------------------------------------- memory


class PointMemory:
    """Obstacle points carried in the base frame by odometry while the body can still reach them.

    After each call the memory holds the obstacle points of the call's scans within
    ``max_range`` of the base origin, plus the remembered points no scan saw again. At the
    next call they are moved into the new base frame by the motion since then; a remembered
    point is dropped when the current beam nearest its direction reads farther (the space is
    seen to be free: contradicted) or about as far (the scan shows it again), and every beam
    towards where it may be (within its uncertainty) is in the field of view and informative;
    it is kept when the nearest beam reads nearer (occluded) and when a beam towards where it may
    be is invalid or outside every field of view. Each
    carry adds the odometry's uncertainty to the point's ``uncertainty`` [m] (:meth:`carry`; a
    turn error also with the base's travel after it until the points are stored again), which the
    filters add to their margin for that point. Beyond ``capacity`` points the farthest are
    forgotten first.

    The points stay in the frame they were stored in, and the motions are composed, so carrying
    costs nothing until the points are recalled.

    Args:
        max_range: points farther than this from the base origin are forgotten [m].
        capacity: largest number of points kept.
    """

    def __init__(self, max_range: float, capacity: int) -> None:
        self.max_range = float(max_range)
        self.capacity = int(capacity)
        self.clear()

    def __len__(self) -> int:
        return int(self._points.shape[0])

    def clear(self) -> None:
        """Forget everything (a reset, or a scan that cannot be trusted)."""
        self._points = np.empty((0, 2))
        self._uncertainty = np.empty(0)
        self._frame = Pose2D()          # the current base frame in the frame the points are stored in
        # Odometry error bound accumulated since they were stored: translation, turn, and each carry's turn times
        # the base's path since that carry (the turn was about where the base was then).
        self._error = np.zeros(3)

    @property
    def points(self) -> np.ndarray:
        """The remembered points in the current base frame ``(M, 2)`` [m]."""
        return self._frame.to_local(self._points) if self._points.shape[0] else self._points

    def moved(self, motion: Pose2D) -> np.ndarray:
        """The remembered points ``(M, 2)`` [m] in a base frame at ``motion`` in the current one (where
        :meth:`carry` with ``motion`` would put them), without carrying them."""
        return self._frame.compose(motion).to_local(self._points) if self._points.shape[0] else self._points

    @property
    def uncertainty(self) -> np.ndarray:
        """Their position uncertainty ``(M,)`` [m]."""
        if not self._points.shape[0]:
            return self._uncertainty
        distance = np.hypot(self._points[:, 0] - self._frame.x, self._points[:, 1] - self._frame.y)
        return self._uncertainty + self._error[0] + distance * self._error[1] + self._error[2]

    def carry(self, motion: Pose2D, uncertainty_rate: tuple[float, float] = (0.0, 0.0)) -> None:
        """Account for the motion to a new base frame, which is at ``motion`` in the old one.

        Args:
            motion: the pose of the new base frame in the old one [m, m, rad].
            uncertainty_rate: odometry error bound ``(e_translation [m], e_rotation [rad])`` of
                this motion; a point at distance ``d`` from the new base origin gains
                ``e_translation + d e_rotation``, and at every later carry (until the points are stored
                again) ``e_rotation`` times that carry's straight-line travel: the turn was about the base
                origin of this carry, which the base leaves behind.
        """
        if self._points.shape[0]:
            self._frame = self._frame.compose(motion)
            self._error[2] += self._error[1] * math.hypot(motion.x, motion.y)
            self._error[:2] += uncertainty_rate

    def recall(self, scans: tuple[LaserScan, ...], tolerance: float, scan_error: tuple[float, float] = (0.0, 0.0),
               compiled: Any = None) -> tuple[np.ndarray, np.ndarray]:
        """The remembered points no current beam sees again or contradicts, and their uncertainty.

        Args:
            scans: the current scans (base frame).
            tolerance: range difference within which a reading shows a remembered point again [m]
                (beyond it, a farther reading contradicts it); the point's own uncertainty is added.
            scan_error: ``(e_translation [m], e_rotation [rad])``: the scans' place in the base frame is uncertain
                by that much (moved there by the measured velocities since they were taken), which a point
                ``d`` from the base origin adds to its uncertainty against them; a point narrowed down to the
                part of its disk beyond an edge of a field of view keeps that (the edge is where the scan is), the
                others their own.
            compiled: the kernels of :mod:`~safenav.filters.kernels` (the same test, by one compiled loop per scan).
        """
        if self._points.shape[0] == 0:
            return np.empty((0, 2)), np.empty(0)
        if compiled is not None and len(scans) == 1 and scans[0].sweep_motion is None:
            return self._recall_compiled(compiled, scans[0], tolerance, scan_error)
        points, own = self.points, self.uncertainty
        uncertainty = own + motion_spread(points, scan_error) if any(scan_error) else own
        against = uncertainty
        keep = np.hypot(points[:, 0], points[:, 1]) <= self.max_range + uncertainty
        for scan in scans:
            # A turning lidar's beams were measured from poses of their own: each point is looked at from the pose
            # of the beam that looks at it (and put back afterwards), as if that beam had been measured from the
            # mount (the scan's place is then off by one beam's motion, in ``scan_error``).
            shift = None if scan.sweep_motion is None else sweep_shift(scan, points, compiled)
            if shift is not None:
                points = shift.to_mount(points)
            if compiled is None:
                seen, points, uncertainty = _seen_again(scan, points, tolerance + uncertainty, uncertainty)
            else:
                seen, points, uncertainty = _seen_again_compiled(compiled, scan, points, tolerance + uncertainty,
                                                                 uncertainty)
            if shift is not None:
                points = shift.back(points)
                seen &= ~shift.unseen
            keep &= ~seen
        uncertainty = np.where(uncertainty == against, own, uncertainty)   # not narrowed: its own uncertainty
        return points[keep], uncertainty[keep]

    def _recall_compiled(self, compiled: Any, scan: LaserScan, tolerance: float, scan_error: tuple[float, float]
                         ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`recall` with one scan taken at once, by the kernel ``compiled.memory_recall`` (the same points)."""
        frame, error, mount, view = self._frame, self._error, scan.mount, scan.field_of_view
        return compiled.memory_recall(
            plain(self._points), plain(self._uncertainty), float(frame.x), float(frame.y), math.cos(frame.yaw),
            math.sin(frame.yaw), float(error[0]), float(error[1]), float(error[2]), float(scan_error[0]),
            float(scan_error[1]), bool(any(scan_error)), self.max_range, float(tolerance), frozen(scan.ranges),
            frozen(scan.readings), _HIT, _NO_RETURN, float(scan.range_max), float(scan.angle_min),
            float(scan.angle_increment), float(mount.x), float(mount.y), float(mount.yaw),
            bool(view >= TWO_PI - 1e-9), bool(view >= math.pi))

    def store(self, current: np.ndarray, recalled: np.ndarray, recalled_uncertainty: np.ndarray,
              current_uncertainty: np.ndarray | None = None) -> None:
        """Remember ``current`` points (exact, or within ``current_uncertainty``) and the ``recalled`` ones, within
        range and capacity.

        Everything else is forgotten; the points are stored in the current base frame. Without
        recalled points the current ones are kept as they are (``current`` must not be changed
        afterwards) and the range and capacity are applied when they are recalled.
        """
        exact = np.zeros(current.shape[0]) if current_uncertainty is None else current_uncertainty
        if recalled.shape[0]:
            points = np.vstack((current, recalled))
            uncertainty = np.concatenate((exact, recalled_uncertainty))
        else:
            points, uncertainty = current, exact
        if points.shape[0] > self.capacity:
            distance = np.hypot(points[:, 0], points[:, 1])
            order = np.argsort(distance, kind="stable")[: self.capacity]
            points, uncertainty = points[order], uncertainty[order]
        self._points, self._uncertainty = points, uncertainty
        self._frame, self._error = Pose2D(), np.zeros(3)


#: Spacing of the grid on which the space no lidar sees now is checked against earlier scans [m].
SEEN_FREE_SPACING = 0.04
#: How many earlier scans :class:`SeenFree` keeps (the oldest go first).
SEEN_FREE_SCANS = 12
#: How far the base moves [m], or turns [rad], between two scans :class:`SeenFree` keeps.
SEEN_FREE_STEP = (0.1, math.radians(20.0))
#: Travel [m] towards a side no lidar sees that the seen-free grid covers at least (more for a robot that needs
#: more to stop from full speed).
SEEN_FREE_TRAVEL = 0.2
#: ... and at most (the grid's cells grow with its square; a robot that needs more to stop backs slower) [m].
SEEN_FREE_MAX_TRAVEL = 1.0
#: Half-widths [beams] of the windows over which a kept scan's smallest reading is precomputed.
_WINDOWS = np.array([1, 2, 4, 8, 16, 32, 64])


@functools.lru_cache(maxsize=32)
def blind_cells(keys: tuple[tuple[float, float, int, float, float, float], ...], inside: float, extent: float,
                spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """The grid cells near the body that lie partly outside every field of view (cached per layout).

    The plane is tiled by squares of side ``spacing`` centred on multiples of it; each is
    enclosed by the disk of radius ``spacing / sqrt(2)`` about its centre. A cell is kept when it
    reaches within ``extent`` of the base origin, is not wholly inside the disk of radius
    ``inside`` about it (the body's own space), and its disk is not wholly inside some lidar's
    field of view (``keys`` as :func:`unknown_region`'s layouts: every point of the other cells is in
    some lidar's view now).

    Returns:
        ``(centres (N, 2) [m], their distances from the base origin (N,) [m])``, nearest first.
    """
    radius = spacing / math.sqrt(2.0)
    count = math.ceil((extent + radius) / spacing)
    axis = spacing * np.arange(-count, count + 1, dtype=float)
    x, y = np.meshgrid(axis, axis, indexing="ij")
    centres = np.column_stack((x.ravel(), y.ravel()))
    distance = np.hypot(centres[:, 0], centres[:, 1])
    keep = (distance - radius < extent) & (distance + radius > inside)
    centres, distance = centres[keep], distance[keep]
    seen = np.zeros(len(centres), dtype=bool)
    for angle_min, increment, n_beams, mx, my, myaw in keys:
        dx, dy = centres[:, 0] - mx, centres[:, 1] - my
        reach = np.hypot(dx, dy)
        if n_beams * increment >= TWO_PI - 1e-9:
            seen |= reach > radius
            continue
        middle = angle_min + 0.5 * (n_beams - 1) * increment
        half_span = 0.5 * n_beams * increment         # each beam covers half an increment either side
        relative = np.abs(np.mod(np.arctan2(dy, dx) - myaw - middle + math.pi, TWO_PI) - math.pi)
        half = np.arcsin(np.minimum(radius / np.maximum(reach, 1e-12), 1.0))
        seen |= (reach > radius) & (relative + half <= half_span)
    order = np.argsort(distance[~seen], kind="stable")
    centres, distance = centres[~seen][order], distance[~seen][order]
    centres.flags.writeable = False
    distance.flags.writeable = False
    return centres, distance


class SeenFree:
    """Earlier scans, carried by odometry, that say which space no lidar sees now was seen free.

    A lidar that does not see all round (the m2wr's 180-degree lidar looks ahead) cannot tell
    whether the space behind the robot is free, so translating towards it is forbidden
    (:func:`unknown_region`'s ``backward``). Yet a robot that drove forward has seen that space:
    this memory keeps up to :data:`SEEN_FREE_SCANS` earlier scans (a new one once the base has
    moved or turned by :data:`SEEN_FREE_STEP` since the last one kept), moves them with the base
    by odometry as :class:`PointMemory` moves points (the same error bound, A5), and answers
    :meth:`travel`: how far the base may translate into the unseen side while the body and the
    margin stay in space some kept scan saw free.

    A kept scan says the space is free along each beam up to its reading (less twice the range
    noise; ``range_max`` for no return), and between two beams as far as both read (a narrower
    obstacle between two beams is A2's, as for every scan). The world is static (A1).

    Args:
        max_range: kept scans whose lidar is farther than this from the base are forgotten [m].
        capacity: largest number of scans kept.
        step: ``(distance [m], angle [rad])`` the base moves or turns between two kept scans.
    """

    def __init__(self, max_range: float, capacity: int = SEEN_FREE_SCANS,
                 step: tuple[float, float] = SEEN_FREE_STEP) -> None:
        self.max_range = float(max_range)
        self.capacity = int(capacity)
        self.step = (float(step[0]), float(step[1]))
        self.clear()

    def __len__(self) -> int:
        return sum(group.count for group in self._groups.values())

    def clear(self) -> None:
        """Forget every kept scan."""
        self._groups: dict[tuple[float, float, int], _KeptScans] = {}     # per beam layout
        self._since: Pose2D | None = None      # the base frame in the frame of the last kept scan
        self._count = 0
        self._rebased()

    def _rebased(self) -> None:
        """Start the carries' sums afresh (the kept poses and errors are as of the current base frame)."""
        self._carries = 0           # carries since the last rebase
        self._frame = Pose2D()      # the current base frame in the frame of the last rebase
        self._path = 0.0            # the base's path since then [m]
        self._shift = 0.0           # the error bound accumulated since then: translation [m] ...
        self._turn = 0.0            # ... and turn [rad]
        self._lever = 0.0           # the sum over those carries of the turn accumulated before each times its path [m]

    def carry(self, motion: Pose2D, uncertainty_rate: tuple[float, float] = (0.0, 0.0)) -> None:
        """Account for the motion to a new base frame, which is at ``motion`` in the old one (as
        :meth:`PointMemory.carry`).

        The motions and error bounds are summed, and the kept scans moved only when they are used (a kept scan
        is used when another is stored and when :meth:`certified` is asked): a call of a filter that does not
        translate towards an unseen side moves nothing.
        """
        if self._since is not None:
            self._since = self._since.compose(motion)
        if self._groups:
            self._carries += 1
            self._frame = self._frame.compose(motion)
            path = math.hypot(motion.x, motion.y)
            self._lever += self._turn * path        # earlier turns' centres fall behind
            self._path += path
            self._shift += uncertainty_rate[0]
            self._turn += uncertainty_rate[1]

    def _rebase(self) -> None:
        """Move the kept scans into the current base frame and add the carries' error bounds since the last rebase.

        For each carry ``c`` (path ``s_c``, error bound ``(e_c, r_c)``), a kept scan's turn error grows by ``r_c``,
        its translation error by ``e_c`` and its lever by its turn error before the carry times ``s_c``; summed
        over the carries since the last rebase, with ``E`` its errors then, that is ``E + sum e_c``, ``E_turn +
        sum r_c`` and ``E_lever + E_turn sum s_c + sum_c (r_1 + ... + r_(c-1)) s_c``.
        """
        if not self._carries:
            return
        frame = self._frame
        cos, sin = math.cos(frame.yaw), math.sin(frame.yaw)
        for group in self._groups.values():
            poses, error = group.poses, group.error
            dx, dy = poses[:, 0] - frame.x, poses[:, 1] - frame.y
            poses[:, 0], poses[:, 1] = cos * dx + sin * dy, -sin * dx + cos * dy
            poses[:, 2] -= frame.yaw
            error[:, 2] += error[:, 1] * self._path + self._lever
            error[:, 0] += self._shift
            error[:, 1] += self._turn
        self._rebased()

    def kept(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per beam layout, the kept scans' lidar poses ``(F, 3)`` in the current base frame [m, m, rad] and their
        odometry error bounds ``(F, 3)`` (translation [m], turn [rad], the turns' lever beyond the base [m])."""
        self._rebase()
        kept = []
        for group in self._groups.values():
            slots = group.slots()
            kept.append((group.poses[slots], group.error[slots]))
        return kept

    def store(self, scans: tuple[LaserScan, ...], noise: float) -> None:
        """Keep ``scans`` (base frame, through their mounts) when the base has moved or turned far enough
        since the last kept ones; ``noise`` is the range noise's standard deviation [m]."""
        since = self._since
        if since is not None and math.hypot(since.x, since.y) < self.step[0] and abs(since.yaw) < self.step[1]:
            return
        self._since = Pose2D()
        self._count += 1
        self._rebase()
        # Forget scans from lidars now out of range, then the oldest beyond the capacity (the new ones count).
        for group in self._groups.values():
            group.used &= np.hypot(group.poses[:, 0], group.poses[:, 1]) <= self.max_range
        new = [scan for scan in scans if math.hypot(scan.mount.x, scan.mount.y) <= self.max_range]
        orders = np.concatenate([group.order[group.used] for group in self._groups.values()]
                                + [np.full(len(new), self._count)])
        if orders.size > self.capacity:
            oldest = np.sort(orders)[orders.size - self.capacity]
            for group in self._groups.values():
                group.used &= group.order >= oldest
        for scan in new:
            key = (scan.angle_min, scan.angle_increment, scan.n_beams)
            group = self._groups.get(key)
            if group is None:
                group = self._groups[key] = _KeptScans(self.capacity, scan.n_beams,
                                                       scan.n_beams * scan.angle_increment >= TWO_PI - 1e-9)
            group.keep(scan.mount, _seen_ranges(scan, 2.0 * noise), self._count)
        self._groups = {key: group for key, group in self._groups.items() if group.count}

    def certified(self, centres: np.ndarray, distance: np.ndarray, radius: float) -> np.ndarray:
        """Which disks of ``radius`` [m] about ``centres`` ``(N, 2)`` [m] (at ``distance`` ``(N,)`` from the base
        origin) some kept scan saw free, with the odometry's error bound added to the radius.

        Each carry's error (``e_translation``, ``e_rotation``) is a translation and a turn about the base
        origin of that moment, which lies within the base's path length since then of the base origin now: a
        point ``d`` from the base is off by at most ``sum(e_translation) + d sum(e_rotation) + sum(e_rotation
        path since)``.
        """
        self._rebase()
        free = np.zeros(len(centres), dtype=bool)
        for (angle_min, increment, n_beams), group in self._groups.items():
            slots = group.slots()
            poses, error, minima = group.poses[slots], group.error[slots], group.minima(slots)
            # The centres in each kept lidar's frame.
            dx = centres[None, :, 0] - poses[:, 0:1]
            dy = centres[None, :, 1] - poses[:, 1:2]
            cos, sin = np.cos(poses[:, 2:3]), np.sin(poses[:, 2:3])
            along, across = cos * dx + sin * dy, cos * dy - sin * dx
            reach = np.sqrt(along * along + across * across)                             # (F, N)
            disk = radius + error[:, 0:1] + (distance[None, :] + radius) * error[:, 1:2] + error[:, 2:3]
            # The beam whose half-increment either side holds each bearing (beam b covers b -+ 1/2 increments).
            offset = np.arctan2(across, along) - (math.remainder(angle_min, TWO_PI) - 0.5 * increment)
            offset += TWO_PI * (offset < 0.0)
            index = (offset * (1.0 / increment)).astype(np.intp)
            half = np.arcsin(np.minimum(disk / np.maximum(reach, 1e-12), 1.0))
            # The window holds every beam whose cell meets the disk's bearings, and one more either side
            # (the beams that bracket its edge directions): half-width ceil(half / increment) + 2, rounded up
            # to a power of two.
            level = np.ceil(np.log2(np.ceil(half * (1.0 / increment)) + 2.0)).astype(np.intp)
            usable = (index < n_beams) & (disk < reach) & (level < len(_WINDOWS))
            seen = minima[slots[:, None], np.minimum(level, len(_WINDOWS) - 1), np.minimum(index, n_beams - 1)]
            free |= np.any(usable & (seen >= reach + disk), axis=0)
        return free

    def travel(self, scans: tuple[LaserScan, ...], inside: float, keep: float, extent: float,
               spacing: float = SEEN_FREE_SPACING) -> float:
        """How far the base may translate [m] with every point no lidar sees now within ``keep`` of its path
        seen free by a kept scan.

        The body (every point within its reach of the base origin) and the margin, ``keep`` [m] in
        all, over a path of length ``s`` from the base origin stay within ``keep + s`` of it; the
        answer is the largest ``s`` such that every grid cell (:func:`blind_cells`) within ``keep + s``
        that no lidar sees now and that is not inside the body's inscribed disk (``inside`` [m]) was
        seen free, at most ``extent - keep`` (the grid reaches ``extent`` [m]). Zero when nothing
        has been kept.
        """
        if not self._groups:
            return 0.0
        keys = tuple(_layout_key(scan) for scan in scans)
        centres, distance = blind_cells(keys, inside, extent, spacing)
        radius = spacing / math.sqrt(2.0)
        if not centres.shape[0]:
            return max(extent - keep, 0.0)
        free = self.certified(centres, distance, radius)
        unseen = distance[~free] - radius
        reach = float(unseen[0]) if unseen.size else extent
        return max(min(reach, extent) - keep, 0.0)


class _KeptScans:
    """The kept scans of one beam layout, each in a slot of fixed arrays (keeping or forgetting one copies none of
    the others).

    Per slot: the lidar's pose (3,) and the odometry error bound accumulated since it was kept (translation, turn,
    and the turns' lever beyond the base: the sum of each carry's turn times the base's path since that carry)
    (3,), both as of the base frame of :class:`SeenFree`'s last rebase; the beams' seen ranges (n,) and the
    windows' smallest of them (W, n), computed when first asked (:meth:`minima`); the order it was kept in.
    """

    def __init__(self, capacity: int, n_beams: int, wraps: bool) -> None:
        self.poses = np.zeros((capacity, 3))
        self.error = np.zeros((capacity, 3))
        self.seen = np.empty((capacity, n_beams))
        self._minima = np.empty((capacity, len(_WINDOWS), n_beams))
        self._ready = np.zeros(capacity, dtype=bool)
        self.order = np.zeros(capacity, dtype=np.int64)
        self.used = np.zeros(capacity, dtype=bool)
        self.wraps = wraps

    @property
    def count(self) -> int:
        return int(np.count_nonzero(self.used))

    def slots(self) -> np.ndarray:
        """The slots in use, in the order their scans were kept."""
        slots = np.flatnonzero(self.used)
        return slots[np.argsort(self.order[slots], kind="stable")]

    def keep(self, mount: Pose2D, seen: np.ndarray, order: int) -> None:
        free = np.flatnonzero(~self.used)
        if not free.size:       # more scans of this layout in one call than the capacity: grow
            free = np.array([self.used.size])
            self.poses, self.error, self.seen, self._minima, self._ready, self.order, self.used = (
                np.concatenate((array, array[:1])) for array in (self.poses, self.error, self.seen, self._minima,
                                                                  self._ready, self.order, self.used))
        slot = int(free[0])
        self.poses[slot] = (mount.x, mount.y, mount.yaw)
        self.error[slot] = 0.0
        self.seen[slot] = seen
        self._ready[slot] = False
        self.order[slot] = order
        self.used[slot] = True

    def minima(self, slots: np.ndarray) -> np.ndarray:
        """The windows' smallest seen ranges of every slot ``(capacity, W, n)``, those of ``slots`` up to date."""
        for slot in slots[~self._ready[slots]]:
            self._minima[slot] = _window_minima(self.seen[slot], self.wraps)
            self._ready[slot] = True
        return self._minima


def _window_minima(seen: np.ndarray, wraps: bool) -> np.ndarray:
    """``(len(_WINDOWS), n)``: per window half-width ``w`` and beam ``b``, the smallest of ``seen[b - w .. b + w]``
    (beams outside the scan count as ``-inf``, or wrap round for a full turn)."""
    n = seen.size
    pad = int(_WINDOWS[-1])
    if wraps:
        padded = np.concatenate((np.resize(seen[::-1], pad)[::-1] if n else seen, seen, np.resize(seen, pad)))
    else:
        padded = np.concatenate((np.full(pad, -np.inf), seen, np.full(pad, -np.inf)))
    out = np.empty((len(_WINDOWS), n))
    # A window of half-width 2w is the smaller of the two windows of half-width w centred w either side.
    current = np.minimum(np.minimum(padded[:-2], padded[1:-1]), padded[2:])      # half-width 1, index shifted by 1
    offset, width = 1, 1
    for level, target in enumerate(_WINDOWS):
        while width < target:
            current = np.minimum(current[:-2 * width], current[2 * width:])
            offset += width
            width *= 2
        out[level] = current[pad - offset: pad - offset + n]
    return out


def dead_reckoning(start: np.ndarray, end: np.ndarray, elapsed: float) -> tuple[Pose2D, tuple[float, float]]:
    """The base's motion between two velocity measurements, and the bound of its error (A5).

    Each component of the base's velocity moves monotonically from the measurement ``start`` to
    the measurement ``end`` (A4, and any base that gets there late, after a delay), so the
    distance [m] (and the angle [rad]) covered lies between ``start elapsed`` and
    ``end elapsed``. The estimate is the middle of that interval, the trapezoid
    ``(start + end) elapsed / 2``, off by at most ``|end - start| elapsed / 2``; the motion is
    the arc of those mean velocities. (A4's bases get there no later than a linear ramp, which
    would allow a quarter; the half also covers a base whose velocity follows the command with a
    delay, as real bases do.) At time ``t`` into the period the heading is off the arc's by at
    most ``t |omega_end - omega_start| / 2``, which drags the path sideways while the base covers
    ground: the end of the period is off by at most the speed's error ``|v_end - v_start|
    elapsed / 2`` plus ``max(|v_start|, |v_end|) elapsed e_rotation / 2`` (a base that turns
    at once from one yaw rate to the other, at full speed, is that far off).

    Args:
        start: ``(v, omega)`` measured at the previous call [m/s, rad/s].
        end: ``(v, omega)`` measured now [m/s, rad/s].
        elapsed: time between the two measurements [s].

    Returns:
        ``(motion, (e_translation, e_rotation))``: the new base frame in the old one [m, m, rad],
        and the bound of the error of its distance [m] and of its angle [rad]; a point ``d`` from
        the base is off by at most ``e_translation + d e_rotation`` after the motion.
    """
    v, omega, error = reckoning(start, end, elapsed)
    return unicycle_step(Pose2D(), v, omega, elapsed), error


def reckoning(start: np.ndarray, end: np.ndarray, elapsed: float) -> tuple[float, float, tuple[float, float]]:
    """:func:`dead_reckoning` before its arc: the mean velocity ``(v [m/s], omega [rad/s])`` the arc holds for
    ``elapsed`` [s] and the bound ``(e_translation [m], e_rotation [rad])`` of the motion's error."""
    (v0, w0), (v1, w1) = (float(value) for value in start), (float(value) for value in end)   # floats: a call's
    rotation = 0.5 * elapsed * abs(w1 - w0)                                                   # arithmetic, not arrays
    drag = 0.5 * elapsed * max(abs(v0), abs(v1)) * rotation
    return 0.5 * (v0 + v1), 0.5 * (w0 + w1), (0.5 * elapsed * abs(v1 - v0) + drag, rotation)


def motion_spread(points: np.ndarray, error: tuple[float, float]) -> np.ndarray:
    """How far [m] each of ``points`` ``(N, 2)`` (base frame [m]) may lie from where a motion with the error bound
    ``error = (e_translation [m], e_rotation [rad])`` (:func:`dead_reckoning`) puts it: ``e_translation + d
    e_rotation``, ``d`` its distance from the base origin."""
    return error[0] + np.hypot(points[:, 0], points[:, 1]) * error[1]


def sweep_poses(ages: np.ndarray, parts: list[tuple[float, float, float]], mount: Pose2D, compiled: Any = None
                ) -> tuple[Pose2D, np.ndarray]:
    """Where a turning lidar was at each beam, ``ages[i]`` [s] before now (monotonic over the beams: one sweep), in
    the current base frame: the lidar pose of the middle beam [m, m, rad], and each beam's ``(n, 3)`` relative to it
    [m, m, rad] (:attr:`~safenav.scan.LaserScan.sweep_motion`).

    ``parts``: ``(length [s], v [m/s], omega [rad/s])`` of the motion back from now, the latest first
    (:meth:`~safenav.filters.SafetyFilter.latent_motion`'s parts); a beam older than all of them was where the oldest
    began. ``mount``: the lidar's pose on the base. ``compiled``: the kernels of :mod:`~safenav.filters.kernels`
    (the same poses, by one compiled loop).
    """
    # The base pose at the end of each part (its start in time), walking back: the end pose composed with the arc
    # of ``(-v, -omega)`` over the part (the inverse of the arc the base drove).
    ends, covered = [Pose2D()], [0.0]
    for part, v, omega in parts:
        ends.append(ends[-1].compose(unicycle_step(Pose2D(), -v, -omega, part)))
        covered.append(covered[-1] + part)
    if compiled is not None:
        reference, relative = compiled.sweep_poses(plain(ages), np.array(covered), np.array(parts, dtype=float).reshape(
            -1, 3), np.array([tuple(end) for end in ends]), float(mount.x), float(mount.y), float(mount.yaw))
        return Pose2D(float(reference[0]), float(reference[1]), float(reference[2])), relative
    # A beam ``s`` into a part (counted back from its end) was at the part's end pose composed with the arc back over
    # ``s``, whose turn is ``-omega s``; each part's beams are a slice of the sorted ages.
    descending = ages[0] > ages[-1]
    order = ages[::-1] if descending else ages
    x, y = np.zeros(ages.size), np.zeros(ages.size)
    cos_yaw, sin_yaw = np.ones(ages.size), np.zeros(ages.size)
    first = int(np.searchsorted(order, 0.0, side="right"))      # beams of age 0 were taken now
    for (part, v, omega), end, start in zip(parts, ends, covered, strict=False):
        last = int(np.searchsorted(order, start + part, side="right"))
        if last > first:
            back = order[first:last] - start
            turn = omega * back
            sin_turn, sin_half = np.sin(turn), np.sin(0.5 * turn)
            cos_turn = 1.0 - 2.0 * sin_half * sin_half
            if abs(omega) > 1e-12:
                ax, ay = (-v / omega) * sin_turn, (2.0 * v / omega) * (sin_half * sin_half)
            else:
                ax, ay = -v * back, np.zeros(back.size)
            c, s = math.cos(end.yaw), math.sin(end.yaw)
            x[first:last], y[first:last] = end.x + c * ax - s * ay, end.y + s * ax + c * ay
            cos_yaw[first:last], sin_yaw[first:last] = c * cos_turn + s * sin_turn, s * cos_turn - c * sin_turn
            first = last
    if first < ages.size:       # older than the parts: where the oldest part began
        x[first:], y[first:] = ends[-1].x, ends[-1].y
        cos_yaw[first:], sin_yaw[first:] = math.cos(ends[-1].yaw), math.sin(ends[-1].yaw)
    if descending:
        x, y, cos_yaw, sin_yaw = x[::-1], y[::-1], cos_yaw[::-1], sin_yaw[::-1]
    # The lidar at each beam (the base pose composed with the mount), relative to the lidar at the middle beam.
    lidar_x = x + cos_yaw * mount.x - sin_yaw * mount.y
    lidar_y = y + sin_yaw * mount.x + cos_yaw * mount.y
    middle = ages.size // 2
    c0, s0 = float(cos_yaw[middle]), float(sin_yaw[middle])
    reference = Pose2D(float(lidar_x[middle]), float(lidar_y[middle]), wrap_angle(math.atan2(s0, c0) + mount.yaw))
    dx, dy = lidar_x - reference.x, lidar_y - reference.y
    cr, sr = math.cos(reference.yaw), math.sin(reference.yaw)
    relative = np.empty((ages.size, 3))
    relative[:, 0] = cr * dx + sr * dy
    relative[:, 1] = -sr * dx + cr * dy
    relative[:, 2] = np.arctan2(c0 * sin_yaw - s0 * cos_yaw, c0 * cos_yaw + s0 * sin_yaw)    # yaw - the middle's
    return reference, relative


class SweepShift(NamedTuple):
    """Points of the base frame as a turning lidar's beams saw them (:func:`sweep_shift`)."""

    cos: np.ndarray
    """``(N,)`` cosines of each point's turn [-]."""
    sin: np.ndarray
    """``(N,)`` its sines."""
    shift: np.ndarray
    """``(N, 2)`` its shift [m]."""
    unseen: np.ndarray
    """``(N,)`` the points no beam looked at: the beam whose pose looks at a point's bearing is not the beam whose pose
    that bearing was taken from (the seam of a full turn that the base turned against, where the sweep left a gap)."""

    def to_mount(self, points: np.ndarray) -> np.ndarray:
        """Each point where it lies for a lidar at the mount as it lay for the lidar of its beam [m]."""
        x, y = points[:, 0], points[:, 1]
        return np.column_stack((self.cos * x - self.sin * y, self.sin * x + self.cos * y)) + self.shift

    def back(self, points: np.ndarray) -> np.ndarray:
        """The inverse of :meth:`to_mount` [m]."""
        x, y = points[:, 0] - self.shift[:, 0], points[:, 1] - self.shift[:, 1]
        return np.column_stack((self.cos * x + self.sin * y, -self.sin * x + self.cos * y))


#: Rounds of finding the beam that looks at a point (each lands on it more nearly by the ratio of the base's turn rate
#: to the lidar's, a few per cent; the last round's beam is the nearest but for a sweep far faster than any base).
SWEEP_ROUNDS = 3


def sweep_step(scan: LaserScan) -> tuple[float, float]:
    """How far [m] and how much [rad] the lidar moved between two neighbouring beams, at most (with the turn about the
    lidar, ``|mount|`` from the base origin), as a bound ``(e_translation, e_rotation)``: the error of looking at a
    point from a neighbour of the beam that looks at it (:func:`sweep_shift`); ``(0, 0)`` without a sweep motion."""
    motion = scan.sweep_motion
    if motion is None or motion.shape[0] < 2:
        return 0.0, 0.0
    step = np.abs(np.diff(motion, axis=0))
    turn = float(step[:, 2].max())
    return float(np.hypot(step[:, 0], step[:, 1]).max()) + math.hypot(scan.mount.x, scan.mount.y) * turn, turn


def seam_gap(scan: LaserScan) -> float:
    """How wide [rad] the gap is that a turning lidar's full turn left where its last beam meets its first, because
    the base turned against the lidar's spin during the sweep (:attr:`~safenav.scan.LaserScan.sweep_motion`): the
    directions between them were looked at by no beam of this scan. 0 for a scan that is no full turn, taken at once,
    or whose base turned with the spin (the turn then overlaps)."""
    motion = scan.sweep_motion
    if motion is None or scan.n_beams * scan.angle_increment < TWO_PI - 1e-9:
        return 0.0
    return max(TWO_PI - (scan.n_beams * scan.angle_increment + float(motion[-1, 2] - motion[0, 2])), 0.0)


def sweep_shift(scan: LaserScan, points: np.ndarray, compiled: Any = None) -> SweepShift:
    """For each of ``points`` (base frame [m]), the map that puts it where a lidar at the scan's mount would see it as
    the beam that looks at it saw it from its own pose (:attr:`~safenav.scan.LaserScan.sweep_motion`): the point in
    that beam's lidar frame, expressed from the mount. The beam is found from the mount's bearing, then again from the
    pose of the beam found (:data:`SWEEP_ROUNDS` rounds); a bearing outside the field of view takes the nearer end
    beam. A point whose bearing from the pose of the beam found lies in another beam's cell is one no beam looked at
    (:attr:`SweepShift.unseen`). ``compiled``: the kernels of :mod:`~safenav.filters.kernels` (the same maps, by one
    compiled loop)."""
    motion = scan.sweep_motion
    mount, n, increment = scan.mount, scan.n_beams, scan.angle_increment
    if compiled is not None:
        return SweepShift(*compiled.sweep_shift(plain(points), frozen(motion), float(mount.x), float(mount.y),
                                                float(mount.yaw), float(scan.angle_min), float(increment),
                                                SWEEP_ROUNDS))
    cm, sm = math.cos(mount.yaw), math.sin(mount.yaw)
    local_x = cm * (points[:, 0] - mount.x) + sm * (points[:, 1] - mount.y)     # in the mount's lidar frame
    local_y = -sm * (points[:, 0] - mount.x) + cm * (points[:, 1] - mount.y)
    turn_cos, turn_sin = np.cos(motion[:, 2]), np.sin(motion[:, 2])
    beams = np.full(points.shape[0], -1, dtype=np.intp)
    x, y = local_x, local_y
    for round_index in range(SWEEP_ROUNDS + 1):
        offset = np.mod(np.arctan2(y, x) - scan.angle_min + 0.5 * increment, TWO_PI) - 0.5 * increment
        index = np.floor(offset / increment + 0.5)
        beyond = index > n - 1      # outside the field of view: the nearer end beam
        index[beyond] = np.where(offset[beyond] - (n - 1) * increment < TWO_PI - offset[beyond], n - 1, 0)
        if round_index == SWEEP_ROUNDS:
            unseen = index.astype(np.intp) != beams
            break
        beams = index.astype(np.intp)
        dx, dy, c, s = motion[beams, 0], motion[beams, 1], turn_cos[beams], turn_sin[beams]
        x = c * (local_x - dx) + s * (local_y - dy)        # in the frame of the lidar at the beam
        y = -s * (local_x - dx) + c * (local_y - dy)
    # The base-frame map p -> M D^-1 M^-1 p: a turn by -turn about the mount and a shift.
    dx, dy, c, s = motion[beams, 0], motion[beams, 1], turn_cos[beams], -turn_sin[beams]     # the turn back
    # D^-1 in the mount's lidar frame: rotate by -turn, then shift by -R(-turn) (dx, dy); in the base frame the
    # rotation is about the mount's origin.
    shift_x = -(c * dx - s * dy)
    shift_y = -(s * dx + c * dy)
    base_shift_x = cm * shift_x - sm * shift_y
    base_shift_y = sm * shift_x + cm * shift_y
    # p' = M.xy + R_m (R(-turn) R_m^T (p - M.xy) + shift) = R(-turn) p + (M.xy - R(-turn) M.xy + R_m shift)
    shift = np.column_stack((mount.x - (c * mount.x - s * mount.y) + base_shift_x,
                             mount.y - (s * mount.x + c * mount.y) + base_shift_y))
    return SweepShift(c, s, shift, unseen)


def _seen_again(scan: LaserScan, points: np.ndarray, tolerance: np.ndarray, uncertainty: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which remembered ``points`` ``scan`` shows or contradicts, and where the others may still be.

    The beam nearest a point's direction sees it again when it is informative and reads no
    nearer than the point minus ``tolerance``: about its range (the point is there and the
    scan carries it now) or farther (the space is free). A nearer reading occludes it,
    ``-inf`` too; ``INVALID`` readings and directions outside the field of view say nothing.
    A point may truly be anywhere within ``uncertainty`` [m] of where it is remembered, which
    the lidar sees over a fan of bearings (all of them when the disk holds the lidar): every
    beam whose cell (half an increment either side) meets the fan must be in the field of view
    and informative too, or the point may be where the lidar does not look. (Where such a beam
    reads nearer, the point may be hidden behind that reading, as any obstacle the robot never
    saw may be: the filters keep the edges of what obstacles hide, ``shadow_points``, for every
    scan. A remembered object narrower than the gap between two beams can be missed by the
    nearest beam, as by any scan: the margin covers the beam gap, ``docs/safety.md``.)

    A point whose fan passes one edge of the field of view, and is seen otherwise, may only be in
    the part of its disk out of view (the part in view the scan accounts for as above), which lies
    beyond the line of that edge (the fan spans less than half a turn: the lidar is outside the
    disk), or, when the disk holds the lidar and the field of view spans half a turn or more,
    beyond the lines of both edges: it is moved to the middle of the chord of the line it lies
    deeper behind, with the chord's half-length as its uncertainty, the smallest disk that holds
    the disk's part beyond that line.

    Returns:
        ``(seen, points, uncertainty)``: the mask of the points seen again, and the points and their
        uncertainty [m] with those beyond one edge narrowed down.
    """
    n = scan.n_beams
    mount = scan.mount
    dx, dy = points[:, 0] - mount.x, points[:, 1] - mount.y
    reach = np.hypot(dx, dy)
    increment = scan.angle_increment
    offset = np.mod(np.arctan2(dy, dx) - mount.yaw - scan.angle_min + 0.5 * increment, TWO_PI) - 0.5 * increment
    index = np.floor(offset / increment + 0.5).astype(np.intp)
    seen = _seen_ranges(scan)
    inside = (index >= 0) & (index < n)
    again = inside & (seen.take(index, mode="clip") >= reach - tolerance)
    if not np.any(again & (uncertainty > 0.0)):
        return again, points, uncertainty
    # The fan's half-angle, and the beams whose cells it meets.
    half = np.where(uncertainty >= reach, math.pi, np.arcsin(np.minimum(uncertainty / np.maximum(reach, 1e-12), 1.0)))
    low = np.floor((offset - half) / increment + 0.5).astype(np.intp)
    high = np.floor((offset + half) / increment + 0.5).astype(np.intp)
    wraps = n * increment >= TWO_PI - 1e-9
    if wraps:
        whole = high - low + 1 >= n
        low, high = np.where(whole, 0, low), np.where(whole, n - 1, high)
        beyond, under, over = (np.zeros(points.shape[0], dtype=bool) for _ in range(3))
    else:
        under, over = low < 0, high >= n
        beyond = again & (under ^ over) & (uncertainty < reach)
        # A disk that holds the lidar meets every bearing; out of a field of view of half a turn or more it
        # lies beyond the lines of both edges.
        beyond |= again & (uncertainty >= reach) & (n * increment >= math.pi)
        again &= ~(under | over)
        low, high = np.maximum(low, 0), np.minimum(high, n - 1)      # the part of the fan in view
    check = (again | beyond) & (high > low)
    if check.any():
        informative = _range_minima(seen, _window_minima(seen, wraps), low[check], high[check]) > -np.inf
        again[check] &= informative
        beyond[check] &= informative
    if not beyond.any():
        return again, points, uncertainty
    # Beyond an edge: the edge's line through the lidar, its normal into the view, the point's distance from it
    # on the side in view (beyond both edges, the larger); the disk's part beyond that line is within the
    # chord's half-length of its middle.
    edges = scan.angle_min + mount.yaw + np.array([-0.5, n - 0.5]) * increment
    normals = np.array([[-math.sin(edges[0]), math.cos(edges[0])], [math.sin(edges[1]), -math.cos(edges[1])]])
    depths = np.column_stack((dx[beyond], dy[beyond])) @ normals.T                 # (B, 2): first, last
    under, over = under[beyond], over[beyond]
    pick = np.where(under & over, np.argmax(depths, axis=1), np.where(under, 0, 1))
    depth, normal = depths[np.arange(pick.size), pick], normals[pick]
    narrowed = depth > 0.0
    rows = np.flatnonzero(beyond)[narrowed]
    depth, normal = depth[narrowed], normal[narrowed]
    points, uncertainty = points.copy(), uncertainty.copy()
    points[rows] -= depth[:, None] * normal
    uncertainty[rows] = np.sqrt(np.maximum(uncertainty[rows] ** 2 - depth ** 2, 0.0))
    return again, points, uncertainty


def _seen_again_compiled(compiled: Any, scan: LaserScan, points: np.ndarray, tolerance: np.ndarray,
                         uncertainty: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_seen_again` by the compiled kernel ``compiled.seen_again`` (the same masks and points)."""
    mount, view = scan.mount, scan.field_of_view
    return compiled.seen_again(frozen(scan.ranges), frozen(scan.readings), _HIT, _NO_RETURN, float(scan.range_max),
                               float(scan.angle_min), float(scan.angle_increment), float(mount.x), float(mount.y),
                               float(mount.yaw), bool(view >= TWO_PI - 1e-9), bool(view >= math.pi),
                               plain(points), plain(tolerance), plain(uncertainty))


def _range_minima(values: np.ndarray, minima: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """The smallest of ``values[low .. high]`` for each pair (indices taken round the turn), from
    :func:`_window_minima`'s ``minima``: two windows of the largest half-width that fits, one from each end;
    ranges wider than the widest window one by one."""
    n = values.size
    length = high - low + 1
    level = np.floor(np.log2(np.maximum((length - 1) // 2, 1))).astype(np.intp)
    fits = (length >= 3) & (level < len(_WINDOWS))
    level = np.minimum(level, len(_WINDOWS) - 1)
    width = _WINDOWS[level]
    out = np.minimum(values.take(low % n), values.take(high % n))
    if fits.any():
        rows = minima[level[fits]]
        picked = np.arange(rows.shape[0])
        from_low, from_high = (low[fits] + width[fits]) % n, (high[fits] - width[fits]) % n
        out[fits] = np.minimum(rows[picked, from_low], rows[picked, from_high])
    for k in np.flatnonzero((length >= 3) & ~fits):
        out[k] = values.take(np.arange(low[k], high[k] + 1) % n).min()
    return out


def _seen_ranges(scan: LaserScan, shrink: float = 0.0) -> np.ndarray:
    """Per beam, the range [m] up to which it shows space as seen: a hit's range less ``shrink`` [m], ``range_max``
    for no return, ``-inf`` for a beam that says nothing (too close, invalid), so that no point passes a test
    against it."""
    readings = scan.readings
    return np.where(readings == _HIT, scan.ranges - shrink, np.where(readings == _NO_RETURN, scan.range_max, -np.inf))


def nearest_per_bin(points: np.ndarray, keys: np.ndarray, centre: tuple[float, float], n_bins: int,
                    angles: np.ndarray | None = None, compiled: Any = None) -> np.ndarray:
    """Indices of the point with the smallest key in each angular bin around ``centre``.

    Args:
        points: ``(N, 2)`` points [m].
        keys: ``(N,)`` values to minimise per bin (e.g. barrier values).
        centre: the point the bins are centred on [m].
        n_bins: number of equal bins over the full turn.
        angles: ``(N,)`` the points' bearings from ``centre`` [rad], when already known (a caller
            that bins the same points several times computes them once).
        compiled: the kernels of :mod:`~safenav.filters.kernels` (the same indices, by one compiled loop).

    Returns:
        Indices into ``points``, in increasing key order.
    """
    if len(points) == 0:
        return np.empty(0, dtype=np.intp)
    if angles is None:
        angles = np.arctan2(points[:, 1] - centre[1], points[:, 0] - centre[0])
    if compiled is not None:
        return compiled.nearest_per_bin(plain(angles), plain(keys), int(n_bins))
    bins = ((angles + math.pi) * (n_bins / TWO_PI)).astype(np.intp) % n_bins
    order = np.lexsort((keys, bins))
    sorted_bins = bins[order]
    first = np.empty(order.size, dtype=bool)
    first[0] = True
    np.not_equal(sorted_bins[1:], sorted_bins[:-1], out=first[1:])
    chosen = order[first]
    return chosen[np.argsort(keys[chosen], kind="stable")]
