"""Constraint families of the CBF filter: each one a small function returning rows ``G z <= h``.

The QP's variables are ``z = (v, omega, t_v, t_omega)``: the command [m/s, rad/s] and two
auxiliaries bounded below by ``|v|`` and ``|omega|`` (and by the current velocity's
magnitudes), through which the arc of a period enters the rows exactly. Every family
returns a :class:`Rows` block: the rows, the obstacle point behind each row (``-1`` when
none), the family's name, and whether the rows are *hard*. Only soft rows (obstacle
barriers and the braking rows derived from them) may ever be relaxed by a slack variable;
hard rows (the unknown region, the auxiliaries) never are: a command that cannot satisfy
them is not sent, the base brakes at its limits instead.

Each family states the invariant it guarantees, under which assumption, in its docstring;
``tests/filters/test_rows.py`` checks each one alone with hypothesis.

Notation: obstacle points ``o`` (base frame [m]); body disks ``j`` with control points
``p_j = c_j + (l, 0)`` (disk centre plus the look-ahead ``l``); barrier
``h_j(o) = ||p_j - o|| - (rho_j + l + margin + e_o)`` with ``e_o`` the point's position
uncertainty; ``n_j(o) = (p_j - o) / ||p_j - o||``. The base-frame velocity of ``p_j`` for a
command ``(v, omega)`` is ``J_j (v, omega)`` with ``J_j = [[1, -p_y], [0, p_x]]``, so the
rate at which ``p_j`` approaches ``o`` is ``a_j(o) . (v, omega)`` with
``a_j(o) = -J_j^T n_j(o)``. All rows are divided by the period (units of m/s).

Longer than most modules because each family carries its invariant and its proof sketch in its
docstring (that is what the tests check); the code of each family is short.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

__all__ = [
    "FAMILIES",
    "FIRST_HARD",
    "Geometry",
    "Rows",
    "abs_rows",
    "barrier_rows",
    "blind_rows",
    "box_range",
    "braking_coefficient",
    "braking_rows",
    "braking_swing",
    "gap_rows",
    "geometry",
    "polygon_geometry",
    "ramp_corners",
    "stack",
    "stopping_speed",
    "sweep_rows",
    "worst_case",
]

FAMILIES = ("barrier", "braking", "sweep", "gap", "blind", "abs")
"""Row family names, in the order :func:`stack` keeps them."""
HARD_FAMILIES = frozenset({"gap", "blind", "abs"})
"""Families that slack never relaxes (the last ones of :data:`FAMILIES`)."""
FIRST_HARD = min(FAMILIES.index(name) for name in HARD_FAMILIES)
"""Index in :data:`FAMILIES` of the first hard family: a row is hard when its family is at least this."""


class Rows(NamedTuple):
    """A block of rows ``G z <= h`` and where each comes from."""

    G: np.ndarray
    """``(k, 4)`` coefficients over ``z = (v, omega, t_v, t_omega)``."""
    h: np.ndarray
    """``(k,)`` right-hand sides [m/s]."""
    point: np.ndarray
    """``(k,)`` index of the obstacle point behind each row, ``-1`` when none."""
    family: np.ndarray
    """``(k,)`` index into :data:`FAMILIES` of each row."""

    @property
    def hard(self) -> np.ndarray:
        """``(k,)`` mask of the rows slack may never relax."""
        return self.family >= FIRST_HARD

    def __len__(self) -> int:
        return int(self.h.size)

    def take(self, mask: np.ndarray) -> Rows:
        return Rows(self.G[mask], self.h[mask], self.point[mask], self.family[mask])


def _rows(G: np.ndarray, h: np.ndarray, point: np.ndarray, family: str) -> Rows:
    return Rows(G, h, point, np.full(h.size, FAMILIES.index(family), dtype=np.intp))


def stack(*blocks: Rows) -> Rows:
    """One block of all the rows of ``blocks``."""
    blocks = tuple(block for block in blocks if block.h.size)
    if not blocks:
        return Rows(np.empty((0, 4)), np.empty(0), np.empty(0, dtype=np.intp), np.empty(0, dtype=np.intp))
    if len(blocks) == 1:
        return blocks[0]
    return Rows(np.vstack([b.G for b in blocks]), np.concatenate([b.h for b in blocks]),
                np.concatenate([b.point for b in blocks]), np.concatenate([b.family for b in blocks]))


class Geometry(NamedTuple):
    """Point-disk pairs of one call: barrier values and approach directions.

    Pairs are flattened point-major: pair ``k`` is point ``k // D`` and disk ``k % D``.
    """

    point: np.ndarray
    """``(K,)`` obstacle point index of each pair."""
    barrier: np.ndarray
    """``(K,)`` barrier value ``h_j(o)`` [m]."""
    approach: np.ndarray
    """``(K, 2)`` ``a_j(o)``: the approach rate of the pair is ``approach . (v, omega)`` [1, m]."""
    arc: np.ndarray
    """``(K, 2)`` coefficients of ``(t_v, t_omega)`` bounding the arc's effect: ``kappa (1, ||p_j||)``.

    The cosine of the point's bearing from the control point, relative to the heading, is
    ``approach[:, 0]`` (``-n_x``)."""


def slide(along: np.ndarray, lateral: np.ndarray, reach: np.ndarray, floor: float, travel: float
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The supporting half-plane of each point that leaves the most room to travel along the heading.

    A point ``o`` at distance ``rho`` from a control point ``p`` is kept ``reach`` away by any
    half-plane ``{x : u . (o - x) >= reach + c}`` with ``u`` a unit vector and ``c >= 0``:
    ``||x - o|| >= u . (o - x)``. The point's own direction (``u = (o - p) / rho``) gives the
    largest ``c``, the barrier ``h = rho - reach``, but every displacement with a component
    towards ``o`` then counts as an approach, so a row written with it forbids sliding past
    ``o`` once ``h`` is small, although the distance barely changes (the linearisation is loose
    by the square of the tangential displacement over ``rho``). Any other unit ``u`` gives a
    valid, smaller ``c'``; this picks, among those with ``c' >= floor`` (so that standing still
    keeps satisfying the barrier condition), the half-plane that contains the segment from
    ``p`` along the heading (towards ``o``'s side) up to ``travel``, with ``K = reach + floor``:

    * the point is within ``K`` already (``rho < K``), or ``travel`` is 0: its own direction;
    * the segment passes ``o`` at a lateral offset ``>= K`` and ``o`` is within ``travel``:
      the lateral direction (the half-plane is parallel to the heading);
    * the segment enters the disk of radius ``K`` about ``o``: the tangent to that disk
      parallel to the segment's line of entry (the largest speed along the heading);
    * otherwise: the direction from the segment's end to ``o``.

    Args:
        along: ``(K,)`` ``|o_x - p_x|``, the distance of each point along the heading [m].
        lateral: ``(K,)`` ``|o_y - p_y|`` [m].
        reach: ``(K,)`` distance kept from each point (radius, look-ahead, margin, uncertainty) [m].
        floor: smallest half-plane value ``c'`` a tilt may reach [m] (``(1 - gamma) H``).
        travel: length of the segment along the heading the half-plane should contain [m].

    Returns:
        ``(u_along, u_lateral, c')``: the half-plane's unit direction towards the point in
        ``(|along|, |lateral|)`` coordinates (signs as the point's), and its value [m].
    """
    distance = np.sqrt(along * along + lateral * lateral)
    own = distance - reach
    keep = reach + floor
    with np.errstate(invalid="ignore", divide="ignore"):
        entry = along - np.sqrt(np.maximum(keep * keep - lateral * lateral, 0.0))
        crossing = lateral < keep
        tangent = crossing & (travel >= entry)                        # the segment enters the disk of radius K
        parallel = ~crossing & (along <= travel)                       # it passes o at a lateral offset >= K
        ratio = np.where(tangent, lateral / np.where(keep > 0.0, keep, 1.0), 0.0)
        end_along = np.maximum(along - travel, 0.0)
        end_norm = np.sqrt(end_along * end_along + lateral * lateral)
        end_norm_safe = np.where(end_norm > 0.0, end_norm, 1.0)
        u_along = np.where(tangent, np.sqrt(np.maximum(1.0 - ratio * ratio, 0.0)),
                           np.where(parallel, 0.0, end_along / end_norm_safe))
        u_lateral = np.where(tangent, ratio, np.where(parallel, 1.0, lateral / end_norm_safe))
    value = u_along * along + u_lateral * lateral - reach
    # the point's own direction where no tilt is allowed (within K, or degenerate)
    own_direction = (distance < keep) | (~tangent & ~parallel & (end_norm <= 0.0)) | (travel <= 0.0)
    safe_distance = np.where(distance > 0.0, distance, 1.0)
    u_along = np.where(own_direction, along / safe_distance, u_along)
    u_lateral = np.where(own_direction, lateral / safe_distance, u_lateral)
    value = np.where(own_direction, own, value)
    return u_along, u_lateral, value


