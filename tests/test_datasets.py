"""Loaders of the real recorded scans (safenav.datasets), checked against shared/data/lidar/README.md.

Tests that need the recordings use the ``lidar_data`` fixture and are skipped when the folder is
absent; the parsing, mapping and error tests build small files of their own.
"""

from __future__ import annotations

import gzip
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from safenav import (
    InvalidConfig,
    InvalidScan,
    LidarMismatch,
    LidarSpec,
    MissingDependency,
    Pose2D,
    Reading,
    SafeNavError,
    preset,
)
from safenav.datasets import (
    RECORDING_FILES,
    RecordedScan,
    lidar_data_dir,
    load_breezyslam,
    load_carmen,
    load_recording,
    load_rosbag,
    recording_files,
    resample,
)
from safenav.errors import UnknownName
from safenav.scan import LaserScan
from safenav.synthetic import Scene, box, synthetic_scan, wall

# README table: short name -> (scans, beams, angle_min [deg], angle increment [deg]).
LAYOUTS = {
    "carmen-intel": (910, 180, -90.0, 1.0),
    "carmen-freiburg-079": (4791, 360, -90.0, 0.5),
    "carmen-csail": (406, 361, -90.0, 0.5),
    "breezyslam-exp1": (756, 683, -120.0, 240.0 / 681),
    "breezyslam-exp2": (641, 683, -120.0, 240.0 / 681),
    "laser-scan-matcher-bag": (360, 681, math.degrees(-2.0862138), math.degrees(2.0 * math.pi / 1024)),
}

# Reading classes over the whole file: (NO_RETURN, INVALID), from the README's marker counts.
# SICK code 81.83 ("measured value > maximum value") is a no return, 81.91 ("not valid") invalid;
# URG 0 is a no return and 1-15 mm are error codes; the bag's 12,699 zeros + 643 codes are invalid.
MARKER_COUNTS = {
    "carmen-intel": (4_172, 0),
    "carmen-freiburg-079": (0, 36_004),
    "carmen-csail": (0, 3_907),
    "breezyslam-exp1": (271_287, 14_391),
    "breezyslam-exp2": (242_258, 10_795),
    "laser-scan-matcher-bag": (0, 12_699 + 643),
}

# Smallest and largest real reading [m] (README).
HIT_EXTENT = {
    "carmen-intel": (0.23, 25.38),
    "carmen-freiburg-079": (0.12, 36.62),
    "carmen-csail": (0.32, 35.12),
    "breezyslam-exp1": (None, 5.562),
    "breezyslam-exp2": (None, 5.580),
    "laser-scan-matcher-bag": (None, 5.468),
}


@pytest.fixture(scope="module")
def recordings(lidar_data: Path) -> dict[str, list[RecordedScan]]:
    """Every scan of the six recordings, loaded once."""
    files = recording_files(lidar_data)
    missing = sorted(set(RECORDING_FILES) - set(files))
    assert not missing, f"recordings missing from {lidar_data}: {missing}"
    return {name: load_recording(path) for name, path in files.items()}


def _all_readings(scans: list[RecordedScan]) -> np.ndarray:
    return np.concatenate([recorded.scan.readings for recorded in scans])


def _world_points(recorded: RecordedScan, reverse: bool = False) -> np.ndarray:
    scan = recorded.scan.with_ranges(recorded.scan.ranges[::-1]) if reverse else recorded.scan
    return recorded.pose.to_parent(scan.points())


def _median_neighbour_distance(scans: list[RecordedScan], pairs: list[int], reverse: bool = False) -> float:
    """Median over scan pairs (i, i+1) of the median distance from scan i+1's points to scan i's [m]."""
    medians = []
    for i in pairs:
        before, after = _world_points(scans[i], reverse), _world_points(scans[i + 1], reverse)
        if len(before) >= 10 and len(after) >= 10:
            medians.append(np.median(cKDTree(before).query(after)[0]))
    return float(np.median(medians))


# ============================================================================ the real recordings


