"""The numba code of :data:`safenav.worlds.shapes.COMPILED_GAPS` (imported only when numba is installed and asked for).

:func:`polygon_gaps` mirrors :func:`safenav.worlds.shapes.polygon_gaps` line for line in loops (the same
separating axes, corner-to-side and centre-to-side distances, in the same arithmetic), without its pruning of
the obstacles that cannot be the nearest (pruning changes no value); ``tests/worlds/test_world.py`` checks
that both give the same values.
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
            cos, sin = boxes[m, 4], boxes[m, 5]
            for v in range(sides):      # shapes.box_distance of the polygon's corners
                dx, dy = polygons[k, v, 0] - boxes[m, 0], polygons[k, v, 1] - boxes[m, 1]
                qx = abs(cos * dx + sin * dy) - boxes[m, 2]
                qy = abs(-sin * dx + cos * dy) - boxes[m, 3]
                apart = min(apart, math.hypot(max(qx, 0.0), max(qy, 0.0)) + min(max(qx, qy), 0.0))
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
