"""Each constraint family alone: its invariant, checked with hypothesis over random inputs."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from safenav import Pose2D, preset, unicycle_step
from safenav.filters import rows as families
from safenav.filters.body import BodyModel, polygon_distance
from safenav.filters.defaults import lag_fraction

DT = 0.05
finite = dict(allow_nan=False, allow_infinity=False)


def body_for(name: str, cover: int) -> BodyModel:
    robot = preset(name)
    return BodyModel.cover(robot, cover) if cover > 1 else BodyModel.disk(robot)


@st.composite
def pairs(draw):
    """Random obstacle points outside the body, a body model, a look-ahead and a command."""
    robot = preset(draw(st.sampled_from(["rosbot", "puzzlebot", "m2wr"])))
    body = body_for(robot.name, draw(st.integers(1, 4)))
    lookahead = draw(st.sampled_from([0.0, 0.1]))
    count = draw(st.integers(1, 20))
    points = np.array([[draw(st.floats(-3, 3, **finite)), draw(st.floats(-3, 3, **finite))] for _ in range(count)])
    assume(body.clearance(points) > 0.01)
    command = np.array([draw(st.floats(robot.v_min, robot.v_max)), draw(st.floats(-robot.omega_max, robot.omega_max))])
    return robot, body, lookahead, points, command


def barriers(points: np.ndarray, body: BodyModel, lookahead: float, margin: float, pose: Pose2D) -> np.ndarray:
    """Every pair's barrier with the base at ``pose`` (points fixed in the start frame)."""
    local = pose.to_local(points)
    return families.geometry(local, np.zeros(len(points)), body.centres, body.radii, lookahead, margin, 0.0)[0].barrier


@settings(max_examples=600)
@given(pairs(), st.floats(0.01, 1.0))
def test_barrier_rows_keep_the_discrete_time_condition_for_the_exact_unicycle(case, gamma):
    _, body, lookahead, points, command = case
    margin = 0.03
    kappa = 0.5 * abs(command[1]) * DT    # the yaw rate held over the period bounds the arc
    geo = families.geometry(points, np.zeros(len(points)), body.centres, body.radii, lookahead, margin, kappa)[0]
    rows = families.barrier_rows(geo, gamma, 1.0, DT)
    z = np.concatenate((command, np.abs(command)))
    assume(np.all(rows.G @ z <= rows.h))
    before = geo.barrier.min()
    after = barriers(points, body, lookahead, margin, unicycle_step(Pose2D(), *command, DT))
    assert after.min() >= (1.0 - gamma) * before - 1e-9


@settings(max_examples=400)
@given(pairs(), st.floats(0.01, 1.0), st.floats(0.0, 1.0))
def test_far_gamma_bounds_each_point_loss(case, gamma, far):
    robot, body, lookahead, points, command = case
    far = max(far, gamma)
    kappa = 0.5 * robot.omega_max * DT
    geo = families.geometry(points, np.zeros(len(points)), body.centres, body.radii, lookahead, 0.03, kappa)[0]
    rows = families.barrier_rows(geo, gamma, far, DT)
    z = np.concatenate((command, np.abs(command)))
    assume(np.all(rows.G @ z <= rows.h))
    after = barriers(points, body, lookahead, 0.03, unicycle_step(Pose2D(), *command, DT))
    outside = geo.barrier > 0.0
    assert np.all(after[outside] >= (1.0 - far) * geo.barrier[outside] - 1e-9)