@pytest.mark.parametrize("name", list(LAYOUTS))
def test_scan_and_beam_counts_and_angles(recordings: dict[str, list[RecordedScan]], name: str) -> None:
    n_scans, n_beams, angle_min_deg, increment_deg = LAYOUTS[name]
    scans = recordings[name]
    assert len(scans) == n_scans
    assert [recorded.index for recorded in scans] == list(range(n_scans))
    assert {recorded.source for recorded in scans} == {RECORDING_FILES[name]}
    for recorded in scans:
        scan = recorded.scan
        assert scan.n_beams == n_beams
        assert scan.angle_min == pytest.approx(math.radians(angle_min_deg), abs=1e-6)
        assert scan.angle_increment == pytest.approx(math.radians(increment_deg), abs=1e-9)
        assert scan.angle_max == pytest.approx(scan.angle_min + (n_beams - 1) * scan.angle_increment, abs=1e-6)
        assert scan.stamp == recorded.time


@pytest.mark.parametrize("name", list(MARKER_COUNTS))
def test_markers_map_to_rep117_classes(recordings: dict[str, list[RecordedScan]], name: str) -> None:
    scans = recordings[name]
    counts = np.bincount(_all_readings(scans), minlength=len(Reading))
    assert (counts[Reading.NO_RETURN], counts[Reading.INVALID]) == MARKER_COUNTS[name]
    assert counts[Reading.TOO_CLOSE] == 0
    hits = np.concatenate([recorded.scan.ranges[recorded.scan.readings == Reading.HIT] for recorded in scans])
    assert np.isfinite(hits).all()
    smallest, largest = HIT_EXTENT[name]
    assert hits.max() == pytest.approx(largest, abs=1e-6)
    if smallest is not None:
        assert hits.min() == pytest.approx(smallest, abs=1e-6)
    # Every finite reading is inside the window: nothing is invalid by accident of the limits...
    finite = np.concatenate([recorded.scan.ranges[np.isfinite(recorded.scan.ranges)] for recorded in scans])
    if not name.endswith("bag"):
        assert finite.min() >= scans[0].scan.range_min and finite.max() <= scans[0].scan.range_max
    # ...and no scan yields a NaN obstacle point.
    assert all(np.isfinite(recorded.scan.points()).all() for recorded in scans[::10])


def test_range_windows_and_timing_fields(recordings: dict[str, list[RecordedScan]]) -> None:
    for name in ("carmen-intel", "carmen-freiburg-079", "carmen-csail"):
        scan = recordings[name][0].scan
        assert (scan.range_min, scan.range_max, scan.mount) == (0.0, 80.0, Pose2D())
    for name in ("breezyslam-exp1", "breezyslam-exp2"):
        scan = recordings[name][0].scan
        assert (scan.range_min, scan.range_max, scan.mount) == (0.02, 5.6, Pose2D(0.145, 0.0, 0.0))
        assert (scan.scan_time, scan.time_increment) == (0.1, 0.1 / 1024)


def test_bag_fields_equal_the_readme(recordings: dict[str, list[RecordedScan]]) -> None:
    for recorded in recordings["laser-scan-matcher-bag"]:
        scan = recorded.scan
        assert scan.angle_min == pytest.approx(-2.0862138, abs=1e-6)
        assert scan.angle_max == pytest.approx(2.0862138, abs=1e-6)
        assert scan.angle_increment == pytest.approx(0.0061359233, abs=1e-9)
        assert scan.time_increment == pytest.approx(9.765625e-05, rel=1e-6)
        assert scan.scan_time == pytest.approx(0.1, rel=1e-6)
        assert scan.range_min == pytest.approx(0.02, rel=1e-6)
        assert scan.range_max == pytest.approx(5.6, rel=1e-6)
        assert scan.intensities.size == 0
        assert scan.frame_id == "laser"
        assert recorded.pose is None
    ranges = np.concatenate([recorded.scan.ranges for recorded in recordings["laser-scan-matcher-bag"]])
    assert np.count_nonzero(ranges == 0.0) == 12_699
    assert np.isfinite(ranges).all()  # the loader keeps the message's values as recorded


