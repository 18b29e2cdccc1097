import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from safenav import (
    InvalidConfig,
    InvalidScan,
    InvalidScanType,
    LaserScan,
    LidarSpec,
    Pose2D,
    Reading,
    SectorState,
    UnknownName,
    preset,
)
from safenav.geometry import wrap_angle
from safenav.synthetic import Scene, synthetic_scan, wall

HALF_PI = 0.5 * math.pi


def make_scan(**changes):
    fields = dict(angle_min=-HALF_PI, angle_max=HALF_PI, angle_increment=math.pi / 4, range_min=0.1,
                  range_max=10.0, ranges=[1.0, 2.0, 3.0, 4.0, 5.0])
    fields.update(changes)
    return LaserScan(**fields)


# ------------------------------------------------------------------ the tutorials' directions

@pytest.mark.parametrize(
    ("name", "front", "left", "right", "behind"),
    [
        ("rosbot", 0, 180, 539, 360),       # lidar mounted backwards: beam 0 looks forward, 360 backward
        ("puzzlebot", 0, 90, 269, 180),     # 0..2pi, counter-clockwise from the front
        ("m2wr", 360, 719, 0, None),        # 180-degree lidar: nothing behind
    ],
)
def test_preset_direction_indices_match_the_tutorials(name, front, left, right, behind):
    scan = preset(name).scan()
    assert scan.beam_index(0.0) == front
    assert scan.beam_index(HALF_PI) == left
    assert scan.beam_index(-HALF_PI) == right
    assert scan.beam_index(math.pi) == behind
    assert scan.covers(math.pi) is (behind is not None)


def test_rosbot_beam_360_looks_backwards():
    scan = preset("rosbot").scan()
    assert abs(wrap_angle(scan.base_angles[360] - math.pi)) < scan.angle_increment
    assert abs(scan.base_angles[0]) < 1e-12


conventions = st.fixed_dictionaries({
    "angle_min": st.floats(-math.pi, 0.0),
    "fov": st.floats(HALF_PI, 2 * math.pi),
    "n": st.integers(10, 2000),
    "mount_yaw": st.floats(-2 * math.pi, 2 * math.pi),  # beyond one turn is rejected as degrees
})


@given(conventions, st.floats(0.0, 1.0))
def test_direction_to_index_to_direction_within_half_an_increment(convention, fraction):
    n, fov = convention["n"], convention["fov"]
    increment = fov / (n - 1)
    scan = LaserScan(angle_min=convention["angle_min"], angle_max=convention["angle_min"] + fov,
                     angle_increment=increment, range_min=0.1, range_max=10.0, ranges=np.ones(n),
                     mount=Pose2D(0.0, 0.0, convention["mount_yaw"]))
    direction = wrap_angle(convention["mount_yaw"] + convention["angle_min"] + fraction * fov)
    index = scan.beam_index(direction)
    assert index is not None
    assert abs(wrap_angle(scan.base_angles[index] - direction)) <= 0.5 * increment + 1e-9


@given(conventions, st.floats(0.0, 1.0))
def test_directions_outside_the_field_of_view_are_not_covered(convention, fraction):
    n, fov = convention["n"], convention["fov"]
    increment = fov / (n - 1)
    gap = 2 * math.pi - fov - increment  # uncovered arc beyond half an increment either side
    if gap <= 1e-6:
        return
    scan = LaserScan(angle_min=convention["angle_min"], angle_max=convention["angle_min"] + fov,
                     angle_increment=increment, range_min=0.1, range_max=10.0, ranges=np.ones(n),
                     mount=Pose2D(0.0, 0.0, convention["mount_yaw"]))
    start = convention["mount_yaw"] + convention["angle_min"] + fov + 0.5 * increment
    direction = start + 1e-7 + fraction * (gap - 2e-7)
    assert scan.beam_index(direction) is None
    assert scan.coverage(direction - 1e-8, direction + 1e-8) == 0.0


# ------------------------------------------------------------------ points

@pytest.mark.parametrize("name", ["rosbot", "puzzlebot", "m2wr"])
@pytest.mark.parametrize("direction", [0.0, 0.4, -1.2])
def test_points_of_a_wall_land_on_the_wall(name, direction):
    robot = preset(name)
    distance = 1.7
    scan = synthetic_scan(robot, Scene.of(wall(distance, direction)))
    points = scan.points()
    assert len(points) > 50
    normal = np.array([math.cos(direction), math.sin(direction)])
    assert np.max(np.abs(points @ normal - distance)) < 1e-9


def test_points_in_laser_and_base_frames_differ_by_the_mount():
    mount = Pose2D(0.15, -0.05, 0.3)
    scan = make_scan(mount=mount)
    assert np.allclose(scan.points("base"), mount.to_parent(scan.points("laser")))