def geometry(points: np.ndarray, uncertainty: np.ndarray, centres: np.ndarray, radii: np.ndarray,
             lookahead: float, margin: float, kappa: float,
             limit: Callable[[float], float] | None = None, *, drop: bool = True, floor_ratio: float = 1.0,
             travel: float = 0.0) -> tuple[Geometry, np.ndarray]:
    """Barrier values and approach directions of every point against every body disk.

    Args:
        points: ``(N, 2)`` obstacle points, base frame [m].
        uncertainty: ``(N,)`` position uncertainty of each point [m] (added to the margin).
        centres: ``(D, 2)`` body disk centres [m].
        radii: ``(D,)`` body disk radii [m].
        lookahead: look-ahead distance ``l`` of the control points [m].
        margin: clearance kept between the disks and every point [m].
        kappa: arc coefficient ``w dt / 2``, ``w`` the fastest yaw rate within the period (see
            :func:`barrier_rows`).
        limit: given the smallest barrier ``H``, the largest barrier a kept pair may have [m]
            (pairs beyond it are dropped before their directions are computed); ``None`` keeps all.
        drop: ``False`` keeps the pairs beyond ``limit`` (untilted): the reference the cut is
            checked against.
        floor_ratio: ``1 - gamma``: tilted half-planes keep a value of at least
            ``floor_ratio H`` (see :func:`slide`).
        travel: segment along the heading the rows leave free [m] (see :func:`slide`; 0 = each
            pair's own direction). Only pairs within ``limit`` are tilted.

    Returns:
        The kept pairs' geometry (``barrier`` the value of each pair's half-plane, at most its
        barrier), and every point's smallest barrier over the disks ``(N,)`` [m].
    """
    control = centres + np.array([lookahead, 0.0])
    count, disks = points.shape[0], control.shape[0]
    if disks == 1:
        dx = control[0, 0] - points[:, 0]
        dy = control[0, 1] - points[:, 1]
    else:
        dx = (control[None, :, 0] - points[:, None, 0]).reshape(-1)
        dy = (control[None, :, 1] - points[:, None, 1]).reshape(-1)
    distance = np.sqrt(dx * dx + dy * dy)
    pair_uncertainty = uncertainty if disks == 1 else np.repeat(uncertainty, disks)
    offsets = radii + (lookahead + margin)
    barrier = distance - (offsets[0] if disks == 1 else np.tile(offsets, count)) - pair_uncertainty
    per_point = barrier if disks == 1 else barrier.reshape(count, disks).min(axis=1)
    pair_point = np.arange(count) if disks == 1 else np.repeat(np.arange(count), disks)
    disk = np.zeros(count, dtype=np.intp) if disks == 1 else np.tile(np.arange(disks), count)
    within = None
    if limit is not None and count:
        within = barrier <= limit(float(per_point.min()))
        if drop:
            keep = np.flatnonzero(within)
            dx, dy, distance, barrier, pair_point, disk = (array[keep] for array in
                                                           (dx, dy, distance, barrier, pair_point, disk))
            within = None
    degenerate = distance < 1e-9
    if degenerate.any():   # a point exactly at a control point: push it back along -x
        dx, dy, distance = np.where(degenerate, 1.0, dx), np.where(degenerate, 0.0, dy), np.where(degenerate, 1.0,
                                                                                                    distance)
        barrier = np.where(degenerate, -offsets[disk] - uncertainty[pair_point], barrier)
    if travel > 0.0 and barrier.size:
        # dx, dy = p - o: the point lies along the heading by -dx, to the side by -dy
        smallest = float(per_point.min())
        u_along, u_lateral, tilted = slide(np.abs(dx), np.abs(dy), distance - barrier, floor_ratio * smallest,
                                           travel)
        nx, ny = np.where(dx < 0.0, -u_along, u_along), np.where(dy < 0.0, -u_lateral, u_lateral)
        if within is not None:   # pairs beyond the limit keep their own direction (their rows cannot bind)
            nx, ny = np.where(within, nx, dx / distance), np.where(within, ny, dy / distance)
            tilted = np.where(within, tilted, barrier)
        barrier = tilted
    else:
        nx, ny = dx / distance, dy / distance
    approach = np.empty((barrier.size, 2))
    approach[:, 0] = -nx
    approach[:, 1] = nx * control[disk, 1] - ny * control[disk, 0]
    reach = np.sqrt(control[:, 0] ** 2 + control[:, 1] ** 2)
    arc = np.empty((barrier.size, 2))
    arc[:, 0] = kappa
    arc[:, 1] = kappa * reach[disk]
    return Geometry(pair_point, barrier, approach, arc), per_point


