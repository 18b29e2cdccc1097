"""The CBF-QP safety filter on synthetic scans: properties, geometry, reduction, solvers, failures."""

from __future__ import annotations

import itertools
import math
from types import SimpleNamespace

import numpy as np
import pytest
import qpsolvers
from hypothesis import given, settings
from hypothesis import strategies as st

from safenav import InvalidConfig, LidarSpec, Pose2D, UnknownName, preset, unicycle_step
from safenav.filters import CBFSafetyFilter, FilterStatus, available_solvers
from safenav.filters.qp import QPOutcome
from safenav.filters.rows import worst_case
from safenav.robot import PRESET_NAMES
from safenav.synthetic import Circle, Scene, Segment, box, synthetic_scan, wall

DT = 0.05
# The properties of the answers are the optimisation's: the filters of the property tests (hundreds of fresh
# filters) and of the solvers' comparisons are built without a compute budget, so that a loaded machine cannot turn
# an answer into a deadline brake (the deadline's own tests: tests/filters/test_cbf_deadline.py).


def lifted(u: np.ndarray, velocity) -> np.ndarray:
    t = np.abs(u) if velocity is None else np.maximum(np.abs(u), np.abs(velocity))
    return np.concatenate((u, t))


def full_residual(filt: CBFSafetyFilter, u_nom, scan, velocity, u, *, hard: bool | None = None) -> np.ndarray:
    """Residual of every row of every family, no cut, at command ``u`` (<= 0 means satisfied) [m/s].

    ``hard=True`` keeps only the rows slack never relaxes, ``False`` only the obstacle rows.
    """
    rows = filt.rows(scan, velocity, reduce=False)
    if hard is not None:
        rows = rows.take(rows.hard == hard)
    return rows.G @ lifted(np.asarray(u, dtype=float), velocity) - rows.h


# ------------------------------------------------------------------ strategies

@st.composite
def lidars(draw, robot):
    """The robot's own lidar, or a random partial field of view and mount."""
    if draw(st.booleans()):
        return robot
    fov = draw(st.floats(math.pi / 2, 2 * math.pi))
    n = draw(st.integers(30, 720))
    angle_min = draw(st.floats(-math.pi, 0.0))
    mount = Pose2D(draw(st.floats(-0.05, 0.1)), draw(st.floats(-0.05, 0.05)), draw(st.floats(-math.pi, math.pi)))
    lidar = LidarSpec(n_beams=n, angle_min=angle_min, angle_max=angle_min + fov, range_min=0.05, range_max=8.0,
                      mount=mount)
    return robot.replace(lidar=lidar)


@st.composite
def scenes(draw):
    kind = draw(st.sampled_from(["clutter", "walls", "empty", "corridor"]))
    if kind == "empty":
        return Scene()
    if kind == "corridor":
        width = draw(st.floats(0.35, 2.0))
        heading = draw(st.floats(-math.pi, math.pi))
        return Scene.of(wall(width / 2, heading + math.pi / 2), wall(width / 2, heading - math.pi / 2))
    if kind == "walls":
        count = draw(st.integers(1, 4))
        return Scene.of(*(wall(draw(st.floats(0.12, 3.0)), draw(st.floats(-math.pi, math.pi)))
                          for _ in range(count)))
    items = []
    for _ in range(draw(st.integers(1, 12))):
        distance = draw(st.floats(0.1, 3.0))
        bearing = draw(st.floats(-math.pi, math.pi))
        centre = (distance * math.cos(bearing), distance * math.sin(bearing))
        if draw(st.booleans()):
            items.append(Circle(centre, draw(st.floats(0.02, 0.5))))
        else:
            items.append(box(centre, (draw(st.floats(0.05, 1.0)), draw(st.floats(0.05, 1.0))),
                             draw(st.floats(-math.pi, math.pi))))
    return Scene.of(*items)


@st.composite
def cases(draw):
    robot = preset(draw(st.sampled_from(["rosbot", "puzzlebot", "m2wr"])))
    robot = draw(lidars(robot))
    scan = synthetic_scan(robot, draw(scenes()))
    scale = draw(st.sampled_from([1.0, 1.0, 1.5]))  # sometimes beyond the limits
    u_nom = np.array([draw(st.floats(robot.v_min * scale, robot.v_max * scale)),
                      draw(st.floats(-robot.omega_max * scale, robot.omega_max * scale))])
    velocity = None
    if draw(st.booleans()):
        velocity = np.array([draw(st.floats(robot.v_min, robot.v_max)),
                             draw(st.floats(-robot.omega_max, robot.omega_max))])
    return robot, scan, u_nom, velocity


# ------------------------------------------------------------------ properties

@settings(max_examples=2000)
@given(cases())
def test_filter_properties_on_random_scans(case):
    robot, scan, u_nom, velocity = case
    filt = CBFSafetyFilter(robot, DT, budget=math.inf)
    result = filt.filter(u_nom, scan, velocity=velocity)
    u = result.u
    assert np.all(np.isfinite(u))
    lower, upper = robot.velocity_bounds(velocity, DT if velocity is not None else None)
    assert np.all(u >= lower - 1e-12) and np.all(u <= upper + 1e-12)
    assert result.status in (FilterStatus.OK, FilterStatus.RECOVERING, FilterStatus.SLACK, FilterStatus.BRAKING)
    if result.status is FilterStatus.BRAKING:
        # Only when no command in the box keeps the hard rows: then the base brakes at its limits.
        assert np.array_equal(u, robot.brake(velocity, DT if velocity is not None else None))
        assert result.reason is not None and result.reason.family == "unknown"
        return
    assert full_residual(filt, u_nom, scan, velocity, u, hard=True).max(initial=0.0) <= 1e-6
    residual = full_residual(filt, u_nom, scan, velocity, u)
    if result.status in (FilterStatus.SLACK, FilterStatus.RECOVERING):
        # Inside the margin, a barrier row may be held at "not approached" (right side 0) instead
        # of the recovery rate; beyond that, obstacle rows are relaxed by at most the slack.
        rows = filt.rows(scan, velocity, reduce=False)
        held = np.where(rows.family == 0, np.maximum(rows.h, 0.0), rows.h)
        assert (rows.G @ lifted(u, velocity) - held).max(initial=0.0) <= result.slack / DT + 1e-6
        if "holding" not in result.message and result.status is FilterStatus.RECOVERING:
            assert residual.max(initial=0.0) <= 1e-6
    else:
        assert residual.max(initial=0.0) <= 1e-6
    assert (result.reason is None) == (not result.modified and result.status is FilterStatus.OK)
    if velocity is None and result.min_barrier >= 0.0:
        assert result.status is FilterStatus.OK   # u = 0 is always feasible then
    nominal_feasible = (np.all(u_nom >= lower) and np.all(u_nom <= upper)
                        and full_residual(filt, u_nom, scan, velocity, u_nom).max(initial=0.0) <= 0.0)
    if nominal_feasible:
        assert np.array_equal(u, u_nom) and result.n_constraints == 0


