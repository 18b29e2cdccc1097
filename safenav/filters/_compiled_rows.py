"""The numba code of :mod:`safenav.filters.kernels` (imported only when numba is installed and asked for).

Each function mirrors numpy code named in its docstring (:mod:`safenav.filters.rows`, the perception's shadow
edges, the MPC's direct SQP and its check of a plan); ``tests/filters/test_kernels.py`` checks each against it.
"""

from __future__ import annotations

import math

import numba
import numpy as np

_jit = numba.njit(cache=True, nogil=True)


@_jit
def braking_coefficient(c, barrier, accel, reference, reaction):
    """rows.braking_coefficient, one coefficient."""
    h = max(barrier, 0.0)
    magnitude = abs(c)
    aT = reference * reaction
    numerator = math.sqrt(magnitude * (magnitude * (aT * aT) + (2.0 * reference * reference / accel) * h)) \
        + magnitude * aT
    denominator = math.sqrt(aT * aT + (2.0 * reference) * h) + aT
    scaled = numerator / denominator if denominator > 0.0 else magnitude
    return math.copysign(scaled, c)

@_jit
def stopping_speed(barrier, accel, reaction):
    """rows.stopping_speed."""
    return math.sqrt((accel * reaction) ** 2 + 2.0 * accel * max(barrier, 0.0)) - accel * reaction

@_jit
def term_signs(k, low, high):
    """rows._term_signs, one coefficient: ``(always, never)``."""
    nonnegative, nonpositive = low >= 0.0, high <= 0.0
    if nonnegative and nonpositive:
        return True, True
    if nonnegative:
        return k >= 0.0, k <= 0.0
    if nonpositive:
        return k <= 0.0, k >= 0.0
    return k == 0.0, k == 0.0

@_jit
def box_halves(lower, upper):
    """The centre and the half-widths of the box ``lower <= z <= upper`` (rows._box_terms)."""
    return 0.5 * (lower + upper), 0.5 * (upper - lower)


@_jit
def box_terms(G, r, centre, half):
    """rows._box_terms, one row: row ``r``'s left side at the box's centre and its spread over the box (its extremes
    over the box are their sum and difference)."""
    middle = 0.0
    spread = 0.0
    for c in range(4):
        middle += G[r, c] * centre[c]
        spread += abs(G[r, c]) * half[c]
    return middle, spread


@_jit
def row_block(count):
    """Room for ``count`` rows ``(G, h, point, family)``, as :class:`~safenav.filters.rows.Rows` holds them."""
    return np.empty((count, 4)), np.empty(count), np.empty(count, dtype=np.intp), np.empty(count, dtype=np.intp)


@_jit
def pair_minima(points, uncertainty, control, offsets):
    """rows.geometry's ``per_point``: every point's smallest barrier over the disks [m]."""
    count, disks = points.shape[0], control.shape[0]
    per_point = np.empty(count)
    for i in range(count):
        best = np.inf
        for d in range(disks):
            dx = control[d, 0] - points[i, 0]
            dy = control[d, 1] - points[i, 1]
            value = math.sqrt(dx * dx + dy * dy) - offsets[d] - uncertainty[i]
            if value < best:
                best = value
        per_point[i] = best
    return per_point

@_jit
def cbf_distances(points, uncertainty, centres, radii, centred, spread):
    """The first steps of CBFSafetyFilter._constraints: every point's distance from the base origin [m], the smallest
    distance less the point's uncertainty (the cut's ceiling, ``inf`` without points) and the body's clearance
    (CBFSafetyFilter._clearance: a ``centred`` disk's nearest distance less its radius; else the disks' smallest
    distance to the points within twice the centres' ``spread`` of the nearest one, as BodyModel.clearance)."""
    count = points.shape[0]
    distance = np.empty(count)
    smallest = np.inf
    nearest = np.inf
    for i in range(count):
        x, y = points[i, 0], points[i, 1]
        value = math.sqrt(x * x + y * y)
        distance[i] = value
        if value - uncertainty[i] < smallest:
            smallest = value - uncertainty[i]
        if value < nearest:
            nearest = value
    if count == 0:
        return distance, smallest, np.inf
    if centred:
        return distance, smallest, nearest - radii[0]
    within = nearest + 2.0 * spread + 1e-9
    clearance = np.inf
    for i in range(count):
        if not distance[i] <= within:
            continue
        for d in range(centres.shape[0]):
            gap = math.hypot(points[i, 0] - centres[d, 0], points[i, 1] - centres[d, 1]) - radii[d]
            if gap < clearance:
                clearance = gap
    return distance, smallest, clearance


@_jit
def cbf_cut(points, uncertainty, distance, near, beyond, centres, radii, lookahead, margin):
    """The cut of CBFSafetyFilter._constraints for disk bodies: the points whose distance less uncertainty is within
    ``near`` [m] (and their uncertainty), whether that is every point, and the smallest barrier (BodyModel.barrier
    with ``lookahead`` and ``margin``) of the points left out within ``beyond`` (``inf`` when none)."""
    count = points.shape[0]
    kept = 0
    for i in range(count):
        if distance[i] - uncertainty[i] <= near:
            kept += 1
    kept_points, kept_uncertainty = np.empty((kept, 2)), np.empty(kept)
    left_out = np.inf
    j = 0
    for i in range(count):
        gap = distance[i] - uncertainty[i]
        if gap <= near:
            kept_points[j, 0], kept_points[j, 1] = points[i, 0], points[i, 1]
            kept_uncertainty[j] = uncertainty[i]
            j += 1
        elif gap <= beyond:
            for d in range(centres.shape[0]):
                value = math.hypot(points[i, 0] - (centres[d, 0] + lookahead), points[i, 1] - (centres[d, 1] + 0.0)) \
                    - (radii[d] + lookahead + margin + uncertainty[i])
                if value < left_out:
                    left_out = value
    return kept_points, kept_uncertainty, kept == count, left_out