def polygon_geometry(points: np.ndarray, uncertainty: np.ndarray, polygon: np.ndarray, margin: float, kappa: float,
                     limit: Callable[[float], float] | None = None, *, drop: bool = True, floor_ratio: float = 1.0,
                     travel: float = 0.0) -> tuple[Geometry, np.ndarray]:
    """Barrier values and approach directions of every point against a convex footprint polygon.

    The barrier is the signed distance from the polygon (counter-clockwise vertices, base
    frame) to the point, minus the margin and the point's uncertainty. Seen from the body,
    a rigid motion moves the point ``o`` by ``-dt (v - omega o_y, omega o_x)`` to first order,
    and the signed distance to a convex set is convex in the point, so its linearisation at
    ``o`` (gradient ``g``) is a lower bound: the approach rate is ``g . (v - omega o_y,
    omega o_x)``, and the second-order remainder of the motion is at most
    ``kappa dt (|v| + |o| |omega|)`` (the arc coefficient uses the point's distance ``|o|``
    from the base origin). The rows of :func:`barrier_rows` then keep ``H(x+) >= (1 - gamma)
    H(x)`` for the polygon exactly as for a disk.

    Args:
        points: ``(N, 2)`` obstacle points, base frame [m].
        uncertainty: ``(N,)`` position uncertainty of each point [m].
        polygon: ``(V, 2)`` the convex footprint, counter-clockwise [m].
        margin: clearance kept between the polygon and every point [m].
        kappa: arc coefficient ``w dt / 2`` (see :func:`geometry`).
        limit, drop, floor_ratio: as :func:`geometry`.
        travel: as :func:`geometry`: each point outside the polygon gets the half-plane
            :func:`slide` picks for its nearest polygon point, if that half-plane still keeps the
            whole polygon ``floor_ratio H`` away (checked with the polygon's support function);
            otherwise its own.

    Returns:
        The kept points' geometry (one pair per point; ``barrier`` the value of each point's
        half-plane), and every point's barrier ``(N,)`` [m].
    """
    count = points.shape[0]
    a = polygon
    edge = np.roll(a, -1, axis=0) - a
    length2 = np.einsum("ij,ij->i", edge, edge)
    normal = np.column_stack((edge[:, 1], -edge[:, 0])) / np.sqrt(length2)[:, None]   # outward (counter-clockwise)
    relative = points[:, None, :] - a[None, :, :]                                    # (N, V, 2)
    t = np.clip(np.einsum("nvi,vi->nv", relative, edge) / length2, 0.0, 1.0)
    difference = relative - t[..., None] * edge[None]                                # point minus nearest edge point
    distance = np.sqrt(np.einsum("nvi,nvi->nv", difference, difference))
    nearest = np.argmin(distance, axis=1)
    rows = np.arange(count)
    plane = np.einsum("nvi,vi->nv", relative, normal)                               # signed distance to each edge line
    inside = np.all(plane <= 0.0, axis=1)
    deepest = np.argmax(plane, axis=1)
    outside_distance = distance[rows, nearest]
    signed = np.where(inside, plane[rows, deepest], outside_distance)
    with np.errstate(invalid="ignore", divide="ignore"):
        gradient = np.where(inside[:, None], normal[deepest],
                            difference[rows, nearest] / outside_distance[:, None])
    on_boundary = ~inside & (outside_distance < 1e-12)
    if on_boundary.any():
        gradient[on_boundary] = normal[nearest[on_boundary]]
    barrier = signed - margin - uncertainty
    keep, within = rows, None
    if limit is not None and count:
        within = barrier <= limit(float(barrier.min()))
        if drop:
            keep, within = np.flatnonzero(within), None
    kept, g = points[keep], gradient[keep]
    values = barrier[keep]
    if travel > 0.0 and keep.size:
        offset = difference[keep, nearest[keep]]            # o minus its nearest polygon point
        u_along, u_lateral, _ = slide(np.abs(offset[:, 0]), np.abs(offset[:, 1]), margin + uncertainty[keep],
                                      floor_ratio * float(barrier.min()), travel)
        tilted = np.column_stack((np.where(offset[:, 0] < 0.0, -u_along, u_along),
                                  np.where(offset[:, 1] < 0.0, -u_lateral, u_lateral)))
        support = np.max(tilted @ a.T, axis=1)
        value = np.einsum("ij,ij->i", tilted, kept) - support - margin - uncertainty[keep]
        use = ~inside[keep] & (value >= floor_ratio * float(barrier.min()) - 1e-12) & (value <= values + 1e-12)
        if within is not None:
            use &= within
        g = np.where(use[:, None], tilted, g)
        values = np.where(use, np.minimum(value, values), values)
    approach = np.empty((keep.size, 2))
    approach[:, 0] = g[:, 0]
    approach[:, 1] = g[:, 1] * kept[:, 0] - g[:, 0] * kept[:, 1]
    arc = np.empty((keep.size, 2))
    arc[:, 0] = kappa
    arc[:, 1] = kappa * np.sqrt(kept[:, 0] ** 2 + kept[:, 1] ** 2)
    return Geometry(keep, values, approach, arc), barrier