def test_points_with_an_unknown_frame_name_the_frame():
    with pytest.raises(InvalidScan, match="frame must be 'base' or 'laser'"):
        make_scan().points("odom")


# ------------------------------------------------------------------ REP-117

@pytest.mark.parametrize(
    ("value", "reading", "gives_point"),
    [
        (2.5, Reading.HIT, True),           # a return at 2.5 m
        (0.1, Reading.HIT, True),           # exactly range_min is in range
        (10.0, Reading.HIT, True),          # exactly range_max is in range
        (math.inf, Reading.NO_RETURN, False),   # nothing within range_max: free
        (-math.inf, Reading.TOO_CLOSE, True),   # object closer than range_min: point at range_min
        (math.nan, Reading.INVALID, False),     # invalid measurement
        (0.05, Reading.INVALID, False),         # below range_min: discarded
        (12.0, Reading.INVALID, False),         # above range_max: discarded
        (0.0, Reading.INVALID, False),          # the classic "no reading" zero
        (-1.0, Reading.INVALID, False),         # negative garbage
    ],
)
def test_rep117_readings(value, reading, gives_point):
    scan = make_scan(ranges=[value, 1.0, 1.0, 1.0, 1.0])
    assert scan.readings[0] == reading
    index, ranges = scan.obstacle_beams()
    assert (0 in index) is gives_point
    if reading is Reading.TOO_CLOSE:
        assert ranges[0] == scan.range_min


# ------------------------------------------------------------------ sectors

def test_sector_reads_obstacle_free_and_unknown():
    robot = preset("m2wr")
    scan = synthetic_scan(robot, Scene.of(wall(2.0, 0.0, length=1.0)))
    front = scan.sector(-0.1, 0.1)
    assert front.state is SectorState.OBSTACLE
    assert front.min_range == pytest.approx(2.0 - robot.lidar.mount.x, abs=1e-5)
    assert front.complete
    left = scan.sector(1.0, 1.5)
    assert left.state is SectorState.FREE and left.min_range == math.inf
    behind = scan.sector(3 * math.pi / 4, -3 * math.pi / 4)
    assert behind.state is SectorState.UNKNOWN and math.isnan(behind.min_range)
    assert behind.n_beams == 0 and behind.coverage == 0.0


def test_sector_with_only_invalid_beams_is_unknown_not_free():
    robot = preset("puzzlebot")
    ranges = np.full(360, math.inf)
    ranges[:20] = math.nan
    ranges[-20:] = 0.0
    scan = robot.scan(ranges)
    front = scan.sector(-math.radians(15), math.radians(15))
    assert front.state is SectorState.UNKNOWN
    assert front.n_beams > 0 and front.n_informative == 0
    assert not front.complete


def test_sector_too_close_counts_as_obstacle_at_range_min():
    ranges = np.full(360, math.inf)
    ranges[0] = -math.inf
    scan = preset("puzzlebot").scan(ranges)
    front = scan.sector(-0.1, 0.1)
    assert front.state is SectorState.OBSTACLE
    assert front.min_range == scan.range_min and front.n_too_close == 1


def test_sector_wrapping_through_pi_and_partial_coverage():
    scan = preset("m2wr").scan()
    assert scan.coverage(0.0, math.pi) == pytest.approx(0.5 + 0.5 * scan.angle_increment / math.pi, abs=1e-9)
    assert scan.coverage(-math.pi, math.pi) == pytest.approx(scan.field_of_view / (2 * math.pi))
    rosbot = preset("rosbot").scan()
    assert rosbot.sector_mask(3 * math.pi / 4, -3 * math.pi / 4).sum() == pytest.approx(180, abs=1)
    assert rosbot.coverage(3.0, -3.0) == 1.0