@settings(max_examples=600)
@given(pairs(), st.floats(0.01, 1.0), st.floats(0.0, 0.2))
def test_tilted_half_planes_keep_the_barrier_condition(case, gamma, travel):
    """Rows written with the half-planes ``slide`` picks (not each point's own direction) still give
    ``H(x+) >= (1 - gamma) H(x)`` for the exact unicycle, and no half-plane goes below the floor."""
    _, body, lookahead, points, command = case
    margin = 0.03
    kappa = 0.5 * abs(command[1]) * DT
    geo, per_point = families.geometry(points, np.zeros(len(points)), body.centres, body.radii, lookahead, margin,
                                       kappa, floor_ratio=1.0 - gamma, travel=travel)
    H = float(per_point.min())
    assert np.all(geo.barrier >= min((1.0 - gamma) * H, H) - 1e-9)
    own = families.geometry(points, np.zeros(len(points)), body.centres, body.radii, lookahead, margin, kappa)[0]
    assert np.all(geo.barrier <= own.barrier + 1e-9)   # a half-plane is never above its pair's barrier
    rows = families.barrier_rows(geo, gamma, 1.0, DT, smallest=H)
    z = np.concatenate((command, np.abs(command)))
    assume(np.all(rows.G @ z <= rows.h))
    after = barriers(points, body, lookahead, margin, unicycle_step(Pose2D(), *command, DT))
    assert after.min() >= (1.0 - gamma) * H - 1e-9


@settings(max_examples=300)
@given(st.floats(0.0, 0.5))
def test_tilted_half_planes_let_the_base_slide_along_a_wall(gap):
    """A straight wall beside the body at the barrier's own level: with the tilt, driving straight
    along it at full speed satisfies every barrier row; with each point's own direction it does not."""
    robot = preset("m2wr")
    body = BodyModel.disk(robot)
    lookahead, margin, gamma = 0.1, 0.03, 0.05
    y = robot.radius + lookahead + margin + gap
    points = np.column_stack((np.linspace(-1.0, 3.0, 801), np.full(801, y)))
    command = np.array([robot.v_max, 0.0])
    z = np.concatenate((command, np.abs(command)))
    tilted, per_point = families.geometry(points, np.zeros(801), body.centres, body.radii, lookahead, margin, 0.0,
                                          floor_ratio=1.0 - gamma, travel=robot.v_max * DT)
    rows = families.barrier_rows(tilted, gamma, 1.0, DT, smallest=float(per_point.min()))
    assert np.all(rows.G @ z <= rows.h + 1e-9)
    own = families.barrier_rows(families.geometry(points, np.zeros(801), body.centres, body.radii, lookahead,
                                                  margin, 0.0)[0], gamma, 1.0, DT)
    if gap < 0.01:   # near the margin, each point's own direction forbids driving past it
        assert not np.all(own.G @ z <= own.h)


@settings(max_examples=400)
@given(pairs(), st.floats(0.0, 0.2), st.floats(0.0, 1.0), st.floats(0.0, 1.0))
def test_ramp_corners_cover_every_base_between_the_velocity_and_the_command(case, time_constant, b_v, b_omega):
    """Rows written at the four corners hold for every mean velocity ``u + B (w0 - u)``, ``B <= lag``."""
    robot, body, lookahead, points, command = case
    kappa = 0.5 * robot.omega_max * DT
    geo = families.geometry(points, np.zeros(len(points)), body.centres, body.radii, lookahead, 0.03, kappa)[0]
    base = families.barrier_rows(geo, 0.2, 1.0, DT)
    velocity = np.clip(command + np.array([0.07, -0.3]), robot.lower, robot.upper)
    lag = lag_fraction(DT, time_constant)
    corners = families.ramp_corners(base, velocity, lag)
    z = np.concatenate((command, np.maximum(np.abs(command), np.abs(velocity))))
    assume(np.all(corners.G @ z <= corners.h))
    mean = command + np.array([b_v, b_omega]) * lag * (velocity - command)
    z_mean = np.concatenate((mean, z[2:]))
    assert np.all(base.G @ z_mean <= base.h + 1e-9)