def barrier_rows(geo: Geometry, gamma: float, far_gamma: float, dt: float, smallest: float | None = None) -> Rows:
    """The discrete-time barrier condition, one row per point-disk pair (soft).

    Invariant: if every row holds for the mean velocity of the period, then
    ``h_j(o, x+) >= (1 - gamma) H(x)`` for every pair (``H`` the smallest barrier now),
    ``h_j(o, x+) >= (1 - gamma) h_j(o, x)`` for pairs inside the margin (``h_j <= 0``: every point
    the body is already too close to is left at the recovery rate), and, with ``far_gamma < 1``,
    ``h_j(o, x+) >= (1 - far_gamma) h_j(o, x)`` for pairs outside the margin. Hence
    ``H(x+) >= (1 - gamma) H(x)``: ``H >= 0`` is invariant.

    Why: ``||.||`` is convex, so ``h(x+) >= h(x) + n . delta`` for the displacement
    ``delta`` of the control point, and the exact displacement of a unicycle holding a
    velocity for ``dt`` differs from ``dt J w`` by at most ``kappa dt (|v| + ||p|| |omega|)``
    with ``kappa = w dt / 2``, ``w`` the fastest yaw rate within the period (the heading turns by
    at most ``w t``; the filter takes ``w`` over the box of reachable commands and the current
    velocity, ``omega_max`` without a velocity). The row
    ``a . w + kappa (t_v + ||p|| t_omega) <= (h - (1 - gamma) H) / dt`` is that bound.

    Assumption: the world is static over the period, the points are where the scan says
    (within the margin's noise allowance), and the base's velocity over the period has the
    mean ``w`` the row is written for (see :func:`ramp_corners`).

    ``smallest`` is ``H`` over every pair (default: over the pairs of ``geo``), so rows can be
    built for a subset of the pairs.
    """
    barrier = geo.barrier
    if smallest is None:
        smallest = float(barrier.min()) if barrier.size else math.inf
    rhs = barrier - (1.0 - gamma) * smallest
    if far_gamma < 1.0:
        rhs = np.where(barrier > 0.0, np.minimum(rhs, far_gamma * barrier), rhs)
    # A pair already inside the margin leaves at its own rate, whatever the smallest barrier: with
    # H < 0 the condition on H alone would let the body close on every shallower pair down to
    # (1 - gamma) H (a point 2 cm inside the margin approached by 17 cm because another is 26 cm in).
    rhs = np.where(barrier <= 0.0, np.minimum(rhs, gamma * barrier), rhs)
    return _rows(np.hstack((geo.approach, geo.arc)), rhs / dt, geo.point, "barrier")