def test_sector_is_the_masked_beams_of_every_scan_of_any_layout():
    """``sector`` (whose beams and coverage are kept per layout and sector) reads exactly the beams of
    ``sector_mask`` of each scan and its ``coverage``: scans of random layouts (clockwise, partial and full
    turns, any mount yaw) asked for the same sectors again with other readings, and layouts that differ only in
    the mount's yaw or the first angle."""
    rng = np.random.default_rng(5)
    layouts = []
    for _ in range(12):
        n = int(rng.integers(4, 400))
        increment = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.2, 1.0) * 2.0 * math.pi / n)
        angle_min = float(rng.uniform(-math.pi, math.pi) if increment > 0.0 else rng.uniform(0.5, math.pi - 0.2))
        mount = Pose2D(0.1, 0.0, float(rng.uniform(-math.pi, math.pi)))
        layouts += [(angle_min, increment, n, mount), (angle_min, increment, n, Pose2D(0.1, 0.0, mount.yaw + 0.3)),
                    (angle_min + 0.2, increment, n, mount)]
    sectors = [tuple(float(v) for v in rng.uniform(-4.0, 4.0, 2)) for _ in range(10)] + [(-0.26, 0.26), (1.0, 1.0)]
    for _ in range(3):
        for angle_min, increment, n, mount in layouts:
            ranges = rng.uniform(0.0, 12.0, n)
            ranges[rng.random(n) < 0.2] = rng.choice([math.inf, -math.inf, math.nan])
            angle_max = angle_min + increment * (n - 1)
            scan = LaserScan(ranges=ranges, angle_min=angle_min, angle_max=angle_max, angle_increment=increment,
                             range_min=0.1, range_max=10.0, mount=mount)
            for lo, hi in sectors:
                got = scan.sector(lo, hi)
                mask = scan.sector_mask(lo, hi)
                readings, values = scan.readings[mask], scan.ranges[mask]
                hits = values[readings == Reading.HIT]
                assert got.n_beams == int(mask.sum())
                assert got.n_informative == int(np.count_nonzero(readings != Reading.INVALID))
                assert got.n_too_close == int(np.count_nonzero(readings == Reading.TOO_CLOSE))
                assert got.coverage == scan.coverage(lo, hi)
                if got.n_too_close:
                    assert got.min_range == scan.range_min
                elif hits.size:
                    assert got.min_range == hits.min()
                else:
                    assert got.min_range == math.inf if got.n_informative else math.isnan(got.min_range)


# ------------------------------------------------------------------ validation

BAD_SCANS = [
    (dict(ranges=[]), InvalidScan, "ranges is empty"),
    (dict(ranges=[1.0, 2.0]), InvalidScan, "ranges has 2 values"),
    (dict(ranges=np.ones(9)), InvalidScan, "ranges has 9 values"),
    (dict(angle_increment=0.0), InvalidScan, "angle_increment must be nonzero, got 0.0"),
    # clockwise, but angle_max where a counter-clockwise scan would end (SICK NAV310's driver publishes this)
    (dict(angle_increment=-math.pi / 4), InvalidScan, "a clockwise scan (angle_increment < 0) ends at angle_max"),
    (dict(angle_min=math.nan), InvalidScan, "angle_min must be finite"),
    (dict(angle_max=math.inf), InvalidScan, "angle_max must be finite"),
    (dict(range_min=10.0), InvalidScan, "range_max must be > range_min"),
    (dict(range_min=5.0, range_max=1.0), InvalidScan, "range_max must be > range_min"),
    (dict(range_min=-0.1), InvalidScan, "range_min must be >= 0"),
    (dict(range_max=math.nan), InvalidScan, "range_max must be finite"),
    (dict(intensities=[1.0, 2.0]), InvalidScan, "intensities has 2 values; expected 0 or 5"),
    (dict(angle_increment=0.01, angle_max=-HALF_PI + 0.04, ranges=np.ones(1000)), InvalidScan, "ranges has 1000"),
    (dict(angle_min=0.0, angle_max=10.0, angle_increment=2.5), InvalidScan, "expected at most one turn"),
    (dict(ranges="1 2 3 4 5"), InvalidScanType, "ranges must be a 1-D sequence of real numbers"),
    (dict(ranges=None), InvalidScanType, "ranges must be a 1-D sequence"),
    (dict(ranges=[1.0, None, 1.0, 1.0, 1.0]), InvalidScanType, "ranges must be a 1-D sequence"),
    (dict(ranges=["1", "2", "3", "4", "5"]), InvalidScanType, "ranges must be a 1-D sequence"),
    (dict(ranges=[[1.0, 2.0]] * 5), InvalidScanType, "ranges must be 1-D, got an array of shape (5, 2)"),
    (dict(ranges=[[1.0], [2.0, 3.0]]), InvalidScanType, "ranges must be a 1-D sequence"),
    (dict(ranges=[True] * 5), InvalidScanType, "dtype bool"),
    (dict(angle_min="-1.57"), InvalidScanType, "angle_min must be a real number"),
    (dict(range_max=None), InvalidScanType, "range_max must be a real number"),
    (dict(angle_increment=True), InvalidScanType, "angle_increment must be a real number"),
    (dict(intensities="bright"), InvalidScanType, "intensities must be a 1-D sequence"),
    (dict(mount=(0.0, 0.0)), InvalidScanType, "mount must be a pose"),
    (dict(mount=(0.0, 0.0, math.nan)), InvalidScan, "mount.yaw must be finite"),
    (dict(stamp="now"), InvalidScanType, "stamp must be a real number"),
    (dict(frame_id=3), InvalidScanType, "frame_id must be a string"),
]