@settings(max_examples=400)
@given(pairs(), st.floats(0.0, 0.2), st.booleans(), st.integers(0, 2**32 - 1))
def test_ramp_corners_in_a_box_keep_the_worst_row_of_all_four_corners(case, time_constant, glitch, seed):
    """Leaving out the rows that cannot bind and the repeated corners keeps, at every command in the box,
    the largest violation of the rows of all four corners (hence the same feasible commands and QP answer).

    The rows have every family's shapes (both terms, ``v`` alone, ``omega`` alone, as the braking
    and sweep rows have), right sides that cut through the box or lie beyond its reach, and a
    start velocity inside the box or (``glitch``) beyond it.
    """
    robot, body, lookahead, points, command = case
    kappa = 0.5 * robot.omega_max * DT
    geo = families.geometry(points, np.zeros(len(points)), body.centres, body.radii, lookahead, 0.03, kappa)[0]
    rng = np.random.default_rng(seed)
    base = families.barrier_rows(geo, 0.2, 1.0, DT)
    G = np.vstack((base.G, base.G, base.G))
    G[len(base): 2 * len(base), 1] = 0.0                # v alone
    G[2 * len(base):, 0] = 0.0                          # omega alone
    step = np.array([robot.a_max, robot.alpha_max]) * DT
    centre = np.clip(command, robot.lower + step, robot.upper - step)
    lower = np.concatenate((centre - step, rng.uniform(0.0, 0.3, 2)))
    upper = np.concatenate((centre + step, lower[2:] + rng.uniform(0.0, 0.5, 2)))
    velocity = rng.uniform(lower[:2], upper[:2])
    if glitch:
        velocity = velocity + np.sign(rng.uniform(-1.0, 1.0, 2)) * 3.0 * step
    best = -families.worst_case(-G, lower, upper)
    highest = families.worst_case(G, lower, upper)
    h = highest - rng.uniform(-0.3, 1.0, G.shape[0]) * (highest - best)
    point = np.concatenate((base.point, base.point, base.point))
    lag = lag_fraction(DT, time_constant)
    corners = np.array(np.meshgrid(*zip(lower, upper, strict=True))).T.reshape(-1, 4)
    commands = np.vstack((corners, rng.uniform(lower, upper, (300, 4)))).T
    left_out = 0
    for index in range(G.shape[0]):    # row by row, so that no other row hides one left out wrongly
        row = families.Rows(G[index: index + 1], h[index: index + 1], point[index: index + 1], np.zeros(1, np.intp))
        every = families.ramp_corners(row, velocity, lag, 0.2, box=(lower, upper), reduce=False)
        kept = families.ramp_corners(row, velocity, lag, 0.2, box=(lower, upper))
        left_out += len(every) - len(kept)
        worst_every = np.maximum(np.max(every.G @ commands - every.h[:, None], axis=0), 0.0)
        worst_kept = (np.maximum(np.max(kept.G @ commands - kept.h[:, None], axis=0), 0.0) if len(kept)
                      else np.zeros(commands.shape[1]))
        np.testing.assert_allclose(worst_kept, worst_every, rtol=0.0, atol=1e-12)
    assert left_out > 0


@pytest.mark.parametrize("low, high", [(0.0, 0.0), (0.0, 1.0), (0.2, 1.0), (-1.0, 0.0), (-1.0, -0.2), (-1.0, 1.0)])
def test_term_signs_agree_with_the_products_at_the_ends_of_the_interval(low, high):
    k = np.array([-2.0, -1e-300, -0.0, 0.0, 1e-300, 3.0])
    always, never = families._term_signs(k, low, high)
    ends = np.stack((k * low, k * high))
    assert np.array_equal(always, (ends >= 0.0).all(axis=0) | (k == 0.0))
    assert np.array_equal(never, (ends <= 0.0).all(axis=0) | (k == 0.0))


@given(st.floats(0.0, 5.0), st.floats(0.1, 3.0), st.floats(0.01, 0.3))
def test_stopping_speed_stops_within_the_barrier(barrier, accel, reaction):
    speed = families.stopping_speed(np.array([barrier]), accel, reaction)[0]
    assert speed >= 0.0
    assert speed * reaction + speed**2 / (2.0 * accel) <= barrier + 1e-9
    faster = speed + 1e-3
    assert faster * reaction + faster**2 / (2.0 * accel) > barrier