def stopping_speed(barrier: np.ndarray, accel: float, reaction: float) -> np.ndarray:
    """Largest approach speed [m/s] from which a base stops within ``barrier`` [m].

    It reacts for ``reaction`` [s] (one period plus the base's lag), then brakes at
    ``accel`` [m/s^2]: ``s reaction + s^2 / (2 accel) <= barrier``.
    """
    reach = np.maximum(barrier, 0.0)
    return np.sqrt((accel * reaction) ** 2 + 2.0 * accel * reach) - accel * reaction


def braking_coefficient(coefficient: np.ndarray, barrier: np.ndarray, accel: float | np.ndarray, reference: float,
                        reaction: float) -> np.ndarray:
    """Row coefficient of a command component whose braking must stop within ``barrier``.

    A component ``x`` of the command (``v`` [m/s] or ``omega`` [rad/s]) contributes
    ``c x`` to a pair's approach rate and brakes at ``accel``; reacting for ``reaction`` and
    then braking, it carries the pair ``c (x reaction + x |x| / (2 accel))`` closer, so it
    stops within ``barrier`` iff ``c x <= |c| X`` with ``X = stopping_speed(barrier / |c|,
    accel, reaction)``. Note that the *approach rate* ``c x`` decelerates at ``|c| accel``,
    not at ``accel``: an oblique point (``|c| < 1``) needs a lower approach rate than a
    point head-on. The returned ``k`` writes that condition as ``k x <= S`` with ``S =
    stopping_speed(barrier, reference, reaction)`` (so that rows stay in [m/s] and ``k = c``
    for a head-on component braking at ``reference``)::

        k = sign(c) (sqrt(c^2 a^2 T^2 + 2 a^2 h |c| / accel) + |c| a T) / (sqrt(a^2 T^2 + 2 a h) + a T)

    with ``a = reference``, ``T = reaction``, ``h = max(barrier, 0)``; at ``h = 0`` it is ``c``
    (with ``T > 0``), and it tends to 0 with ``c``.
    """
    h = np.maximum(barrier, 0.0)
    magnitude = np.abs(coefficient)
    aT = reference * reaction
    numerator = np.sqrt(magnitude * (magnitude * (aT * aT) + (2.0 * reference * reference / accel) * h)) \
        + magnitude * aT
    denominator = np.sqrt(aT * aT + (2.0 * reference) * h) + aT
    scaled = np.divide(numerator, denominator, out=magnitude.copy(), where=denominator > 0.0)
    return np.copysign(scaled, coefficient)


def _term_signs(k: np.ndarray, low: float, high: float) -> tuple[np.ndarray, np.ndarray]:
    """Whether ``k x >= 0`` (``always``) and whether ``k x <= 0`` (``never``) for every ``x`` in ``[low, high]``."""
    nonnegative, nonpositive = low >= 0.0, high <= 0.0
    if nonnegative and nonpositive:     # x = 0 only
        everywhere = np.ones(k.shape, dtype=bool)
        return everywhere, everywhere
    if nonnegative:
        return k >= 0.0, k <= 0.0
    if nonpositive:
        return k <= 0.0, k >= 0.0
    zero = k == 0.0                     # x takes both signs: only a zero term has one sign
    return zero, zero


