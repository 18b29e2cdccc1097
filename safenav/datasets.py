"""Real recorded laser scans as :class:`~safenav.scan.LaserScan` objects, for tests and benchmarks.

The loaders read the six public recordings described in ``shared/data/lidar/README.md``
(the files are not shipped with safenav: their licences are unsettled) and turn
every scan into a :class:`RecordedScan`: the scan with REP-117 values, its time,
and its pose when the recording has one.

=====================  ===================  ==========================  ========================  ====================
source                 loader               beams (laser frame, CCW)    range window [m]          pose
=====================  ===================  ==========================  ========================  ====================
CARMEN ``*.log[.gz]``  ``load_carmen``      -90 deg + i * (1 or 0.5)    0 .. 80 (SICK LMS 2xx)    corrected, map frame
BreezySLAM ``*.dat``   ``load_breezyslam``  -120 deg + i * 240/681      0.02 .. 5.6 (URG-04LX)    wheel odometry
ROS 1 ``*.bag``        ``load_rosbag``      as in the message           as in the message         none
=====================  ===================  ==========================  ========================  ====================

Each sensor marks a missing or bad reading with its own status code; the loaders
map the codes by what the sensor's protocol says they mean:

* **SICK LMS 2xx (CARMEN)**, centimetre mode: readings of 81.83 m and above are
  status codes, not distances. 8183 ("measured value > maximum value") becomes
  ``+inf`` (no return); every other code, in practice 8191 ("measured value not
  valid"), becomes ``NaN``. This is how ROS's ``sicktoolbox_wrapper`` maps them
  for REP-117. The data agree: in freiburg-079, 97 % of the 81.91 readings sit
  next to a real reading under 5 m (median 0.87 m), and 41 % inside an unbroken
  surface, so they are dropouts, not open space.
* **Hokuyo URG-04LX (BreezySLAM)**, millimetres: 0 ("detected object is possibly
  at 22 m", SCIP 2.0) becomes ``+inf``; 1-19 mm are error codes and become ``NaN``.
* **ROS bag**: taken as recorded unless ``no_return=`` says otherwise. Its 0.0 and
  0.006-0.015 m error codes lie below ``range_min`` = 0.02 m, so plain REP-117 classifies
  them as ``INVALID``. The 0.0 is the URG's "no return" (as in the BreezySLAM logs):
  ``load_rosbag(path, no_return="zero")``, or a robot whose lidar says
  ``LidarSpec(no_return="zero")``, reads it as ``+inf``
  (``examples/replay_rosbag.py`` replays the bag through a filter that way).

:func:`resample` puts any scan onto another lidar's beam layout (for example the
ROSbot's backwards-mounted 360-degree lidar) by base-frame direction, so real
180- and 240-degree scans can drive robots with other conventions.

Longer than most modules because each of the six recordings has its own file format and loader; they
share only the small :class:`RecordedScan` type, which is why they sit together.
"""

from __future__ import annotations

import gzip
import itertools
import math
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from pathlib import Path
from types import MappingProxyType
from typing import Any, TextIO

import numpy as np

from safenav._optional import require
from safenav.errors import InvalidConfig, InvalidScan, UnknownName
from safenav.geometry import TWO_PI, Pose2D, unicycle_rollout, wrap_angle
from safenav.robot import LidarSpec
from safenav.scan import LaserScan, Reading

__all__ = [
    "RECORDING_FILES",
    "RecordedScan",
    "lidar_data_dir",
    "load_breezyslam",
    "load_carmen",
    "load_recording",
    "load_rosbag",
    "recording_files",
    "resample",
]

#: The six known recordings: short name -> file name in the data folder.
RECORDING_FILES: Mapping[str, str] = MappingProxyType({
    "carmen-intel": "carmen-intel-corrected.log.gz",
    "carmen-freiburg-079": "carmen-freiburg-079-corrected.log.gz",
    "carmen-csail": "carmen-csail-corrected.log.gz",
    "breezyslam-exp1": "breezyslam-exp1.dat",
    "breezyslam-exp2": "breezyslam-exp2.dat",
    "laser-scan-matcher-bag": "scan_tools-laser_scan_matcher-demo.bag",
})