@pytest.mark.parametrize(("changes", "exception", "fragment"), BAD_SCANS)
def test_bad_scans_raise_naming_the_field(changes, exception, fragment):
    with pytest.raises(exception) as info:
        make_scan(**changes)
    assert type(info.value) is exception
    assert fragment in str(info.value)


# ------------------------------------------------------------------ a turning lidar's sweep

def test_each_beam_is_measured_after_the_stamp_as_sensor_msgs_defines_it_also_for_a_clockwise_message():
    """The stamp is the first beam's time and beam ``i`` of the message is measured ``i * time_increment`` later;
    a clockwise message's first beam is stored last."""
    counter = make_scan(ranges=[1.0] * 5, time_increment=0.01)
    np.testing.assert_allclose(counter.beam_times, [0.0, 0.01, 0.02, 0.03, 0.04])
    clockwise = make_scan(angle_min=HALF_PI, angle_max=-HALF_PI, angle_increment=-math.pi / 4, ranges=[1.0] * 5,
                          time_increment=0.01)
    np.testing.assert_allclose(clockwise.beam_times, [0.04, 0.03, 0.02, 0.01, 0.0])   # message beam 0 is stored last
    np.testing.assert_array_equal(make_scan(ranges=[1.0] * 5).beam_times, np.zeros(5))


def test_a_sweep_motion_puts_each_point_where_the_lidar_was_for_its_beam_and_its_error_bounds_them():
    rng = np.random.default_rng(3)
    scan = make_scan(ranges=rng.uniform(0.5, 4.0, 5), mount=(0.2, -0.1, 0.7))
    motion = np.column_stack((rng.uniform(-0.05, 0.05, 5), rng.uniform(-0.05, 0.05, 5), rng.uniform(-0.2, 0.2, 5)))
    swept = scan.with_sweep_motion(motion)
    index, ranges = swept.obstacle_beams()
    lidar_at = [Pose2D(*scan.mount).compose(Pose2D(*motion[i])) for i in index]
    expected = np.array([pose.to_parent(np.array([[r * math.cos(swept.angles[i]), r * math.sin(swept.angles[i])]]))[0]
                         for pose, i, r in zip(lidar_at, index, ranges, strict=True)])
    np.testing.assert_allclose(swept.points(), expected, atol=1e-12)
    translation, rotation = swept.sweep_error
    moved = np.hypot(*(swept.points() - scan.points()).T)
    assert np.all(moved <= translation + np.hypot(*scan.points().T) * rotation + 1e-12)
    assert scan.sweep_error == (0.0, 0.0) and scan.sweep_motion is None
    # A new mount keeps the motion relative to it; new readings (another sweep) drop it.
    assert swept.with_mount((0.0, 0.0, 0.0)).sweep_motion is swept.sweep_motion
    assert swept.with_ranges([1.0] * 5).sweep_motion is None
    assert not swept.sweep_motion.flags.writeable


@pytest.mark.parametrize("motion", [np.zeros((4, 3)), np.full((5, 3), math.nan), [[0.0, 0.0]] * 5])
def test_a_sweep_motion_of_the_wrong_shape_or_not_finite_is_refused(motion):
    with pytest.raises(InvalidScan, match=r"sweep motion must be \(5, 3\) finite numbers") as caught:
        make_scan(ranges=[1.0] * 5).with_sweep_motion(motion)
    assert isinstance(caught.value, ValueError)


# ------------------------------------------------------------------ clockwise scans

def test_a_clockwise_scan_is_stored_counter_clockwise_with_every_beam_where_it_looked():
    """Drivers of lidars spinning clockwise or mounted upside down publish ``angle_increment < 0``
    (``angle_max = angle_min + (n - 1) * angle_increment < angle_min``); ROS allows it. The scan keeps
    every reading in its direction, stored counter-clockwise: the same points, readings, sectors and
    filter answers as the counter-clockwise message of the same beams."""
    ranges, intensities = [1.0, math.inf, 3.0, -math.inf, math.nan], [10.0, 20.0, 30.0, 40.0, 50.0]
    clockwise = make_scan(angle_min=HALF_PI, angle_max=-HALF_PI, angle_increment=-math.pi / 4, ranges=ranges,
                          intensities=intensities, time_increment=0.001, mount=(0.1, 0.0, math.pi))
    twin = make_scan(ranges=ranges[::-1], intensities=intensities[::-1], time_increment=-0.001,
                     mount=(0.1, 0.0, math.pi))
    for name in ("angle_min", "angle_max", "angle_increment", "time_increment"):
        assert getattr(clockwise, name) == pytest.approx(getattr(twin, name), abs=1e-12), name
    np.testing.assert_array_equal(clockwise.ranges, twin.ranges)
    np.testing.assert_array_equal(clockwise.intensities, twin.intensities)
    np.testing.assert_array_equal(clockwise.readings, twin.readings)
    np.testing.assert_allclose(clockwise.points(), twin.points(), atol=1e-12)
    # the message's beam 0 looked at +90 deg in the laser frame, backwards-mounted: -90 deg on the base
    assert clockwise.ranges[-1] == 1.0 and clockwise.angles[-1] == pytest.approx(HALF_PI)
    assert clockwise.beam_index(-HALF_PI) == 4
    assert not clockwise.ranges.flags.writeable and not clockwise.intensities.flags.writeable
    assert clockwise.replace(frame_id="other").angle_increment == pytest.approx(math.pi / 4)