@_jit
def obstacle_rows(points, uncertainty, control, offsets, per_point, limit, floor_ratio, travel, kappa,
                  gamma, own, period, smallest, with_velocity, velocity, a_max, alpha_max, reaction, allowance,
                  braking_reach, box_lower, box_upper, lag, z_lower, z_upper):
    """The obstacle rows of CBFSafetyFilter._constraints with the cut, for disk bodies: rows.geometry (the
    pairs within ``limit``, tilted by rows.slide), rows.barrier_rows, the pairs within ``braking_reach``,
    rows.braking_rows, rows.sweep_rows, rows.ramp_corners (``reduce=True``, the headroom ``gamma``), stacked
    in that order. Returns ``(G, h, point, family)``."""
    count, disks = points.shape[0], control.shape[0]
    # rows.geometry with drop=True: the pairs within the limit, point-major
    pairs = count * disks
    pair_point = np.empty(pairs, dtype=np.intp)
    barrier = np.empty(pairs)
    approach = np.empty((pairs, 2))
    arc = np.empty((pairs, 2))
    reach_of = np.empty(disks)
    for d in range(disks):
        reach_of[d] = math.sqrt(control[d, 0] ** 2 + control[d, 1] ** 2)
    floor = floor_ratio * per_point.min() if count else 0.0
    kept = 0
    for i in range(count):
        for d in range(disks):
            dx = control[d, 0] - points[i, 0]
            dy = control[d, 1] - points[i, 1]
            distance = math.sqrt(dx * dx + dy * dy)
            value = distance - offsets[d] - uncertainty[i]
            if not value <= limit:
                continue
            if distance < 1e-9:      # a point exactly at a control point: pushed back along -x
                dx, dy, distance = 1.0, 0.0, 1.0
                value = -offsets[d] - uncertainty[i]
            if travel > 0.0:
                # rows.slide, one pair
                along, lateral, reach = abs(dx), abs(dy), distance - value
                own_distance = math.sqrt(along * along + lateral * lateral)
                keep = reach + floor
                entry = along - math.sqrt(max(keep * keep - lateral * lateral, 0.0))
                crossing = lateral < keep
                tangent = crossing and travel >= entry
                parallel = (not crossing) and along <= travel
                end_along = max(along - travel, 0.0)
                end_norm = math.sqrt(end_along * end_along + lateral * lateral)
                if tangent:
                    ratio = lateral / (keep if keep > 0.0 else 1.0)
                    u_along, u_lateral = math.sqrt(max(1.0 - ratio * ratio, 0.0)), ratio
                elif parallel:
                    u_along, u_lateral = 0.0, 1.0
                else:
                    end_norm_safe = end_norm if end_norm > 0.0 else 1.0
                    u_along, u_lateral = end_along / end_norm_safe, lateral / end_norm_safe
                tilted = u_along * along + u_lateral * lateral - reach
                if (own_distance < keep or (not tangent and not parallel and end_norm <= 0.0)
                        or travel <= 0.0):
                    safe = own_distance if own_distance > 0.0 else 1.0
                    u_along, u_lateral, tilted = along / safe, lateral / safe, own_distance - reach
                nx = -u_along if dx < 0.0 else u_along
                ny = -u_lateral if dy < 0.0 else u_lateral
                value = tilted
            else:
                nx, ny = dx / distance, dy / distance
            pair_point[kept] = i
            barrier[kept] = value
            approach[kept, 0] = -nx
            approach[kept, 1] = nx * control[d, 1] - ny * control[d, 0]
            arc[kept, 0] = kappa
            arc[kept, 1] = kappa * reach_of[d]
            kept += 1
    # at most: a barrier row, three braking rows and two sweep rows per pair (every entry of a row is written)
    G, h, point, family = row_block(6 * kept)
    # rows.barrier_rows (family 0)
    for k in range(kept):
        value = barrier[k]
        rhs = value - (1.0 - gamma) * smallest
        if own < 1.0 and value > 0.0:
            rhs = min(rhs, own * value)
        if value <= 0.0:
            rhs = min(rhs, gamma * value)
        G[k, 0], G[k, 1], G[k, 2], G[k, 3] = approach[k, 0], approach[k, 1], arc[k, 0], arc[k, 1]
        h[k] = rhs / period
        point[k] = pair_point[k]
        family[k] = 0
    rows = kept
    if not with_velocity:
        return G[:rows], h[:rows], point[:rows], family[:rows]
    # the pairs within the braking reach (CBFSafetyFilter._constraints)
    close = np.empty(kept, dtype=np.intp)
    closes = 0
    for k in range(kept):
        if barrier[k] + allowance <= braking_reach:
            close[closes] = k
            closes += 1
    limit_of = np.empty(closes)
    k_v = np.empty(closes)
    k_omega = np.empty(closes)
    kinds = np.zeros((3, closes), dtype=np.bool_)
    for j in range(closes):
        k = close[j]
        value = barrier[k] + allowance
        limit_of[j] = stopping_speed(value, a_max, reaction)
        k_v[j] = braking_coefficient(approach[k, 0], value, a_max, a_max, reaction)
        k_omega[j] = braking_coefficient(approach[k, 1], value, alpha_max, a_max, reaction)
        always_v, never_v = term_signs(k_v[j], box_lower[0], box_upper[0])
        always_omega, never_omega = term_signs(k_omega[j], box_lower[1], box_upper[1])
        both = (not never_v) and (not never_omega)
        v_alone = (not always_omega) and (not never_v)
        omega_alone = (not always_v) and (not never_omega)
        kinds[0, j] = both or not (both or v_alone or omega_alone)
        kinds[1, j] = v_alone
        kinds[2, j] = omega_alone
    # rows.braking_rows (family 1): both terms, v alone, omega alone
    for kind in range(3):
        for j in range(closes):
            if not kinds[kind, j]:
                continue
            k = close[j]
            G[rows, 0] = 0.0 if kind == 2 else k_v[j]
            G[rows, 1] = 0.0 if kind == 1 else k_omega[j]
            G[rows, 2], G[rows, 3] = arc[k, 0], arc[k, 1]
            h[rows] = limit_of[j]
            point[rows] = pair_point[k]
            family[rows] = 1
            rows += 1
    # rows.sweep_rows (family 2): the heading's block, then the reverse heading's
    rate = abs(velocity[1]) + alpha_max * period
    sweep = rate * reaction + rate * rate / (2.0 * alpha_max)
    cos_limit, cos_sweep, sin_sweep = math.cos(min(sweep, math.pi)), math.cos(sweep), math.sin(sweep)
    for block in range(2):
        sign = 1.0 if block == 0 else -1.0
        for j in range(closes):
            k = close[j]
            forward = approach[k, 0]
            cosine = sign * forward
            sine = math.sqrt(max(1.0 - forward * forward, 0.0))
            effective = 1.0 if cosine >= cos_limit else cosine * cos_sweep + sine * sin_sweep
            if not (sweep >= math.pi or effective > 1e-6):
                continue
            value = barrier[k] + allowance
            coefficient = 1.0 if effective >= 1.0 else braking_coefficient(min(effective, 1.0), value, a_max,
                                                                          a_max, reaction)
            G[rows, 0] = sign * coefficient
            G[rows, 1] = 0.0
            G[rows, 2], G[rows, 3] = arc[k, 0], arc[k, 1]
            h[rows] = limit_of[j]
            point[rows] = pair_point[k]
            family[rows] = 2
            rows += 1
    if lag <= 0.0 or rows == 0:
        return G[:rows], h[:rows], point[:rows], family[:rows]
    # rows.ramp_corners with the box and reduce=True: the rows that can bind, in four corners
    hull_lower, hull_upper = z_lower.copy(), z_upper.copy()
    for c in range(2):
        hull_lower[c] = min(z_lower[c], velocity[c])
        hull_upper[c] = max(z_upper[c], velocity[c])
    middle, half = box_halves(hull_lower, hull_upper)
    bind = np.empty(rows, dtype=np.intp)
    binding = 0
    for r in range(rows):
        worst, spread = box_terms(G, r, middle, half)
        if worst + spread > h[r]:
            bind[binding] = r
            binding += 1
    G_out, h_out, point_out, family_out = row_block(4 * binding)
    written = 0
    for corner in range(4):
        b_v = lag if corner == 1 or corner == 3 else 0.0
        b_omega = lag if corner >= 2 else 0.0
        for j in range(binding):
            r = bind[j]
            if (b_v > 0.0 and G[r, 0] == 0.0) or (b_omega > 0.0 and G[r, 1] == 0.0):
                continue
            if corner == 0:
                h_out[written] = h[r] - gamma * abs(h[r])
            else:
                h_out[written] = h[r] - ((b_v * velocity[0]) * G[r, 0] + (b_omega * velocity[1]) * G[r, 1])
            G_out[written, 0] = G[r, 0] * (1.0 - b_v)
            G_out[written, 1] = G[r, 1] * (1.0 - b_omega)
            G_out[written, 2], G_out[written, 3] = G[r, 2], G[r, 3]
            point_out[written] = point[r]
            family_out[written] = family[r]
            written += 1
    return G_out[:written], h_out[:written], point_out[:written], family_out[:written]