def braking_rows(geo: Geometry, accel: float, alpha: float, reaction: float, allowance: float = 0.0,
                 box: tuple[np.ndarray, np.ndarray] | None = None) -> Rows:
    """Approach caps that keep braking possible, up to three rows per pair (soft; needs the velocity).

    The approach rate of a pair is ``c_v v + c_omega omega`` (``c = geo.approach``). Braking
    after one period and the lag (``reaction``), ``v`` decelerates at ``a_max`` and ``omega``
    at ``alpha_max``, independently, so the pair closes by at most
    ``D = D_v + D_omega``, ``D_x = (c_x x)^+ (T + |x| / (2 accel_x))``. Each ``D_x`` is convex in
    ``s_x = (c_x x)^+``, so ``D <= h`` holds on the triangle ``s_v / S_v + s_omega / S_omega
    <= 1`` (``S_x`` the largest ``s_x`` alone that stops within ``h``, see
    :func:`braking_coefficient`), which with the positive parts is three linear rows: both
    terms, ``v``'s alone, ``omega``'s alone. A row is left out when another implies it for
    every command in ``box`` (a term of one sign over the whole box).

    Invariant: from any command the rows allow, a base that reacts for ``reaction`` and then
    brakes at its limits closes every pair's half-plane by at most its barrier (plus
    ``allowance``), to first order in the heading change (the heading's own change is the
    :func:`sweep_rows`' part; the arc terms bound the period's second-order motion).

    Assumption: the base decelerates at ``a_max`` and ``alpha_max`` once commanded to, after at
    most ``reaction`` = one period plus its lag time constant.

    ``allowance`` [m] (the range-noise part of the margin) is added to every barrier: the
    base stays able to stop before the margin less the allowance, so that noise that puts a
    reading just inside the margin does not forbid every approach (the barrier rows still
    push the base back out of the margin).
    """
    count = geo.barrier.size
    if not count:
        return stack()
    barrier = geo.barrier + allowance
    limit = stopping_speed(barrier, accel, reaction)
    k_v = braking_coefficient(geo.approach[:, 0], barrier, accel, accel, reaction)
    k_omega = braking_coefficient(geo.approach[:, 1], barrier, alpha, accel, reaction)
    if box is None:
        always_v, never_v = _term_signs(k_v, -math.inf, math.inf)
        always_omega, never_omega = _term_signs(k_omega, -math.inf, math.inf)
    else:
        # the sign of each term over the whole box: c x >= 0 (always approaching) or <= 0 (never);
        # a term with a zero coefficient is both, and needs no row of its own
        lower, upper = box
        always_v, never_v = _term_signs(k_v, float(lower[0]), float(upper[0]))
        always_omega, never_omega = _term_signs(k_omega, float(lower[1]), float(upper[1]))
    both = ~never_v & ~never_omega
    v_alone = ~always_omega & ~never_v
    omega_alone = ~always_v & ~never_omega
    # a pair that no command can make approach still gets its combined row (the arc terms)
    both |= ~(both | v_alone | omega_alone)
    # the three blocks in order (both terms, v alone, omega alone), built at once
    kind, index = np.nonzero(np.stack((both, v_alone, omega_alone)))
    G = np.empty((index.size, 4))
    G[:, 0] = np.where(kind == 2, 0.0, k_v[index])
    G[:, 1] = np.where(kind == 1, 0.0, k_omega[index])
    G[:, 2:] = geo.arc[index]
    return _rows(G, limit[index], geo.point[index], "braking")


def braking_swing(velocity: np.ndarray, alpha: float, dt: float, reaction: float) -> float:
    """Largest heading change [rad] from now until a braking base has stopped turning.

    Within the period the yaw rate reaches at most ``w = |omega| + alpha dt``; it holds (at
    most) ``w`` for the ``reaction`` time and then decelerates at ``alpha``:
    ``Delta = w reaction + w^2 / (2 alpha)``.

    Args:
        velocity: the base's velocity now ``(v, omega)`` [m/s, rad/s].
        alpha: yaw acceleration limit [rad/s^2].
        dt: the period [s].
        reaction: time before a braking command takes effect [s].
    """
    rate = abs(float(velocity[1])) + alpha * dt
    return rate * reaction + rate * rate / (2.0 * alpha)