def test_a_clockwise_message_reads_like_its_counter_clockwise_twin_in_both_filters(lidar_data):
    """A real recorded scan (the ROS 1 bag of the shared data) sent clockwise: both filters answer as for
    the message as recorded."""
    from safenav.datasets import load_rosbag
    from safenav.filters import CBFSafetyFilter, MPCSafetyFilter

    recorded = load_rosbag(lidar_data / "scan_tools-laser_scan_matcher-demo.bag", limit=1)[0].scan
    message = ros1_like(angle_min=recorded.angle_min + (recorded.n_beams - 1) * recorded.angle_increment,
                        angle_max=recorded.angle_min, angle_increment=-recorded.angle_increment,
                        range_min=recorded.range_min, range_max=recorded.range_max,
                        ranges=tuple(recorded.ranges[::-1]), time_increment=0.0)
    clockwise = LaserScan.from_msg(message)
    np.testing.assert_allclose(clockwise.points(), recorded.points(), atol=1e-9)
    robot = preset("rosbot").replace(lidar=LidarSpec.from_scan(recorded, mount=(0.05, 0.0, 0.0)))
    for cls in (CBFSafetyFilter, MPCSafetyFilter):
        answers = [cls(robot, 0.05).filter((0.5, 0.3), scan, velocity=(0.3, 0.0)) for scan in (recorded, clockwise)]
        np.testing.assert_allclose(answers[0].u, answers[1].u, atol=1e-9)
        assert answers[0].status is answers[1].status


def test_a_lidar_described_clockwise_is_refused_with_its_counter_clockwise_description():
    with pytest.raises(InvalidConfig) as info:
        LidarSpec(n_beams=5, angle_min=HALF_PI, angle_max=-HALF_PI, range_min=0.1, range_max=5.0)
    assert f"angle_min={-HALF_PI!r}, angle_max={HALF_PI!r}" in str(info.value)


def test_off_by_one_beam_count_of_some_drivers_is_accepted():
    scan = make_scan(angle_max=HALF_PI + math.pi / 4, ranges=np.ones(5))
    assert scan.n_beams == 5


def test_ranges_are_copied_and_read_only():
    source = np.ones(5)
    scan = make_scan(ranges=source)
    source[0] = 99.0
    assert scan.ranges[0] == 1.0
    with pytest.raises(ValueError):
        scan.ranges[0] = 2.0


def test_single_beam_scan_is_valid():
    scan = LaserScan(angle_min=0.0, angle_max=0.0, angle_increment=0.01, range_min=0.1, range_max=5.0, ranges=[1.0])
    assert scan.beam_index(0.0) == 0 and scan.beam_index(1.0) is None
    assert scan.points().tolist() == [[1.0, 0.0]]


# ------------------------------------------------------------------ from_msg

def ros1_like(**changes):
    header = SimpleNamespace(stamp=SimpleNamespace(secs=12, nsecs=500_000_000), frame_id="laser_frame")
    fields = dict(header=header, angle_min=-HALF_PI, angle_max=HALF_PI, angle_increment=math.pi / 4,
                  time_increment=0.001, scan_time=0.1, range_min=0.1, range_max=10.0,
                  ranges=(1.0, 2.0, math.inf, -math.inf, math.nan), intensities=())
    fields.update(changes)
    return SimpleNamespace(**fields)


def test_from_msg_reads_every_field_and_the_ros1_stamp():
    scan = LaserScan.from_msg(ros1_like(), mount=(0.1, 0.0, math.pi))
    assert scan.stamp == pytest.approx(12.5)
    assert scan.frame_id == "laser_frame"
    assert scan.mount == Pose2D(0.1, 0.0, math.pi)
    assert scan.readings.tolist() == [Reading.HIT, Reading.HIT, Reading.NO_RETURN, Reading.TOO_CLOSE, Reading.INVALID]
    assert scan.time_increment == 0.001 and scan.scan_time == 0.1