#: File-name endings :func:`load_recording` understands.
RECORDING_SUFFIXES = (".log.gz", ".log", ".dat", ".bag")

#: Environment variable naming the folder of the recordings.
LIDAR_DATA_ENV = "SAFENAV_LIDAR_DATA"

# --- CARMEN / SICK LMS 2xx -------------------------------------------------------------------
#: Smallest range of the SICK LMS 2xx [m]: the sensor states none; ROS's LMS 2xx drivers publish 0.
CARMEN_RANGE_MIN = 0.0
#: Largest range of the SICK LMS 2xx in centimetre mode [m] (nominal 80 m; the largest real
#: reading in the three logs is 36.62 m, the status codes start at 81.83 m).
CARMEN_RANGE_MAX = 80.0
#: Readings at or above this value [m] are taken as SICK status codes, not distances (the codes
#: are 81.83-81.91 m in centimetre mode; no real reading in the logs is above 36.62 m).
_SICK_CODE_THRESHOLD = 80.0
#: SICK centimetre-mode code 8183, "measured value > maximum value": no return.
_SICK_CM_NO_RETURN = 8183
#: First beam of every CARMEN front-laser scan [rad] (CARMEN's ``readlog.c``).
_CARMEN_ANGLE_MIN = -0.5 * math.pi
#: Beam count -> angle increment [rad], as CARMEN's ``carmen_laser_guess_angle_increment``.
_CARMEN_INCREMENTS = MappingProxyType({
    180: math.pi / 180.0, 181: math.pi / 180.0, 360: math.pi / 360.0, 361: math.pi / 360.0,
})
#: FLASER tokens besides the n ranges: tag, n, two pose triples, ipc time, host, logger time.
_FLASER_EXTRA_TOKENS = 11

# --- BreezySLAM / Hokuyo URG-04LX -------------------------------------------------------------
#: Smallest URG-04LX range [m]; smaller values (1-19 mm) are SCIP error codes.
URG_RANGE_MIN = 0.02
#: Nominal URG-04LX range [m] (the largest reading in exp1/exp2 is 5.58 m).
URG_RANGE_MAX = 5.6
#: URG-04LX scan period [s] and mirror steps per turn (time between beams = period / steps).
_URG_SCAN_TIME = 0.1
_URG_STEPS_PER_TURN = 1024
#: BreezySLAM's beam layout: reading k at -120 deg + k * 240 deg / 681 (``coreslam.c``).
_BREEZY_ANGLE_MIN = math.radians(-120.0)
_BREEZY_ANGLE_INCREMENT = math.radians(240.0) / 681.0
#: Laser position on the robot: 145 mm ahead of the wheel axle (``coreslam.h``, ``mines.py``).
_BREEZY_MOUNT = Pose2D(0.145, 0.0, 0.0)
#: Line layout: 707 tokens, time [us] first, left and right wheel ticks at 2 and 3, ranges from 24.
_BREEZY_TOKENS = 707
_BREEZY_FIRST_RANGE = 24
#: Odometry of the Mines rover as BreezySLAM models it.
_BREEZY_TICKS_PER_TURN = 2000.0
_BREEZY_WHEEL_RADIUS = 0.077  # [m]
_BREEZY_HALF_AXLE = 0.165  # [m]

# --- timestamps ---------------------------------------------------------------------------------
#: A logged time in scientific notation coarser than this [s] is dropped (csail prints ``1.13486e+09``).
_MAX_TIME_RESOLUTION = 0.1

_LASER_SCAN_MSGTYPE = "sensor_msgs/msg/LaserScan"