def test_times(recordings: dict[str, list[RecordedScan]]) -> None:
    intel = np.array([recorded.time for recorded in recordings["carmen-intel"]])
    assert (intel[0], intel[-1]) == pytest.approx((32.9068, 2683.77))
    steps = np.diff(intel)
    assert np.count_nonzero(steps < 0) == 4 and steps.min() >= -0.87
    freiburg = np.array([recorded.time for recorded in recordings["carmen-freiburg-079"]])
    assert (freiburg[0], freiburg[-1]) == pytest.approx((0.227623, 1061.5))
    assert (np.diff(freiburg) >= 0).all()
    assert all(recorded.time is None and recorded.scan.stamp is None for recorded in recordings["carmen-csail"])
    for name, duration in (("breezyslam-exp1", 74.6), ("breezyslam-exp2", 63.2), ("laser-scan-matcher-bag", 35.8)):
        times = np.array([recorded.time for recorded in recordings[name]])
        assert times[-1] - times[0] == pytest.approx(duration, abs=0.1)
    bag_steps = np.diff([recorded.time for recorded in recordings["laser-scan-matcher-bag"]])
    assert bag_steps.min() >= 0.094 and bag_steps.max() <= 0.105


@pytest.mark.parametrize("name", ["carmen-intel", "carmen-freiburg-079", "carmen-csail"])
def test_carmen_poses_equal_the_flaser_pose(recordings: dict[str, list[RecordedScan]], lidar_data: Path,
                                            name: str) -> None:
    expected = []
    with gzip.open(lidar_data / RECORDING_FILES[name], "rt") as log:
        for line in log:
            if line.startswith("FLASER"):
                tokens = line.split()
                n_beams = int(tokens[1])
                expected.append(tuple(float(token) for token in tokens[2 + n_beams:5 + n_beams]))
    assert [tuple(recorded.pose) for recorded in recordings[name]] == expected


def test_carmen_pose_extent(recordings: dict[str, list[RecordedScan]]) -> None:
    poses = np.array([recorded.pose for recorded in recordings["carmen-intel"]])
    assert poses[:, 0].min() == pytest.approx(-9.2, abs=0.05) and poses[:, 0].max() == pytest.approx(16.5, abs=0.05)
    assert poses[:, 1].min() == pytest.approx(-22.1, abs=0.05) and poses[:, 1].max() == pytest.approx(3.9, abs=0.05)


@pytest.mark.parametrize(("name", "path_length"), [("breezyslam-exp1", 46.0), ("breezyslam-exp2", 44.5)])
def test_breezyslam_odometry(recordings: dict[str, list[RecordedScan]], name: str, path_length: float) -> None:
    poses = np.array([recorded.pose for recorded in recordings[name]])
    assert tuple(poses[0]) == (0.0, 0.0, 0.0)
    assert np.hypot(*np.diff(poses[:, :2], axis=0).T).sum() == pytest.approx(path_length, abs=1.0)
    assert np.ptp(poses[:, 0]) < 16.0 and np.ptp(poses[:, 1]) < 16.0
    assert (np.abs(poses[:, 2]) <= math.pi).all()


@pytest.mark.parametrize("name", ["carmen-intel", "carmen-csail"])
def test_carmen_beam_order_consecutive_scans_overlap(recordings: dict[str, list[RecordedScan]], name: str) -> None:
    scans = recordings[name]
    pairs = list(range(len(scans) - 1))
    counter_clockwise = _median_neighbour_distance(scans, pairs)
    assert counter_clockwise < 0.1  # README: 0.042 m (intel), 0.072 m (csail)
    assert _median_neighbour_distance(scans, pairs, reverse=True) > 4 * counter_clockwise


@pytest.mark.parametrize("name", ["breezyslam-exp1", "breezyslam-exp2"])
def test_breezyslam_beam_order_on_turns(recordings: dict[str, list[RecordedScan]], name: str) -> None:
    scans = recordings[name]
    turns = [i for i in range(len(scans) - 1)
             if abs(math.remainder(scans[i + 1].pose.yaw - scans[i].pose.yaw, math.tau)) > math.radians(3.0)]
    assert len(turns) > 100
    counter_clockwise = _median_neighbour_distance(scans, turns)
    assert counter_clockwise < 0.07  # README: 0.028 m (exp1), 0.056 m (exp2)
    assert _median_neighbour_distance(scans, turns, reverse=True) > 2 * counter_clockwise


