"""PointCloud2 to LaserScan (safenav.pointcloud), with real ``sensor_msgs`` message classes from rosbags."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from safenav import (
    CloudSlice,
    InvalidConfig,
    InvalidScan,
    InvalidScanType,
    LidarMismatch,
    LidarSpec,
    Pose2D,
    Reading,
    UnknownName,
    preset,
)
from safenav.pointcloud import flatten_points, read_points, scan_from_cloud
from safenav.synthetic import Circle, Scene, box, cast, synthetic_scan, wall

typesys = pytest.importorskip("rosbags.typesys")
STORE = typesys.get_typestore(typesys.Stores.ROS2_HUMBLE)
PointCloud2 = STORE.types["sensor_msgs/msg/PointCloud2"]
PointField = STORE.types["sensor_msgs/msg/PointField"]
Header = STORE.types["std_msgs/msg/Header"]
Time = STORE.types["builtin_interfaces/msg/Time"]

#: A 3D lidar flattened to a 360-degree scan: 0.1 m band around the sensor plane, empty bins free.
LIDAR_3D = LidarSpec(n_beams=720, angle_min=-math.pi, angle_max=math.pi - 2 * math.pi / 720, range_min=0.3,
                     range_max=20.0, mount=Pose2D(0.05, 0.0, 0.0), frame_id="velodyne",
                     cloud=CloudSlice(z_min=-0.25, z_max=0.3, empty="no_return"))
#: A depth camera with a 1.5 rad field of view in its optical frame; empty bins unknown.
DEPTH_CAMERA = LidarSpec(n_beams=160, angle_min=-0.75, angle_max=0.75, range_min=0.2, range_max=4.0,
                         mount=Pose2D(0.12, 0.0, 0.0), frame_id="camera_depth_optical_frame",
                         cloud=CloudSlice(z_min=-0.1, z_max=0.4, empty="invalid", axes="optical"))
SCENE = Scene.of(box((0.0, 0.0), (6.0, 5.0)), wall(1.5, 0.3, length=1.0), Circle((-1.2, 1.0), 0.3),
                 Circle((0.9, -1.1), 0.2))


def make_cloud(points: np.ndarray, *, dtype: str = "<f4", extra_bytes: int = 4, row_padding: int = 0,
               height: int = 1, frame_id: str = "velodyne", stamp: Time | None = None):
    """A real ``sensor_msgs/PointCloud2`` holding ``points`` ``(N, 3)`` as x, y, z, plus an intensity field."""
    points = np.asarray(points, dtype=float)
    item = np.dtype(dtype)
    width = len(points) // height
    point_step = 3 * item.itemsize + extra_bytes
    records = np.zeros(len(points), dtype=np.dtype({
        "names": ["x", "y", "z", "intensity"],
        "formats": [item, item, item, "u1"],
        "offsets": [0, item.itemsize, 2 * item.itemsize, 3 * item.itemsize],
        "itemsize": point_step,
    }))
    records["x"], records["y"], records["z"] = points[:, 0], points[:, 1], points[:, 2]
    records["intensity"] = 7
    rows = records.view(np.uint8).reshape(height, width * point_step)
    row_step = width * point_step + row_padding
    data = np.zeros((height, row_step), dtype=np.uint8)
    data[:, :width * point_step] = rows
    datatype = PointField.FLOAT32 if item.itemsize == 4 else PointField.FLOAT64
    fields = [PointField(name=name, offset=i * item.itemsize, datatype=datatype, count=1)
              for i, name in enumerate("xyz")]
    fields.append(PointField(name="intensity", offset=3 * item.itemsize, datatype=PointField.UINT8, count=1))
    return PointCloud2(
        header=Header(stamp=stamp or Time(sec=1_700_000_000, nanosec=250_000_000), frame_id=frame_id),
        height=height, width=width, fields=fields, is_bigendian=item.byteorder == ">", point_step=point_step,
        row_step=row_step, data=data.reshape(-1), is_dense=False,
    )


def scene_cloud(lidar: LidarSpec, heights: tuple[float, ...], *, rays_per_beam: int = 1) -> np.ndarray:
    """Points where rays from the sensor at the origin of ``SCENE`` hit it, at several heights, in the sensor frame.

    Plus clutter the flattening must ignore: floor and ceiling points nearer than the walls,
    NaN points and points at the sensor origin (a driver's "no return").
    """
    sensor = lidar.mount
    spacing = lidar.angle_increment / rays_per_beam
    offsets = (np.arange(rays_per_beam) - 0.5 * (rays_per_beam - 1)) * spacing
    angles = (lidar.scan().angles[:, None] + offsets[None, :]).ravel()
    ranges = cast((sensor.x, sensor.y), angles + sensor.yaw, SCENE)
    hit = np.isfinite(ranges)
    xy = np.column_stack((ranges[hit] * np.cos(angles[hit]), ranges[hit] * np.sin(angles[hit])))
    layers = [np.column_stack((xy, np.full(len(xy), z))) for z in heights]
    near = 0.5 * xy
    clutter = [np.column_stack((near, np.full(len(near), -1.0))),       # floor, below the band
               np.column_stack((near, np.full(len(near), 1.5))),        # ceiling, above it
               np.full((5, 3), np.nan), np.zeros((5, 3)), np.array([[1.0, 0.0, np.inf]])]
    points = np.vstack(layers + clutter)
    return points[np.random.default_rng(3).permutation(len(points))]


def to_optical(points: np.ndarray) -> np.ndarray:
    """REP-103 points (x forward, y left, z up) in a camera optical frame (z forward, x right, y down)."""
    return np.column_stack((-points[:, 1], -points[:, 2], points[:, 0]))


# ============================================================================ round trips


@pytest.mark.parametrize("dtype", ["<f4", ">f4", "<f8"])
def test_cloud_of_a_scene_gives_the_obstacle_points_of_the_scan_of_that_scene(dtype):
    cloud = make_cloud(scene_cloud(LIDAR_3D, heights=(-0.2, 0.0, 0.25)), dtype=dtype)
    scan = scan_from_cloud(cloud, LIDAR_3D)
    truth = synthetic_scan(LIDAR_3D, SCENE)
    assert scan.n_beams == truth.n_beams and scan.mount == LIDAR_3D.mount
    assert np.array_equal(scan.readings, truth.readings)
    assert np.allclose(scan.points(), truth.points(), atol=2e-5)     # float32 coordinates
    assert scan.frame_id == "velodyne" and scan.stamp == pytest.approx(1_700_000_000.25)


def test_a_dense_cloud_gives_one_point_per_beam_on_the_scene():
    cloud = make_cloud(scene_cloud(LIDAR_3D, heights=(0.0, 0.1), rays_per_beam=5))
    scan = scan_from_cloud(cloud, LIDAR_3D)
    truth = synthetic_scan(LIDAR_3D, SCENE)
    points = scan.points()
    assert len(points) == len(truth.points())
    # Every flattened point is a surface point of the scene moved onto its beam's centre line,
    # so at most half a beam increment away from the scene...
    laser_ranges = np.hypot(*(points - LIDAR_3D.mount[:2]).T)
    off_scene = np.array([abs(SCENE.clearance(point, 0.0)) for point in points])
    assert np.all(off_scene <= laser_ranges * math.sin(0.5 * LIDAR_3D.angle_increment) + 1e-5)
    assert np.median(off_scene) > 1e-4            # (the dense cloud is not just the beams' own rays)
    # ... and no farther than the beam's own ray: it is the nearest of its bin.
    hit = truth.readings == Reading.HIT
    assert np.all(scan.ranges[hit] <= truth.ranges[hit] + 1e-5)


def test_an_optical_frame_cloud_is_turned_to_rep103_axes():
    points = scene_cloud(DEPTH_CAMERA, heights=(0.0, 0.3))
    scan = scan_from_cloud(make_cloud(to_optical(points), frame_id=DEPTH_CAMERA.frame_id), DEPTH_CAMERA)
    truth = synthetic_scan(DEPTH_CAMERA, SCENE)
    hit = truth.readings == Reading.HIT
    assert hit.sum() > 100
    assert np.allclose(scan.ranges[hit], truth.ranges[hit], atol=2e-5)


def test_an_organized_cloud_with_row_padding_reads_like_a_flat_one():
    points = scene_cloud(LIDAR_3D, heights=(-0.1, 0.1))[:2000]
    flat = read_points(make_cloud(points))
    organized = read_points(make_cloud(points, height=4, row_padding=12))
    assert organized.shape == (2000, 3)
    assert np.array_equal(flat, organized, equal_nan=True)


def test_a_serialized_and_deserialized_message_reads_the_same():
    cloud = make_cloud(scene_cloud(LIDAR_3D, heights=(0.0,)))
    copy = STORE.deserialize_cdr(STORE.serialize_cdr(cloud, PointCloud2.__msgtype__), PointCloud2.__msgtype__)
    assert np.array_equal(scan_from_cloud(copy, LIDAR_3D).ranges, scan_from_cloud(cloud, LIDAR_3D).ranges)


@pytest.mark.parametrize("data", [bytes, bytearray, list, lambda array: __import__("array").array("B", array)])
def test_data_in_every_container_of_the_ros_clients(data):
    cloud = make_cloud(scene_cloud(LIDAR_3D, heights=(0.0,))[:50])
    message = SimpleNamespace(**{name: getattr(cloud, name) for name in
                                 ("height", "width", "fields", "is_bigendian", "point_step", "row_step")},
                              data=data(cloud.data.tobytes() if data is not list else cloud.data.tolist()))
    assert np.array_equal(read_points(message), read_points(cloud), equal_nan=True)


# ============================================================================ readings of a beam


def beam_cloud(*points: tuple[float, float, float]):
    return make_cloud(np.array(points, dtype=float).reshape(-1, 3))


def test_each_beam_reads_the_nearest_point_of_its_bin_and_empty_bins_by_the_option():
    lidar = LIDAR_3D
    cloud = beam_cloud((3.0, 0.0, 0.0), (2.0, 0.001, 0.1), (2.5, -0.001, 0.0),   # nearest 2.0 ahead
                       (1.0, 0.0, 2.0),                                           # above the band: ignored
                       (0.0, 0.1, 0.0),                                           # closer than range_min
                       (-30.0, 0.0, 0.0))                                         # beyond range_max
    scan = scan_from_cloud(cloud, lidar)
    laser_ahead = int(np.argmin(np.abs(scan.angles)))
    assert scan.ranges[laser_ahead] == pytest.approx(2.0, abs=1e-6)
    assert scan.readings[int(np.argmin(np.abs(scan.angles - math.pi / 2)))] == Reading.TOO_CLOSE
    behind = int(np.argmin(np.abs(np.abs(scan.angles) - math.pi)))
    assert scan.ranges[behind] == math.inf
    others = np.ones(scan.n_beams, dtype=bool)
    others[[laser_ahead, behind, int(np.argmin(np.abs(scan.angles - math.pi / 2)))]] = False
    assert np.all(scan.ranges[others] == math.inf)                   # empty bins of a 3D lidar: free
    camera = LidarSpec(**{**_fields(lidar), "cloud": CloudSlice(z_min=-0.25, z_max=0.3, empty="invalid")})
    assert np.all(np.isnan(scan_from_cloud(cloud, camera).ranges[others]))   # of a depth camera: unknown


def _fields(lidar: LidarSpec) -> dict:
    return {name: getattr(lidar, name) for name in lidar.__dataclass_fields__}


@given(st.lists(st.tuples(st.floats(-8, 8), st.floats(-8, 8), st.floats(-0.5, 0.5)), min_size=0, max_size=60))
def test_flattening_equals_a_brute_force_nearest_point_per_beam(points):
    lidar = LidarSpec(n_beams=36, angle_min=-math.pi, angle_max=math.pi - math.pi / 18, range_min=0.3,
                      range_max=6.0, cloud=CloudSlice(z_min=-0.2, z_max=0.2, empty="invalid"))
    xyz = np.array(points, dtype=float).reshape(-1, 3)
    ranges = flatten_points(xyz, lidar)
    increment = lidar.angle_increment
    for beam, angle in enumerate(lidar.scan().angles):
        in_band = (np.abs(xyz[:, 2]) <= 0.2) & np.any(xyz != 0.0, axis=1)
        bearing = np.arctan2(xyz[:, 1], xyz[:, 0])
        in_bin = in_band & (np.abs((bearing - angle + math.pi) % (2 * math.pi) - math.pi) < 0.5 * increment - 1e-9)
        edge = in_band & (np.abs(np.abs((bearing - angle + math.pi) % (2 * math.pi) - math.pi)
                                 - 0.5 * increment) <= 1e-9)
        if edge.any():
            continue                                   # a point on a bin edge may go either way
        planar = np.hypot(xyz[in_bin, 0], xyz[in_bin, 1])
        if planar.size == 0:
            assert math.isnan(ranges[beam])
        elif planar.min() < 0.3:
            assert ranges[beam] == -math.inf
        elif planar.min() > 6.0:
            assert ranges[beam] == math.inf
        else:
            assert ranges[beam] == planar.min()


# ============================================================================ a robot with a cloud source


def test_a_robot_can_carry_a_depth_camera_and_match_its_scans():
    robot = preset("puzzlebot").replace(extra_lidars=(DEPTH_CAMERA,))
    points = scene_cloud(DEPTH_CAMERA, heights=(0.0,))
    scan = scan_from_cloud(make_cloud(to_optical(points), frame_id=DEPTH_CAMERA.frame_id), DEPTH_CAMERA)
    assert robot.match_scan(scan) is scan                         # its own layout and mount
    assert robot.lidar_for(DEPTH_CAMERA.frame_id) is DEPTH_CAMERA
    with pytest.raises(LidarMismatch, match="'velodyne' names none of the lidars"):
        robot.match_scan(scan_from_cloud(make_cloud(points), LIDAR_3D))


# ============================================================================ malformed clouds


def good_message(**changes):
    cloud = make_cloud(scene_cloud(LIDAR_3D, heights=(0.0,))[:10])
    fields = {name: getattr(cloud, name) for name in
              ("header", "height", "width", "fields", "is_bigendian", "point_step", "row_step", "data")}
    fields.update(changes)
    return SimpleNamespace(**{name: value for name, value in fields.items() if value is not _DROP})


_DROP = object()
F32 = PointField.FLOAT32


def _fields_with(**z):
    return [PointField(name="x", offset=0, datatype=F32, count=1),
            PointField(name="y", offset=4, datatype=F32, count=1),
            SimpleNamespace(**{"name": "z", "offset": 8, "datatype": F32, "count": 1, **z})]


MALFORMED = [
    (dict(height=_DROP), InvalidScan, "has no field 'height'"),
    (dict(width=_DROP), InvalidScan, "has no field 'width'"),
    (dict(point_step=_DROP), InvalidScan, "has no field 'point_step'"),
    (dict(row_step=_DROP), InvalidScan, "has no field 'row_step'"),
    (dict(is_bigendian=_DROP), InvalidScan, "has no field 'is_bigendian'"),
    (dict(fields=_DROP), InvalidScan, "has no field 'fields'"),
    (dict(data=_DROP), InvalidScan, "has no field 'data'"),
    (dict(width=-1), InvalidScan, "PointCloud2.width must be an integer >= 0, got -1"),
    (dict(height=1.5), InvalidScan, "PointCloud2.height must be an integer >= 0, got 1.5"),
    (dict(point_step=0), InvalidScan, "PointCloud2.point_step must be an integer >= 1, got 0"),
    (dict(row_step="16"), InvalidScan, "PointCloud2.row_step must be an integer >= 0, got '16'"),
    (dict(row_step=100), InvalidScan, "PointCloud2.row_step=100 is less than width * point_step = 10 * 16"),
    (dict(is_bigendian="yes"), InvalidScan, "PointCloud2.is_bigendian must be True or False, got 'yes'"),
    (dict(data=b"\x00" * 159), InvalidScan, "PointCloud2.data has 159 bytes; expected height * row_step = 1 * 160"),
    (dict(data="0" * 160), InvalidScanType, "PointCloud2.data must be bytes"),
    (dict(data=np.zeros(160)), InvalidScanType, "PointCloud2.data must be bytes or a sequence of byte values 0-255"),
    (dict(data=[300] * 160), InvalidScanType, "PointCloud2.data must be bytes or a sequence of byte values 0-255"),
    (dict(data=None), InvalidScanType, "PointCloud2.data must be bytes"),
    (dict(fields="xyz"), InvalidScanType, "PointCloud2.fields must be a sequence of PointField"),
    (dict(fields=_fields_with()[:2]), InvalidScan, "PointCloud2 has no field 'z'; its fields are x, y"),
    (dict(fields=_fields_with(datatype=9)), InvalidScan, "field 'z' datatype=9; expected a PointField code 1-8"),
    (dict(fields=_fields_with(offset=14)), InvalidScan, "field 'z' offset=14 with 1 x 4 bytes ends at byte 18, "
                                                        "beyond point_step=16"),
    (dict(fields=_fields_with(offset=-4)), InvalidScan, "field 'z' offset must be an integer >= 0, got -4"),
    (dict(fields=_fields_with(count=0)), InvalidScan, "field 'z' count must be an integer >= 1, got 0"),
    (dict(fields=_fields_with(name="x")), InvalidScan, "field 'x' appears twice"),
    (dict(fields=_fields_with(name="")), InvalidScan, "PointCloud2.fields[2].name must be a non-empty string"),
    (dict(fields=[*_fields_with()[:2], SimpleNamespace(name="z", offset=8, count=1)]), InvalidScan,
     "PointCloud2.fields[2] has no 'datatype'"),
]


@pytest.mark.parametrize(("changes", "exception", "fragment"), MALFORMED)
def test_every_malformed_field_raises_naming_it(changes, exception, fragment):
    with pytest.raises(exception) as info:
        scan_from_cloud(good_message(**changes), LIDAR_3D)
    assert isinstance(info.value, InvalidScan) and fragment in str(info.value)


def test_the_unmodified_message_of_the_malformed_table_is_good():
    assert scan_from_cloud(good_message(), LIDAR_3D).n_beams == LIDAR_3D.n_beams


def test_a_stamp_of_no_known_form_names_its_type():
    with pytest.raises(InvalidScanType, match=r"header\.stamp must be .* got 'yesterday' of type str"):
        scan_from_cloud(good_message(header=SimpleNamespace(stamp="yesterday", frame_id="velodyne")), LIDAR_3D)


@pytest.mark.parametrize(
    ("call", "exception", "fragment"),
    [
        (lambda: scan_from_cloud(good_message(), preset("rosbot").lidar), InvalidConfig,
         "lidar 'laser' has no CloudSlice"),
        (lambda: flatten_points(np.zeros((4, 2)), LIDAR_3D), InvalidScan, "points must be an (N, 3) array"),
        (lambda: CloudSlice(z_min=0.5, z_max=0.1, empty="invalid"), InvalidConfig, "CloudSlice.z_max must be > z_min"),
        (lambda: CloudSlice(z_min=0.0, z_max=0.1, empty="free"), UnknownName,
         "unknown CloudSlice.empty reading 'free'; expected one of: invalid, no_return"),
        (lambda: CloudSlice(z_min=0.0, z_max=0.1, empty="invalid", axes="camera"), UnknownName,
         "unknown CloudSlice.axes convention 'camera'; expected one of: optical, rep103"),
        (lambda: LidarSpec(n_beams=10, angle_min=0.0, angle_max=1.0, range_min=0.1, range_max=2.0, cloud=(0, 1)),
         InvalidConfig, "LidarSpec.cloud must be a CloudSlice or None"),
    ],
)
def test_bad_cloud_settings_raise(call, exception, fragment):
    with pytest.raises(exception) as info:
        call()
    assert fragment in str(info.value)