@_jit
def scan_readings(ranges, range_min, range_max, hit, no_return, too_close, invalid):
    """LaserScan.readings, its ``_hit_mask`` and ``n_informative`` in one pass over the ranges."""
    n = ranges.size
    codes = np.empty(n, dtype=np.int8)
    hits = np.empty(n, dtype=np.bool_)
    informative = 0
    for i in range(n):
        r = ranges[i]
        inside = r >= range_min and r <= range_max
        hits[i] = inside
        if inside:
            codes[i] = hit
        elif r == np.inf:
            codes[i] = no_return
        elif r == -np.inf:
            codes[i] = too_close
        else:
            codes[i] = invalid
            continue
        informative += 1
    return codes, hits, informative


@_jit
def hit_points(ranges, hits, cos_base, sin_base, mount_x, mount_y):
    """perception.beam_points of one scan taken at once: the base-frame point of every ``HIT`` beam, in beam order
    (LaserScan.beam_points), and whether a beam reads ``TOO_CLOSE`` (whose point these do not give)."""
    count = 0
    close = False
    for i in range(ranges.size):
        if hits[i]:
            count += 1
        elif ranges[i] == -np.inf:
            close = True
    out = np.empty((count, 2))
    j = 0
    for i in range(ranges.size):
        if hits[i]:
            out[j, 0] = mount_x + ranges[i] * cos_base[i]
            out[j, 1] = mount_y + ranges[i] * sin_base[i]
            j += 1
    return out, close


@_jit
def shadow_beams(ranges, readings, hit, no_return, limit, spacing, jump, wraps):
    """perception.shadow_points of one scan, before the beams' directions: the beam and the range [m] of every
    point along the edges of what obstacles hide (``limit``: the reach plus the lidar's lever [m])."""
    n = ranges.size
    steps = np.zeros(n, dtype=np.intp)
    total = 0
    for i in range(n):
        if readings[i] != hit or not ranges[i] < limit - spacing:
            continue
        beyond = ranges[i] + jump
        edge = False
        for j in (i - 1, i + 1):
            if j < 0 or j >= n:
                if not wraps:
                    continue
                j = n - 1 if j < 0 else 0
            if readings[j] == hit:
                farther = ranges[j]
            elif readings[j] == no_return:
                farther = np.inf
            else:
                farther = -np.inf
            if farther > beyond:
                edge = True
        if edge:
            steps[i] = math.floor((limit - ranges[i]) / spacing)
            total += steps[i]
    beams = np.empty(total, dtype=np.intp)
    distances = np.empty(total)
    written = 0
    for i in range(n):
        for step in range(1, steps[i] + 1):
            beams[written] = i
            distances[written] = ranges[i] + spacing * step
            written += 1
    return beams, distances