def test_from_msg_reads_a_ros2_stamp_and_float32_arrays():
    import array
    message = ros1_like(header=SimpleNamespace(stamp=SimpleNamespace(sec=3, nanosec=250_000_000), frame_id="l"),
                        ranges=array.array("f", [1.0, 2.0, 3.0, 4.0, 5.0]))
    scan = LaserScan.from_msg(message)
    assert scan.stamp == pytest.approx(3.25)
    assert scan.ranges.dtype == np.float64


def test_from_msg_names_a_missing_field():
    message = ros1_like()
    del message.range_max
    with pytest.raises(InvalidScan, match="has no field 'range_max'"):
        LaserScan.from_msg(message)


def test_from_msg_accepts_a_message_without_header_or_intensities():
    message = ros1_like()
    del message.header, message.intensities
    scan = LaserScan.from_msg(message, stamp=4.0)
    assert scan.stamp == 4.0 and scan.intensities.size == 0


# ------------------------------------------------------------------ mount given or not

def test_a_scan_without_mount_is_at_the_identity_but_says_the_mount_was_not_given():
    scan = make_scan()
    assert not scan.mount_given and scan.mount == Pose2D()
    assert np.allclose(scan.points("base"), scan.points("laser"))
    assert LaserScan.from_msg(ros1_like()).mount_given is False
    assert make_scan(mount=Pose2D()).mount_given is True                      # the identity, given
    assert LaserScan.from_msg(ros1_like(), mount=(0.0, 0.0, 0.0)).mount_given is True
    assert preset("puzzlebot").scan().mount_given is True                    # the simulator's scans


def test_not_given_survives_replace_pickling_and_copies():
    import copy
    import dataclasses
    import pickle

    scan = make_scan()
    for twin in (scan.replace(stamp=3.0), scan.with_ranges([1.0] * 5), dataclasses.replace(scan, frame_id="x"),
                 pickle.loads(pickle.dumps(scan)), copy.deepcopy(scan)):
        assert twin.mount_given is False and twin.mount == Pose2D()
    assert scan.replace(mount=(0.1, 0.0, 0.0)).mount_given is True
    assert make_scan(mount=(0.1, 0.0, 0.0)).replace(mount=None).mount_given is False


def test_with_mount_places_the_scan_and_shares_its_readings():
    scan = make_scan(ranges=[1.0, math.nan, math.inf, 2.0, 0.05])
    readings = scan.readings
    moved = scan.with_mount((0.2, 0.1, math.pi))
    assert moved.mount == Pose2D(0.2, 0.1, math.pi) and moved.mount_given
    assert moved.ranges is scan.ranges and moved.readings is readings
    assert np.allclose(moved.points(), Pose2D(0.2, 0.1, math.pi).to_parent(scan.points("laser")))
    assert not scan.mount_given                                              # the original is unchanged
    with pytest.raises(InvalidScan, match=r"mount\.yaw=180\.0 looks like degrees"):
        scan.with_mount((0.0, 0.0, 180))


# ------------------------------------------------------------------ degrees

DEGREE_MISTAKES = [
    (dict(mount=(0.0, 0.0, 180.0)), "mount.yaw=180.0 looks like degrees; expected radians"),
    (dict(mount=(0.15, 0.0, -90.0)), "mount.yaw=-90.0 looks like degrees; expected radians"),
    (dict(angle_min=-90.0, angle_max=90.0, angle_increment=45.0),
     "angle_min=-90.0 and angle_max=90.0 look like degrees; expected radians"),
    (dict(angle_min=0.0, angle_max=359.0, angle_increment=1.0, ranges=np.ones(360)),
     "angle_max=359.0 looks like degrees; expected radians"),
    (dict(angle_increment=45.0), "angle_increment=45.0 looks like degrees; expected radians"),
    (dict(angle_min=-math.pi, angle_max=math.pi, angle_increment=0.5, ranges=np.ones(721)),
     "angle_increment=0.5 looks like degrees; expected radians"),
]


@pytest.mark.parametrize(("changes", "fragment"), DEGREE_MISTAKES)
def test_angles_that_look_like_degrees_are_rejected(changes, fragment):
    with pytest.raises(InvalidScan) as info:
        make_scan(**changes)
    assert fragment in str(info.value)


@pytest.mark.parametrize("yaw", [2 * math.pi, -2 * math.pi, math.pi, 6.0])
def test_any_yaw_within_one_turn_is_radians(yaw):
    assert make_scan(mount=(0.0, 0.0, yaw)).mount.yaw == yaw


# ------------------------------------------------------------------ timestamps

class RclpyTime:
    """The interface of ``rclpy.time.Time`` that safenav reads (rclpy is not installed here)."""

    def __init__(self, nanoseconds: int) -> None:
        self._nanoseconds = nanoseconds

    @property
    def nanoseconds(self) -> int:
        return self._nanoseconds


