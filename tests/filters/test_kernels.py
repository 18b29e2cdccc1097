"""The compiled obstacle rows (safenav.filters.kernels) against the numpy families they mirror."""

from __future__ import annotations

import functools
import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from safenav import Pose2D, _kernels, preset, unicycle_step
from safenav.errors import MissingDependency, SafeNavError, SafeNavWarning, UnknownName
from safenav.filters import CBFSafetyFilter, MPCSafetyFilter, kernels
from safenav.filters.base import View
from safenav.filters.mpc import MPCProblem
from safenav.filters.perception import Frontier, shadow_points
from safenav.synthetic import Scene, Segment, swept_scan, synthetic_scan

numba = pytest.importorskip("numba", reason="the compiled kernels need numba (pip install 'safenav[fast]')")

finite = dict(allow_nan=False, allow_infinity=False)


def view_of(points: np.ndarray, uncertainty: np.ndarray) -> View:
    none = np.empty((0, 2))
    return View((), points, uncertainty, points.shape[0], Frontier(none, none, False, False, False, False))


def sorted_rows(rows) -> np.ndarray:
    """The rows as one array ``(k, 7)`` (G, h, point, family), lexicographically sorted."""
    table = np.column_stack((rows.G, rows.h, rows.point, rows.family))
    return table[np.lexsort(table.T[::-1])] if len(table) else table


@st.composite
def problems(draw):
    robot = preset(draw(st.sampled_from(["rosbot", "puzzlebot", "m2wr"])))
    body = draw(st.sampled_from(["disk", "cover"]))
    dt = draw(st.sampled_from([0.02, 0.05, 0.1, 0.25]))
    time_constant = draw(st.sampled_from([0.0, 0.0, 0.1]))
    count = draw(st.integers(0, 40))
    near = draw(st.floats(0.0, 1.5))
    points = np.array([[draw(st.floats(-near - 0.5, near + 0.5, **finite)), draw(st.floats(-near - 0.5, near + 0.5,
                                                                                            **finite))]
                       for _ in range(count)]).reshape(-1, 2)
    uncertainty = np.array([draw(st.sampled_from([0.0, 0.0, 0.01, 0.05])) for _ in range(count)])
    velocity = None if draw(st.booleans()) else np.array([draw(st.floats(robot.v_min, robot.v_max)),
                                                          draw(st.floats(-robot.omega_max, robot.omega_max))])
    u_nom = np.array([draw(st.floats(robot.v_min, robot.v_max)), draw(st.floats(-robot.omega_max, robot.omega_max))])
    return robot, body, dt, time_constant, points, uncertainty, velocity, u_nom