@_jit
def seen_again(ranges, readings, hit, no_return, range_max, angle_min, increment, mount_x, mount_y, mount_yaw,
               wraps, wide, points, tolerance, uncertainty):
    """perception._seen_again for one scan, point by point: ``(again, points, uncertainty)``, the last two copies
    (narrowed beyond an edge of the field of view where the numpy code narrows them). ``wraps``: the scan covers
    the full turn; ``wide``: it covers half a turn or more."""
    n, count = ranges.size, points.shape[0]
    seen = np.empty(n)   # perception._seen_ranges
    for b in range(n):
        if readings[b] == hit:
            seen[b] = ranges[b]
        elif readings[b] == no_return:
            seen[b] = range_max
        else:
            seen[b] = -np.inf
    again = np.zeros(count, dtype=np.bool_)
    dx, dy = np.empty(count), np.empty(count)
    reach, offset = np.empty(count), np.empty(count)
    fans = False
    two_pi = 2.0 * math.pi
    for i in range(count):
        dx[i] = points[i, 0] - mount_x
        dy[i] = points[i, 1] - mount_y
        reach[i] = math.hypot(dx[i], dy[i])
        offset[i] = (math.atan2(dy[i], dx[i]) - mount_yaw - angle_min + 0.5 * increment) % two_pi - 0.5 * increment
        index = math.floor(offset[i] / increment + 0.5)
        if 0 <= index < n and seen[int(index)] >= reach[i] - tolerance[i]:
            again[i] = True
            fans = fans or uncertainty[i] > 0.0
    points_out, uncertainty_out = points.copy(), uncertainty.copy()
    if not fans:
        return again, points_out, uncertainty_out
    # the edges' lines through the lidar, their normals into the view (used by points beyond an edge)
    first = angle_min + mount_yaw - 0.5 * increment
    last = angle_min + mount_yaw + (n - 0.5) * increment
    normals = np.array([[-math.sin(first), math.cos(first)], [math.sin(last), -math.cos(last)]])
    for i in range(count):
        if not again[i]:
            continue
        u, r = uncertainty[i], reach[i]
        half = math.pi if u >= r else math.asin(min(u / max(r, 1e-12), 1.0))
        low = math.floor((offset[i] - half) / increment + 0.5)
        high = math.floor((offset[i] + half) / increment + 0.5)
        under = over = beyond = False
        if wraps:
            if high - low + 1 >= n:
                low, high = 0, n - 1
        else:
            under, over = low < 0, high >= n
            beyond = (under != over and u < r) or (u >= r and wide)
            if under or over:
                again[i] = False
            low, high = max(low, 0), min(high, n - 1)
        if (again[i] or beyond) and high > low:
            smallest = np.inf   # perception._range_minima: the smallest reading over the fan, round the turn
            for b in range(low, high + 1):
                value = seen[b % n]
                if value < smallest:
                    smallest = value
            if smallest == -np.inf:   # a beam the fan meets says nothing
                again[i] = beyond = False
        if not beyond:
            continue
        depth_first = dx[i] * normals[0, 0] + dy[i] * normals[0, 1]
        depth_last = dx[i] * normals[1, 0] + dy[i] * normals[1, 1]
        pick = 1
        if under and over:
            pick = 0 if depth_first >= depth_last else 1
        elif under:
            pick = 0
        depth = depth_first if pick == 0 else depth_last
        if depth > 0.0:
            points_out[i, 0] -= depth * normals[pick, 0]
            points_out[i, 1] -= depth * normals[pick, 1]
            uncertainty_out[i] = math.sqrt(max(u * u - depth * depth, 0.0))
    return again, points_out, uncertainty_out


@_jit
def memory_recall(stored, stored_uncertainty, frame_x, frame_y, cos_yaw, sin_yaw, error_0, error_1, error_2,
                  spread_0, spread_1, spread, max_range, tolerance, ranges, readings, hit, no_return, range_max,
                  angle_min, increment, mount_x, mount_y, mount_yaw, wraps, wide):
    """perception.PointMemory.recall with one scan taken at once: the stored points moved into the current base frame
    (the frame's ``cos_yaw``, ``sin_yaw``: Pose2D.to_local), their uncertainty (PointMemory.uncertainty, with the scan's
    ``spread`` when asked: motion_spread), those within ``max_range``, seen_again, and the points kept with their
    uncertainty (their own where the scan did not narrow them)."""
    count = stored.shape[0]
    points = np.empty((count, 2))
    own, uncertainty, allowed = np.empty(count), np.empty(count), np.empty(count)
    keep = np.empty(count, dtype=np.bool_)
    for i in range(count):
        dx, dy = stored[i, 0] - frame_x, stored[i, 1] - frame_y
        x = cos_yaw * dx + sin_yaw * dy
        y = -sin_yaw * dx + cos_yaw * dy
        points[i, 0], points[i, 1] = x, y
        own[i] = stored_uncertainty[i] + error_0 + math.hypot(dx, dy) * error_1 + error_2
        distance = math.hypot(x, y)
        uncertainty[i] = own[i] + (spread_0 + distance * spread_1) if spread else own[i]
        keep[i] = distance <= max_range + uncertainty[i]
        allowed[i] = tolerance + uncertainty[i]
    again, moved, narrowed = seen_again(ranges, readings, hit, no_return, range_max, angle_min, increment, mount_x,
                                        mount_y, mount_yaw, wraps, wide, points, allowed, uncertainty)
    kept = 0
    for i in range(count):
        keep[i] = keep[i] and not again[i]
        kept += keep[i]
    out_points, out_uncertainty = np.empty((kept, 2)), np.empty(kept)
    j = 0
    for i in range(count):
        if keep[i]:
            out_points[j, 0], out_points[j, 1] = moved[i, 0], moved[i, 1]
            out_uncertainty[j] = own[i] if narrowed[i] == uncertainty[i] else narrowed[i]
            j += 1
    return out_points, out_uncertainty