def sweep_rows(geo: Geometry, velocity: np.ndarray, accel: float, alpha: float, dt: float, reaction: float,
               allowance: float = 0.0) -> Rows:
    """Speed caps along the heading for points the heading can still swing towards (soft; needs the velocity).

    While the base brakes its heading keeps turning, by at most ``Delta``
    (:func:`braking_swing`). A point within ``Delta`` of the
    heading (or of the reverse heading) may come to lie straight ahead before the base
    stops, so the speed along the heading is capped as if the base already faced it:
    ``sign v cos(max(|bearing| - Delta, 0)) + arc terms <= stopping_speed(h)``, the cosine
    entering through :func:`braking_coefficient` (a heading at angle ``phi`` from the point
    closes it by ``cos(phi)`` of the braking distance).

    Assumption: as :func:`braking_rows`; the yaw rate decelerates at ``alpha_max``.
    ``allowance``: as :func:`braking_rows`.
    """
    sweep = braking_swing(velocity, alpha, dt, reaction)
    barrier = geo.barrier + allowance
    limit = stopping_speed(barrier, accel, reaction)
    forward = geo.approach[:, 0]                 # cos of the bearing from the control point
    count = forward.size
    # cos(max(acos(cosine) - sweep, 0)) of the heading (first block) and the reverse heading (second),
    # without trigonometry per point
    cosine = np.concatenate((forward, -forward))
    sine = np.sqrt(np.maximum(1.0 - forward * forward, 0.0))
    effective = np.where(cosine >= math.cos(min(sweep, math.pi)), 1.0,
                         cosine * math.cos(sweep) + np.concatenate((sine, sine)) * math.sin(sweep))
    inside = np.flatnonzero(effective > 1e-6) if sweep < math.pi else np.arange(2 * count)
    pair = inside % count if count else inside
    cosine_inside = effective[inside]
    G = np.zeros((inside.size, 4))
    G[:, 0] = np.where(inside < count, 1.0, -1.0) * np.where(cosine_inside >= 1.0, 1.0, braking_coefficient(
        np.minimum(cosine_inside, 1.0), barrier[pair], accel, accel, reaction))
    G[:, 2:] = geo.arc[pair]
    return _rows(G, limit[pair], geo.point[pair], "sweep")