@settings(max_examples=300)
@given(st.floats(0.0, 2.0), st.floats(0.2, 3.0), st.floats(0.02, 0.1), st.floats(0.0, 0.1))
def test_braking_rows_cap_a_head_on_approach_to_one_that_stops_in_time(barrier, accel, dt, lag):
    """A point straight ahead: any speed the braking row allows stops within the barrier (reaction, then braking)."""
    centres, radii = np.zeros((1, 2)), np.array([0.2])
    point = np.array([[0.2 + 0.03 + barrier, 0.0]])
    geo = families.geometry(point, np.zeros(1), centres, radii, 0.0, 0.03, 0.0)[0]
    rows = families.braking_rows(geo, accel, 3.0, dt + lag)
    assert np.allclose(rows.G[:, 0], 1.0) and np.allclose(rows.G[:, 1:], 0.0)   # head-on: the row is v <= h
    allowed = float(rows.h.min())
    travelled = allowed * (dt + lag) + allowed**2 / (2.0 * accel)
    assert travelled <= barrier + 1e-9


def braked_distance(speed: float, accel: float, reaction: float) -> float:
    """Signed distance a component covers reacting for ``reaction``, then braking at ``accel`` to 0."""
    return speed * reaction + speed * abs(speed) / (2.0 * accel)


@st.composite
def braking_cases(draw):
    """A body point off the base origin (a cover disk or the polygon), a point, a command, the limits."""
    robot = preset(draw(st.sampled_from(["rosbot", "puzzlebot", "m2wr"])))
    points = np.array([[draw(st.floats(-2, 2, **finite)), draw(st.floats(-2, 2, **finite))]])
    if draw(st.booleans()) and robot.footprint is not None:
        polygon = np.asarray(robot.footprint, dtype=float)
        assume(polygon_distance(polygon, points)[0] > 0.01)
        geo = families.polygon_geometry(points, np.zeros(1), polygon, 0.03, 0.0)[0]
    else:
        body = body_for(robot.name, draw(st.integers(1, 4)))
        assume(body.clearance(points) > 0.01)
        geo = families.geometry(points, np.zeros(1), body.centres, body.radii, 0.0, 0.03, 0.0)[0]
    command = np.array([draw(st.floats(robot.v_min, robot.v_max)), draw(st.floats(-robot.omega_max, robot.omega_max))])
    reaction = draw(st.floats(0.02, 0.2))
    return robot, geo, command, reaction, draw(st.floats(0.0, 0.02))


@settings(max_examples=800)
@given(braking_cases(), st.booleans())
def test_braking_rows_stop_every_pair_within_its_barrier_with_the_yaw_rate_braking_at_its_own_limit(case, boxed):
    """Any command the braking rows allow, held for the reaction time and then braked at ``a_max`` and
    ``alpha_max`` (each component alone), closes every pair by at most its barrier plus the allowance
    (to first order: ``c_v D_v + c_omega D_omega``). The rows of a head-on approach rate braking at
    ``a_max`` (the old rows) fail this for oblique and off-centre points."""
    robot, geo, command, reaction, allowance = case
    box = (command - np.array([0.1, 0.3]), command + np.array([0.1, 0.3])) if boxed else None
    rows = families.braking_rows(geo, robot.a_max, robot.alpha_max, reaction, allowance, box=box)
    z = np.concatenate((command, np.abs(command)))
    assume(np.all(rows.G @ z <= rows.h))
    closing = (geo.approach[:, 0] * braked_distance(command[0], robot.a_max, reaction)
               + geo.approach[:, 1] * braked_distance(command[1], robot.alpha_max, reaction))
    assert np.all(closing <= np.maximum(geo.barrier + allowance, 0.0) + 1e-9)