@_jit
def sqp_values(centres, points, inverse_radii, radii, row_state, row_window, check_window):
    """mpc.sqp.DirectSQP.solve, the start of an iteration: every clearance row's value at the iterate ``(M, C)``
    [m] and its ``dx``, ``dy`` (centre minus point); the rows that start in the QP (active at the last answer,
    and each column's nearest within ``row_window``) and those checked (within ``check_window``), flat."""
    count, columns = points.shape[0], centres.shape[1]
    dx = np.empty((count, columns))
    dy = np.empty((count, columns))
    values = np.empty((count, columns))
    working = np.empty(count * columns, dtype=np.bool_)
    candidates = np.empty(count * columns, dtype=np.bool_)
    for i in range(count):
        for c in range(columns):
            x = centres[0, c] - points[i, 0]
            y = centres[1, c] - points[i, 1]
            value = x * x
            value += y * y
            value *= inverse_radii[i, c]
            value -= radii[i, c]
            value *= 0.5
            dx[i, c], dy[i, c], values[i, c] = x, y, value
            flat = i * columns + c
            working[flat] = row_state[flat] != 0
            candidates[flat] = value <= check_window
    if count:
        for c in range(columns):
            nearest = 0
            for i in range(1, count):
                if values[i, c] < values[nearest, c]:
                    nearest = i
            if values[nearest, c] <= row_window:
                working[nearest * columns + c] = True
    return dx, dy, values, working, candidates


@_jit
def sqp_clearance_rows(rows, columns, centre_jacobian, dx, dy, inverse_radii, relief, values, knots, matrix, n_linear,
                       n_knot_vars, slack_column):
    """mpc.sqp.DirectSQP.solve, a round's QP rows: the clearance rows ``rows`` (flat indices) written into
    ``matrix`` below its ``n_linear`` linear rows (``-gradient . x - relief b - s <= value - gradient . knots``);
    returns their right sides."""
    width = matrix.shape[1]
    upper = np.empty(rows.size)
    for r in range(rows.size):
        flat = rows[r]
        i, c = flat // columns, flat % columns
        scale = inverse_radii[i, c]
        a = dx[i, c] * -scale
        b = dy[i, c] * scale
        out = n_linear + r
        total = 0.0
        for j in range(n_knot_vars):
            entry = centre_jacobian[0, c, j] * a
            entry -= centre_jacobian[1, c, j] * b
            matrix[out, j] = entry
            total += entry * knots[j]
        matrix[out, n_knot_vars] = -relief[i, c]
        for j in range(n_knot_vars + 1, width):
            matrix[out, j] = 0.0
        matrix[out, slack_column[i]] = -1.0
        upper[r] = values[i, c] + total
    return upper


@_jit
def sqp_violated(centre_jacobian, move, dx, dy, inverse_radii, values, relief, buffer_slack, slacks, candidates,
                 working, tolerance, per_point):
    """mpc.sqp.DirectSQP.solve, a round's check: every checked row linearised at the QP's answer (through the
    centres' displacement ``centre_jacobian @ move``), the mask of those it misses by more than ``tolerance``
    [m] that are not in the QP yet; with ``per_point``, of each point's such rows the one it misses most (the
    first column of a tie)."""
    count, columns = dx.shape
    moved_x = np.empty(columns)
    moved_y = np.empty(columns)
    for c in range(columns):
        sx = 0.0
        sy = 0.0
        for j in range(move.size):
            sx += centre_jacobian[0, c, j] * move[j]
            sy += centre_jacobian[1, c, j] * move[j]
        moved_x[c], moved_y[c] = sx, sy
    violated = np.zeros(count * columns, dtype=np.bool_)
    for i in range(count):
        worst, pick = -tolerance, -1
        for c in range(columns):
            flat = i * columns + c
            if working[flat] or not candidates[flat]:
                continue
            linearised = dx[i, c] * moved_x[c]
            linearised += dy[i, c] * moved_y[c]
            linearised *= inverse_radii[i, c]
            linearised += values[i, c]
            linearised += relief[i, c] * buffer_slack + slacks[i]
            if not per_point:
                violated[flat] = linearised < -tolerance
            elif linearised < worst:
                worst, pick = linearised, flat
        if pick >= 0:
            violated[pick] = True
    return violated