@settings(max_examples=300, deadline=None)
@given(problems())
def test_the_compiled_rows_are_the_numpy_rows(problem):
    """Every row of every family, its right side, point and family, to rounding, on random points (some inside
    the body and the margin, some at a control point's distance), with and without the velocity."""
    robot, body, dt, time_constant, points, uncertainty, velocity, u_nom = problem
    compiled = CBFSafetyFilter(robot, dt, body=body, time_constant=time_constant, kernels="numba")
    reference = CBFSafetyFilter(robot, dt, body=body, time_constant=time_constant, kernels="numpy")
    assert compiled._kernels is not None and reference._kernels is None
    view = view_of(points, uncertainty)
    a = compiled._constraints(view, velocity, dt, u_nom=u_nom)
    b = reference._constraints(view, velocity, dt, u_nom=u_nom)
    # the cut keeps the same points, and the clearance is the same number
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.uncertainty, b.uncertainty)
    assert a.clearance == b.clearance
    assert a.min_barrier == pytest.approx(b.min_barrier, abs=1e-12)
    np.testing.assert_allclose(a.barrier, b.barrier, atol=1e-12)
    # the same rows in the same order (the order the QP sees)
    assert len(a.rows) == len(b.rows)
    np.testing.assert_array_equal(a.rows.point, b.rows.point)
    np.testing.assert_array_equal(a.rows.family, b.rows.family)
    np.testing.assert_allclose(a.rows.G, b.rows.G, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(a.rows.h, b.rows.h, rtol=1e-12, atol=1e-12)


@settings(max_examples=300, deadline=None)
@given(problems(), st.floats(0.0, 2.5), st.floats(0.0, 1.0))
def test_the_compiled_cut_is_the_numpy_cut(problem, near, farther):
    """``cbf_distances`` and ``cbf_cut`` against the numpy they replace, bit for bit: every point's distance, the
    cut's ceiling, the body's clearance (one centred disk, and the cover's disks), the points within ``near`` and the
    smallest barrier (``BodyModel.barrier``) of those left out within ``near + farther``."""
    robot, body_name, dt, _, points, uncertainty, _, _ = problem
    safety = CBFSafetyFilter(robot, dt, body=body_name, kernels="numba")
    compiled, body = safety._kernels, safety._shape.body
    centred = body.n_disks == 1 and not body.centres.any()
    spread = 0.0 if centred else float(np.max(np.hypot(body.centres[:, 0], body.centres[:, 1])))
    distance, ceiling, clearance = compiled.cbf_distances(points, uncertainty, body.centres, body.radii, centred,
                                                          spread)
    expected = np.sqrt(points[:, 0] ** 2 + points[:, 1] ** 2)
    np.testing.assert_array_equal(distance, expected)
    assert clearance == safety._clearance(points, expected)
    if not points.shape[0]:
        assert ceiling == math.inf
        return
    assert ceiling == float(np.min(expected - uncertainty))
    kept, kept_uncertainty, every, left_out = compiled.cbf_cut(
        points, uncertainty, distance, near, near + farther, body.centres, body.radii, safety.lookahead, safety.margin)
    within = expected - uncertainty <= near
    np.testing.assert_array_equal(kept, points[within])
    np.testing.assert_array_equal(kept_uncertainty, uncertainty[within])
    assert every == bool(within.all())
    outside = ~within & (expected - uncertainty <= near + farther)
    assert left_out == (body.barrier(points[outside], safety.margin, uncertainty[outside], safety.lookahead)
                        if outside.any() else math.inf)


def test_a_point_at_a_control_point_gets_the_same_rows():
    """The degenerate pair (a point exactly at a control point) is pushed back along -x by both."""
    robot = preset("rosbot")
    compiled = CBFSafetyFilter(robot, 0.05, kernels="numba")
    reference = CBFSafetyFilter(robot, 0.05, kernels="numpy")
    points = np.array([[compiled.lookahead, 0.0], [0.5, 0.2]])
    view = view_of(points, np.zeros(2))
    for velocity in (None, np.array([0.3, 0.5])):
        a = compiled._constraints(view, velocity, 0.05)
        b = reference._constraints(view, velocity, 0.05)
        np.testing.assert_array_equal(sorted_rows(a.rows), sorted_rows(b.rows))
        assert np.all(np.isfinite(a.rows.G)) and np.all(np.isfinite(a.rows.h))


@pytest.mark.parametrize(("kind", "name", "dt"), [
    ("cbf", "rosbot", 0.02), ("cbf", "rosbot", 0.1), ("cbf", "m2wr", 0.02), ("cbf", "m2wr", 0.1),
    ("mpc", "rosbot", 0.05), ("mpc", "m2wr", 0.1)])
def test_closed_loops_give_the_same_commands(kind, name, dt):
    """Issue 18's wall scene (a wall just beside the path, the nominal turning into it at full speed), both
    kernels side by side on every call, the loop driven by the numpy filter: the same command to 1e-12 (the
    MPC's plans to 1e-9) and the same status on every call, and the body clear of the wall. (Both filters without
    a compute budget: a call that runs out of it brakes or follows the stored plan, whichever kernels.)"""
    robot = preset(name)
    rng = np.random.default_rng(3)
    tolerance = 1e-12 if kind == "cbf" else 1e-9
    for side in (1.0, -1.0):
        scene = Scene.of(Segment((0.16, side * (robot.radius + 0.05)), (4.0, side * (robot.radius + 0.05))))
        if kind == "cbf":
            compiled = CBFSafetyFilter(robot, dt, kernels="numba", budget=math.inf)
            reference = CBFSafetyFilter(robot, dt, kernels="numpy", budget=math.inf)
        else:
            compiled = MPCSafetyFilter(robot, dt, kernels="numba", budget=math.inf)
            reference = MPCSafetyFilter(robot, dt, kernels="numpy", budget=math.inf)
            assert compiled.backend.kernels is not None and reference.backend.kernels is None
        pose, velocity = Pose2D(), np.zeros(2)
        nominal = np.array([robot.v_max, side * robot.omega_max])
        for _ in range(round(2.0 / dt)):
            scan = synthetic_scan(robot, scene, pose, noise_std=robot.lidar.noise_std, rng=rng)
            a = compiled.filter(nominal, scan, velocity=velocity)
            b = reference.filter(nominal, scan, velocity=velocity)
            np.testing.assert_allclose(a.u, b.u, atol=tolerance)
            assert a.status == b.status
            assert b.clearance > 0.0
            velocity = robot.clip(b.u, velocity, dt)
            pose = unicycle_step(pose, float(velocity[0]), float(velocity[1]), dt)


def test_kernels_setting_is_checked():
    with pytest.raises(UnknownName) as error:
        CBFSafetyFilter(preset("rosbot"), kernels="cython")
    assert isinstance(error.value, SafeNavError) and isinstance(error.value, ValueError)
    assert "cython" in str(error.value)
    assert kernels.resolve("auto") == "numba"
    assert CBFSafetyFilter(preset("rosbot"), body="polygon").rows_body.name == "polygon"   # numpy, kernels or not


def test_asking_for_numba_without_it_names_the_pip_line(monkeypatch):
    monkeypatch.setattr(_kernels, "require", _missing)
    monkeypatch.setattr(_kernels, "available", lambda: False)
    with pytest.raises(MissingDependency) as error:
        CBFSafetyFilter(preset("rosbot"), kernels="numba")
    assert 'pip install "safenav[fast]"' in str(error.value) or "safenav[fast]" in str(error.value)
    assert CBFSafetyFilter(preset("rosbot"))._kernels is None   # "auto" falls back to numpy


def _missing(module: str, *, extra: str, purpose: str, package: str | None = None):
    raise MissingDependency(package or module, purpose, extra)


def _recorded_scans(folder) -> list:
    from safenav.datasets import load_recording, recording_files

    scans = []
    for path in recording_files(folder).values():
        scans += [recorded.scan for recorded in load_recording(path, limit=40)]
    return scans


@pytest.mark.parametrize("reach", [0.3, 1.0, 4.0])
def test_the_compiled_shadow_points_are_the_numpy_ones(lidar_data, reach):
    """Every real recorded scan (full turns and partial fields of view, NaN, +-inf, out-of-range readings)
    and synthetic scans of every preset: the edges of what obstacles hide, the same points in the same order."""
    compiled = kernels.load()
    scans = _recorded_scans(lidar_data)
    rng = np.random.default_rng(5)
    for name in ("rosbot", "puzzlebot", "m2wr"):
        robot = preset(name)
        for _ in range(10):
            scene = Scene.of(*(Segment(tuple(rng.uniform(-3, 3, 2)), tuple(rng.uniform(-3, 3, 2))) for _ in range(4)))
            scans.append(synthetic_scan(robot, scene, Pose2D(), noise_std=0.01, rng=rng))
    assert len(scans) > 100
    found = 0
    for scan in scans:
        a = shadow_points((scan,), reach, 0.3, compiled)
        b = shadow_points((scan,), reach, 0.3)
        np.testing.assert_array_equal(a, b)
        found += a.shape[0]
    assert found > 0
    pair = (scans[0], scans[-1])
    np.testing.assert_array_equal(shadow_points(pair, reach, 0.3, compiled), shadow_points(pair, reach, 0.3))


def test_the_compiled_readings_and_points_are_the_scans(lidar_data):
    """Every real recorded scan (NaN, +-inf, readings below range_min and beyond range_max) and random scans with
    every kind of reading, some with TOO_CLOSE beams: ``classify`` sets what the scan's numpy would compute (the
    same readings, hit mask and count), read-only, and ``beam_points`` with the kernels gives the same points in the
    same order (through numpy where a beam reads TOO_CLOSE, whose point depends on the body)."""
    from safenav.filters.perception import beam_points, classify

    compiled = kernels.load()
    rng = np.random.default_rng(11)
    robot = preset("rosbot")
    scans = _recorded_scans(lidar_data)
    for _ in range(60):
        ranges = rng.uniform(-1.0, 15.0, robot.lidar.n_beams)
        for value, share in ((np.nan, 0.05), (np.inf, 0.2), (-np.inf, 0.01 * rng.integers(0, 2)), (0.0, 0.02)):
            ranges[rng.random(ranges.size) < share] = value
        scans.append(robot.scan(ranges))
    assert len(scans) > 100
    close = 0
    for recorded in scans:
        scan, twin = recorded.replace(), recorded.replace()     # nothing computed yet
        assert "readings" not in scan.__dict__
        classify((scan,), compiled)
        assert "readings" not in twin.__dict__
        np.testing.assert_array_equal(scan.readings, twin.readings)
        assert scan.readings.dtype == twin.readings.dtype and not scan.readings.flags.writeable
        np.testing.assert_array_equal(scan._hit_mask, twin._hit_mask)
        assert scan.n_informative == twin.n_informative and type(scan.n_informative) is int
        for body in (robot.radius, 0.05):
            np.testing.assert_array_equal(beam_points((scan,), body, compiled=compiled), beam_points((twin,), body))
        close += bool(np.any(scan.ranges == -np.inf))
    assert close > 0


@pytest.mark.parametrize("full_turn", [True, False])
def test_an_occluder_at_the_first_beam_is_an_edge_only_round_a_full_turn(full_turn):
    """Beam 0 hits at 1 m, the last beam has no return: round a full turn they are neighbours (an edge of
    what beam 0's obstacle hides), across the gap of a partial field of view they are not."""
    from safenav.scan import LaserScan

    n = 360
    increment = (2.0 * np.pi if full_turn else np.pi) / n
    ranges = np.full(n, 1.0)
    ranges[-1] = np.inf
    ranges[1] = 1.0
    scan = LaserScan(angle_min=0.0, angle_max=increment * (n - 1), angle_increment=increment, ranges=ranges,
                     range_min=0.1, range_max=10.0, mount=(0.0, 0.0, 0.0))
    a = shadow_points((scan,), 2.0, 0.3, kernels.load())
    np.testing.assert_array_equal(a, shadow_points((scan,), 2.0, 0.3))
    at_first = np.isclose(np.arctan2(a[:, 1], a[:, 0]), 0.0, atol=1e-9)
    assert at_first.any() == full_turn


def _memory_scan(rng: np.random.Generator):
    """A random scan (a full turn or a part of one, the lidar anywhere on the base, any yaw; hits, no returns,
    NaN, -inf, readings under range_min) and remembered points: on its hits, near them, anywhere, at the lidar;
    their uncertainties from none to disks that hold the lidar."""
    from safenav.scan import LaserScan

    n = int(rng.integers(8, 721))
    view = float(rng.choice([np.radians(60.0), np.radians(120.0), np.pi, np.radians(270.0), np.radians(359.0),
                             2.0 * np.pi]))
    if view == 2.0 * np.pi:
        increment, angle_min = view / n, -np.pi
    else:
        increment, angle_min = view / (n - 1), -0.5 * view
    ranges = rng.uniform(0.2, 5.0, n)
    if rng.random() < 0.7:   # runs of equal readings: walls, so that fans meet informative beams
        ranges = np.repeat(ranges[: n // 8 + 1], 8)[:n]
    kind = rng.random(n)
    ranges[kind < 0.05] = np.inf
    ranges[(kind >= 0.05) & (kind < 0.08)] = np.nan
    ranges[(kind >= 0.08) & (kind < 0.1)] = -np.inf
    ranges[(kind >= 0.1) & (kind < 0.12)] = 0.01
    mount = (float(rng.uniform(-0.2, 0.2)), float(rng.uniform(-0.1, 0.1)), float(rng.uniform(-np.pi, np.pi)))
    scan = LaserScan(angle_min=angle_min, angle_max=angle_min + (n - 1) * increment, angle_increment=increment,
                     ranges=ranges, range_min=0.05, range_max=6.0, mount=mount)
    count = int(rng.integers(0, 41))
    beams = rng.integers(0, n, count)
    on_hits = scan.beam_points(beams, np.where(np.isfinite(ranges[beams]), ranges[beams], 1.0))
    points = on_hits + rng.normal(0.0, rng.choice([0.0, 0.01, 0.3]), on_hits.shape)
    anywhere = rng.random(count) < 0.2
    points[anywhere] = rng.uniform(-4.0, 4.0, (int(anywhere.sum()), 2))
    at_lidar = rng.random(count) < 0.03
    points[at_lidar] = mount[:2]
    uncertainty = rng.choice([0.0, 0.0, 0.01, 0.1, 0.5, 1.0, 6.0], count)
    return scan, points, uncertainty


def test_the_compiled_recall_test_is_the_numpy_one():
    """perception._seen_again, compiled and numpy, on 3000 random scans and remembered points (every field of
    view, any mount, invalid readings, fans over several beams, round the turn, past an edge, disks that hold the
    lidar): the same points seen again, the same points and uncertainties kept, to rounding. Every branch is met:
    points seen again, points a fan over a silent beam keeps, points narrowed beyond an edge."""
    from safenav.filters import perception

    compiled = kernels.load()
    rng = np.random.default_rng(11)
    met = dict(again=0, silent=0, narrowed=0)
    for _ in range(3000):
        scan, points, uncertainty = _memory_scan(rng)
        tolerance = 0.02 + uncertainty
        a = perception._seen_again_compiled(compiled, scan, points, tolerance, uncertainty)
        b = perception._seen_again(scan, points, tolerance, uncertainty)
        np.testing.assert_array_equal(a[0], b[0])
        np.testing.assert_allclose(a[1], b[1], rtol=0.0, atol=1e-12)
        np.testing.assert_allclose(a[2], b[2], rtol=0.0, atol=1e-12)
        met["again"] += int(b[0].sum())
        nearest_only = perception._seen_again(scan, points, tolerance, np.zeros_like(uncertainty))[0]
        met["silent"] += int(np.sum(nearest_only & ~b[0] & (uncertainty > 0.0)))
        met["narrowed"] += int(np.sum(b[2] < uncertainty))
    assert min(met.values()) > 50, met


def test_the_compiled_memory_recall_is_the_numpy_one():
    """PointMemory.recall with one scan taken at once, compiled (``memory_recall``: the move into the current frame,
    the uncertainty, the range, the scan's spread, seen_again, the points kept) and numpy, on 1500 random scans and
    memories carried by random motions with and without odometry error and scan error: the same points kept, to
    rounding, with the same uncertainties; points are kept, dropped as seen again and dropped out of range."""
    from safenav.filters.perception import PointMemory

    compiled = kernels.load()
    rng = np.random.default_rng(13)
    kept = dropped = far = 0
    for _ in range(1500):
        scan, points, uncertainty = _memory_scan(rng)
        memory = PointMemory(max_range=float(rng.choice([1.0, 3.0, 10.0])), capacity=1000)
        memory.store(points, np.empty((0, 2)), np.empty(0), uncertainty)
        for _ in range(int(rng.integers(0, 3))):
            error = (0.0, 0.0) if rng.random() < 0.3 else (float(rng.uniform(0.0, 0.02)), float(rng.uniform(0.0, 0.02)))
            memory.carry(Pose2D(*rng.normal(0.0, [0.1, 0.1, 0.3])), error)
        scan_error = (0.0, 0.0) if rng.random() < 0.5 else (float(rng.uniform(0.0, 0.02)),
                                                            float(rng.uniform(0.0, 0.01)))
        a = memory.recall((scan,), tolerance=0.02, scan_error=scan_error, compiled=compiled)
        b = memory.recall((scan,), tolerance=0.02, scan_error=scan_error)
        assert a[0].shape == b[0].shape
        np.testing.assert_allclose(a[0], b[0], rtol=0.0, atol=1e-12)
        np.testing.assert_allclose(a[1], b[1], rtol=0.0, atol=1e-12)
        kept += a[0].shape[0]
        moved = memory.points
        far += int(np.sum(np.hypot(moved[:, 0], moved[:, 1]) > memory.max_range + memory.uncertainty + 0.05))
        dropped += len(memory) - a[0].shape[0]
    assert min(kept, dropped - far, far) > 100, (kept, dropped, far)


def test_the_compiled_sqp_plans_every_recorded_problem_as_numpy_does():
    """The MPC's direct SQP with the compiled clearance rows (values, QP rows, check) and with numpy, on the 500
    recorded closed-loop problems of test_mpc_replay: both solve or fail together, the same plans to 1e-9 (the
    rows differ by rounding only; the replay test compares the compiled SQP with casadi's sqpmethod)."""
    replay = pytest.importorskip("tests.filters.test_mpc_replay")
    if not replay.DATA.exists():
        pytest.skip("tests/data/mpc_replay.npz is missing")
    cases = replay.problems()
    assert len(cases) >= 500
    worst, solved = 0.0, 0
    for case in cases:
        safety = replay.make(case["config"], "daqp")
        assert safety.backend.kernels is not None
        _, compiled = replay.solve(case, "daqp")
        safety.backend.kernels = None
        try:
            _, reference = replay.solve(case, "daqp")
        finally:
            safety.backend.kernels = safety._kernels
        assert (compiled.commands is None) == (reference.commands is None)
        if compiled.commands is not None:
            solved += 1
            worst = max(worst, float(np.max(np.abs(compiled.commands - reference.commands))))
    assert solved >= 490
    assert worst <= 1e-9, worst


@functools.cache
def _planners(name: str, dt: float, settings_key: tuple) -> tuple[MPCSafetyFilter, MPCSafetyFilter]:
    settings_ = dict(settings_key)
    return (MPCSafetyFilter(preset(name), dt, kernels="numba", **settings_),
            MPCSafetyFilter(preset(name), dt, kernels="numpy", **settings_))


PLANNERS = [("rosbot", ()), ("m2wr", (("body", "cover"), ("n_disks", 3))), ("puzzlebot", (("time_constant", 0.1),)),
            ("m2wr", (("body", "cover"), ("time_constant", 0.05)))]


@settings(max_examples=200, deadline=None)
@given(st.data())
def test_the_compiled_plan_check_is_the_numpy_check(data):
    """The MPC's verification of a plan (the rollout through the base's lag and the drift knot, the body disks at
    every knot, the smallest distance to every point, the bounds, the acceleration between periods and the hold)
    compiled and in numpy, on random plans and problems: the same numbers to 1e-12, plans that break the bounds
    included; a plan with a non-finite command fails every test in both."""
    name, settings_key = data.draw(st.sampled_from(PLANNERS))
    dt = data.draw(st.sampled_from([0.02, 0.05, 0.1]))
    compiled, reference = _planners(name, dt, settings_key)
    robot = compiled.robot
    horizon, disks = compiled.horizon, compiled.offsets.shape[0]
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    count = data.draw(st.integers(0, 40))
    hold = data.draw(st.integers(1, 3))
    scale = np.array([robot.v_max, robot.omega_max])
    commands = rng.uniform(-1.1, 1.1, (horizon, 2)) * scale
    if data.draw(st.booleans()):    # a smooth plan, within the acceleration limits
        commands = np.cumsum(rng.uniform(-1.0, 1.0, (horizon, 2)) * compiled._step, axis=0)
    lower = np.tile(robot.lower, (horizon, 1)) * rng.uniform(0.5, 1.0, (horizon, 2))
    upper = np.tile(robot.upper, (horizon, 1)) * rng.uniform(0.5, 1.0, (horizon, 2))
    radii = rng.uniform(0.1, 0.5, (count, disks))
    guaranteed = radii - rng.uniform(0.0, 0.05, (count, disks))
    if disks > 1 and count:
        guaranteed[:, -1] = -np.inf         # a column that is never verified
    problem = MPCProblem(u_nom=scale.copy(), velocity=rng.uniform(-1.0, 1.0, 2) * scale,
                         points=rng.uniform(-3.0, 3.0, (count, 2)), uncertainty=np.zeros(count), radii=radii,
                         guaranteed=guaranteed, floor=guaranteed, lower=lower, upper=upper,
                         layout=compiled._layout_for(hold), frontier=None, min_barrier=0.0, clearance=0.0)
    originals = compiled.offsets, reference.offsets
    if data.draw(st.booleans()):    # disks anywhere in the base frame (off the axis too)
        compiled.offsets = reference.offsets = rng.uniform(-0.3, 0.3, (disks, 2))
    try:
        a, b = compiled.check_plan(problem, commands), reference.check_plan(problem, commands)
    finally:
        compiled.offsets, reference.offsets = originals
    for field in ("limits", "clearance", "planned"):
        assert getattr(a, field) == pytest.approx(getattr(b, field), rel=0.0, abs=1e-12), field
    for field in ("distances", "poses", "velocities"):
        np.testing.assert_allclose(getattr(a, field), getattr(b, field), rtol=0.0, atol=1e-12, err_msg=field)
    commands[rng.integers(horizon), rng.integers(2)] = rng.choice([np.nan, np.inf])
    for check in (compiled.check_plan(problem, commands), reference.check_plan(problem, commands)):
        assert check.limits == math.inf and check.clearance == check.planned == -math.inf


def test_the_compiled_polygon_test_is_the_numpy_one():
    """The zones' compiled even-odd test gives ``body.inside_polygon``'s mask exactly: random convex and concave
    polygons either way round (horizontal and vertical edges, repeated vertices), points anywhere in and around
    them, on their vertices and on their edges; and the zones filter decides the same on random scans either
    way."""
    from safenav.filters import ZonesFilter
    from safenav.filters.body import inside_polygon

    compiled = kernels.load()
    rng = np.random.default_rng(4)
    inside_count = 0
    for trial in range(400):
        corners = int(rng.integers(3, 40))
        angles = np.sort(rng.uniform(0.0, 2.0 * math.pi, corners))
        radii = rng.uniform(0.2, 1.0, corners) if trial % 2 else np.full(corners, rng.uniform(0.2, 1.0))
        polygon = np.column_stack((radii * np.cos(angles), radii * np.sin(angles))) + rng.normal(0.0, 0.3, 2)
        if trial % 5 == 0:
            polygon = np.round(polygon, 1)          # horizontal and vertical edges, repeated vertices
        if trial % 3 == 0:
            polygon = polygon[::-1].copy()
        edge = rng.integers(0, corners, 60)
        edges = polygon[edge] + rng.random((60, 1)) * (np.roll(polygon, -1, axis=0)[edge] - polygon[edge])
        points = np.vstack((rng.uniform(-1.8, 1.8, (300, 2)), polygon, edges, np.round(rng.uniform(-1, 1, (40, 2)), 1)))
        want = inside_polygon(polygon, points)
        np.testing.assert_array_equal(compiled.inside_polygon(polygon, points), want)
        inside_count += int(want.sum())
    assert inside_count > 10_000
    robot = preset("rosbot")
    for use_footprint in (False, True):
        fast = ZonesFilter(robot, 0.05, kernels="numba", use_footprint=use_footprint)
        reference = ZonesFilter(robot, 0.05, kernels="numpy", use_footprint=use_footprint)
        assert fast._kernels is not None and reference._kernels is None
        for _ in range(100):
            scene = Scene.of(Segment(tuple(rng.uniform(-1.0, 1.0, 2)), tuple(rng.uniform(-1.0, 1.0, 2))))
            scan = synthetic_scan(robot, scene, Pose2D(), noise_std=0.01, rng=rng)
            nominal = rng.uniform(-0.5, 0.5, 2)
            a, b = fast.filter(nominal, scan), reference.filter(nominal, scan)
            assert np.array_equal(a.u, b.u) and a.message == b.message and a.n_constraints == b.n_constraints


def test_the_compiled_nearest_per_bin_is_the_numpy_one():
    """The working sets' compiled binning gives ``perception.nearest_per_bin``'s indices in its order exactly:
    random points round any centre, 1 to 512 bins, keys with many ties (the lowest index wins, the order stays
    stable), NaN keys, bearings of exactly -pi and pi, no points."""
    from safenav.filters.perception import nearest_per_bin

    compiled = kernels.load()
    rng = np.random.default_rng(6)
    ties = 0
    for trial in range(2000):
        count = int(rng.integers(0, 300))
        points = rng.normal(0.0, 2.0, (count, 2))
        if count and trial % 7 == 0:
            points[: count // 3] = [[-1.0, 0.0]]             # bearing pi (and -pi through -0.0 below)
            points[: count // 6, 1] = -0.0
        keys = rng.normal(0.0, 1.0, count)
        if trial % 3 == 0:
            keys = np.round(keys, 1)                          # ties
        if trial % 5 == 0 and count:
            keys[rng.random(count) < 0.2] = np.nan
        centre = (0.0, 0.0) if trial % 2 else tuple(rng.normal(0.0, 0.5, 2))
        n_bins = int(rng.choice([1, 3, 8, 32, 64, 512]))
        want = nearest_per_bin(points, keys, centre, n_bins)
        got = nearest_per_bin(points, keys, centre, n_bins, compiled=compiled)
        np.testing.assert_array_equal(got, want)
        ties += len(want) - len(np.unique(keys[want]))
    assert ties > 100


def _random_rows(rng: np.random.Generator, count: int) -> tuple[np.ndarray, ...]:
    """Random rows over ``z = (v, omega, t_v, t_omega)`` as the CBF's decision takes them: columns that are often 0,
    repeated rows, points (-1: none) and families (hard from 3 on)."""
    G = rng.normal(0.0, 1.0, (count, 4)) * (rng.random((count, 4)) < 0.7)
    if count > 3:
        G[count // 2] = G[0]
    h = rng.normal(0.0, 0.5, count)
    point = rng.integers(-1, 40, count).astype(np.intp)
    family = rng.integers(0, 6, count).astype(np.intp)
    return G, h, point, family


def test_the_compiled_decision_is_the_numpy_one():
    """The CBF's decision around its QPs, compiled, gives its numpy references' answers (``cbf._screen``,
    ``_qp_rows``, ``_violated``, ``_answer``): the same rows, QP rows (the slack column's -0.0 bit for bit), working
    sets, worst rows, binding rows and points, slack tiers (``_stage``), on random rows, boxes, answers and masks, with
    NaN in some answers."""
    from safenav.filters import cbf
    from safenav.filters.rows import FIRST_HARD

    compiled = kernels.load()
    rng = np.random.default_rng(11)
    excluded = bound_rows = nan = raised = 0
    for trial in range(1500):
        count = int(rng.integers(0, 120))
        G, h, point, family = _random_rows(rng, count)
        lower = -rng.random(4)
        upper = rng.random(4)
        want, got = cbf._screen(G, h, point, family, lower, upper, 1e-6), compiled.cbf_screen(
            G, h, point, family, lower, upper, 1e-6)
        for a, b in zip(want, got, strict=True):
            np.testing.assert_array_equal(a, b)
        excluded += want[-1]
        working = rng.random(count) < 0.5
        minus_relaxed = -(rng.random(count) < 0.5).astype(float)
        fixed_G, fixed_h = rng.normal(size=(4, 4)), rng.normal(size=4)
        for with_slack in (False, True):
            want, got = (function(fixed_G, fixed_h, G, h, minus_relaxed, working, with_slack)
                         for function in (cbf._qp_rows, compiled.cbf_qp_rows))
            for a, b in zip(want, got, strict=True):
                np.testing.assert_array_equal(a, b)
                np.testing.assert_array_equal(np.signbit(a), np.signbit(b))
        z = rng.normal(0.0, 0.5, 5)
        relaxed = rng.random(count) < 0.5
        mask_a, mask_b = working.copy(), working.copy()
        added = cbf._violated(G, h, relaxed, float(z[4]), z, mask_a, 1e-7), compiled.cbf_violated(
            G, h, relaxed, float(z[4]), z, mask_b, 1e-7)
        assert added[0] == added[1]
        np.testing.assert_array_equal(mask_a, mask_b)
        lifted, nominal = rng.normal(0.0, 0.5, 4), rng.normal(0.0, 0.5, 4)
        if trial % 10 == 0 and count:
            lifted[int(rng.integers(0, 4))] = np.nan
            nan += 1
        bound = h + np.where(relaxed, 0.1, 0.0)
        if count and trial % 3 == 0:   # rows held exactly at the answer, and within the tolerance of it
            held = rng.random(count) < 0.3
            bound[held] = h[held] = G[held] @ lifted + rng.choice([0.0, 5e-7, -5e-7], int(held.sum()))
        used_rows = np.flatnonzero(working)
        want = cbf._answer(G, h, bound, family, point, lifted, nominal, used_rows, 40, FIRST_HARD, 1e-6)
        got = compiled.cbf_answer(G, h, bound, family, point, lifted, nominal, used_rows, 40, FIRST_HARD, 1e-6)
        assert want[0] == got[0] and want[2:4] == got[2:4], (trial, want[:4], got[:4])
        np.testing.assert_allclose(want[1], got[1], rtol=1e-12, atol=1e-15)
        np.testing.assert_array_equal(want[4], got[4])
        np.testing.assert_array_equal(want[5], got[5])
        bound_rows += want[3] >= 0
        uncertainty, barrier = rng.random(40) * 0.04, rng.normal(0.05, 0.1, 40)
        for tier in range(3):
            want, got = (function(h, point, family, uncertainty, barrier, 0.02, tier, FIRST_HARD, 0, tier == 2)
                         for function in (cbf._stage, compiled.cbf_stage))
            np.testing.assert_array_equal(want[0], got[0])
            np.testing.assert_array_equal(want[1], got[1])
            raised += int(np.sum(want[0] != h))
    assert excluded > 100 and bound_rows > 100 and nan > 50 and raised > 100


def test_the_compiled_daqp_arrays_are_the_numpy_ones():
    """DAQP's arrays built by the kernel are ``DirectDAQP``'s numpy ones bit for bit (infinite and huge bounds,
    one- and two-sided rows, equalities, warm starts of any integer type), and its answers the same."""
    from safenav.filters.qp import DirectDAQP, QPData

    reference, fast = DirectDAQP(), DirectDAQP()
    fast.kernels = kernels.load()
    rng = np.random.default_rng(12)
    equalities = solved = 0
    for trial in range(1000):
        n, m = int(rng.integers(1, 8)), int(rng.integers(0, 30))
        lb, ub = -rng.random(n) - 0.1, rng.random(n) + 0.1
        lb[rng.random(n) < 0.2], ub[rng.random(n) < 0.2] = -np.inf, 2e30
        G = rng.normal(size=(m, n))
        h = G @ rng.uniform(lb.clip(-1.0), ub.clip(None, 1.0)) + rng.random(m)
        h[rng.random(m) < 0.1] = np.inf
        h_lower = None
        if trial % 2:
            h_lower = np.where(np.isfinite(h), h, 1.0) - rng.random(m) * 2.0
            h_lower[rng.random(m) < 0.2] = -np.inf
            equal = rng.random(m) < 0.1
            h_lower[equal] = h[equal] = np.where(np.isfinite(h[equal]), h[equal], 1.0)
            h_lower = np.minimum(h_lower, h)
        guess = None if trial % 3 == 0 else rng.integers(-1, 2, n + m).astype(np.int8 if trial % 3 == 1 else int)
        qp = QPData(np.diag(rng.random(n) + 0.1), rng.normal(size=n), G, h, lb, ub, h_lower, guess)
        want = DirectDAQP._arrays(qp)
        got = fast.kernels.daqp_arrays(lb, ub, h, np.zeros(0) if h_lower is None else h_lower,
                                       np.zeros(0, np.int8) if guess is None else np.sign(guess).astype(np.int8),
                                       np.array([3, 0, 1], dtype=np.int32), 5)
        for a, b in zip(want, got, strict=True):
            np.testing.assert_array_equal(a, b)
        equalities += int(np.sum(want[2] == 5))
        a, b = reference.solve(qp), fast.solve(qp)
        assert (a.x is None) == (b.x is None) and a.status == b.status
        if a.x is not None:
            np.testing.assert_array_equal(a.x, b.x)
            np.testing.assert_array_equal(a.active, b.active)
            solved += 1
    assert equalities > 100 and solved > 300


def test_the_compiled_sweep_poses_are_the_numpy_ones():
    """Where a turning lidar was at each beam: the compiled loop gives ``perception.sweep_poses``'s poses exactly, for
    sweeps forwards and backwards in the beams, ages from now to past every part, straight and turning parts, and no
    part at all."""
    from safenav.filters.perception import sweep_poses

    compiled = kernels.load()
    rng = np.random.default_rng(11)
    for trial in range(500):
        count = int(rng.integers(2, 800))
        times = np.arange(count) * rng.uniform(1e-5, 3e-4)
        ages = np.maximum(rng.uniform(0.0, 0.3) - (times if trial % 2 else times[::-1]), 0.0)
        parts = [(float(rng.uniform(0.005, 0.1)), float(rng.uniform(-1.0, 1.0)),
                  float(rng.uniform(-3.0, 3.0)) if rng.random() < 0.7 else 0.0) for _ in range(int(rng.integers(0, 5)))]
        mount = Pose2D(*rng.uniform(-0.3, 0.3, 2), float(rng.uniform(-math.pi, math.pi)))
        want_reference, want = sweep_poses(ages, parts, mount)
        got_reference, got = sweep_poses(ages, parts, mount, compiled)
        assert tuple(got_reference) == tuple(want_reference)
        np.testing.assert_array_equal(got, want)


def test_the_compiled_sweep_shift_is_the_numpy_one():
    """From which beam's pose the memory looks at each remembered point: the compiled loop gives
    ``perception.sweep_shift``'s maps exactly, for fields of view of half a turn to a whole one, points all round
    (outside the field of view too), any mount."""
    from safenav.filters.perception import sweep_shift
    from safenav.scan import LaserScan

    compiled = kernels.load()
    rng = np.random.default_rng(12)
    for _ in range(300):
        count = int(rng.integers(10, 800))
        view = float(rng.choice([math.pi, 1.5 * math.pi, 2.0 * math.pi * (1.0 - 1.0 / count)]))
        scan = LaserScan(angle_min=-view / 2, angle_max=view / 2, angle_increment=view / (count - 1),
                         ranges=np.ones(count), range_min=0.1, range_max=10.0, mount=tuple(rng.uniform(-0.3, 0.3, 3)))
        extent = np.linspace(-1.0, 1.0, count)
        motion = np.column_stack((rng.uniform(-0.03, 0.03) * extent, rng.uniform(-0.03, 0.03) * extent,
                                  rng.uniform(-0.2, 0.2) * extent))
        swept = scan.with_sweep_motion(motion)
        points = rng.normal(0.0, 1.5, (int(rng.integers(0, 500)), 2))
        want, got = sweep_shift(swept, points), sweep_shift(swept, points, compiled)
        for name in ("cos", "sin", "shift", "unseen"):
            np.testing.assert_array_equal(getattr(got, name), getattr(want, name))


def test_auto_keeps_to_numpy_with_a_warning_when_the_kernels_do_not_compile(monkeypatch):
    """A numba that is installed but cannot compile (an unsupported CPU, a broken LLVM): ``"auto"`` still gives a
    filter, on numpy, and says why once; ``"numba"`` raises the compile error."""
    def broken():
        raise RuntimeError("LLVM ERROR: no target for this CPU")

    monkeypatch.setattr(kernels.GROUP, "compiled", None)
    monkeypatch.setattr(kernels.GROUP, "failure", None)
    monkeypatch.setattr(kernels, "_build", broken)
    with pytest.warns(SafeNavWarning, match="no target for this CPU"):
        safety = CBFSafetyFilter(preset("rosbot"))
    assert safety._kernels is None
    scan = synthetic_scan(preset("rosbot"), Scene.of(Segment((0.5, -1.0), (0.5, 1.0))), Pose2D())
    assert safety.filter((0.5, 0.0), scan, velocity=(0.5, 0.0)).u[0] < 0.5
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert MPCSafetyFilter(preset("rosbot"), 0.05)._kernels is None     # once: no second warning
    with pytest.raises(RuntimeError, match="no target"):
        CBFSafetyFilter(preset("rosbot"), kernels="numba")


def test_the_environment_decides_for_auto(monkeypatch):
    monkeypatch.setenv("SAFENAV_KERNELS", "numpy")
    assert CBFSafetyFilter(preset("rosbot"))._kernels is None
    assert CBFSafetyFilter(preset("rosbot"), kernels="numba")._kernels is not None   # an explicit setting wins
    monkeypatch.setenv("SAFENAV_KERNELS", "numba")
    assert MPCSafetyFilter(preset("rosbot"), 0.05).backend.kernels is not None
    monkeypatch.setenv("SAFENAV_KERNELS", "fortran")
    with pytest.raises(UnknownName, match="fortran"):
        CBFSafetyFilter(preset("rosbot"))


def test_no_call_compiles_a_kernel_again():
    """Every kernel was compiled, when the first filter was built, for the argument types the filters pass: after
    calls of every filter (both bodies, with and without the velocity, scans of known age, the MPC solving), each
    kernel still has exactly one compiled specialisation (a second would be a compile of seconds in a call)."""
    from safenav.filters import ZonesFilter

    robot = preset("m2wr")
    side = robot.radius + 0.05
    scene = Scene.of(Segment((0.16, side), (4.0, side)), Segment((1.0, -1.0), (1.0, -0.3)))
    filters = [CBFSafetyFilter(robot, 0.05), CBFSafetyFilter(robot, 0.05, body="cover"),
               CBFSafetyFilter(robot, 0.05, body="polygon"),
               MPCSafetyFilter(robot, 0.05), MPCSafetyFilter(robot, 0.05, reference="cbf"), ZonesFilter(robot, 0.05)]
    rng = np.random.default_rng(2)
    for safety in filters:
        pose, velocity = Pose2D(), np.zeros(2)
        for step in range(30):
            scan = synthetic_scan(robot, scene, pose, noise_std=0.005, rng=rng)
            if step % 5 == 4:   # a turning lidar's scan
                scan = swept_scan(robot, scene, lambda t, pose=pose, velocity=velocity: unicycle_step(
                    pose, float(velocity[0]), float(velocity[1]), t), 0.0)
            result = safety.filter((robot.v_max, robot.omega_max), scan,
                                   velocity=None if step % 3 == 0 else velocity, scan_age=0.05 if step % 2 else None)
            velocity = robot.clip(result.u, velocity, 0.05)
            pose = unicycle_step(pose, float(velocity[0]), float(velocity[1]), 0.05)
    for name, dispatcher in vars(kernels.load()).items():
        assert len(dispatcher.signatures) == 1, (name, dispatcher.signatures)


@pytest.mark.parametrize("velocity", [None, (0.4, 0.0)])
def test_a_point_just_shallower_than_the_deepest_inside_the_margin_keeps_its_own_direction(velocity):
    """The tilt's boundary: with the deepest point inside the margin (H < 0), a second point whose barrier lies
    between H and (1 - gamma) H is within ``K = reach + (1 - gamma) H`` of its control point and keeps its own
    direction; just beyond that band it is tilted. Both kernels agree on either side of the boundary."""
    robot = preset("rosbot")
    compiled = CBFSafetyFilter(robot, 0.05, kernels="numba")
    reference = CBFSafetyFilter(robot, 0.05, kernels="numpy")
    offset = robot.radius + compiled.lookahead + compiled.margin
    control = np.array([compiled.lookahead, 0.0])
    deepest = -0.02
    for shallower in (deepest * (1.0 - 0.5 * compiled.gamma), deepest * (1.0 - 2.0 * compiled.gamma), 0.01):
        bearing = np.radians(70.0)
        points = np.array([control + (offset + deepest) * np.array([1.0, 0.0]),
                           control + (offset + shallower) * np.array([math.cos(bearing), math.sin(bearing)])])
        view = view_of(points, np.zeros(2))
        u = None if velocity is None else np.array(velocity)
        a = compiled._constraints(view, u, 0.05)
        b = reference._constraints(view, u, 0.05)
        np.testing.assert_allclose(sorted_rows(a.rows), sorted_rows(b.rows), rtol=1e-12, atol=1e-12)