@settings(max_examples=300)
@given(braking_cases())
def test_braking_rows_leave_a_command_that_closes_no_pair_free(case):
    """The rows never forbid a command under which braking does not close the pair at all."""
    robot, geo, command, reaction, allowance = case
    assume(np.all(geo.barrier + allowance > 1e-6))
    terms = geo.approach * command
    assume(np.all(terms <= 0.0))
    rows = families.braking_rows(geo, robot.a_max, robot.alpha_max, reaction, allowance)
    z = np.concatenate((command, np.abs(command)))
    assert np.all(rows.G @ z <= rows.h + 1e-12)


@settings(max_examples=300)
@given(st.floats(0.01, 1.0), st.floats(0.0, 1.5), st.floats(0.3, 3.0), st.floats(0.02, 0.2))
def test_an_oblique_braking_coefficient_stops_within_the_barrier_along_the_half_plane(cosine, barrier, accel,
                                                                                       reaction):
    """A point at angle ``phi`` from the heading (``cos phi`` of each metre travelled closes it): the
    largest speed the coefficient allows closes it by exactly the barrier, not more."""
    k = families.braking_coefficient(np.array([cosine]), np.array([barrier]), accel, accel, reaction)[0]
    limit = families.stopping_speed(np.array([barrier]), accel, reaction)[0]
    assume(k > 0.0 and limit > 0.0)
    speed = limit / k
    assert cosine * braked_distance(speed, accel, reaction) == pytest.approx(barrier, rel=1e-6, abs=1e-9)


@settings(max_examples=300)
@given(st.floats(-math.pi, math.pi), st.floats(0.0, 1.0), st.floats(-2.0, 2.0), st.floats(0.2, 2.0))
def test_sweep_rows_cap_the_speed_towards_points_the_heading_can_swing_to(bearing, speed, turn, distance):
    robot = preset("rosbot")
    velocity = np.array([speed, turn])
    point = np.array([[distance * math.cos(bearing), distance * math.sin(bearing)]])
    geo = families.geometry(point, np.zeros(1), np.zeros((1, 2)), np.array([robot.radius]), 0.0, 0.03, 0.0)[0]
    reaction = DT
    rows = families.sweep_rows(geo, velocity, robot.a_max, robot.alpha_max, DT, reaction)
    sweep = families.braking_swing(velocity, robot.alpha_max, DT, reaction)
    limit = families.stopping_speed(geo.barrier, robot.a_max, reaction)[0]
    if abs(bearing) <= sweep:   # the heading may face it before stopping: the forward speed is capped fully
        forward = rows.take(rows.G[:, 0] > 0)
        assert len(forward) == 1 and forward.G[0, 0] == 1.0 and forward.h[0] == limit
    if abs(bearing) >= math.pi / 2 + sweep:   # it cannot come ahead: no forward cap
        assert not np.any(rows.G[:, 0] > 0)


@settings(max_examples=300)
@given(st.floats(-2.0, 2.0), st.floats(-1.0, 1.0), st.floats(0.5, 10.0), st.floats(0.01, 0.2), st.floats(0.0, 0.3))
def test_braking_swing_bounds_the_heading_change_of_a_braking_base(turn, command_share, alpha, dt, lag):
    """A base at its yaw acceleration limit: any command reachable within the period, held for
    the reaction time, then braking to zero yaw rate, turns by at most the braking swing."""
    reaction = dt + lag
    swing = families.braking_swing(np.array([0.5, turn]), alpha, dt, reaction)
    command = turn + command_share * alpha * dt
    rate, heading, step = turn, 0.0, 1e-4
    for k in range(int(reaction / step) + int((abs(command) + alpha * dt) / alpha / step) + 10):
        target = command if k * step < reaction else 0.0
        rate += float(np.clip(target - rate, -alpha * step, alpha * step))
        heading += rate * step
    assert abs(heading) <= swing + 1e-3 * (1.0 + swing)


@st.composite
def outline_samples(draw):
    body = body_for(draw(st.sampled_from(["rosbot", "m2wr"])), draw(st.integers(1, 3)))
    points, normals = body.boundary()
    chosen = draw(st.lists(st.integers(0, len(points) - 1), min_size=1, max_size=12, unique=True))
    return body, points[chosen], normals[chosen]