@_jit
def plan_check(commands, reached, velocity, rho, beta, dt, coast, offsets, points, guaranteed, radii, lower, upper,
               steps):
    """MPCSafetyFilter.check_plan: the rollout (plan.BaseModel.knot_poses, geometry.unicycle_rollout), the disk
    centres at the knots (plan.disk_centres), the smallest knot distance per point and disk (plan.distances) and
    the limits' violation; ``coast`` is the lag's time constant (0: no drift knot); ``reached`` (P, 2) the
    velocities at the periods' ends without a lag (plan.BaseModel.reached: the commands, or late blocks' ramps).

    Returns ``(limits, clearance, planned, distances (M, D), poses (P + 1, 3), velocities (P + 1, 2))``.
    """
    periods = commands.shape[0]
    limits = -np.inf
    for k in range(periods):
        for axis in range(2):
            limits = max(limits, lower[k, axis] - commands[k, axis], commands[k, axis] - upper[k, axis])
    for k in range(periods - 1):
        for axis in range(2):
            limits = max(limits, abs(commands[k + 1, axis] - commands[k, axis]) - steps[k, axis])
    velocities = np.empty((periods + 1, 2))
    velocities[0, 0], velocities[0, 1] = velocity[0], velocity[1]
    poses = np.zeros((periods + 1, 3))
    ends = reached if rho == 0.0 else commands
    for k in range(periods):
        for axis in range(2):
            if rho == 0.0:
                velocities[k + 1, axis] = reached[k, axis]
            else:   # lfilter([1 - rho], [1, -rho]): y = b0 x + z, z = rho y
                velocities[k + 1, axis] = (1.0 - rho) * commands[k, axis] + rho * velocities[k, axis]
        mean_v = ends[k, 0] + beta * (velocities[k, 0] - ends[k, 0])
        mean_omega = ends[k, 1] + beta * (velocities[k, 1] - ends[k, 1])
        turn = mean_omega * dt
        chord = mean_v * dt * np.sinc(0.5 * turn / math.pi)
        heading = poses[k, 2] + 0.5 * turn
        poses[k + 1, 0] = poses[k, 0] + chord * math.cos(heading)
        poses[k + 1, 1] = poses[k, 1] + chord * math.sin(heading)
        poses[k + 1, 2] = poses[k, 2] + turn
    n_knots = periods + 1 if coast > 0.0 else periods
    knots = np.empty((n_knots, 3))
    knots[:periods] = poses[1:]
    if coast > 0.0:
        drift = coast * velocities[periods, 0]
        knots[periods, 0] = poses[periods, 0] + drift * math.cos(poses[periods, 2])
        knots[periods, 1] = poses[periods, 1] + drift * math.sin(poses[periods, 2])
        knots[periods, 2] = poses[periods, 2]
    disks = offsets.shape[0]
    centred = True
    for d in range(disks):
        if offsets[d, 0] != 0.0 or offsets[d, 1] != 0.0:
            centred = False
    centres = np.empty((n_knots, disks, 2))
    for k in range(n_knots):
        cos, sin = math.cos(knots[k, 2]), math.sin(knots[k, 2])
        for d in range(disks):
            if centred:
                centres[k, d, 0], centres[k, d, 1] = knots[k, 0], knots[k, 1]
            else:
                centres[k, d, 0] = knots[k, 0] + cos * offsets[d, 0] - sin * offsets[d, 1]
                centres[k, d, 1] = knots[k, 1] + sin * offsets[d, 0] + cos * offsets[d, 1]
    count = points.shape[0]
    gaps = np.empty((count, disks))
    clearance = planned = np.inf
    for i in range(count):
        for d in range(disks):
            best = np.inf
            for k in range(n_knots):
                dx = centres[k, d, 0] - points[i, 0]
                dy = centres[k, d, 1] - points[i, 1]
                best = min(best, dx * dx + dy * dy)
            gap = math.sqrt(best)
            gaps[i, d] = gap
            clearance = min(clearance, gap - guaranteed[i, d])
            planned = min(planned, gap - radii[i, d])
    return limits, clearance, planned, gaps, poses, velocities


@_jit
def inside_polygon(polygon, points):
    """body.inside_polygon: the even-odd rule of every point in the polygon's bounding box, edge by edge."""
    count, corners = points.shape[0], polygon.shape[0]
    low_x, low_y = polygon[:, 0].min(), polygon[:, 1].min()
    high_x, high_y = polygon[:, 0].max(), polygon[:, 1].max()
    inside = np.zeros(count, dtype=np.bool_)
    for i in range(count):
        x, y = points[i, 0], points[i, 1]
        if not (low_x <= x <= high_x and low_y <= y <= high_y):
            continue
        crossings = 0
        for v in range(corners):
            ax, ay = polygon[v, 0], polygon[v, 1]
            bx, by = polygon[(v + 1) % corners, 0], polygon[(v + 1) % corners, 1]
            if (ay > y) != (by > y) and x < ax + (y - ay) * (bx - ax) / (by - ay):
                crossings += 1
        inside[i] = crossings % 2 == 1
    return inside


@_jit
def nearest_per_bin(angles, keys, n_bins):
    """perception.nearest_per_bin from the bearings: per bin the point with the smallest key (the lowest index among
    equal keys, a NaN key after every other), those points by increasing key (stable; NaN last)."""
    best = np.full(n_bins, -1, dtype=np.intp)
    scale = n_bins / (2.0 * math.pi)
    for i in range(angles.size):
        b = int((angles[i] + math.pi) * scale) % n_bins
        j = best[b]
        if j < 0 or keys[i] < keys[j] or (keys[j] != keys[j] and keys[i] == keys[i]):
            best[b] = i
    count = 0
    for b in range(n_bins):
        if best[b] >= 0:
            count += 1
    chosen = np.empty(count, dtype=np.intp)
    count = 0
    for b in range(n_bins):
        if best[b] >= 0:
            chosen[count] = best[b]
            count += 1
    # insertion sort by key, stable, NaN last (a few dozen points)
    for i in range(1, chosen.size):
        moving = chosen[i]
        key = keys[moving]
        j = i - 1
        while j >= 0 and (keys[chosen[j]] > key or (keys[chosen[j]] != keys[chosen[j]] and key == key)):
            chosen[j + 1] = chosen[j]
            j -= 1
        chosen[j + 1] = moving
    return chosen