@dataclass(frozen=True)
class RecordedScan:
    """One scan of a recording, with its time and pose.

    Attributes:
        scan: the scan, REP-117 values, :attr:`LaserScan.stamp` equal to :attr:`time`.
        time: recording time of the scan [s], or ``None`` when the recording's times are
            unusable (csail prints them with 6 significant digits).
        pose: pose of the scan's base frame [m, m, rad]: the SLAM-corrected pose in the map
            frame for CARMEN, the wheel-odometry pose (start at the origin) for BreezySLAM,
            ``None`` for the bag. World points are ``pose.to_parent(scan.points())``.
        source: file name of the recording.
        index: position of the scan in the recording, from 0.
    """

    scan: LaserScan
    time: float | None
    pose: Pose2D | None
    source: str
    index: int

    def __post_init__(self) -> None:
        if not isinstance(self.scan, LaserScan):
            raise InvalidConfig(f"RecordedScan.scan must be a LaserScan, got {type(self.scan).__name__}")
        if isinstance(self.index, bool) or not isinstance(self.index, int) or self.index < 0:
            raise InvalidConfig(f"RecordedScan.index must be an integer >= 0, got {self.index!r}")


# ======================================================================================= discovery


def lidar_data_dir() -> Path | None:
    """The folder of the real recordings, or ``None`` when it cannot be found.

    Looked up, in order, in ``$SAFENAV_LIDAR_DATA``, in ``shared/data/lidar`` next to the
    repository (``<repo>/../shared/data/lidar``), and at ``/work/shared/data/lidar``. A folder
    counts when it holds at least one of the known recordings (:data:`RECORDING_FILES`).
    """
    candidates = []
    from_env = os.environ.get(LIDAR_DATA_ENV, "")
    if from_env:
        candidates.append(Path(from_env))
    candidates.append(Path(__file__).resolve().parents[2] / "shared" / "data" / "lidar")
    candidates.append(Path("/work/shared/data/lidar"))
    for candidate in candidates:
        if candidate.is_dir() and any((candidate / name).is_file() for name in RECORDING_FILES.values()):
            return candidate
    return None


