"""What every safety filter promises under bad input: documented errors, braking, never NaN.

Runs against each filter (CBF, and MPC when it is installed) through the shared
:class:`safenav.filters.SafetyFilter` contract.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from safenav import InvalidCommand, InvalidCommandType, InvalidScan, InvalidScanType, LaserScan, SafeNavError, preset
from safenav.filters import BRAKING_STATUSES, CBFSafetyFilter, FilterResult, FilterStatus
from safenav.filters.base import Deadlock
from safenav.filters.perception import dead_reckoning
from safenav.geometry import Pose2D, unicycle_step
from safenav.synthetic import Circle, Scene, synthetic_scan, wall

DT = 0.05


def filter_factories():
    factories = [pytest.param(lambda robot: CBFSafetyFilter(robot, DT), id="cbf")]
    try:
        from safenav.filters.mpc import MPCSafetyFilter
    except ImportError:
        return factories
    factories.append(pytest.param(lambda robot: MPCSafetyFilter(robot, DT), id="mpc"))
    return factories


FILTERS = filter_factories()


def assert_safe_command(result: FilterResult, robot, velocity=None) -> None:
    assert np.all(np.isfinite(result.u))
    lower, upper = robot.velocity_bounds(velocity, DT if velocity is not None else None)
    assert np.all(result.u >= lower - 1e-9) and np.all(result.u <= upper + 1e-9)


# ------------------------------------------------------------------ stale data watchdog

@pytest.mark.parametrize("make", FILTERS)
def test_scan_older_than_the_timeout_brakes_and_a_fresh_one_does_not(make):
    robot = preset("rosbot")
    filt = make(robot)
    scan = robot.scan()
    fresh = filt.filter((0.5, 0.0), scan, scan_age=0.1, velocity=(0.5, 0.0))
    assert fresh.status is FilterStatus.OK and fresh.u[0] == pytest.approx(0.5, abs=1e-6)
    stale = filt.filter((0.5, 0.0), scan, scan_age=filt.scan_timeout + 0.01, velocity=(0.5, 0.0))
    assert stale.status is FilterStatus.STALE and stale.braked
    assert stale.u == pytest.approx(robot.brake((0.5, 0.0), DT))
    assert "old" in stale.message and "timeout" in stale.message


@pytest.mark.parametrize("make", FILTERS)
def test_watchdog_reads_the_scan_stamp_against_a_clock(make):
    robot = preset("puzzlebot")
    filt = make(robot)
    scan = robot.scan(stamp=100.0)
    assert filt.filter((0.2, 0.0), scan, now=100.2, velocity=(0.2, 0.0)).status is FilterStatus.OK
    assert filt.filter((0.2, 0.0), scan, now=101.0).status is FilterStatus.STALE
    assert filt.filter((0.2, 0.0), scan, scan_age=math.nan).status is FilterStatus.STALE


def test_scan_timeout_is_configurable():
    robot = preset("rosbot")
    filt = CBFSafetyFilter(robot, DT, scan_timeout=2.0)
    assert filt.filter((0.5, 0.0), robot.scan(), scan_age=1.5).status is FilterStatus.OK


# ------------------------------------------------------------------ malformed input: a table

MALFORMED_CALLS = [
    # (u_nom, scan or None for a valid one, velocity, exception, fragment)
    ((1.0,), None, None, InvalidCommand, "u_nom must have shape (2,)"),
    ((1.0, 2.0, 3.0), None, None, InvalidCommand, "u_nom must have shape (2,)"),
    ([[0.1, 0.2]], None, None, InvalidCommand, "u_nom must have shape (2,)"),
    ("forward", None, None, InvalidCommandType, "u_nom must be a pair"),
    (None, None, None, InvalidCommandType, "u_nom must be a pair"),
    ((0.1, "left"), None, None, InvalidCommandType, "u_nom must be a pair"),
    ((0.1, 0.0), "scan", None, InvalidScanType, "scan must be a safenav LaserScan"),
    ((0.1, 0.0), [1.0, 2.0], None, InvalidScanType, "scan must be a safenav LaserScan"),
    ((0.1, 0.0), SimpleNamespace(ranges=[1.0]), None, InvalidScanType, "use LaserScan.from_msg"),
    ((0.1, 0.0), None, (0.1,), InvalidCommand, "velocity must have shape (2,)"),
    ((0.1, 0.0), None, "fast", InvalidCommandType, "velocity must be a pair"),
]


@pytest.mark.parametrize("make", FILTERS)
@pytest.mark.parametrize(("u_nom", "scan", "velocity", "exception", "fragment"), MALFORMED_CALLS)
def test_structural_garbage_raises_the_documented_error(make, u_nom, scan, velocity, exception, fragment):
    robot = preset("rosbot")
    filt = make(robot)
    with pytest.raises(exception) as info:
        filt.filter(u_nom, robot.scan() if scan is None else scan, velocity=velocity)
    assert type(info.value) is exception
    assert isinstance(info.value, SafeNavError)
    assert fragment in str(info.value)


GARBAGE_READINGS = [
    ("all NaN", lambda n: np.full(n, math.nan), FilterStatus.NO_DATA),
    ("all below range_min", lambda n: np.full(n, 0.01), FilterStatus.NO_DATA),
    ("all negative", lambda n: np.full(n, -3.0), FilterStatus.NO_DATA),
    ("all 1e308", lambda n: np.full(n, 1e308), FilterStatus.NO_DATA),
    ("all denormal", lambda n: np.full(n, 5e-324), FilterStatus.NO_DATA),
    ("all +inf", lambda n: np.full(n, math.inf), FilterStatus.OK),
    ("all -inf", lambda n: np.full(n, -math.inf), None),   # an object at the sensor all around
]


@pytest.mark.parametrize("make", FILTERS)
@pytest.mark.parametrize(("label", "readings", "expected"), GARBAGE_READINGS)
def test_garbage_readings_are_handled_per_rep117_and_never_give_nan(make, label, readings, expected):
    robot = preset("rosbot")
    filt = make(robot)
    scan = robot.scan(readings(robot.lidar.n_beams))
    result = filt.filter((0.8, 1.0), scan, velocity=(0.5, 0.0))
    assert_safe_command(result, robot, (0.5, 0.0))
    if expected is not None:
        assert result.status is expected, label
    else:
        assert result.status is not FilterStatus.OK   # surrounded: it must not pass the nominal through
        assert result.message
    if result.braked:
        assert result.message


@pytest.mark.parametrize("make", FILTERS)
@pytest.mark.parametrize("u_nom", [(math.nan, 0.0), (0.0, math.inf), (-math.inf, math.nan)])
def test_non_finite_nominal_brakes_with_bad_input(make, u_nom):
    robot = preset("m2wr")
    result = make(robot).filter(u_nom, robot.scan(), velocity=(0.6, 0.2))
    assert result.status is FilterStatus.BAD_INPUT and result.braked
    assert result.u == pytest.approx(robot.brake((0.6, 0.2), DT))
    assert "u_nom is not finite" in result.message


def _along_a_wall(safety, robot, steps: int = 30):
    """Drive the m2wr (its lidar sees the front half only) along a wall on its left, the odometry pose given: the
    wall behind it is then remembered. Returns the last scan, pose and velocity."""
    scene = Scene.of(wall(0.45, math.pi / 2, 6.0))
    pose, velocity = Pose2D(), np.zeros(2)
    for _ in range(steps):
        scan = synthetic_scan(robot, scene, pose)
        result = safety.filter((0.3, 0.0), scan, velocity=velocity, pose=tuple(pose))
        velocity = np.array(result.u)
        pose = unicycle_step(pose, float(velocity[0]), float(velocity[1]), DT)
    return synthetic_scan(robot, scene, pose), pose, velocity


@pytest.mark.parametrize("make", FILTERS)
@pytest.mark.parametrize("bad", [(math.nan, 0.0, 0.0), (0.0, math.inf, 0.0), (1.0, 2.0, -math.inf)])
def test_a_non_finite_pose_brakes_with_bad_input_and_keeps_the_memory(make, bad):
    """An odometry glitch (a NaN or infinite pose) is bad input like a non-finite velocity: the call brakes and says
    so, and the remembered points are carried by the measured velocity instead of being moved to NaN and forgotten
    (the m2wr's memory holds the wall behind it, which its lidar no longer sees); the next call with a finite pose
    has them all, with the odometry from there on."""
    robot = preset("m2wr")
    safety = make(robot)
    scan, pose, velocity = _along_a_wall(safety, robot)
    remembered = len(safety.memory)
    assert remembered > 100
    carried = safety.remembered_points(velocity=velocity)      # where a call without the pose puts them
    assert np.all(np.isfinite(carried)) and carried.shape[0] == remembered
    result = safety.filter((0.3, 0.0), scan, velocity=velocity, pose=bad)
    assert result.status is FilterStatus.BAD_INPUT and result.braked
    assert "pose is not finite" in result.message
    assert result.u == pytest.approx(robot.brake(velocity, DT))
    # carried by the velocity, not forgotten (and the pose given to an inspection is taken as the call takes it)
    np.testing.assert_allclose(safety.memory.points, carried, atol=1e-12)
    np.testing.assert_allclose(safety.remembered_points(velocity=velocity, pose=bad),
                               safety.remembered_points(velocity=velocity), atol=1e-12)
    after = safety.filter((0.3, 0.0), scan, velocity=velocity, pose=tuple(pose))
    assert after.status is not FilterStatus.BAD_INPUT and len(safety.memory) >= 0.9 * remembered


@pytest.mark.parametrize("make", FILTERS)
@pytest.mark.parametrize(("pose", "error"), [
    ((1.0, 2.0), InvalidCommand), ("abc", InvalidCommandType), ((1.0, 2.0, "x"), InvalidCommandType),
    ((1.0, 2.0, 3.0, 4.0), InvalidCommand), (None, None)])
def test_a_pose_that_is_not_three_numbers_is_a_clear_error(make, pose, error):
    """``pose`` must be ``(x [m], y [m], yaw [rad])`` (or a Pose2D): two numbers (a forgotten yaw would have been
    taken as 0 and moved every remembered point wrong) or text are an InvalidCommand, a SafeNavError and a
    ValueError/TypeError, that names the value."""
    robot = preset("rosbot")
    safety = make(robot)
    if error is None:
        assert safety.filter((0.1, 0.0), robot.scan(), pose=Pose2D(1.0, 2.0, 0.5)).status is FilterStatus.OK
        return
    with pytest.raises(error, match="pose") as caught:
        safety.filter((0.1, 0.0), robot.scan(), pose=pose)
    assert isinstance(caught.value, SafeNavError) and isinstance(caught.value, ValueError)
    with pytest.raises(error, match="pose"):
        safety.remembered_points(pose=pose)


@pytest.mark.parametrize("make", FILTERS)
def test_non_finite_velocity_brakes_with_bad_input(make):
    robot = preset("rosbot")
    result = make(robot).filter((0.3, 0.0), robot.scan(), velocity=(math.nan, 0.0))
    assert result.status is FilterStatus.BAD_INPUT and result.u.tolist() == [0.0, 0.0]


@pytest.mark.parametrize("make", FILTERS)
def test_single_beam_and_huge_scans_are_filtered(make):
    from safenav import LidarSpec

    single = LaserScan(angle_min=0.0, angle_max=0.0, angle_increment=0.01, range_min=0.1, range_max=10.0,
                       ranges=[0.6])
    robot = preset("rosbot").replace(lidar=LidarSpec.from_scan(single, mount=(0.0, 0.0, 0.0)))
    filt = make(robot)
    result = filt.filter((0.5, 0.0), single)
    assert_safe_command(result, robot)
    assert result.u[0] <= 1e-12   # one beam sees almost nothing: forward motion is into the unknown
    n = 100_000
    rng = np.random.default_rng(0)
    huge = LaserScan(angle_min=-math.pi, angle_max=math.pi - 2 * math.pi / n, angle_increment=2 * math.pi / n,
                     range_min=0.1, range_max=10.0, ranges=rng.uniform(0.5, 5.0, n))
    robot = preset("rosbot").replace(lidar=LidarSpec.from_scan(huge, mount=(0.0, 0.0, 0.0)))
    filt = make(robot)
    result = filt.filter((0.5, 0.3), huge)
    assert_safe_command(result, robot)
    # Answered, or, where 100 000 beams take most of the compute budget (half the period) on this machine,
    # braked for the deadline and saying so; without a budget, answered.
    assert result.status in (FilterStatus.OK, FilterStatus.RECOVERING) or (
        result.status is FilterStatus.FALLBACK and result.reason.family == "deadline"
        and result.filter_time >= 0.5 * filt.budget)
    unlimited = type(filt)(robot, DT, budget=math.inf).filter((0.5, 0.3), huge)
    assert_safe_command(unlimited, robot)
    assert unlimited.status in (FilterStatus.OK, FilterStatus.RECOVERING)


# ------------------------------------------------------------------ fuzzing

special = st.sampled_from([math.nan, math.inf, -math.inf, -1.0, 0.0, 5e-324, 1e-310, 1e308, -1e308, 1e-3])
reading = st.one_of(st.floats(0.0, 20.0), special)


@st.composite
def hostile_scans(draw):
    """Well-formed scans (they validate) whose readings are anything REP-117 allows, and worse."""
    robot = preset(draw(st.sampled_from(["rosbot", "puzzlebot", "m2wr"])))
    n = robot.lidar.n_beams
    base = draw(st.sampled_from(["garbage", "wall", "free"]))
    if base == "wall":
        ranges = synthetic_scan(robot, Scene.of(wall(draw(st.floats(0.05, 3.0)), draw(st.floats(-3.2, 3.2))))).ranges
        ranges = ranges.copy()
    elif base == "free":
        ranges = np.full(n, math.inf)
    else:
        ranges = np.full(n, draw(reading))
    for _ in range(draw(st.integers(0, 30))):
        start = draw(st.integers(0, n - 1))
        ranges[start:start + draw(st.integers(1, 60))] = draw(reading)
    return robot, robot.scan(ranges)


commands = st.one_of(
    st.tuples(st.floats(-3.0, 3.0), st.floats(-10.0, 10.0)),
    st.tuples(st.sampled_from([math.nan, math.inf, -math.inf, 1e308]), st.floats(-1.0, 1.0)),
)


@settings(max_examples=2500)
@given(hostile_scans(), commands, st.one_of(st.none(), st.tuples(st.floats(-1.0, 1.0), st.floats(-3.0, 3.0))),
       st.one_of(st.none(), st.floats(0.0, 1.0)))
def test_cbf_never_raises_never_returns_nan_on_hostile_readings(case, u_nom, velocity, scan_age):
    robot, scan = case
    result = CBFSafetyFilter(robot, DT).filter(u_nom, scan, velocity=velocity, scan_age=scan_age)
    assert_safe_command(result, robot, velocity)
    assert (result.status in BRAKING_STATUSES) == result.braked
    if result.status is not FilterStatus.OK:
        assert result.message


message_fields = {
    "angle_min": st.one_of(st.floats(-4.0, 4.0), st.sampled_from([math.nan, math.inf, "0", None])),
    "angle_max": st.one_of(st.floats(-4.0, 7.0), st.sampled_from([math.nan, -math.inf, None])),
    "angle_increment": st.one_of(st.floats(-0.1, 0.1), st.sampled_from([0.0, math.nan, 1e-300, True, "x"])),
    "range_min": st.one_of(st.floats(-1.0, 1.0), st.sampled_from([math.nan, None])),
    "range_max": st.one_of(st.floats(-1.0, 40.0), st.sampled_from([math.inf, math.nan, "12"])),
    "time_increment": st.one_of(st.floats(-1e-3, 1e-3), st.sampled_from([math.nan, None])),
    "scan_time": st.one_of(st.floats(0.0, 0.2), st.sampled_from([math.inf, "0.1"])),
    "ranges": st.one_of(st.lists(reading, max_size=400), st.sampled_from([None, "1 2 3", [[1.0, 2.0]], [1.0, None],
                                                                          [[1.0], [2.0, 3.0]], {"a": 1}, 3.0])),
    "intensities": st.one_of(st.lists(st.floats(0, 100), max_size=5), st.sampled_from([None, "bright", ()])),
}


@settings(max_examples=2500)
@given(st.fixed_dictionaries(message_fields), st.booleans(), commands)
def test_from_msg_raises_only_documented_errors_and_what_it_accepts_filters_safely(fields, drop, u_nom):
    message = SimpleNamespace(**fields)
    if drop:
        del message.scan_time
    try:
        scan = LaserScan.from_msg(message)
    except InvalidScan as error:   # InvalidScanType is a subclass
        assert str(error)
        return
    robot = preset("rosbot")
    result = CBFSafetyFilter(robot, DT).filter(u_nom, scan)
    assert np.all(np.isfinite(result.u))
    assert np.all(result.u >= robot.lower - 1e-9) and np.all(result.u <= robot.upper + 1e-9)


# ------------------------------------------------------------------ latency compensation

@pytest.mark.parametrize("make", FILTERS)
def test_an_old_scan_is_moved_into_the_current_frame(make):
    robot = preset("rosbot")
    filt = make(robot)
    scan = synthetic_scan(robot, Scene.of(wall(1.0)))
    fresh = filt.filter((0.0, 0.0), scan, velocity=(1.0, 0.0))
    late = filt.filter((0.0, 0.0), scan, velocity=(1.0, 0.0), scan_age=0.2)   # 0.2 m closer by now, at 1 m/s
    assert fresh.clearance == pytest.approx(1.0 - robot.radius, abs=1e-9)
    assert late.clearance == pytest.approx(0.8 - robot.radius, abs=1e-9)


def test_current_frame_turns_the_scan_with_the_base():
    robot = preset("puzzlebot")
    scan = synthetic_scan(robot, Scene.of(wall(1.0)))
    turned = CBFSafetyFilter.current_frame(scan, np.array([0.0, math.pi / 2]), 1.0)   # a quarter turn left
    points = turned.points()
    assert np.allclose(points[:, 1], -1.0, atol=1e-9)   # the wall that was ahead is now on the right


def test_latency_compensation_can_be_switched_off():
    robot = preset("rosbot")
    filt = CBFSafetyFilter(robot, DT, compensate_latency=False)
    scan = synthetic_scan(robot, Scene.of(wall(1.0)))
    result = filt.filter((0.0, 0.0), scan, velocity=(1.0, 0.0), scan_age=0.2)
    assert result.clearance == pytest.approx(1.0 - robot.radius, abs=1e-9)


@settings(max_examples=400)
@given(hostile_scans(), commands, st.one_of(st.none(), st.tuples(st.floats(-1.0, 1.0), st.floats(-3.0, 3.0))))
def test_mpc_never_raises_never_returns_nan_on_hostile_readings(case, u_nom, velocity):
    from safenav.filters.mpc import MPCSafetyFilter

    robot, scan = case
    result = MPCSafetyFilter(robot, DT).filter(u_nom, scan, velocity=velocity)
    assert_safe_command(result, robot, velocity)
    assert (result.status in BRAKING_STATUSES) == result.braked
    if result.status is not FilterStatus.OK:
        assert result.message


# ---------------------------------------------------------------------- the memory where the next call finds it


def _pillar_scan(robot, pose, stamp):
    return synthetic_scan(robot, Scene.of(Circle((1.0, 0.6), 0.2), wall(2.0)), pose, stamp=stamp)


@pytest.mark.parametrize("make", FILTERS)
@pytest.mark.parametrize("carry", ["pose", "velocity", "command"])
def test_remembered_points_are_the_memory_moved_as_the_next_call_will_move_it(make, carry):
    """``remembered_points`` gives the memory in the frame of a call made with the same arguments, without
    changing the filter: by the odometry pose's change, by the measured velocities' trapezoid, or by the last
    command (A5), whichever the call would use."""
    robot = preset("m2wr")      # a 180-degree lidar: the memory keeps what it no longer sees
    first, second, elapsed = Pose2D(0.0, 0.0, 0.0), Pose2D(0.03, 0.004, 0.15), 0.07
    start, end = np.array([0.2, 1.0]), np.array([0.25, 0.8])
    before, after = {"pose": ({"pose": first}, {"pose": second}), "velocity": ({"velocity": start}, {"velocity": end}),
                     "command": ({}, {})}[carry]
    safety, twin = make(robot), make(robot)
    for each in (safety, twin):
        result = each.filter((0.3, 1.0), _pillar_scan(robot, first, 1.0), now=1.0, **before)
    motion = {"pose": second, "velocity": dead_reckoning(start, end, elapsed)[0],
              "command": unicycle_step(Pose2D(), float(result.u[0]), float(result.u[1]), elapsed)}[carry]
    remembered = safety.remembered_points(now=1.0 + elapsed, **after)
    assert remembered.shape[0] > 100
    np.testing.assert_allclose(remembered, motion.to_local(_pillar_scan(robot, first, 1.0).points()), atol=1e-9)
    # Asking changes nothing: the same call on the twin that was not asked gives the same answer.
    scan = _pillar_scan(robot, second, 1.0 + elapsed)
    asked = safety.filter((0.3, 1.0), scan, now=1.0 + elapsed, **after)
    np.testing.assert_array_equal(asked.u, twin.filter((0.3, 1.0), scan, now=1.0 + elapsed, **after).u)
    later = {"now": 1.0 + 2.0 * elapsed, **after}
    np.testing.assert_array_equal(safety.remembered_points(**later), twin.remembered_points(**later))


@pytest.mark.parametrize("make", FILTERS)
def test_remembered_points_before_the_first_call_and_without_a_memory_are_empty(make):
    robot = preset("m2wr")
    assert make(robot).remembered_points().shape == (0, 2)
    forgetful = CBFSafetyFilter(robot, DT, memory_capacity=0)
    forgetful.filter((0.3, 0.0), _pillar_scan(robot, Pose2D(), None))
    assert forgetful.remembered_points(velocity=(0.3, 0.0)).shape == (0, 2)


@pytest.mark.parametrize("make", FILTERS)
def test_the_memory_and_scan_views_reject_what_filter_rejects_with_the_same_errors(make):
    """``remembered_points`` and ``current_scans`` take ``filter``'s arguments and raise its documented errors,
    naming the bad value, before anything is read."""
    robot = preset("m2wr")
    safety = make(robot)
    scan = _pillar_scan(robot, Pose2D(), None)
    for view in (safety.remembered_points, lambda **kw: safety.current_scans(scan, **kw)):
        with pytest.raises(InvalidCommand, match="velocity"):
            view(velocity="fast")
        with pytest.raises(InvalidCommand, match=r"shape \(2,\)"):
            view(velocity=(0.1, 0.0, 0.0))
    with pytest.raises(SafeNavError, match="now must be a finite number, got 'soon'"):
        safety.remembered_points(now="soon")
    with pytest.raises(InvalidScanType, match="LaserScan"):
        safety.current_scans("scan")
    with pytest.raises(InvalidScanType, match="one age per scan"):
        safety.current_scans(scan, velocity=(0.1, 0.0), scan_age=[0.1, 0.2])
    # A stale scan, or a non-finite velocity, is handed back as it is (the call itself brakes for it).
    assert safety.current_scans(scan, velocity=(0.1, 0.0), scan_age=5.0)[0] is scan
    assert safety.current_scans(scan, velocity=(math.nan, 0.0), scan_age=0.1)[0] is scan
    moved = safety.current_scans(scan, velocity=(0.5, 0.0), scan_age=0.1)[0]
    np.testing.assert_allclose(moved.points(), scan.points() - (0.05, 0.0), atol=1e-9)


def test_a_deadlock_reads_as_a_sentence():
    assert str(Deadlock(1.5, None, "acceleration")) == "deadlocked for 1.5 s by an acceleration constraint"
    assert str(Deadlock(2.0, (1.0, -0.25), "barrier")) == ("deadlocked for 2.0 s by a barrier constraint "
                                                           "at (1.00, -0.25) m")


def test_the_escape_keeps_its_odometry_through_a_pose_glitch():
    """The deadlock escape tracks its m-line by the odometry pose: a NaN pose is not taken (it dead-reckons on
    from the last one; the wrapped filter brakes and says so), and a pose that is not three numbers is the same clear
    error as the filter's."""
    from safenav.filters import Escape

    robot = preset("m2wr")
    escape = Escape(CBFSafetyFilter(robot, DT))
    escape.filter((0.3, 0.0), robot.scan(), velocity=(0.0, 0.0), pose=(1.0, 2.0, 0.5))
    result = escape.filter((0.3, 0.0), robot.scan(), velocity=(0.0, 0.0), pose=(math.nan, 2.0, 0.5))
    assert result.status is FilterStatus.BAD_INPUT and "pose is not finite" in result.message
    odometry = escape._odometry     # dead-reckoned on by the commands from the last finite pose, not NaN
    assert all(math.isfinite(value) for value in odometry)
    assert math.hypot(odometry.x - 1.0, odometry.y - 2.0) < 0.05 and abs(odometry.yaw - 0.5) < 0.05
    with pytest.raises(InvalidCommand, match="pose"):
        escape.filter((0.3, 0.0), robot.scan(), pose=(1.0, 2.0))