def test_limit_stops_early(lidar_data: Path) -> None:
    for name, path in recording_files(lidar_data).items():
        first = load_recording(path, limit=3)
        assert [recorded.index for recorded in first] == [0, 1, 2], name
        assert load_recording(path, limit=0) == []


@pytest.mark.parametrize("name", list(LAYOUTS))
@pytest.mark.parametrize("robot", ["rosbot", "puzzlebot", "m2wr"])
def test_resample_real_scans_onto_presets(recordings: dict[str, list[RecordedScan]], name: str, robot: str) -> None:
    lidar = preset(robot).lidar
    for recorded in recordings[name][::50]:
        out = resample(recorded.scan, lidar)
        assert out.n_beams == lidar.n_beams and out.angle_min == lidar.angle_min
        assert out.mount.yaw == lidar.mount.yaw
        assert out.range_max == min(lidar.range_max, recorded.scan.range_max)
        # Directions the source does not see are unknown; the forward beam comes from the source.
        for beam, direction in enumerate(out.base_angles):
            if not recorded.scan.covers(direction):
                assert math.isnan(out.ranges[beam])
        assert out.covers(0.0) and recorded.scan.covers(0.0)
        front = out.ranges[out.beam_index(0.0)]
        source_beam = recorded.scan.beam_index(0.0)
        source_front = recorded.scan.ranges[source_beam]
        if recorded.scan.readings[source_beam] == Reading.HIT and out.range_min <= source_front <= out.range_max:
            assert front == source_front


# ======================================================================= resample on synthetic scans

FRONT_180 = LidarSpec(n_beams=181, angle_min=-0.5 * math.pi, angle_max=0.5 * math.pi, range_min=0.1, range_max=30.0)


def test_resample_wall_onto_rosbot_front_beam() -> None:
    source = synthetic_scan(FRONT_180, Scene.of(wall(distance=2.0)))
    rosbot = preset("rosbot").lidar
    out = resample(source, rosbot)
    assert out.ranges[0] == pytest.approx(2.0) and out.ranges[-1] == pytest.approx(2.0)  # beam 0 faces forward
    assert out.ranges[out.beam_index(0.0)] == pytest.approx(2.0)
    assert out.sector(-0.1, 0.1).min_range == pytest.approx(2.0)
    behind = out.beam_index(math.pi)
    assert behind == 360 and math.isnan(out.ranges[behind])
    assert out.sector(math.radians(100), math.radians(-100)).state.value == "unknown"
    assert np.count_nonzero(np.isnan(out.ranges)) == pytest.approx(360, abs=2)
    puzzle = resample(source, preset("puzzlebot").lidar)
    assert puzzle.ranges[0] == pytest.approx(2.0) and math.isnan(puzzle.ranges[180])


def test_resample_round_trips_directions() -> None:
    room = Scene.of(box(center=(0.5, -0.3), size=(6.0, 4.0)))
    source = synthetic_scan(FRONT_180, room, Pose2D(0.0, 0.0, 0.3))
    back = resample(resample(source, preset("rosbot").lidar), FRONT_180)
    assert np.array_equal(back.ranges, source.ranges)
    assert back.base_angles == pytest.approx(source.base_angles)