def recording_files(folder: str | os.PathLike[str]) -> dict[str, Path]:
    """The known recordings present in ``folder``, by short name (see :data:`RECORDING_FILES`).

    Args:
        folder: the data folder, e.g. :func:`lidar_data_dir`.

    Returns:
        Short name -> path, in the order of :data:`RECORDING_FILES`; missing files are left out.

    Raises:
        InvalidConfig: ``folder`` is not a directory.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InvalidConfig(f"lidar data folder {str(folder)!r} is not a directory")
    return {name: folder / file for name, file in RECORDING_FILES.items() if (folder / file).is_file()}


def load_recording(path: str | os.PathLike[str], **options: Any) -> list[RecordedScan]:
    """Load any supported recording, chosen by its file name.

    ``*.log.gz`` and ``*.log`` go to :func:`load_carmen`, ``*.dat`` to :func:`load_breezyslam`,
    ``*.bag`` to :func:`load_rosbag`.

    Args:
        path: the file.
        **options: passed on to the loader (``limit``, and ``topic`` for bags).

    Raises:
        UnknownName: the file name has none of the supported endings (the message lists them).
    """
    path = Path(path)
    name = path.name.lower()
    if name.endswith((".log.gz", ".log")):
        return load_carmen(path, **options)
    if name.endswith(".dat"):
        return load_breezyslam(path, **options)
    if name.endswith(".bag"):
        return load_rosbag(path, **options)
    raise UnknownName(
        "recording file type", path.name, RECORDING_SUFFIXES,
        hint="CARMEN logs (.log, .log.gz), BreezySLAM logs (.dat) or ROS 1 bags (.bag)",
    )


# ========================================================================================== CARMEN


def load_carmen(path: str | os.PathLike[str], *, limit: int | None = None) -> list[RecordedScan]:
    """Scans of a CARMEN log (``FLASER`` lines of a ``.log`` or gzip ``.log.gz`` file).

    Beam ``i`` is at ``-pi/2 + i * increment`` counter-clockwise, with an increment of 1 deg for
    180 or 181 beams and 0.5 deg for 360 or 361 (CARMEN's own log reader). Readings are metres;
    SICK status codes (>= 80 m) become ``+inf`` for code 8183 ("measured value > maximum value")
    and ``NaN`` for the others (8191, "measured value not valid"). The range window is
    [:data:`CARMEN_RANGE_MIN`, :data:`CARMEN_RANGE_MAX`] = [0, 80] m.

    The pose is the first pose triple of the line (in the "corrected" logs both triples are the
    SLAM-corrected pose) and the laser frame is the base frame (mount at the origin; freiburg-079's
    ``robot_frontlaser_offset`` of -0.04 m is not applied, since the corrected pose was estimated
    from the scans themselves). The time is the line's ``ipc_timestamp``, or ``None`` when it is
    printed in scientific notation more coarsely than 0.1 s (all of csail's times). ``ODOM``,
    ``PARAM``, ``NEFF`` and comment lines are skipped.

    Args:
        path: the log file.
        limit: stop after this many scans (``None``: all).

    Raises:
        InvalidScan: a ``FLASER`` line is malformed or has a beam count CARMEN cannot place
            (the message names the file and line).
    """
    _check_limit(limit)
    path = Path(path)
    scans: list[RecordedScan] = []
    with _open_text(path) as lines:
        flaser = ((number, line) for number, line in enumerate(lines, start=1) if line.startswith("FLASER"))
        for index, (number, line) in enumerate(itertools.islice(flaser, limit)):
            ranges, pose, time = _parse_flaser(line, path, number)
            increment = _CARMEN_INCREMENTS[ranges.size]
            scan = LaserScan(
                angle_min=_CARMEN_ANGLE_MIN,
                angle_max=_CARMEN_ANGLE_MIN + (ranges.size - 1) * increment,
                angle_increment=increment,
                ranges=ranges,
                range_min=CARMEN_RANGE_MIN,
                range_max=CARMEN_RANGE_MAX,
                stamp=time,
            )
            scans.append(RecordedScan(scan, time, pose, path.name, index))
    return scans


def _parse_flaser(line: str, path: Path, number: int) -> tuple[np.ndarray, Pose2D, float | None]:
    """Ranges [m] (REP-117), corrected pose and time [s] of one ``FLASER`` line."""
    tokens = line.split()
    where = f"{path.name} line {number}"
    try:
        n_beams = int(tokens[1])
    except (IndexError, ValueError):
        raise InvalidScan(f"{where}: FLASER needs a beam count after the tag, got {line[:40]!r}") from None
    if n_beams not in _CARMEN_INCREMENTS:
        raise InvalidScan(
            f"{where}: FLASER with {n_beams} beams; expected 180, 181, 360 or 361 "
            "(the SICK LMS layouts CARMEN's log reader knows)"
        )
    if len(tokens) != n_beams + _FLASER_EXTRA_TOKENS:
        raise InvalidScan(
            f"{where}: FLASER with {n_beams} beams needs {n_beams + _FLASER_EXTRA_TOKENS} tokens, got {len(tokens)}"
        )
    try:
        ranges = np.array(tokens[2:2 + n_beams], dtype=float)
        x, y, yaw = (float(token) for token in tokens[2 + n_beams:5 + n_beams])
    except ValueError as exc:
        raise InvalidScan(f"{where}: FLASER holds a token that is not a number ({exc})") from None
    return _sick_codes_to_rep117(ranges), Pose2D(x, y, yaw), _logged_time(tokens[n_beams + 8])


def _sick_codes_to_rep117(ranges: np.ndarray) -> np.ndarray:
    """Replace SICK LMS 2xx centimetre-mode status codes by ``+inf`` (code 8183) or ``NaN`` (others)."""
    codes = ranges >= _SICK_CODE_THRESHOLD
    if codes.any():
        beyond_max = codes & (np.rint(ranges * 100.0) == _SICK_CM_NO_RETURN)
        ranges[codes] = math.nan
        ranges[beyond_max] = math.inf
    return ranges


def _logged_time(token: str) -> float | None:
    """A logged time [s], or ``None`` when it is not a finite number or is printed in scientific
    notation more coarsely than 0.1 s (csail's ``1.13486e+09`` is only good to 1e4 s).

    Plain decimals are kept: ``%g`` drops trailing zeros, so ``1153`` in intel means 1153.00 s.
    """
    try:
        value = Decimal(token)
    except InvalidOperation:
        return None
    if not value.is_finite():
        return None
    exponent = value.as_tuple().exponent
    if "e" in token.lower() and isinstance(exponent, int) and 10.0 ** exponent > _MAX_TIME_RESOLUTION:
        return None
    return float(value)


# ====================================================================================== BreezySLAM


def load_breezyslam(path: str | os.PathLike[str], *, limit: int | None = None) -> list[RecordedScan]:
    """Scans of a BreezySLAM / CoreSLAM log (``exp1.dat``, ``exp2.dat``: Hokuyo URG-04LX, one scan a line).

    All 683 readings of a line are kept. Reading ``k`` is at ``-120 deg + k * 240/681 deg``
    counter-clockwise, BreezySLAM's convention for the first 682; the 683rd, which BreezySLAM
    drops, continues the same step to +120.35 deg (it reads 0 in 740 of exp1's 756 scans).
    Readings are millimetres: 0 ("object possibly at 22 m", beyond range) becomes ``+inf``,
    1-19 mm (error codes) ``NaN``, the rest metres. The range window is
    [:data:`URG_RANGE_MIN`, :data:`URG_RANGE_MAX`] = [0.02, 5.6] m. Readings 0-49 are 0 in every
    scan of both logs, so the rightmost 17.6 deg always read ``+inf``, as the sensor reported them;
    they may well be masked by the robot's own structure rather than free.

    The laser sits 0.145 m ahead of the wheel axle (``scan.mount``). The pose is the axle
    centre's wheel odometry from the first scan (at the origin), integrated along arcs with
    BreezySLAM's rover constants: 2000 ticks per wheel turn, wheel radius 0.077 m, half axle
    0.165 m. The ticks have small glitches, which are integrated as logged. The time is the
    first token [us] in seconds.

    Args:
        path: the log file.
        limit: stop after this many scans (``None``: all).

    Raises:
        InvalidScan: a line does not have 707 numeric tokens (the message names the line).
    """
    _check_limit(limit)
    path = Path(path)
    rows = []
    with _open_text(path) as lines:
        numbered = ((number, line) for number, line in enumerate(lines, start=1) if line.strip())
        for number, line in itertools.islice(numbered, limit):
            tokens = line.split()
            if len(tokens) != _BREEZY_TOKENS:
                raise InvalidScan(f"{path.name} line {number}: expected {_BREEZY_TOKENS} tokens, got {len(tokens)}")
            rows.append(tokens)
    try:
        table = np.array(rows, dtype=float).reshape(len(rows), _BREEZY_TOKENS)
    except ValueError as exc:
        raise InvalidScan(f"{path.name}: a line holds a token that is not a number ({exc})") from None
    times = table[:, 0] * 1e-6
    poses = _integrate_wheel_ticks(table[:, 2], table[:, 3])
    millimetres = table[:, _BREEZY_FIRST_RANGE:]
    ranges = millimetres * 1e-3
    ranges[millimetres < 1000.0 * URG_RANGE_MIN] = math.nan
    ranges[millimetres == 0.0] = math.inf
    n_beams = ranges.shape[1]
    layout = {
        "angle_min": _BREEZY_ANGLE_MIN,
        "angle_max": _BREEZY_ANGLE_MIN + (n_beams - 1) * _BREEZY_ANGLE_INCREMENT,
        "angle_increment": _BREEZY_ANGLE_INCREMENT,
        "range_min": URG_RANGE_MIN,
        "range_max": URG_RANGE_MAX,
        "scan_time": _URG_SCAN_TIME,
        "time_increment": _URG_SCAN_TIME / _URG_STEPS_PER_TURN,
        "mount": _BREEZY_MOUNT,
    }
    return [
        RecordedScan(LaserScan(ranges=ranges[index], stamp=float(times[index]), **layout),
                     float(times[index]), Pose2D(*map(float, poses[index])), path.name, index)
        for index in range(len(rows))
    ]


def _integrate_wheel_ticks(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """``(N, 3)`` poses [m, m, rad] of the axle centre from cumulative wheel ticks, starting at the origin."""
    if left.size == 0:
        return np.empty((0, 3))
    radians_per_tick = TWO_PI / _BREEZY_TICKS_PER_TURN
    left_turn = np.diff(left) * radians_per_tick
    right_turn = np.diff(right) * radians_per_tick
    forward = _BREEZY_WHEEL_RADIUS * 0.5 * (left_turn + right_turn)
    yaw = _BREEZY_WHEEL_RADIUS * (right_turn - left_turn) / (2.0 * _BREEZY_HALF_AXLE)
    poses = unicycle_rollout(Pose2D(), np.column_stack((forward, yaw)), 1.0)
    poses[:, 2] = wrap_angle(poses[:, 2])
    return poses


# ========================================================================================= ROS bag


def load_rosbag(path: str | os.PathLike[str], *, topic: str = "/scan", limit: int | None = None,
                no_return: str | None = None) -> list[RecordedScan]:
    """``sensor_msgs/LaserScan`` messages of a ROS 1 bag (or anything ``rosbags``' AnyReader opens).

    Needs the optional package ``rosbags`` (``pip install "safenav[ros]"``). Each message becomes
    a scan through :meth:`LaserScan.from_msg`, fields as recorded: by default readings below
    ``range_min`` (the URG's 0.0 and error codes in the demo bag) are ``INVALID`` by the scan
    model; ``no_return="zero"`` reads the 0.0 as ``+inf``. The time is ``header.stamp``; bags
    carry no pose (``pose`` is ``None``) and no mount (:attr:`LaserScan.mount_given` is
    ``False``: :meth:`safenav.robot.RobotSpec.match_scan` puts the scans on the robot's lidar).

    Args:
        path: the bag file.
        topic: the scan topic.
        limit: stop after this many scans (``None``: all).
        no_return: the driver's no-return marker (``"zero"``, ``"range_max"``; see
            :mod:`safenav.scan`); ``None`` is plain REP-117.

    Raises:
        MissingDependency: ``rosbags`` is not installed (the message gives the pip line).
        FileNotFoundError: ``path`` does not exist.
        UnknownName: the bag has no ``topic`` (the message lists its topics).
        InvalidConfig: ``topic`` does not carry ``sensor_msgs/LaserScan``.
    """
    _check_limit(limit)
    highlevel = require("rosbags.highlevel", extra="ros", purpose="reading ROS 1 bags", package="rosbags")
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"ROS bag {str(path)!r} does not exist")
    scans: list[RecordedScan] = []
    with highlevel.AnyReader([path]) as reader:
        connections = [connection for connection in reader.connections if connection.topic == topic]
        if not connections:
            topics = {connection.topic for connection in reader.connections}
            raise UnknownName("topic", topic, topics, hint=f"in {path.name}")
        for connection in connections:
            if connection.msgtype != _LASER_SCAN_MSGTYPE:
                raise InvalidConfig(
                    f"topic {topic!r} in {path.name} carries {connection.msgtype}; expected {_LASER_SCAN_MSGTYPE}"
                )
        messages = itertools.islice(reader.messages(connections=connections), limit)
        for index, (connection, _, raw) in enumerate(messages):
            scan = LaserScan.from_msg(reader.deserialize(raw, connection.msgtype), no_return=no_return)
            scans.append(RecordedScan(scan, scan.stamp, None, path.name, index))
    return scans


# ======================================================================================== resample


def resample(scan: LaserScan, lidar: LidarSpec) -> LaserScan:
    """``scan`` put onto another lidar's beam layout, beam by base-frame direction.

    Each beam of ``lidar`` takes the reading of the source beam nearest its direction in the
    base frame, if one lies within half a source increment (half-way between two, the
    counter-clockwise one, as :meth:`LaserScan.beam_index`). Beams outside the source's field of
    view read ``NaN``: unknown, never free.

    The result has ``lidar``'s angles, yaw, beam count and timing; it keeps the source laser's
    position on the base (``mount = (scan.mount.x, scan.mount.y, lidar.mount.yaw)``), so every
    obstacle point stays where the source saw it, and its stamp and frame id. Its range window
    is the intersection of both: ``[max(range_min), min(range_max)]``, so every value keeps
    its REP-117 meaning:

    ======================================  =============================================
    source reading                          result
    ======================================  =============================================
    hit ``r`` inside the window             ``r``
    hit ``r`` beyond the window's max       ``+inf``: nothing within the (smaller) max
    hit ``r`` below the window's min        ``-inf``: an object closer than ``range_min``
    ``+inf`` (free up to source max)        ``+inf``: free up to the window's max, which
                                            is no larger (a target range_max beyond the
                                            source's would claim unseen free space)
    ``-inf``                                ``-inf``
    ``NaN`` / out-of-window (invalid)       ``NaN``
    no source beam in that direction        ``NaN``
    ======================================  =============================================

    Intensities, when present, follow their beams (``NaN`` where no source beam).

    Args:
        scan: the source scan.
        lidar: the target lidar (e.g. ``preset("rosbot").lidar``).

    Raises:
        InvalidConfig: the two range windows do not overlap.
    """
    range_min = max(scan.range_min, lidar.range_min)
    range_max = min(scan.range_max, lidar.range_max)
    if range_max <= range_min:
        raise InvalidConfig(
            f"resample: the source range window [{scan.range_min:g}, {scan.range_max:g}] m and the target's "
            f"[{lidar.range_min:g}, {lidar.range_max:g}] m do not overlap"
        )
    template = lidar.scan()
    index, covered = _nearest_beams(scan, template.base_angles)
    source = scan.ranges[index]
    reading = scan.readings[index]
    hit = reading == Reading.HIT
    ranges = np.full(template.n_beams, math.nan)
    ranges[hit] = source[hit]
    ranges[(reading == Reading.NO_RETURN) | (hit & (source > range_max))] = math.inf
    ranges[(reading == Reading.TOO_CLOSE) | (hit & (source < range_min))] = -math.inf
    ranges[~covered] = math.nan
    intensities: Iterable[float] = ()
    if scan.intensities.size:
        intensities = np.where(covered, scan.intensities[index], math.nan)
    return template.replace(
        ranges=ranges,
        intensities=intensities,
        range_min=range_min,
        range_max=range_max,
        mount=Pose2D(scan.mount.x, scan.mount.y, lidar.mount.yaw),
        stamp=scan.stamp,
        frame_id=scan.frame_id,
    )


def _nearest_beams(scan: LaserScan, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For base-frame directions [rad]: index of ``scan``'s nearest beam, and whether it is within half an increment.

    The vectorised twin of :meth:`LaserScan.beam_index`.
    """
    increment = scan.angle_increment
    last = scan.n_beams - 1
    offset = (directions - scan.mount.yaw - scan.angle_min) % TWO_PI
    best_index = np.zeros(directions.size, dtype=np.intp)
    best_error = np.full(directions.size, math.inf)
    for turn in (0.0, -TWO_PI):
        shifted = offset + turn
        index = np.clip(np.floor(shifted / increment + 0.5 + 1e-9), 0, last).astype(np.intp)
        error = np.abs(shifted - index * increment)
        better = error < best_error - 1e-9
        best_index[better] = index[better]
        best_error[better] = error[better]
    covered = best_error <= 0.5 * increment * (1.0 + 1e-9) + 1e-9
    return best_index, covered


# ========================================================================================= helpers


def _check_limit(limit: int | None) -> None:
    if limit is not None and (isinstance(limit, bool) or not isinstance(limit, int) or limit < 0):
        raise InvalidConfig(f"limit must be None or an integer >= 0, got {limit!r}")


def _open_text(path: Path) -> TextIO:
    """``path`` opened for reading text, gunzipped when its name ends in ``.gz``."""
    if path.name.endswith(".gz"):
        return gzip.open(path, "rt", encoding="ascii", errors="replace")
    return open(path, encoding="ascii", errors="replace")