@settings(max_examples=300, deadline=None)
@given(cases())
def test_with_the_velocity_every_pair_keeps_its_own_rate(case):
    """With ``velocity=`` no barrier row lets a pair outside the margin lose more than ``gamma`` of
    its own barrier per period (``a . w <= gamma h / dt``), whichever pair is the nearest.

    Without it the rows ask only ``h(x+) >= (1 - gamma) H``: a far pair could then be approached at
    ``(h - (1 - gamma) H) / dt`` and, once it became the nearest, need more deceleration than the
    base has (falsifier case -0.0444). ``h`` here is the pair's barrier without the point's
    uncertainty, at least the barrier the row is written for (the tilted half-plane's value is at most it).
    """
    robot, scan, _, velocity = case
    if velocity is None:
        velocity = np.zeros(2)
    filt = CBFSafetyFilter(robot, DT, budget=math.inf)
    rows = filt.rows(scan, velocity, reduce=False)
    barrier = rows.take(rows.family == 0)
    # The rows are written for four mean velocities of the period (rows.ramp_corners); the first
    # block is the one for the command itself (mean = command), with the right side as built.
    assert len(barrier) % 4 == 0
    barrier = barrier.take(np.arange(len(barrier)) < len(barrier) // 4)
    points = filt.points(scan)[barrier.point]
    control = filt.body.centres + np.array([filt.lookahead, 0.0])
    gaps = np.hypot(points[:, None, 0] - control[None, :, 0], points[:, None, 1] - control[None, :, 1])
    highest = np.max(gaps - filt.body.radii[None, :] - filt.lookahead - filt.margin, axis=1)
    outside = highest > 0.0
    assert np.all(barrier.h[outside] <= filt.gamma * highest[outside] / DT + 1e-9)


@settings(max_examples=1000)
@given(cases())
def test_reduction_gives_the_answer_of_the_full_qp(case):
    """The cut, pruning, binning and constraint generation change the answer by at most 1e-6.

    The reference builds every family (barrier, braking, sweep, ramp corners, unknown region)
    from every valid beam, with no cut at all (``reduce=False``); about half the cases give the
    velocity (acceleration-aware families), half do not.
    """
    robot, scan, u_nom, velocity = case
    filt = CBFSafetyFilter(robot, DT, budget=math.inf)
    result = filt.filter(u_nom, scan, velocity=velocity)
    if result.status not in (FilterStatus.OK, FilterStatus.RECOVERING) or not result.modified:
        return
    if "holding" in result.message:   # the answer of a relaxed stage, as with slack
        return
    full = filt.build_qp(u_nom, scan, velocity, reduce=False)
    reference = qpsolvers.solve_problem(full, solver="quadprog")
    if not reference.found:
        # Only problems infeasible by less than the verification tolerance get here (e.g. both
        # directions unseen and a current velocity of 1e-7 m/s): the answer must satisfy the
        # full QP to that tolerance, and there is no exact optimum to compare with.
        assert full_residual(filt, u_nom, scan, velocity, result.u).max() <= 1e-6
        return
    assert np.max(np.abs(reference.x[:2] - result.u)) <= 1e-6
    assert result.n_constraints <= full.G.shape[0] - 4


def _uncovered_binding_rows(filt: CBFSafetyFilter, scan, velocity) -> int:
    """How many rows of the full problem (no cut) some command in the box violates that the reduced rows
    do not contain (the same left side, a right side no larger)."""
    robot = filt.robot
    lower, upper = robot.velocity_bounds(velocity, DT if velocity is not None else None)
    t_low = np.abs(velocity) if velocity is not None else np.zeros(2)
    t_high = np.maximum(np.maximum(np.abs(lower), np.abs(upper)), t_low)
    z_lower, z_upper = np.concatenate((lower, t_low)), np.concatenate((upper, t_high))
    full, kept = filt.rows(scan, velocity, reduce=False), filt.rows(scan, velocity)
    binding = full.take(worst_case(full.G, z_lower, z_upper) > full.h + 1e-9)
    order = np.argsort(kept.G[:, 0])
    first = kept.G[order, 0]
    starts = np.searchsorted(first, binding.G[:, 0] - 1e-9, side="left")
    stops = np.searchsorted(first, binding.G[:, 0] + 1e-9, side="right")
    uncovered = 0
    for row, start, stop in zip(range(len(binding)), starts, stops, strict=True):
        same = order[start:stop]
        same = same[np.abs(kept.G[same] - binding.G[row]).max(axis=1) <= 1e-9]
        uncovered += not np.any(kept.h[same] <= binding.h[row] + 1e-9)
    return uncovered


@settings(max_examples=300)
@given(cases())
def test_the_cut_keeps_every_row_a_command_in_the_box_can_violate(case):
    """docs/safety.md's exact reduction, row by row: a point is left out only when no row built from it can
    bind for any command in the box."""
    robot, scan, _, velocity = case
    assert _uncovered_binding_rows(CBFSafetyFilter(robot, DT), scan, velocity) == 0


def _where_barrier(filt: CBFSafetyFilter, origin, direction, barrier: float) -> np.ndarray:
    """The point [m] along ``origin + t direction`` (base frame) whose barrier is ``barrier`` [m] (bisection)."""
    origin, direction = np.asarray(origin, dtype=float), np.asarray(direction, dtype=float)
    low, high = 0.0, 5.0
    for _ in range(50):
        middle = 0.5 * (low + high)
        value = filt.body.barrier((origin + middle * direction)[None], filt.margin, 0.0, filt.lookahead)
        low, high = (middle, high) if value < barrier else (low, middle)
    return origin + high * direction


@pytest.mark.parametrize("body", ["disk", "polygon"])
def test_the_cut_keeps_the_rows_the_command_corner_can_bind(body):
    """A pillar just inside the margin beside a fast robot (``H`` < 0) and a wall ahead whose barrier lies between
    what the barrier rows reach without the command corner's headroom (``gamma`` of each right side, see
    ``rows.ramp_corners``) and with it. The cut kept only what the rows reach without it until 2026-11-27 and
    dropped the wall (answers up to 2.5e-4 m/s from the full QP's)."""
    rng = np.random.default_rng(2)
    for k in range(40):
        robot = preset(("rosbot", "puzzlebot")[k % 2])   # lidars that see beside the base
        filt = CBFSafetyFilter(robot, DT, body=body)
        velocity = np.array([rng.uniform(0.6, 1.0) * robot.v_max, rng.uniform(-0.1, 0.1) * robot.omega_max])
        side = rng.choice([-1.0, 1.0])
        beside = _where_barrier(filt, (rng.uniform(-0.1, 0.0), 0.0), (0.0, side), rng.uniform(-0.03, 0.0))
        pillar = Circle((beside[0], beside[1] + 0.03 * side), 0.03)
        # The largest approach in a period (box speed and turn, their arc terms) and the two reaches.
        speed = min(robot.v_max, velocity[0] + robot.a_max * DT)
        turn = abs(velocity[1]) + robot.alpha_max * DT
        reach = DT * (speed + filt.lookahead * turn) * (1.0 + 0.5 * robot.omega_max * DT) / filt.gamma
        barrier = reach * rng.uniform(1.0, 1.01)   # the rows' own arc terms stay below the bound's
        ahead = _where_barrier(filt, (0.0, 0.0), (1.0, 0.0), barrier)[0]
        scan = synthetic_scan(robot, Scene.of(pillar, Segment((ahead, -3.0), (ahead, 3.0))), Pose2D())
        assert _uncovered_binding_rows(CBFSafetyFilter(robot, DT, body=body), scan, velocity) == 0, (
            robot.name, velocity, barrier)


@pytest.mark.parametrize("dt", [0.2, 0.25, 0.5])
@pytest.mark.parametrize("ahead", [2.0, 1.0, 0.45])
def test_gamma_one_filters_as_the_full_qp(dt, ahead):
    """A slow robot filtering at its slow scan rate (a TurtleBot at 5, 4 and 2 Hz: ``gamma = min(1, a_max dt /
    v_max)`` is 0.91, then 1): no error, the cut's answer is the full QP's, and a wall 2 m or 1 m ahead leaves the
    top speed (until 2026-11-27 the full QP reversed there, and a headroom-aware reach divided by zero)."""
    robot = preset("rosbot").replace(name="turtlebot_like", radius=0.16, v_max=0.22, v_min=-0.22, omega_max=2.84,
                                     a_max=1.0, alpha_max=3.0)
    filt = CBFSafetyFilter(robot, dt, budget=math.inf)
    assert filt.gamma == pytest.approx(min(1.0, robot.a_max * dt / robot.v_max))
    scan = synthetic_scan(robot, Scene.of(Segment((ahead, -0.6), (ahead, 0.6))), Pose2D())
    u_nom, velocity = np.array([0.22, 0.0]), np.array([0.2, 0.0])
    result = filt.filter(u_nom, scan, velocity=velocity)
    assert np.all(np.isfinite(result.u))
    reference = qpsolvers.solve_problem(CBFSafetyFilter(robot, dt).build_qp(u_nom, scan, velocity, reduce=False),
                                        solver="quadprog")
    if result.status is FilterStatus.OK:
        assert reference.found and np.max(np.abs(reference.x[:2] - result.u)) <= 1e-6
    if ahead >= 1.0:
        assert result.status is FilterStatus.OK and result.u[0] == pytest.approx(0.22)


@settings(max_examples=600)
@given(cases(), st.floats(-1.0, 1.0), st.floats(-3.0, 3.0))
def test_slack_never_changes_the_sign_of_a_hard_row(case, v, omega):
    """Whatever the obstacle rows need, the rows of the unknown region and the box hold exactly."""
    robot, scan, u_nom, _ = case
    velocity = np.clip([v, omega], robot.lower, robot.upper)   # often too fast to stop: slack or braking
    filt = CBFSafetyFilter(robot, DT, budget=math.inf)
    result = filt.filter(u_nom, scan, velocity=velocity)
    if result.status is FilterStatus.BRAKING:
        # Only when no command in the box keeps every hard row (checked here by an independent solver).
        rows = filt.rows(scan, velocity, reduce=False)
        rows = rows.take(rows.hard)
        lower, upper = robot.velocity_bounds(velocity, DT)
        t_low = np.abs(velocity)
        t_high = np.maximum(np.maximum(np.abs(lower), np.abs(upper)), t_low)
        abs_rows = np.array([[1, 0, -1, 0], [-1, 0, -1, 0], [0, 1, 0, -1], [0, -1, 0, -1]], dtype=float)
        keep = qpsolvers.solve_qp(np.eye(4), np.zeros(4), np.vstack((abs_rows, rows.G)),
                                  np.concatenate((np.zeros(4), rows.h)), lb=np.concatenate((lower, t_low)),
                                  ub=np.concatenate((upper, t_high)), solver="quadprog")
        assert keep is None or np.max(rows.G @ keep - rows.h) > 1e-9
        assert np.array_equal(result.u, robot.brake(velocity, DT))
        return
    hard = full_residual(filt, u_nom, scan, velocity, result.u, hard=True)
    assert hard.max(initial=0.0) <= 1e-6
    lower, upper = robot.velocity_bounds(velocity, DT)
    assert np.all(result.u >= lower - 1e-12) and np.all(result.u <= upper + 1e-12)
    frontier = filt._observe((scan,)).frontier
    if frontier.backward:
        assert result.u[0] >= 0.0
    if frontier.forward:
        assert result.u[0] <= 0.0


def test_working_set_and_constraint_generation_match_the_full_qp(monkeypatch):
    """Force the binned working set (as for scans with thousands of beams) and check exactness."""
    import safenav.filters.cbf as cbf

    monkeypatch.setattr(cbf, "DIRECT_ROWS", 0)
    rng = np.random.default_rng(7)
    robot = preset("rosbot")
    rounds = 0
    for _ in range(300):
        bearings = rng.uniform(-math.pi, math.pi, 8)
        distances = rng.uniform(0.35, 0.9, 8)
        items = [Circle((d * math.cos(b), d * math.sin(b)), rng.uniform(0.03, 0.15))
                 for d, b in zip(distances, bearings, strict=True)]
        scene = Scene.of(*items, wall(rng.uniform(0.4, 0.8), rng.uniform(-math.pi, math.pi)))
        scan = synthetic_scan(robot, scene)
        filt = CBFSafetyFilter(robot, DT, n_bins=8)
        u_nom = rng.uniform(robot.lower, robot.upper)
        result = filt.filter(u_nom, scan)
        if result.status is not FilterStatus.OK or not result.modified:
            continue
        reference = qpsolvers.solve_problem(filt.build_qp(u_nom, scan, reduce=False), solver="quadprog")
        assert np.max(np.abs(reference.x[:2] - result.u)) <= 1e-6
        rounds += 1
    assert rounds > 50


# ------------------------------------------------------------------ geometry

def test_wall_ahead_limits_speed_to_the_derived_bound():
    robot = preset("rosbot")
    filt = CBFSafetyFilter(robot, DT)
    distance = 0.45
    scan = synthetic_scan(robot, Scene.of(wall(distance)))
    result = filt.filter((robot.v_max, 0.0), scan)
    ell, margin = filt.lookahead, filt.margin
    barrier = distance - ell - (robot.radius + ell + margin)      # nearest wall point, seen from p
    bound = filt.gamma * barrier / (DT * (1.0 + filt.kappa))      # v dt (1 + kappa) <= gamma h
    assert barrier > 0
    assert result.status is FilterStatus.OK
    assert result.u[0] == pytest.approx(bound, abs=1e-6)
    assert result.u[0] <= bound + 1e-9
    assert abs(result.u[1]) <= 1e-6
    assert result.min_barrier == pytest.approx(barrier, abs=1e-9)
    assert result.clearance == pytest.approx(distance - robot.radius, abs=1e-9)
    # The active constraint is the wall point straight ahead.
    nearest = result.constraint_points[list(result.active)]
    assert np.any(np.hypot(nearest[:, 0] - distance, nearest[:, 1]) < 1e-9)


def test_obstacle_behind_a_180_degree_lidar_does_not_permit_reversing():
    robot = preset("m2wr")
    filt = CBFSafetyFilter(robot, DT)
    scan = synthetic_scan(robot, Scene.of(wall(0.4, math.pi)))   # the wall is invisible: behind the lidar
    assert np.all(np.isinf(scan.ranges))
    result = filt.filter((-0.5, 0.3), scan)
    assert result.u[0] >= -1e-12
    assert result.u[1] == pytest.approx(0.3)
    assert filt.filter((0.5, 0.0), scan).u[0] == 0.5


def test_robot_between_two_walls_still_drives_along_the_corridor(robot):
    filt = CBFSafetyFilter(robot, DT)
    half_width = robot.radius + filt.lookahead + filt.margin + 0.15
    scan = synthetic_scan(robot, Scene.of(wall(half_width, math.pi / 2), wall(half_width, -math.pi / 2)))
    result = filt.filter((0.8 * robot.v_max, 0.0), scan)
    assert result.status is FilterStatus.OK
    assert np.array_equal(result.u, [0.8 * robot.v_max, 0.0])


def test_closed_loop_turning_into_a_wall_keeps_the_margin(robot):
    """Exact kinematics and exact scans: the guarantee holds to within the beam-spacing error."""
    filt = CBFSafetyFilter(robot, DT)
    scene = Scene.of(wall(1.0, math.pi / 2), wall(1.0, -math.pi / 2), wall(4.0, 0.0))
    pose = Pose2D(0.0, 0.0, 0.0)
    worst = math.inf
    modified = 0
    for _ in range(300):
        scan = synthetic_scan(robot, scene, pose)
        result = filt.filter((robot.v_max, 0.2), scan)
        modified += result.modified
        pose = unicycle_step(pose, *result.u, DT)
        worst = min(worst, scene.clearance(pose[:2], robot.radius))
    assert modified > 20
    assert worst >= filt.margin - 2e-3


def test_unknown_sector_in_front_blocks_forward_motion():
    robot = preset("puzzlebot")
    ranges = np.full(360, math.inf)
    ranges[:15] = math.nan      # beams 0..14 and 345..359: +-15 degrees ahead, no information
    ranges[-15:] = math.nan
    filt = CBFSafetyFilter(robot, DT)
    result = filt.filter((0.3, 0.2), robot.scan(ranges))
    assert result.u[0] <= 1e-12
    assert result.u[1] == pytest.approx(0.2)
    few = np.full(360, math.inf)
    few[[0, 2, 4]] = math.nan    # isolated dropouts are bridged by their neighbours
    assert filt.filter((0.3, 0.2), robot.scan(few)).u[0] == 0.3


def test_robot_inside_the_margin_moves_back_out():
    robot = preset("rosbot")
    filt = CBFSafetyFilter(robot, DT)
    scan = synthetic_scan(robot, Scene.of(wall(0.2)))
    result = filt.filter((0.5, 0.0), scan)
    assert result.min_barrier < 0
    assert result.status is FilterStatus.RECOVERING
    assert result.u[0] < 0.0
    assert "inside the margin" in result.message


def test_moving_too_fast_to_brake_relaxes_with_slack_and_brakes_hard():
    robot = preset("rosbot")
    filt = CBFSafetyFilter(robot, DT)
    scan = synthetic_scan(robot, Scene.of(wall(0.5)))
    result = filt.filter((1.0, 0.0), scan, velocity=(1.0, 0.0))
    assert result.status is FilterStatus.SLACK
    assert result.slack > 0
    assert result.u[0] == pytest.approx(1.0 - robot.a_max * DT)   # the hardest braking allowed
    assert "cannot brake in time" in result.message


def test_velocity_given_keeps_the_command_reachable():
    robot = preset("puzzlebot")
    filt = CBFSafetyFilter(robot, DT)
    result = filt.filter((0.4, 2.0), robot.scan(), velocity=(0.0, 0.0))
    assert result.u == pytest.approx([robot.a_max * DT, robot.alpha_max * DT])


def test_all_inf_scan_returns_the_nominal_unchanged(robot):
    filt = CBFSafetyFilter(robot, DT)
    result = filt.filter((0.1, -0.2), robot.scan())
    assert result.status is FilterStatus.OK and not result.modified
    assert result.clearance == math.inf and result.min_barrier == math.inf


def test_centre_barrier_constrains_speed_only():
    robot = preset("rosbot")
    filt = CBFSafetyFilter(robot, DT, lookahead=0.0)
    scan = synthetic_scan(robot, Scene.of(Circle((0.5, 0.1), 0.1)))
    result = filt.filter((1.0, 1.0), scan)
    assert result.u[1] == pytest.approx(1.0, abs=1e-6)
    assert result.u[0] < 1.0


def test_lookahead_barrier_steers_around_an_offset_obstacle():
    robot = preset("rosbot")
    filt = CBFSafetyFilter(robot, DT)
    scan = synthetic_scan(robot, Scene.of(Circle((0.45, 0.12), 0.05)))
    result = filt.filter((1.0, 0.0), scan)
    assert result.u[1] < -1e-3     # turns right, away from the obstacle on the left


@settings(max_examples=300, deadline=None)
@given(cases())
def test_a_shorter_look_ahead_never_lowers_a_barrier(case):
    """What makes shortening the look-ahead safe at any call: every pair's barrier, hence ``H``, is at
    least as large (the control point moves back by the difference, the radius shrinks by it)."""
    robot, scan, _, _ = case
    barriers = []
    for lookahead in (0.1, 0.05, 0.0):
        filt = CBFSafetyFilter(robot, DT, lookahead=lookahead, min_lookahead=lookahead)
        barriers.append(filt.filter((0.0, 0.0), scan).min_barrier)
    assert barriers[0] <= barriers[1] + 1e-12 and barriers[1] <= barriers[2] + 1e-12


def corridor(robot, width: float) -> Scene:
    """Two walls along the heading from 0.3 m ahead to 1.5 m, ``width`` apart, centred on the robot."""
    return Scene.of(Segment((0.3, 0.5 * width), (1.5, 0.5 * width)), Segment((0.3, -0.5 * width), (1.5, -0.5 * width)))


def test_in_a_narrow_passage_the_filter_shortens_its_look_ahead_and_gets_through():
    """A corridor 2 (R + margin) + 4 cm wide: the 0.1 m look-ahead's control disk does not fit. With
    ``passage`` set (as the escape does through a gap) the filter drives through with the rows of the shortest
    look-ahead, each answer keeping every row of the look-ahead it used and saying so; once out and the flag
    cleared, it takes the longer one back when there is room."""
    robot = preset("rosbot")
    filt = CBFSafetyFilter(robot, DT, budget=math.inf)      # every status checked: the math, not the machine's load
    scene = corridor(robot, 2.0 * (robot.radius + filt.margin) + 0.04)
    pose, velocity = Pose2D(), np.zeros(2)
    used, worst = [], math.inf
    for _ in range(300):
        filt.passage = pose.x < 1.6
        scan = synthetic_scan(robot, scene, pose)
        result = filt.filter((0.3, 0.0), scan, velocity=velocity)
        lookahead = filt.lookahead
        checker = CBFSafetyFilter(robot, DT, lookahead=lookahead, min_lookahead=lookahead)
        assert result.status is FilterStatus.OK
        assert np.all(full_residual(checker, result.u_nom, scan, velocity, result.u) <= 1e-6)
        assert (lookahead == 0.0) == ("look-ahead 0 m (a narrow passage)" in result.message) or not result.modified
        used.append(lookahead)
        worst = min(worst, result.clearance)
        velocity = result.u.copy()
        for _ in range(10):
            pose = unicycle_step(pose, float(velocity[0]), float(velocity[1]), DT / 10)
    assert worst >= filt.margin - 1e-9
    assert pose.x > 2.0                     # through the corridor and out
    assert used[0] == 0.0 and used[-1] == 0.1


@pytest.mark.parametrize("room, back", [(0.1, True), (0.03, False)])
def test_out_of_a_passage_the_longer_look_ahead_returns_when_its_own_barrier_has_room(room, back):
    """A wall beside the robot: the longer look-ahead's barrier is the shorter one's less one look-ahead, not
    two (the bound a head-on point needs). Out of the passage the filter takes the longer look-ahead back as soon
    as its own barrier over the call's points has ``LOOKAHEAD_ROOM`` (5 cm), and keeps the shorter one while it
    has less; the answer keeps every row of the look-ahead it used either way. Until 2026-11-27 it waited for
    the shorter barrier to exceed ``2 l + LOOKAHEAD_ROOM`` (0.25 m), so in clutter a robot that had passed one
    gap kept the look-ahead that cannot steer, and braked in front of corners it could have turned from."""
    robot = preset("rosbot")
    filt = CBFSafetyFilter(robot, DT)
    side = robot.radius + filt.margin + 0.1 + room        # the longer look-ahead's barrier is `room`
    scan = synthetic_scan(robot, Scene.of(Segment((-1.0, side), (1.5, side))))
    filt.passage = True
    filt.filter((0.3, 0.0), scan, velocity=np.zeros(2))
    assert filt.lookahead == 0.0
    filt.passage = False
    result = filt.filter((0.3, 0.0), scan, velocity=np.zeros(2))
    assert filt.lookahead == (0.1 if back else 0.0)
    assert result.min_barrier == pytest.approx(room if back else room + 0.1, abs=2e-3)
    checker = CBFSafetyFilter(robot, DT, lookahead=filt.lookahead, min_lookahead=filt.lookahead)
    assert np.all(full_residual(checker, result.u_nom, scan, np.zeros(2), result.u) <= 1e-6)


def test_without_the_passage_flag_the_look_ahead_stays_and_the_body_stops_and_reset_restores_it():
    robot = preset("rosbot")
    held, narrow = CBFSafetyFilter(robot, DT), CBFSafetyFilter(robot, DT)
    narrow.passage = True
    scan = synthetic_scan(robot, corridor(robot, 2.0 * (robot.radius + held.margin) + 0.04), Pose2D(0.2, 0.0, 0.0))
    for _ in range(30):
        stopped = held.filter((0.3, 0.0), scan, velocity=np.zeros(2))
        moved = narrow.filter((0.3, 0.0), scan, velocity=np.zeros(2))
    assert stopped.u[0] < 0.03 and stopped.deadlock is not None and held.lookahead == 0.1
    assert moved.u[0] > 0.05 and narrow.lookahead == 0.0
    assert held.corridor_half_width == narrow.corridor_half_width == robot.radius + held.margin
    narrow.reset()
    assert narrow.lookahead == 0.1 and not narrow.passage


# ------------------------------------------------------------------ solvers

SOLVERS = [pytest.param(name, marks=[pytest.mark.slow] if name == "osqp" else [])   # OSQP: about a minute
           for name in ("daqp", "quadprog", "osqp", "qpsolvers:daqp", "qpsolvers:quadprog")
           if name.split(":")[-1] in available_solvers()]


@pytest.mark.parametrize("solver", SOLVERS)
def test_every_solver_gives_the_same_answer(solver):
    rng = np.random.default_rng(3)
    robot = preset("rosbot")
    reference = CBFSafetyFilter(robot, DT, solver="quadprog", budget=math.inf)
    filt = CBFSafetyFilter(robot, DT, solver=solver, budget=math.inf)
    compared = 0
    for _ in range(60):
        items = [Circle(tuple(rng.uniform(-1.2, 1.2, 2)), rng.uniform(0.03, 0.3)) for _ in range(6)]
        scan = synthetic_scan(robot, Scene.of(*items))
        u_nom = rng.uniform(robot.lower, robot.upper)
        velocity = rng.uniform(robot.lower, robot.upper) if rng.random() < 0.5 else None
        expected = reference.filter(u_nom, scan, velocity=velocity)
        got = filt.filter(u_nom, scan, velocity=velocity)
        if solver == "osqp" and expected.status is FilterStatus.SLACK and got.status is FilterStatus.FALLBACK:
            # ADMM does not always reach 1e-9 on a slack problem (no curvature in the auxiliaries):
            # the filter then brakes within the box and names the solver, it never sends the iterate.
            assert got.reason.family == "solver" and "osqp" in got.reason.detail
            continue
        assert got.status is expected.status
        # Active-set solvers agree to round-off; OSQP (first-order, no polishing) to 1e-5.
        assert got.u == pytest.approx(expected.u, abs=1e-5 if solver == "osqp" else 2e-6)
        compared += expected.modified
    assert compared > 10


def test_osqp_keeps_one_workspace():
    robot = preset("puzzlebot")
    filt = CBFSafetyFilter(robot, DT, solver="osqp", budget=math.inf)
    rng = np.random.default_rng(0)
    for _ in range(30):
        scan = synthetic_scan(robot, Scene.of(Circle(tuple(rng.uniform(-0.5, 0.5, 2)), 0.1), wall(0.4)))
        filt.filter((0.4, rng.uniform(-2, 2)), scan)
    setups = filt.backend.setups
    assert 1 <= setups <= 3
    for _ in range(30):
        scan = synthetic_scan(robot, Scene.of(Circle(tuple(rng.uniform(-0.5, 0.5, 2)), 0.1), wall(0.4)))
        filt.filter((0.4, rng.uniform(-2, 2)), scan)
    assert filt.backend.setups == setups   # updated in place, not set up again


def test_unknown_solver_lists_the_installed_ones():
    with pytest.raises(UnknownName, match=r"unknown QP solver 'gurobi'; expected one of: .*daqp"):
        CBFSafetyFilter(preset("rosbot"), DT, solver="gurobi")


@pytest.mark.parametrize(
    ("changes", "fragment"),
    [
        (dict(gamma=0.0), r"CBFConfig.gamma must be a finite number > 0 and <= 1, got 0.0"),
        (dict(gamma=1.5), r"CBFConfig.gamma must be a finite number > 0 and <= 1, got 1.5"),
        (dict(gamma=True), r"CBFConfig.gamma must be a finite number .* got True of type bool"),
        (dict(margin=-0.1), r"CBFConfig.margin must be a finite number >= 0 and <= 10, got -0.1"),
        (dict(lookahead=math.nan), r"CBFConfig.lookahead must be a finite number >= 0 and <= 10, got nan"),
        (dict(weights=(1.0, -1.0)), r"CBFConfig.weights\[1\] must be a finite number > 0, got -1.0"),
        (dict(n_bins=0), r"CBFConfig.n_bins must be an integer >= 1, got 0"),
        (dict(scan_timeout=0.0), r"CBFConfig.scan_timeout must be a finite number > 0, got 0.0"),
        (dict(time_constant=-0.1), r"CBFConfig.time_constant must be a finite number >= 0 and <= 1, got -0.1"),
    ],
)
def test_bad_config_is_rejected(changes, fragment):
    with pytest.raises(InvalidConfig, match=fragment):
        CBFSafetyFilter(preset("rosbot"), DT, **changes)


@pytest.mark.parametrize(("dt", "fragment"), [
    (-0.1, r"dt must be a finite number > 0, got -0.1"),
    (50, r"dt must be a duration in seconds in \(0, 1\], got 50 \(milliseconds\?\)"),
    ("0.05", r"dt must be a finite number > 0, got '0.05' of type str"),
])
def test_bad_period_is_rejected(dt, fragment):
    with pytest.raises(InvalidConfig, match=fragment):
        CBFSafetyFilter(preset("rosbot"), dt=dt)


# ------------------------------------------------------------------ failures

class BrokenBackend:
    """A back-end that fails in a chosen way."""

    name = "broken"
    direct_rows = 512

    def __init__(self, answer):
        self.answer = answer

    def solve(self, problem):
        x = None if self.answer is None else np.full(problem.P.shape[0], self.answer)
        return QPOutcome(x, "broken", 0.0)


@pytest.mark.parametrize("answer", [None, math.nan, 5.0])
def test_solver_failure_or_wrong_answer_brakes_and_says_so(answer):
    robot = preset("rosbot")
    filt = CBFSafetyFilter(robot, DT)
    filt.backend = BrokenBackend(answer)
    scan = synthetic_scan(robot, Scene.of(wall(0.5)))
    result = filt.filter((1.0, 0.0), scan, velocity=(0.6, 0.0))
    assert result.status is FilterStatus.FALLBACK
    assert result.braked
    assert result.u == pytest.approx(robot.brake((0.6, 0.0), DT))
    assert np.all(np.isfinite(result.u))
    assert "broken" in result.message or "violates" in result.message


# ------------------------------------------------------------------ real recordings

REAL_COMMANDS = [(1.0, 0.0), (0.3, 1.5), (-0.4, -0.5), (0.0, 3.0)]


@pytest.mark.parametrize("name", ["carmen-intel", pytest.param("carmen-freiburg-079", marks=pytest.mark.slow),
                                  "carmen-csail", "breezyslam-exp1", "breezyslam-exp2", "laser-scan-matcher-bag"])
def test_every_real_scan_filters_without_error_nan_or_solver_fallback(lidar_data, name):
    from safenav import LidarSpec, Pose2D
    from safenav.datasets import load_recording, recording_files, resample

    recording = load_recording(recording_files(lidar_data)[name])
    first = recording[0].scan
    recorded = preset("rosbot").replace(lidar=LidarSpec.from_scan(first, mount=None if first.mount_given else Pose2D()))
    resampled_robot = preset("rosbot")
    resampled_robot = resampled_robot.replace(lidar=LidarSpec.from_scan(resample(first, resampled_robot.lidar)))
    # The solver on every real scan, whatever the machine's pauses (a 264 ms one under the suite's load once braked a
    # call for its budget): no compute budget.
    filters = {False: CBFSafetyFilter(recorded, DT, budget=math.inf),
               True: CBFSafetyFilter(resampled_robot, DT, budget=math.inf)}
    statuses: dict[FilterStatus, int] = {}
    for index, record in enumerate(recording):
        scan = record.scan
        if index % 10 == 0:   # also through the ROSbot's own convention (beam 0 forward, -pi..pi)
            scan = resample(scan, resampled_robot.lidar)
        filt = filters[index % 10 == 0]
        for command_index, u_nom in enumerate(REAL_COMMANDS):
            velocity = (0.5, 0.0) if (index + command_index) % 2 else None
            result = filt.filter(u_nom, scan, velocity=velocity)
            assert np.all(np.isfinite(result.u)), (index, u_nom)
            assert result.status is not FilterStatus.FALLBACK, (index, u_nom, result.message)
            statuses[result.status] = statuses.get(result.status, 0) + 1
    assert statuses.get(FilterStatus.OK, 0) > len(recording)   # mostly a normal day


# ------------------------------------------------------------------ liveness beside a wall


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_a_base_at_its_acceleration_limits_slides_along_a_wall_the_nominal_turns_into(name):
    """A wall 0.15 m beside the body, the nominal turning into it at full speed and full yaw rate,
    a base ramping at its acceleration limits, the velocity and odometry given: the filter keeps
    the margin and lets the base slide along the wall at most of its top speed."""
    robot = preset(name)
    y = robot.radius + 0.15
    scene = Scene.of(Segment((0.16, y), (6.0, y)))
    filt = CBFSafetyFilter(robot, DT)
    pose, velocity = Pose2D(), np.zeros(2)
    nominal = np.array([robot.v_max, robot.omega_max])
    duration, worst, statuses = 4.0, math.inf, []
    for _ in range(round(duration / DT)):
        result = filt.filter(nominal, synthetic_scan(robot, scene, pose), velocity=velocity,
                             pose=(pose.x, pose.y, pose.yaw))
        statuses.append(result.status)
        for _ in range(10):
            velocity = robot.clip(result.u, velocity, DT / 10)
            pose = unicycle_step(pose, float(velocity[0]), float(velocity[1]), DT / 10)
            worst = min(worst, y - pose.y - robot.radius)
    assert worst >= filt.margin - 0.01
    ramp = robot.v_max / robot.a_max
    reachable = robot.v_max * (duration - ramp) + 0.5 * robot.v_max * ramp
    assert pose.x >= 0.6 * reachable, f"{name} slid only {pose.x:.2f} m of {reachable:.2f} m"


def test_hard_rows_the_stop_command_keeps_need_no_lp_and_others_get_one():
    """Whether any command in the box keeps the hard rows (asked when the first QP has no answer): the
    command nearest a stop answers without an LP when it keeps them; otherwise the LP decides. Here the
    blind rows of a side behind the m2wr (no backing faster than ``speed``)."""
    from safenav.filters import rows as families

    robot = preset("m2wr")
    filt = CBFSafetyFilter(robot, DT, budget=math.inf)
    view = filt._inspected(synthetic_scan(robot, Scene.of(wall(1.0))))
    solves = []
    solve = filt.backend.solve
    filt.backend.solve = lambda qp: solves.append(qp) or solve(qp)
    slowest = -0.45 + robot.a_max * DT      # backing at 0.45 m/s, the base slows to this within the period
    assert -0.42 < slowest < -0.38
    for velocity, speed, feasible, lp in [((0.3, 0.0), 0.0, True, 0), ((-0.45, 0.0), 0.42, True, 0),
                                          ((-0.45, 0.0), 0.0, False, 1), ((-0.45, 0.0), 0.38, False, 1)]:
        solves.clear()
        problem = filt._constraints(view, np.array(velocity), DT)
        assert filt._hard_feasible(families.blind_rows(False, True, speed), problem) is feasible
        assert len(solves) == lp


def test_a_row_no_command_in_the_box_keeps_needs_no_qp_to_say_the_rows_need_slack():
    """When some row's smallest left side over the box exceeds its right side, the QP without slack has no answer:
    the filter goes to the slack tiers without solving it. The answers are those of the filter that solves it
    (here the shortcut turned off), with fewer QPs (the first solve's rounds of constraint generation); where every
    row can be kept, the QPs are those of before. The scenes: walls ahead, and a post beside and behind the body,
    inside the margin, that a stopped base can leave at the rate the barrier asks (a shortcut that took a row
    some command misses for one no command keeps would only hold its distance there)."""
    robot = preset("rosbot")
    scenes = [Scene.of(wall(distance)) for distance in (0.35, 0.45, 0.6)]
    scenes += [Scene.of(Circle((distance * math.cos(angle), distance * math.sin(angle)), 0.03))
               for angle, distance in [(2.09, 0.23), (-2.09, 0.23), (2.62, 0.2)]]
    skipped = 0
    for scan in (synthetic_scan(robot, scene) for scene in scenes):
        for velocity in [(0.0, 0.0), (0.5, 0.0), (0.8, 1.0), (-0.3, -2.0)]:
            for nominal in [(1.0, 0.5), (-0.3, 0.0)]:
                answers, counts = [], []
                for shortcut in (True, False):
                    filt = CBFSafetyFilter(robot, DT, budget=math.inf)
                    if not shortcut:   # the screen never says that a row excludes every command
                        def screen(*args, screen=filt._decide.cbf_screen):
                            return (*screen(*args)[:-1], False)
                        filt._decide = SimpleNamespace(**{**vars(filt._decide), "cbf_screen": screen})
                    calls = []
                    solve = filt.backend.solve
                    filt.backend.solve = lambda qp, solve=solve, calls=calls: calls.append(qp) or solve(qp)
                    answers.append(filt.filter(nominal, scan, velocity=velocity))
                    counts.append(len(calls))
                fast, slow = answers
                assert np.array_equal(fast.u, slow.u) and fast.status is slow.status
                assert fast.reason == slow.reason and fast.slack == slow.slack
                assert counts[0] <= counts[1]
                if counts[0] < counts[1]:
                    skipped += 1
                    assert fast.status in (FilterStatus.SLACK, FilterStatus.RECOVERING, FilterStatus.BRAKING)
    assert skipped >= 8


_SPECIAL = [0.0, -0.0, 0.3, -0.3, 5e-324, -1.0, 1.0, math.nan, math.inf, -math.inf]


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and np.array_equal(a, b, equal_nan=True) and np.array_equal(np.signbit(a), np.signbit(b))


def test_the_commands_python_arithmetic_is_numpys_to_the_bit():
    """The decision's clip of a command and its lifted ``z`` (Python floats, for speed) give numpy's ``np.clip`` and
    ``(u, max(|u|, |velocity|))`` to the bit on every pair of special values (signed zeros, NaN, infinities, the
    smallest subnormal), bounds equal to the value included."""
    from safenav.filters.cbf import _clipped

    count = 0
    for v, omega in itertools.product(_SPECIAL, repeat=2):
        u = np.array([v, omega])
        for low, high in itertools.product(_SPECIAL[:7], repeat=2):
            if not low <= high:
                continue
            lower, upper = np.array([low, -high]), np.array([high, -low])
            assert _same_bits(_clipped(u, lower, upper), np.clip(u, lower, upper)), (u, lower, upper)
            count += 1
        for velocity in (None, np.array([0.5, -0.0]), np.array([-0.0, 3.0]), np.array([-1e-300, 0.0])):
            t = np.abs(u) if velocity is None else np.maximum(np.abs(u), np.abs(velocity))
            assert _same_bits(CBFSafetyFilter._lifted(u, SimpleNamespace(velocity=velocity)), np.concatenate((u, t)))
    assert count > 2000