def test_resample_keeps_the_rep117_meaning() -> None:
    # Source beams at -3..+3 deg; the target has a beam every 1 deg over -180..180 deg.
    source = LaserScan(angle_min=math.radians(-3), angle_max=math.radians(3), angle_increment=math.radians(1),
                       ranges=[1.0, math.inf, -math.inf, math.nan, 0.12, 20.0, 50.0], range_min=0.1, range_max=30.0,
                       intensities=[1, 2, 3, 4, 5, 6, 7], stamp=4.5, frame_id="front")
    target = LidarSpec(n_beams=361, angle_min=-math.pi, angle_max=math.pi, range_min=0.15, range_max=12.0,
                       mount=Pose2D(0.2, 0.0, 0.0))
    out = resample(source, target)
    got = out.ranges[177:184]
    expected = [1.0, math.inf, -math.inf, math.nan, -math.inf, math.inf, math.nan]
    np.testing.assert_array_equal(got, expected)
    assert np.isnan(np.delete(out.ranges, range(177, 184))).all()
    np.testing.assert_array_equal(out.intensities[177:184], [1, 2, 3, 4, 5, 6, 7])
    assert (out.range_min, out.range_max) == (0.15, 12.0)
    assert out.mount == Pose2D(0.0, 0.0, 0.0)  # the source laser's position, the target's yaw
    assert (out.stamp, out.frame_id) == (4.5, "front")
    # A source with a shorter reach caps range_max, so +inf still means "free up to range_max".
    short = source.replace(range_max=5.6)
    assert resample(short, target).range_max == 5.6


def test_resample_honours_both_mount_yaws() -> None:
    backwards = FRONT_180.scan().replace(mount=Pose2D(0.0, 0.0, math.pi))  # looks behind the robot
    source = backwards.with_ranges(np.linspace(1.0, 2.0, 181))
    for robot in ("rosbot", "puzzlebot", "m2wr"):
        out = resample(source, preset(robot).lidar)
        # Beam by beam, the same source beam as the scalar LaserScan.beam_index picks.
        for beam, direction in enumerate(out.base_angles):
            index = source.beam_index(direction)
            if index is None:
                assert math.isnan(out.ranges[beam])
            else:
                assert out.ranges[beam] == source.ranges[index]
        assert not out.covers(0.0) or math.isnan(out.ranges[out.beam_index(0.0)])  # forward is unseen
    # Two 180-degree lidars facing opposite ways share only the edge beams (half a source increment).
    assert np.count_nonzero(np.isfinite(resample(source, preset("m2wr").lidar).ranges)) == 4


# ================================================================ parsing small files of our own


def _flaser(ranges: list[str], pose: str = "1.5 -2.0 0.25", time: str = "12.345678") -> str:
    return f"FLASER {len(ranges)} {' '.join(ranges)} {pose} {pose} {time} host {time}\n"


def test_carmen_parsing_and_sick_codes(tmp_path: Path) -> None:
    ranges = ["1.00"] * 180
    ranges[0], ranges[1], ranges[2] = "81.83", "81.91", "81.90"
    text = ("# comment\nPARAM robot_frontlaser_offset 0.0 1 host 1\n"
            "ODOM 1 2 0.1 0 0 0 3.0 host 3.0\n"
            + _flaser(ranges) + "NEFF 7\n" + _flaser(["2.5"] * 361, time="1.13486e+09"))
    plain = tmp_path / "tiny.log"
    plain.write_text(text)
    packed = tmp_path / "tiny.log.gz"
    packed.write_bytes(gzip.compress(text.encode()))
    for path in (plain, packed):
        first, second = load_recording(path)
        assert first.scan.ranges[0] == math.inf and np.isnan(first.scan.ranges[1:3]).all()
        assert first.scan.readings[3] == Reading.HIT and first.scan.ranges[3] == 1.0
        assert first.pose == Pose2D(1.5, -2.0, 0.25) and first.time == 12.345678 == first.scan.stamp
        assert first.scan.angle_increment == pytest.approx(math.pi / 180)
        assert second.scan.n_beams == 361 and second.scan.angle_max == pytest.approx(0.5 * math.pi)
        assert second.time is None and second.scan.stamp is None  # printed to 1e4 s
        assert (first.index, second.index, first.source) == (0, 1, path.name)