class RospyTime:
    """The interface of ``rospy.Time`` beyond ``secs``/``nsecs``: ``to_sec()``."""

    def __init__(self, seconds: float) -> None:
        self._seconds = seconds

    def to_sec(self) -> float:
        return self._seconds


def _builtin_time(sec: int, nanosec: int):
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE).types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


STAMPS = [
    (12.5, 12.5),                                                     # float seconds
    (np.float32(0.25), 0.25),
    (1_700_000_000, 1_700_000_000.0),                                 # integer seconds (< 1e14)
    (1_700_000_000_123_456_789, 1_700_000_000.123456789),             # integer nanoseconds
    (np.int64(1_700_000_000_500_000_000), 1_700_000_000.5),
    (10**14, 100_000.0),                                              # the threshold itself is nanoseconds
    (SimpleNamespace(secs=12, nsecs=500_000_000), 12.5),              # ROS 1
    (SimpleNamespace(sec=3, nanosec=250_000_000), 3.25),              # ROS 2 message
    (_builtin_time(1_282_836_370, 970_876_375), 1_282_836_370.970876375),   # rosbags builtin_interfaces
    (RclpyTime(1_700_000_000_000_000_001), 1_700_000_000.000000001),
    (RospyTime(42.125), 42.125),
    (None, None),
]


@pytest.mark.parametrize(("stamp", "seconds"), STAMPS)
def test_every_accepted_stamp_form(stamp, seconds):
    from safenav import stamp_seconds

    result = stamp_seconds(stamp)
    assert result == (None if seconds is None else pytest.approx(seconds, abs=1e-6, rel=0))
    assert make_scan(stamp=stamp).stamp == result
    header = SimpleNamespace(stamp=stamp, frame_id="laser")
    assert LaserScan.from_msg(ros1_like(header=header)).stamp == result
    assert LaserScan.from_msg(ros1_like(), stamp=stamp).stamp == (result if stamp is not None else 12.5)


BAD_STAMPS = [
    ("now", InvalidScanType, "stamp must be a real number of seconds, integer nanoseconds (>= 1e14) or a ROS time "
                             "(sec/nanosec, secs/nsecs, nanoseconds or to_sec()), got 'now' of type str"),
    (object(), InvalidScanType, "of type object"),
    (True, InvalidScanType, "got True of type bool"),
    (SimpleNamespace(seconds=3), InvalidScanType, "of type SimpleNamespace"),
    (SimpleNamespace(sec=3), InvalidScanType, "stamp of type SimpleNamespace has 'sec' but no 'nanosec'"),
    (SimpleNamespace(secs=3, nsecs=2_000_000_000), InvalidScan, "stamp.nsecs must be a finite number >= 0 and < 1e+09"),
    (SimpleNamespace(sec="3", nanosec=0), InvalidScan, "stamp.sec must be a finite number, got '3' of type str"),
    (1.7e18, InvalidScan, "stamp=1.7e+18 looks like nanoseconds; expected seconds, or nanoseconds as an integer"),
    (-10**15, InvalidScan, "looks like nanoseconds"),
    (math.nan, InvalidScan, "stamp must be finite, got nan"),
    (RclpyTime(math.inf), InvalidScan, "stamp.nanoseconds must be a finite number"),
]


@pytest.mark.parametrize(("stamp", "exception", "fragment"), BAD_STAMPS)
def test_a_stamp_of_no_accepted_form_raises_naming_it(stamp, exception, fragment):
    from safenav import stamp_seconds

    with pytest.raises(exception) as info:
        stamp_seconds(stamp)
    assert fragment in str(info.value)
    with pytest.raises(exception, match=r"header\.stamp"):
        LaserScan.from_msg(ros1_like(header=SimpleNamespace(stamp=stamp, frame_id="laser")))