@_jit
def sweep_poses(ages, covered, parts, ends, mount_x, mount_y, mount_yaw):
    """perception.sweep_poses: the lidar pose of the middle beam ``(3,)`` and each beam's relative to it ``(n, 3)``
    (``covered``, ``ends``: where each part ends, counted back from now, and the base pose there)."""
    n = ages.size
    x, y, cos_yaw, sin_yaw = np.zeros(n), np.zeros(n), np.ones(n), np.zeros(n)
    count = parts.shape[0]
    for i in range(n):
        age = ages[i]
        if age <= 0.0:
            continue
        k = 0
        while k < count and age > covered[k] + parts[k, 0]:
            k += 1
        if k == count:      # older than the parts: where the oldest began
            x[i], y[i] = ends[count, 0], ends[count, 1]
            cos_yaw[i], sin_yaw[i] = math.cos(ends[count, 2]), math.sin(ends[count, 2])
            continue
        back = age - covered[k]
        v, omega = parts[k, 1], parts[k, 2]
        turn = omega * back
        sin_turn, sin_half = math.sin(turn), math.sin(0.5 * turn)
        cos_turn = 1.0 - 2.0 * sin_half * sin_half
        if abs(omega) > 1e-12:
            ax, ay = (-v / omega) * sin_turn, (2.0 * v / omega) * (sin_half * sin_half)
        else:
            ax, ay = -v * back, 0.0
        c, s = math.cos(ends[k, 2]), math.sin(ends[k, 2])
        x[i], y[i] = ends[k, 0] + c * ax - s * ay, ends[k, 1] + s * ax + c * ay
        cos_yaw[i], sin_yaw[i] = c * cos_turn + s * sin_turn, s * cos_turn - c * sin_turn
    middle = n // 2
    c0, s0 = cos_yaw[middle], sin_yaw[middle]
    reference = np.empty(3)
    reference[0] = x[middle] + c0 * mount_x - s0 * mount_y
    reference[1] = y[middle] + s0 * mount_x + c0 * mount_y
    yaw = math.atan2(s0, c0) + mount_yaw
    reference[2] = (yaw + math.pi) % (2.0 * math.pi) - math.pi      # geometry.wrap_angle
    cr, sr = math.cos(reference[2]), math.sin(reference[2])
    relative = np.empty((n, 3))
    for i in range(n):
        dx = x[i] + cos_yaw[i] * mount_x - sin_yaw[i] * mount_y - reference[0]
        dy = y[i] + sin_yaw[i] * mount_x + cos_yaw[i] * mount_y - reference[1]
        relative[i, 0] = cr * dx + sr * dy
        relative[i, 1] = -sr * dx + cr * dy
        relative[i, 2] = math.atan2(c0 * sin_yaw[i] - s0 * cos_yaw[i], c0 * cos_yaw[i] + s0 * sin_yaw[i])
    return reference, relative


@_jit
def sweep_shift(points, motion, mount_x, mount_y, mount_yaw, angle_min, increment, rounds):
    """perception.sweep_shift: each point's map to where a lidar at the mount sees it as the beam that looks at it
    saw it, as ``(cos, sin, shift)`` (``(N,)``, ``(N,)``, ``(N, 2)``)."""
    count, n = points.shape[0], motion.shape[0]
    two_pi = 2.0 * math.pi
    cm, sm = math.cos(mount_yaw), math.sin(mount_yaw)
    turn_cos, turn_sin = np.cos(motion[:, 2]), np.sin(motion[:, 2])
    cos_out, sin_out, shift = np.empty(count), np.empty(count), np.empty((count, 2))
    unseen = np.zeros(count, dtype=np.bool_)
    for i in range(count):
        local_x = cm * (points[i, 0] - mount_x) + sm * (points[i, 1] - mount_y)
        local_y = -sm * (points[i, 0] - mount_x) + cm * (points[i, 1] - mount_y)
        x, y = local_x, local_y
        beam = -1
        for round_index in range(rounds + 1):
            offset = (math.atan2(y, x) - angle_min + 0.5 * increment) % two_pi - 0.5 * increment
            index = math.floor(offset / increment + 0.5)
            if index > n - 1:
                index = n - 1 if offset - (n - 1) * increment < two_pi - offset else 0
            if int(index) == beam:
                break
            if round_index == rounds:
                unseen[i] = True
                break
            beam = int(index)
            dx, dy, c, s = motion[beam, 0], motion[beam, 1], turn_cos[beam], turn_sin[beam]
            x = c * (local_x - dx) + s * (local_y - dy)
            y = -s * (local_x - dx) + c * (local_y - dy)
        dx, dy, c, s = motion[beam, 0], motion[beam, 1], turn_cos[beam], -turn_sin[beam]
        shift_x = -(c * dx - s * dy)
        shift_y = -(s * dx + c * dy)
        cos_out[i], sin_out[i] = c, s
        shift[i, 0] = mount_x - (c * mount_x - s * mount_y) + (cm * shift_x - sm * shift_y)
        shift[i, 1] = mount_y - (s * mount_x + c * mount_y) + (sm * shift_x + cm * shift_y)
    return cos_out, sin_out, shift, unseen


@_jit
def cbf_screen(G, h, point, family, lower, upper, tolerance):
    """cbf._screen: the rows some ``z`` in the box violates (their coefficients, right sides, points, families and
    indices) and whether some row is missed by every ``z`` in the box by more than ``tolerance``."""
    count = h.size
    centre, half = box_halves(lower, upper)
    kept = np.empty(count, dtype=np.intp)
    n = 0
    excluded = False
    for i in range(count):
        middle, spread = box_terms(G, i, centre, half)
        if middle + spread > h[i]:
            kept[n] = i
            n += 1
        if middle - spread > h[i] + tolerance:
            excluded = True
    candidate = kept[:n].copy()
    taken = np.empty((n, 4))
    bound = np.empty(n)
    taken_point = np.empty(n, dtype=point.dtype)
    taken_family = np.empty(n, dtype=family.dtype)
    for r in range(n):
        i = candidate[r]
        for j in range(4):
            taken[r, j] = G[i, j]
        bound[r] = h[i]
        taken_point[r] = point[i]
        taken_family[r] = family[i]
    return taken, bound, taken_point, taken_family, candidate, excluded


