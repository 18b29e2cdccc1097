"""The numba code of :data:`safenav.worlds.shapes.COMPILED_GAPS` (imported only when numba is installed and asked for).

:func:`polygon_gaps` mirrors :func:`safenav.worlds.shapes.polygon_gaps` line for line in loops (the same
separating axes, corner-to-side and centre-to-side distances, in the same arithmetic), without its pruning of
the obstacles that cannot be the nearest (pruning changes no value); :func:`signed_distance` mirrors
:meth:`safenav.worlds.World.signed_distance` (:func:`safenav.worlds.shapes.box_distance` and the circles' distances
in the same arithmetic); ``tests/worlds/test_world.py`` checks that both give the same values.
"""

from __future__ import annotations

import math

import numba
import numpy as np

_jit = numba.njit(cache=True, nogil=True)


@_jit
def _segment_distance(px, py, sx, sy, ex, ey):
    """shapes._segment_distances, one point and one segment ``s .. s + e``."""
    x, y = px - sx, py - sy
    t = min(max((x * ex + y * ey) / (ex * ex + ey * ey), 0.0), 1.0)
    return math.hypot(x - t * ex, y - t * ey)


@_jit
def _box_point(px, py, box):
    """shapes.box_distance, one point and one box (a row of ``shapes.box_array``) [m]."""
    dx, dy = px - box[0], py - box[1]
    cos, sin = box[4], box[5]
    qx = abs(cos * dx + sin * dy) - box[2]
    qy = abs(-sin * dx + cos * dy) - box[3]
    return math.hypot(max(qx, 0.0), max(qy, 0.0)) + min(max(qx, qy), 0.0)


@_jit
def signed_distance(points, boxes, circles):
    """World.signed_distance: ``(N,)`` the signed distance [m] of each point ``(N, 2)`` to the nearest of the boxes
    (rows of ``shapes.box_array``) and ``circles`` ``(C, 3)``; ``inf`` without obstacles."""
    count = points.shape[0]
    best = np.full(count, np.inf)
    for i in range(count):
        px, py = points[i, 0], points[i, 1]
        nearest = np.inf
        for m in range(boxes.shape[0]):
            nearest = min(nearest, _box_point(px, py, boxes[m]))
        for c in range(circles.shape[0]):
            nearest = min(nearest, math.hypot(px - circles[c, 0], py - circles[c, 1]) - circles[c, 2])
        best[i] = nearest
    return best


@_jit
def polygon_gaps(polygons, boxes, corners, normals, circles):
    """shapes.polygon_gaps: ``(K,)`` signed distances [m] of the convex counter-clockwise ``polygons`` ``(K, V, 2)``
    to the boxes (``boxes`` ``(M, 6)``, their ``corners`` and side ``normals`` ``(M, 4, 2)``) and ``circles``
    ``(C, 3)``; minus the penetration depth when they overlap, ``inf`` without obstacles."""
    count, sides = polygons.shape[0], polygons.shape[1]
    gaps = np.full(count, np.inf)
    edge = np.empty((sides, 2))
    normal = np.empty((sides, 2))
    for k in range(count):
        for v in range(sides):
            w = v + 1 if v + 1 < sides else 0
            ex, ey = polygons[k, w, 0] - polygons[k, v, 0], polygons[k, w, 1] - polygons[k, v, 1]
            edge[v, 0], edge[v, 1] = ex, ey
            length = math.hypot(ex, ey)
            normal[v, 0], normal[v, 1] = ey / length, -ex / length
        best = np.inf
        for m in range(boxes.shape[0]):
            # Separating axes: the polygon's edge normals (the box's corners beyond each edge) and the box's.
            separation = -np.inf
            for v in range(sides):
                beyond = np.inf
                for c in range(4):
                    beyond = min(beyond, (corners[m, c, 0] - polygons[k, v, 0]) * normal[v, 0]
                                 + (corners[m, c, 1] - polygons[k, v, 1]) * normal[v, 1])
                separation = max(separation, beyond)
            for e in range(4):
                outside = np.inf
                for v in range(sides):
                    outside = min(outside, (polygons[k, v, 0] - corners[m, e, 0]) * normals[m, e, 0]
                                  + (polygons[k, v, 1] - corners[m, e, 1]) * normals[m, e, 1])
                separation = max(separation, outside)
            if separation <= 0.0:
                best = min(best, separation)
                continue
            # Apart, the nearest pair is a corner of one and a side of the other.
            apart = np.inf
            for v in range(sides):      # shapes.box_distance of the polygon's corners
                apart = min(apart, _box_point(polygons[k, v, 0], polygons[k, v, 1], boxes[m]))
            for c in range(4):
                for v in range(sides):
                    apart = min(apart, _segment_distance(corners[m, c, 0], corners[m, c, 1], polygons[k, v, 0],
                                                         polygons[k, v, 1], edge[v, 0], edge[v, 1]))
            best = min(best, apart)
        for i in range(circles.shape[0]):
            depth, nearest = -np.inf, np.inf
            for v in range(sides):
                rx, ry = circles[i, 0] - polygons[k, v, 0], circles[i, 1] - polygons[k, v, 1]
                depth = max(depth, rx * normal[v, 0] + ry * normal[v, 1])          # < 0 inside the polygon
                nearest = min(nearest, _segment_distance(circles[i, 0], circles[i, 1], polygons[k, v, 0],
                                                         polygons[k, v, 1], edge[v, 0], edge[v, 1]))
            best = min(best, (depth if depth < 0.0 else nearest) - circles[i, 2])
        gaps[k] = best
    return gaps