@given(st.integers(10**14, 4 * 10**18))
def test_integer_nanoseconds_round_trip_to_the_microsecond(nanoseconds):
    from safenav import stamp_seconds

    seconds = stamp_seconds(nanoseconds)
    assert abs(seconds - nanoseconds // 10**9 - (nanoseconds % 10**9) * 1e-9) <= 1e-6
    assert stamp_seconds(SimpleNamespace(sec=nanoseconds // 10**9, nanosec=nanoseconds % 10**9)) == seconds


# ------------------------------------------------------------------ no-return markers

@pytest.mark.parametrize(
    ("no_return", "value", "reading"),
    [
        (None, 0.0, Reading.INVALID),           # plain REP-117: zero is below range_min
        ("zero", 0.0, Reading.NO_RETURN),       # the driver's "no return"
        ("zero", 0.05, Reading.INVALID),        # other codes below range_min stay invalid
        ("zero", 10.0, Reading.HIT),
        (None, 10.0, Reading.HIT),              # plain REP-117: range_max is a hit
        ("range_max", 10.0, Reading.NO_RETURN),
        ("range_max", 10.5, Reading.NO_RETURN),
        ("range_max", 9.99, Reading.HIT),
        ("range_max", 0.0, Reading.INVALID),
        ("zero", math.nan, Reading.INVALID),
        ("zero", -math.inf, Reading.TOO_CLOSE),
    ],
)
def test_no_return_option_turns_the_drivers_marker_into_inf(no_return, value, reading):
    scan = make_scan(ranges=[value, 1.0, 1.0, 1.0, 1.0], no_return=no_return)
    assert scan.readings[0] == reading
    assert bool(scan.ranges[0] == math.inf) == (reading == Reading.NO_RETURN)
    message = LaserScan.from_msg(ros1_like(ranges=(value, 1.0, 1.0, 1.0, 1.0)), no_return=no_return)
    assert message.readings[0] == reading and message.no_return == no_return


def test_no_return_applies_to_new_readings_and_can_be_stated_once():
    scan = make_scan(ranges=[0.0, 1.0, 0.0, 1.0, 1.0])
    assert scan.n_informative == 3
    zeros = scan.with_no_return("zero")
    assert zeros.readings.tolist() == [Reading.NO_RETURN, Reading.HIT, Reading.NO_RETURN, Reading.HIT, Reading.HIT]
    assert zeros.n_informative == 5 and scan.n_informative == 3               # caches follow the readings
    assert zeros.with_ranges([0.0] * 5).n_informative == 5
    assert zeros.with_no_return("zero") is zeros
    with pytest.raises(InvalidScan, match="built with no_return='zero'; cannot re-read it with no_return='range_max'"):
        zeros.with_no_return("range_max")
    with pytest.raises(UnknownName, match="unknown no_return convention 'zeros'; expected one of: range_max, zero"):
        make_scan(no_return="zeros")


@pytest.mark.parametrize("no_return", [None, "zero", "range_max"])
def test_with_ranges_is_the_scan_built_afresh(no_return):
    """``with_ranges`` (which validates only the readings) gives the scan the constructor builds from the same layout:
    the same fields, readings and points, for clockwise and counter-clockwise layouts, stated and unstated mounts,
    a new stamp or the old one, with and without intensities; the caches of the old readings are not kept, and a
    wrong count or a bad value is named."""
    rng = np.random.default_rng(4)
    for increment, mount in ((np.pi / 90, (0.1, 0.0, np.pi)), (-np.pi / 90, None)):
        n = 181
        start = -np.pi / 2 if increment > 0 else np.pi / 2
        template = LaserScan(angle_min=start, angle_max=start + (n - 1) * increment, angle_increment=increment,
                             ranges=np.full(n, 2.0), range_min=0.1, range_max=8.0, mount=mount, stamp=1.5,
                             no_return=no_return)
        template.readings, template.n_informative   # noqa: B018  (caches of the old readings)
        for stamp in (None, 2.25, "keep"):
            ranges = rng.choice([0.0, 0.05, 1.0, 3.0, 8.0, 9.0, np.inf, -np.inf, np.nan], n)
            intensities = rng.uniform(0.0, 1.0, n) if stamp is None else ()
            kwargs = {} if stamp == "keep" else {"stamp": stamp}
            fast = template.with_ranges(ranges, intensities, **kwargs)
            built = LaserScan(angle_min=template.angle_min, angle_max=template.angle_max,
                              angle_increment=template.angle_increment, ranges=ranges, intensities=intensities,
                              range_min=0.1, range_max=8.0, mount=template.mount if mount else None,
                              stamp=1.5 if stamp == "keep" else stamp, no_return=no_return)
            for name in ("angle_min", "angle_max", "angle_increment", "range_min", "range_max", "stamp", "mount",
                         "no_return", "mount_given", "n_informative"):
                assert getattr(fast, name) == getattr(built, name), name
            for name in ("ranges", "intensities", "readings", "base_angles"):
                np.testing.assert_array_equal(getattr(fast, name), getattr(built, name))
            np.testing.assert_array_equal(fast.points(), built.points())
            assert not fast.ranges.flags.writeable and not fast.intensities.flags.writeable
        with pytest.raises(InvalidScan, match="180 values; expected 181"):
            template.with_ranges(np.ones(180))
        with pytest.raises(InvalidScan, match="intensities has 3 values"):
            template.with_ranges(np.ones(n), [1.0, 2.0, 3.0])
        with pytest.raises(InvalidScanType, match="ranges"):
            template.with_ranges(["a"] * n)