@settings(max_examples=400)
@given(outline_samples(), st.floats(-1.0, 1.0), st.floats(-3.0, 3.0), st.floats(0.0, 0.2))
def test_gap_rows_never_move_the_outline_towards_a_gap(case, v, omega, tolerance):
    body, points, normals = case
    rows = families.gap_rows(points, normals, tolerance, body.reach)
    z = np.array([v, omega, abs(v), abs(omega)])
    assume(np.all(rows.G @ z <= 0.0))
    outward = normals[:, 0] * (v - omega * points[:, 1]) + normals[:, 1] * omega * points[:, 0]
    allowance = math.sin(tolerance) * (abs(v) + body.reach * abs(omega))
    assert np.all(outward <= 2.0 * allowance + 1e-9)


@settings(max_examples=300)
@given(st.lists(st.tuples(st.floats(-1, 1, **finite), st.floats(-1, 1, **finite)), min_size=1, max_size=20),
       st.floats(-1, 1), st.floats(-1, 1))
def test_the_cone_of_many_homogeneous_rows_is_their_two_extreme_rows(directions, v, omega):
    G = np.array(directions)
    assume(np.all(np.hypot(G[:, 0], G[:, 1]) > 1e-6))
    reduced = families._cone(G)
    u = np.array([v, omega])
    if np.all(reduced @ u <= 0.0):
        assert np.all(G @ u <= 1e-9)


def test_blind_rows_forbid_exactly_the_blocked_directions():
    both = families.blind_rows(True, True)
    assert both.G.tolist() == [[1.0, 0.0, 0.0, 0.0], [-1.0, 0.0, 0.0, 0.0]] and both.h.tolist() == [0.0, 0.0]
    assert len(families.blind_rows(False, False)) == 0
    assert np.all(both.hard) and not np.any(families.barrier_rows(
        families.geometry(np.array([[1.0, 0.0]]), np.zeros(1), np.zeros((1, 2)), np.array([0.2]), 0.0, 0.0, 0.0)[0],
        0.5, 1.0, DT).hard)


@st.composite
def polygon_pairs(draw):
    """Random points outside a footprint polygon, and a command."""
    robot = preset(draw(st.sampled_from(["rosbot", "m2wr"])))
    body = BodyModel.polygon(robot)
    count = draw(st.integers(1, 20))
    points = np.array([[draw(st.floats(-2, 2, **finite)), draw(st.floats(-2, 2, **finite))] for _ in range(count)])
    assume(body.clearance(points) > 0.005)
    command = np.array([draw(st.floats(robot.v_min, robot.v_max)), draw(st.floats(-robot.omega_max, robot.omega_max))])
    return robot, body, points, command


@settings(max_examples=600)
@given(polygon_pairs(), st.floats(0.01, 1.0))
def test_polygon_barrier_rows_keep_the_condition_for_the_exact_unicycle(case, gamma):
    """The point-to-polygon barrier: rows that hold give H(x+) >= (1 - gamma) H(x), turning included."""
    _, body, points, command = case
    kappa = 0.5 * abs(command[1]) * DT    # the yaw rate held over the period bounds the arc
    geo, _ = families.polygon_geometry(points, np.zeros(len(points)), body.outline, 0.03, kappa)
    rows = families.barrier_rows(geo, gamma, 1.0, DT)
    z = np.concatenate((command, np.abs(command)))
    assume(np.all(rows.G @ z <= rows.h))
    moved = unicycle_step(Pose2D(), *command, DT).to_local(points)
    _, after = families.polygon_geometry(moved, np.zeros(len(points)), body.outline, 0.03, kappa)
    assert after.min() >= (1.0 - gamma) * geo.barrier.min() - 1e-9