@_jit
def cbf_qp_rows(fixed_G, fixed_h, G, h, minus_relaxed, working, with_slack):
    """cbf.CBFSafetyFilter._assembler's QP rows: the fixed rows, then the rows ``working`` picks; with
    ``with_slack`` a fifth column, ``-0.0`` on the fixed rows and ``minus_relaxed`` on the others."""
    fixed = fixed_h.size
    n = 0
    for i in range(h.size):
        if working[i]:
            n += 1
    columns = 5 if with_slack else 4
    matrix = np.empty((fixed + n, columns))
    bound = np.empty(fixed + n)
    for r in range(fixed):
        for j in range(4):
            matrix[r, j] = fixed_G[r, j]
        bound[r] = fixed_h[r]
        if with_slack:
            matrix[r, 4] = -0.0
    r = fixed
    for i in range(h.size):
        if not working[i]:
            continue
        for j in range(4):
            matrix[r, j] = G[i, j]
        bound[r] = h[i]
        if with_slack:
            matrix[r, 4] = minus_relaxed[i]
        r += 1
    return matrix, bound


@_jit
def cbf_violated(G, h, relaxed, slack, z, working, tolerance):
    """cbf.CBFSafetyFilter._solve_generating, a round's check: every row not in ``working`` that ``z`` misses by more
    than ``tolerance`` (the rows ``relaxed`` marks relaxed by ``slack``) joins it; whether any did."""
    added = False
    for i in range(h.size):
        if working[i]:
            continue
        left = G[i, 0] * z[0] + G[i, 1] * z[1] + G[i, 2] * z[2] + G[i, 3] * z[3]
        bound = h[i] + slack if relaxed[i] else h[i]
        if left > bound + tolerance:
            working[i] = True
            added = True
    return added


@_jit
def cbf_answer(G, h, bound, family, point, lifted, nominal, used_rows, n_points, first_hard, near):
    """cbf._answer: of the rows at the answer ``lifted``, the one it misses its ``bound`` most by (``NaN`` first) and
    by how much, the soft row it misses its right side most by, the row that bound it (of the rows within ``near``
    of their right sides, the one the lifted nominal misses most; -1 when none), and which points the rows
    ``used_rows`` refer to and which of them hold within ``near`` of their bounds."""
    worst = -1
    worst_excess = -np.inf
    soft_worst = -1
    soft_excess = -np.inf
    binding = -1
    binding_excess = -np.inf
    left = np.empty(h.size)
    for i in range(h.size):
        value = G[i, 0] * lifted[0] + G[i, 1] * lifted[1] + G[i, 2] * lifted[2] + G[i, 3] * lifted[3]
        left[i] = value
        excess = value - bound[i]
        if worst < 0 or (not math.isnan(worst_excess) and (math.isnan(excess) or excess > worst_excess)):
            worst, worst_excess = i, excess
        own = value - h[i]
        if family[i] < first_hard and (soft_worst < 0 or own > soft_excess):
            soft_worst, soft_excess = i, own
        if own >= -near:
            wanted = G[i, 0] * nominal[0] + G[i, 1] * nominal[1] + G[i, 2] * nominal[2] + G[i, 3] * nominal[3] - h[i]
            if binding < 0 or wanted > binding_excess:
                binding, binding_excess = i, wanted
    used = np.zeros(n_points + 1, dtype=np.bool_)      # the extra slot absorbs rows without a point (-1)
    active = np.zeros(n_points + 1, dtype=np.bool_)
    for i in used_rows:
        slot = point[i] if point[i] >= 0 else n_points
        used[slot] = True
        if abs(left[i] - bound[i]) <= near:
            active[slot] = True
    return worst, worst_excess, soft_worst, binding, used[:n_points], active[:n_points]


@_jit
def daqp_arrays(lb, ub, h, h_lower, guess, guess_sense, equality):
    """qp.DirectDAQP.solve's arrays: the upper and lower bounds of the simple bounds then the rows (``h_lower`` empty:
    one-sided rows), every infinite or larger bound as +-1e30, and each one's flag (``guess_sense`` of the warm start
    ``guess``, empty: none; ``equality`` where the bounds are equal)."""
    n = lb.size
    total = n + h.size
    upper = np.empty(total)
    lower = np.empty(total)
    for i in range(total):
        high = ub[i] if i < n else h[i - n]
        low = lb[i] if i < n else (h_lower[i - n] if h_lower.size else -1e30)
        upper[i] = 1e30 if high > 1e30 else high
        lower[i] = -1e30 if low < -1e30 else low
    sense = np.zeros(total, dtype=np.int32)
    for i in range(total):
        if lower[i] == upper[i]:
            sense[i] = equality
        elif guess.size:
            sign = 1 if guess[i] > 0 else (-1 if guess[i] < 0 else 0)
            sense[i] = guess_sense[sign + 1]
    return upper, lower, sense


@_jit
def daqp_answer(x, multipliers):
    """qp.DirectDAQP.solve's reading of an answer: whether every entry of ``x`` is finite, and the sign of each
    constraint's multiplier (the active set, as int8)."""
    finite = True
    for value in x:
        if not math.isfinite(value):
            finite = False
    active = np.empty(multipliers.size, dtype=np.int8)
    for i in range(multipliers.size):
        value = multipliers[i]
        active[i] = 1 if value > 0.0 else (-1 if value < 0.0 else 0)
    return finite, active


@_jit
def cbf_stage(h, point, family, uncertainty, barrier, margin, tier, first_hard, barrier_family, every):
    """cbf._stage: the right sides and the relaxed rows of a slack tier."""
    bound = h.copy()
    relaxed = np.zeros(h.size, dtype=np.bool_)
    for i in range(h.size):
        if family[i] >= first_hard:
            continue
        if every:
            relaxed[i] = True
        p = point[i]
        if p < 0:
            continue
        lost = uncertainty[p] > margin
        if tier == 0:
            relaxed[i] = lost
            continue
        inside = barrier[p] <= 0.0
        if inside and family[i] == barrier_family and h[i] < 0.0:
            bound[i] = 0.0
        if not every:
            relaxed[i] = inside or lost
    return bound, relaxed