def worst_case(G: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Largest left side of each row of ``G`` ``(k, 4)`` over the finite box ``lower <= z <= upper``."""
    centre, spread = _box_terms(G, lower, upper)
    return centre + spread


def box_range(G: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Largest and smallest left side of each row of ``G`` ``(k, 4)`` over the finite box ``lower <= z <= upper``
    (the first is :func:`worst_case`'s)."""
    centre, spread = _box_terms(G, lower, upper)
    return centre + spread, centre - spread


def _box_terms(G: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each row's left side at the box's centre and its spread over the box: the extremes are their sum and
    difference."""
    # max(g l, g u) = g (l + u) / 2 + |g| (u - l) / 2: two matrix-vector products (a third of the time of the
    # elementwise form for a few hundred rows; equal to rounding). Finite bounds only: an infinite one gives
    # inf - inf here. Every caller passes the velocity box and the auxiliaries' bounds, finite.
    return G @ (0.5 * (lower + upper)), np.abs(G) @ (0.5 * (upper - lower))


def ramp_corners(rows: Rows, velocity: np.ndarray | None, lag: float, headroom: float = 0.0,
                 box: tuple[np.ndarray, np.ndarray] | None = None, *, reduce: bool = True) -> Rows:
    """The rows written for every mean velocity a base between ``velocity`` and the command can have.

    Over a period the base's velocity moves from ``velocity`` (``w0``) towards the command
    ``u``; its mean is ``u + B (w0 - u)`` with ``B = diag(b_v, b_omega)``, ``b in [0, lag]``
    (``lag`` = 1/2 for a base that reaches the command within the period, linearly or at
    its acceleration limit; ``(tau / dt)(1 - exp(-dt / tau))`` for a first-order lag of time
    constant ``tau``). Rows are linear in the mean, so holding at the four corners
    ``b in {0, lag}^2`` they hold for every such base. Without a velocity only ``B = 0``.

    The corner ``B = 0`` (the command itself) keeps ``headroom`` of the right side's magnitude for
    the next period, on the rows that some mean velocity within ``box`` (the bounds ``(lower, upper)``
    on ``z``; each component also between the box and ``w0``) violates without it; a row that no such
    velocity can violate holds as it is and gets none (the guarantee needs no headroom; held back from
    every row, with ``gamma`` near 1 it forbade approaching anything in range: a TurtleBot filtering at
    4 Hz reversed from a wall 2 m ahead). Without ``box`` every row gets it.

    With ``reduce``, only the rows that can bind are written, and each once (exact: the answer of a QP
    over them is that of the QP over all four corners within the box): a row is left out when its largest
    left side over every mean velocity is within its right side at ``B = 0``, which is the smallest; and
    a corner that only scales a zero term (a row without a ``v`` or an ``omega`` term, as the sweep rows
    and the one-term braking rows) repeats a corner with the same left side and a right side no smaller,
    so it is left out.
    """
    if velocity is None or lag <= 0.0 or not len(rows):
        return rows
    first = rows.h
    if box is not None:
        lower, upper = box
        hull_lower, hull_upper = lower.copy(), upper.copy()
        hull_lower[:2] = np.minimum(lower[:2], velocity)
        hull_upper[:2] = np.maximum(upper[:2], velocity)
        bind = worst_case(rows.G, hull_lower, hull_upper) > rows.h
        if headroom > 0.0:
            first = np.where(bind, rows.h - headroom * np.abs(rows.h), rows.h)
        if reduce and not bind.all():
            rows, first = rows.take(bind), first[bind]
    elif headroom > 0.0:
        first = rows.h - headroom * np.abs(rows.h)
    # the four corners at once: corner c scales the v and omega terms by (1 - b_v, 1 - b_omega) and moves
    # their share of the start velocity to the right side
    b = np.array([[0.0, 0.0], [lag, 0.0], [0.0, lag], [lag, lag]])
    h = (rows.h[None, :] - (b * velocity) @ rows.G[:, :2].T)
    h[0] = first
    count = len(rows)
    if box is None or not reduce:
        corner, index = np.repeat(np.arange(4), count), np.tile(np.arange(count), 4)
    else:
        distinct = np.empty((4, count), dtype=bool)
        distinct[0] = True
        distinct[1] = rows.G[:, 0] != 0.0
        distinct[2] = rows.G[:, 1] != 0.0
        distinct[3] = distinct[1] & distinct[2]
        corner, index = np.nonzero(distinct)       # corner-major, as the corners stacked
    G = rows.G[index]
    G[:, :2] *= (1.0 - b)[corner]
    return Rows(G, h[corner, index], rows.point[index], rows.family[index])


def _cone(G: np.ndarray) -> np.ndarray:
    """The rows ``g . (v, omega) <= 0`` that matter among ``G`` ``(k, 2)``: at most the two extreme ones.

    ``{u : g_k . u <= 0}`` is the polar of the cone the ``g_k`` span; if they span a
    half-plane or more, only ``u = 0`` is left, which the two rows ``+-g`` of any ``g``
    with the largest spread also leave (together with the bounds).
    """
    norms = np.hypot(G[:, 0], G[:, 1])
    G = G[norms > 1e-12] / norms[norms > 1e-12, None]
    if G.shape[0] <= 2:
        return G
    angles = np.sort(np.arctan2(G[:, 1], G[:, 0]))
    gaps = np.diff(np.concatenate((angles, angles[:1] + 2.0 * math.pi)))
    widest = int(np.argmax(gaps))
    if gaps[widest] <= math.pi:   # the directions span more than a half-plane: only u = 0 (and the axes) remain
        return np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    first, last = angles[(widest + 1) % angles.size], angles[widest]
    return np.array([[math.cos(first), math.sin(first)], [math.cos(last), math.sin(last)]])


def gap_rows(points: np.ndarray, normals: np.ndarray, side_tolerance: float, reach: float) -> Rows:
    """No part of the outline moves towards unknown space behind a run of invalid beams (hard).

    Invariant: for every outline sample ``b`` that faces a gap (a run of invalid beams wider
    than ``max_gap``, see :func:`~safenav.filters.perception.unknown_region`) the command
    moves ``b`` no further outwards: ``n . (v - omega b_y, omega b_x) <= 0``. Components
    within ``side_tolerance`` of tangential are tolerated (a translation almost along the
    outline, or a turn whose outward speed at ``b`` is below ``sin(tol) reach |omega|``).

    Assumption: nothing is known beyond the gap, so nothing may be approached there.
    """
    if points.shape[0] == 0:
        return stack()
    threshold = math.sin(side_tolerance)
    translate = np.where(np.abs(normals[:, 0]) > threshold, normals[:, 0], 0.0)
    turn = -normals[:, 0] * points[:, 1] + normals[:, 1] * points[:, 0]
    turn = np.where(np.abs(turn) > threshold * reach, turn, 0.0)
    coefficients = _cone(np.column_stack((translate, turn)))
    G = np.zeros((coefficients.shape[0], 4))
    G[:, :2] = coefficients
    return _rows(G, np.zeros(G.shape[0]), np.full(G.shape[0], -1), "gap")


def blind_rows(forward: bool, backward: bool, speed: float = 0.0) -> Rows:
    """No translation towards a side of the body outside every field of view beyond ``speed`` (hard).

    Invariant: ``v <= speed`` when translating forward would sweep outline samples that no
    lidar sees and whose way ahead does not come into view within the body's size (a
    180-degree lidar mounted backwards); ``v >= -speed`` likewise backwards (the rear of a
    forward-facing 180-degree lidar). ``speed`` [m/s] is 0 unless earlier scans saw the space
    that side free (the caller's stopping distance within it). Assumption: unknown space is
    never free.
    """
    G, h = [], []
    if forward:
        G.append([1.0, 0.0, 0.0, 0.0])
        h.append(speed)
    if backward:
        G.append([-1.0, 0.0, 0.0, 0.0])
        h.append(speed)
    G_array = np.array(G, dtype=float).reshape(-1, 4)
    return _rows(G_array, np.array(h, dtype=float), np.full(len(h), -1), "blind")


#: ``|v| <= t_v`` and ``|omega| <= t_omega`` over ``z = (v, omega, t_v, t_omega)``.
_ABS = np.array([[1.0, 0.0, -1.0, 0.0], [-1.0, 0.0, -1.0, 0.0], [0.0, 1.0, 0.0, -1.0], [0.0, -1.0, 0.0, -1.0]])


def abs_rows() -> Rows:
    """``|v| <= t_v``, ``|omega| <= t_omega`` (hard): the auxiliaries bound the command's magnitudes."""
    return _rows(_ABS.copy(), np.zeros(4), np.full(4, -1), "abs")