def test_breezyslam_parsing_and_odometry(tmp_path: Path) -> None:
    def line(time_us: int, left: int, right: int, ranges: list[int]) -> str:
        tokens = [time_us, 14000, left, right] + [0] * 20 + ranges
        return " ".join(str(token) for token in tokens) + " \n"

    ranges = [0, 7, 19, 20, 1500] + [3000] * 678
    path = tmp_path / "tiny.dat"
    quarter_turn = round(0.5 * math.pi * 0.165 / 0.077 * 2000 / (2 * math.pi))  # ticks, each wheel, opposite ways
    path.write_text(line(1_000_000, 0, 0, ranges) + line(1_100_000, 2000, 2000, ranges)
                    + line(1_200_000, 2000 - quarter_turn, 2000 + quarter_turn, ranges))
    first, straight, turned = load_breezyslam(path)
    scan = first.scan
    assert scan.ranges[0] == math.inf and np.isnan(scan.ranges[1:3]).all()
    np.testing.assert_array_equal(scan.ranges[3:5], [0.02, 1.5])
    assert scan.angle_min == pytest.approx(math.radians(-120)) and scan.n_beams == 683
    assert scan.angle_min + 681 * scan.angle_increment == pytest.approx(math.radians(120))
    assert (first.time, straight.time) == pytest.approx((1.0, 1.1))
    assert straight.pose == pytest.approx((2 * math.pi * 0.077, 0.0, 0.0))
    assert turned.pose == pytest.approx((2 * math.pi * 0.077, 0.0, 0.5 * math.pi), abs=1e-3)


def test_lidar_data_dir_honours_the_environment(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / RECORDING_FILES["breezyslam-exp1"]).write_text("")
    monkeypatch.setenv("SAFENAV_LIDAR_DATA", str(tmp_path))
    assert lidar_data_dir() == tmp_path
    assert recording_files(tmp_path) == {"breezyslam-exp1": tmp_path / RECORDING_FILES["breezyslam-exp1"]}
    monkeypatch.setenv("SAFENAV_LIDAR_DATA", str(tmp_path / "nowhere"))
    assert lidar_data_dir() != tmp_path / "nowhere"


def test_missing_rosbags_names_the_pip_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "rosbags", None)
    monkeypatch.setitem(sys.modules, "rosbags.highlevel", None)
    pip_line = r"reading ROS 1 bags needs the optional package 'rosbags': pip install \"safenav\[ros\]\""
    with pytest.raises(MissingDependency, match=pip_line) as caught:
        load_rosbag(tmp_path / "any.bag")
    assert isinstance(caught.value, ImportError) and isinstance(caught.value, SafeNavError)
    with pytest.raises(MissingDependency):
        load_recording(tmp_path / "any.bag")


def test_bag_topic_must_exist(lidar_data: Path) -> None:
    with pytest.raises(UnknownName, match=r"unknown topic '/laser'; expected one of: /scan"):
        load_rosbag(lidar_data / RECORDING_FILES["laser-scan-matcher-bag"], topic="/laser")


def _bad_flaser_count(tmp_path: Path) -> Path:
    path = tmp_path / "bad.log"
    path.write_text(_flaser(["1.0"] * 10))
    return path


def _bad_flaser_tokens(tmp_path: Path) -> Path:
    path = tmp_path / "bad.log"
    path.write_text(_flaser(["1.0"] * 180).replace(" host ", " "))
    return path


def _bad_flaser_number(tmp_path: Path) -> Path:
    path = tmp_path / "bad.log"
    path.write_text(_flaser(["1.0"] * 179 + ["x"]))
    return path


def _bad_dat(tmp_path: Path) -> Path:
    path = tmp_path / "bad.dat"
    path.write_text("1 2 3 4 5\n")
    return path