@_jit
def _circle_entry(ox, oy, ux, uy, cx, cy, radius):
    """Where the ray from ``o`` along the unit ``u`` enters the circle (``inf``: it does not; ``-1``: it starts
    inside)."""
    wx, wy = ox - cx, oy - cy
    along = wx * ux + wy * uy
    outside = wx * wx + wy * wy - radius * radius
    if outside <= 0.0:
        return -1.0
    if along < 0.0 and along * along >= outside:
        return -along - math.sqrt(along * along - outside)
    return np.inf


@_jit
def _slab(position, velocity, half, enter, leave):
    """The times ``[enter, leave]`` narrowed to when ``|position + t velocity| <= half`` (empty: ``enter > leave``)."""
    if velocity == 0.0:
        return (enter, leave) if abs(position) <= half else (np.inf, -np.inf)
    near, far = (-half - position) / velocity, (half - position) / velocity
    return max(enter, min(near, far)), min(leave, max(near, far))


@_jit
def _box_entry(ox, oy, ux, uy, box):
    """Where the ray from ``o`` along the unit ``u`` enters the box (a row of ``shapes.box_array``; ``inf``: it
    does not; ``-1``: it starts inside)."""
    dx, dy = ox - box[0], oy - box[1]
    cb, sb, hx, hy = box[4], box[5], box[2], box[3]
    lx, ly = cb * dx + sb * dy, -sb * dx + cb * dy
    if abs(lx) <= hx and abs(ly) <= hy:
        return -1.0
    enter, leave = _slab(lx, cb * ux + sb * uy, hx, -np.inf, np.inf)
    enter, leave = _slab(ly, -sb * ux + cb * uy, hy, enter, leave)
    return enter if 0.0 <= enter <= leave else np.inf


@_jit
def ray_reach(x, y, yaw, mounts, increments, counts, directions, lengths, boxes, circles, slack):
    """Per ray of a base at ``(x, y, yaw)`` [m, m, rad]: how far it must reach to meet what it first meets among the
    boxes (rows of ``shapes.box_array``) and ``circles`` ``(C, 3)``, plus ``slack`` [m]; its full length
    (``lengths``) when that is shorter, when it meets nothing, or when its lidar sits inside an obstacle. The rays
    are the lidars' beams in order, their unit ``directions`` ``(R, 2)`` in the base frame: lidar ``l`` at
    ``mounts[l] = (x, y, first beam's angle)`` in the base frame, ``counts[l]`` beams ``increments[l]`` apart.
    Each obstacle is met only by the beams within its bounding circle's angular width (and one beam more either
    side). (A cylinder's circumscribed polygon, which the simulator casts against, holds its circle: the polygon
    is met no farther along than the circle.)"""
    c, s = math.cos(yaw), math.sin(yaw)
    reach = lengths.copy()
    first = np.full(lengths.size, np.inf)
    two_pi = 2.0 * math.pi
    n_circles = circles.shape[0]
    offset = 0
    for lidar in range(mounts.shape[0]):
        n, increment = counts[lidar], increments[lidar]
        ox = x + c * mounts[lidar, 0] - s * mounts[lidar, 1]
        oy = y + s * mounts[lidar, 0] + c * mounts[lidar, 1]
        start = mounts[lidar, 2] + yaw
        inside = False
        for k in range(n_circles + boxes.shape[0]):
            if k < n_circles:
                cx, cy, bound = circles[k, 0], circles[k, 1], circles[k, 2]
            else:
                box = boxes[k - n_circles]
                cx, cy, bound = box[0], box[1], math.hypot(box[2], box[3])
            distance = math.hypot(cx - ox, cy - oy)
            whole = distance <= bound
            bearing = (math.atan2(cy - oy, cx - ox) - start) % two_pi
            half = math.pi if whole else math.asin(bound / distance)
            for centre in (bearing - two_pi, bearing, bearing + two_pi):
                low = 0 if whole else max(math.floor((centre - half) / increment) - 1, 0)
                high = n - 1 if whole else min(math.ceil((centre + half) / increment) + 1, n - 1)
                for beam in range(low, high + 1):
                    ray = offset + beam
                    ux = c * directions[ray, 0] - s * directions[ray, 1]
                    uy = s * directions[ray, 0] + c * directions[ray, 1]
                    if k < n_circles:
                        entry = _circle_entry(ox, oy, ux, uy, cx, cy, bound)
                    else:
                        entry = _box_entry(ox, oy, ux, uy, boxes[k - n_circles])
                    if entry < 0.0:
                        inside = True
                        break
                    if entry < first[ray]:
                        first[ray] = entry
                if inside or whole:
                    break
            if inside:
                break
        if not inside:
            for beam in range(n):
                ray = offset + beam
                if first[ray] + slack < lengths[ray]:
                    reach[ray] = first[ray] + slack
        offset += n
    return reach