@settings(max_examples=300)
@given(polygon_pairs())
def test_polygon_geometry_is_the_signed_distance_and_its_gradient(case):
    _, body, points, _ = case
    geo, barrier = families.polygon_geometry(points, np.zeros(len(points)), body.outline, 0.0, 0.0)
    np.testing.assert_allclose(barrier, polygon_distance(body.outline, points), atol=1e-12)
    step = 1e-6   # the gradient, by finite differences along it
    gradient_x = (polygon_distance(body.outline, points + np.array([step, 0.0])) - barrier) / step
    np.testing.assert_allclose(geo.approach[:, 0], gradient_x, atol=1e-4)


@settings(max_examples=400)
@given(polygon_pairs(), st.floats(0.01, 1.0), st.floats(0.0, 0.2))
def test_tilted_polygon_half_planes_keep_the_barrier_condition(case, gamma, travel):
    _, body, points, command = case
    kappa = 0.5 * abs(command[1]) * DT
    geo, barrier = families.polygon_geometry(points, np.zeros(len(points)), body.outline, 0.03, kappa,
                                             floor_ratio=1.0 - gamma, travel=travel)
    H = float(barrier.min())
    assert np.all(geo.barrier >= min((1.0 - gamma) * H, H) - 1e-9)
    assert np.all(geo.barrier <= barrier[geo.point] + 1e-9)
    rows = families.barrier_rows(geo, gamma, 1.0, DT, smallest=H)
    z = np.concatenate((command, np.abs(command)))
    assume(np.all(rows.G @ z <= rows.h))
    moved = unicycle_step(Pose2D(), *command, DT).to_local(points)
    _, after = families.polygon_geometry(moved, np.zeros(len(points)), body.outline, 0.03, kappa)
    assert after.min() >= (1.0 - gamma) * H - 1e-9


def test_the_command_corner_holds_headroom_back_only_on_rows_a_command_in_the_box_can_violate():
    """``gamma |h|`` is held back at the command's corner where some mean velocity in the box violates the plain
    row; a row that none can violate keeps its right side (with ``gamma = 1`` held back everywhere it forbade
    approaching anything in range)."""
    lower, upper = np.array([0.1, -0.2, 0.1, 0.0]), np.array([0.3, 0.2, 0.3, 0.2])
    G = np.array([[1.0, 0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.5, 0.5, 0.0, 0.0]])
    h = np.array([10.0, 0.2, 0.1])              # beyond any command; within reach; within reach
    rows = families.Rows(G, h, np.arange(3), np.zeros(3, np.intp))
    velocity = np.array([0.2, 0.0])
    for headroom in (0.3, 1.0):
        written = families.ramp_corners(rows, velocity, 0.5, headroom, box=(lower, upper), reduce=False)
        command_corner = written.h[:3]          # corner-major: the command's corner first
        np.testing.assert_allclose(command_corner, [10.0, 0.2 * (1.0 - headroom), 0.1 * (1.0 - headroom)])
        kept = families.ramp_corners(rows, velocity, 0.5, headroom, box=(lower, upper))
        assert 0 not in kept.point               # the row no command can violate is left out


def test_box_range_is_each_rows_largest_and_smallest_left_side_at_the_boxs_corners():
    """A linear row's extremes over a box are at its corners: ``box_range`` gives both, the largest being
    ``worst_case``'s to the bit."""
    rng = np.random.default_rng(7)
    G = rng.normal(size=(50, 4))
    G[::5, 1] = 0.0
    lower = rng.uniform(-1.0, 0.0, 4)
    upper = lower + rng.uniform(0.0, 2.0, 4)
    upper[3] = lower[3]                      # a flat side
    corners = np.array(np.meshgrid(*zip(lower, upper, strict=True))).T.reshape(-1, 4)
    largest, smallest = families.box_range(G, lower, upper)
    assert np.allclose(largest, (G @ corners.T).max(axis=1), rtol=0.0, atol=1e-12)
    assert np.allclose(smallest, (G @ corners.T).min(axis=1), rtol=0.0, atol=1e-12)
    assert np.array_equal(largest, families.worst_case(G, lower, upper))