ERRORS = [
    (lambda tmp: load_recording(tmp / "scan.csv"), UnknownName,
     r"unknown recording file type 'scan.csv'; expected one of: \.bag, \.dat, \.log, \.log\.gz"),
    (lambda tmp: load_carmen(_bad_flaser_count(tmp)), InvalidScan,
     r"bad.log line 1: FLASER with 10 beams; expected 180"),
    (lambda tmp: load_carmen(_bad_flaser_tokens(tmp)), InvalidScan, r"needs 191 tokens, got 190"),
    (lambda tmp: load_carmen(_bad_flaser_number(tmp)), InvalidScan,
     r"line 1: FLASER holds a token that is not a number"),
    (lambda tmp: load_breezyslam(_bad_dat(tmp)), InvalidScan, r"bad.dat line 1: expected 707 tokens, got 5"),
    (lambda tmp: load_carmen(tmp / "x.log", limit=-1), InvalidConfig, r"limit must be None or an integer >= 0, got -1"),
    (lambda tmp: load_breezyslam(tmp / "x.dat", limit=2.5), InvalidConfig, r"got 2.5"),
    (lambda tmp: load_rosbag(tmp / "missing.bag"), FileNotFoundError, r"missing.bag"),
    (lambda tmp: recording_files(tmp / "nowhere"), InvalidConfig, r"nowhere' is not a directory"),
    (lambda tmp: resample(FRONT_180.scan().replace(range_min=20.0), preset("rosbot").lidar), InvalidConfig,
     r"source range window \[20, 30\] m and the target's \[0.15, 12\] m do not overlap"),
    (lambda tmp: RecordedScan(scan="scan", time=None, pose=None, source="x", index=0), InvalidConfig,
     r"RecordedScan.scan must be a LaserScan, got str"),
]


@pytest.mark.parametrize(("call", "error", "message"), ERRORS)
def test_errors(tmp_path: Path, call, error: type[Exception], message: str) -> None:
    with pytest.raises(error, match=message):
        call(tmp_path)


# ============================================================================ the bag through a filter


def test_bag_zeros_read_as_no_return_when_the_driver_says_so(lidar_data: Path) -> None:
    scans = load_rosbag(lidar_data / RECORDING_FILES["laser-scan-matcher-bag"], no_return="zero")
    counts = np.bincount(_all_readings(scans), minlength=len(Reading))
    assert (counts[Reading.NO_RETURN], counts[Reading.INVALID]) == (12_699, 643)   # zeros free, codes invalid
    assert all(recorded.scan.no_return == "zero" and not recorded.scan.mount_given for recorded in scans)


def _replay_example():
    import runpy

    return runpy.run_path(str(Path(__file__).resolve().parents[1] / "examples" / "replay_rosbag.py"),
                          run_name="replay_rosbag")


def test_bag_replayed_with_the_right_description_has_no_spurious_intervention(lidar_data: Path) -> None:
    from safenav.filters import CBFSafetyFilter

    example = _replay_example()
    scans = example["bag_scans"](lidar_data / RECORDING_FILES["laser-scan-matcher-bag"])
    rosbot = CBFSafetyFilter(preset("rosbot"))
    for scan in (scans[0], scans[0].with_mount(preset("rosbot").lidar.mount)):   # the README's old wirings
        with pytest.raises(LidarMismatch, match=r"681 beams vs 720") as caught:
            rosbot.filter((0.3, 0.0), scan)
        assert "LidarSpec(n_beams=681, angle_min=-2.08621, angle_max=2.08621" in str(caught.value)
    replay = example["replay"]
    turned = replay(scans, "turned", "held", 0.3)                   # what the old wiring amounted to
    assert turned.spurious > 150 and turned.statuses.get("ok", 0) < 10
    assert replay(scans, "turned", "fed back", 0.3).mean_speed < 0.01            # stopped for good
    assert replay(scans, "zeros-invalid", "held", 0.3).spurious > 20             # zeros read as unknown
    held = replay(scans, "right", "held", 0.3)                      # the right description
    assert held.spurious == 0 and held.slack <= 0.25 * len(scans)
    for speed in (0.1, 0.3, 0.5):
        fed_back = replay(scans, "right", "fed back", speed)
        assert fed_back.spurious == 0 and fed_back.slack <= 0.05 * len(scans)
        assert fed_back.mean_speed >= 0.8 * speed                   # the robot keeps going


@pytest.mark.parametrize("name", list(LAYOUTS))
def test_a_lidar_described_from_the_first_scan_matches_every_scan_of_the_recording(
        recordings: dict[str, list[RecordedScan]], name: str) -> None:
    scans = [recorded.scan for recorded in recordings[name]]
    mount = None if scans[0].mount_given else Pose2D()          # BreezySLAM's laser sits 0.145 m ahead
    robot = preset("rosbot").replace(lidar=LidarSpec.from_scan(scans[0], mount=mount))
    assert all(robot.match_scan(scan).mount_given for scan in scans)
