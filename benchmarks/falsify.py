"""An adversarial search for the filters' safety: the project's own falsifier.

The filters state a guarantee (``docs/safety.md``): inside its assumptions the body keeps
``margin`` of clearance from every obstacle. This benchmark tries to break it. It owns a
small simulator that shares nothing with ``safenav.sim_bullet`` (exact analytic ray casting
against circles and segments, the exact unicycle in 20 sub-steps per period, four models of
the base's velocity loop) and searches scenario parameters with CMA-ES (the ``cma`` package)
from seeded random starts, minimising

    objective = min over the episode of (true clearance - margin)

with the filter's own minimum barrier as a tie-breaker. Each episode starts inside the
assumptions: every obstacle at least ``margin`` from the body and the filter's barrier
``H >= 0`` on its first call. A violation is a contact, or a clearance below
``margin - tolerance`` (1 cm). (The start must also be recoverable: a robot that starts already
moving must get a first answer without slack; starting at rest always does.) Every worst case
is printed with a one-line reproduction::

    python -m benchmarks.falsify --episodes 2000 --seed 0 --json falsify.json
    python -m benchmarks.falsify --replay '{"robot": "m2wr", ...}'

Bases (the velocity ``w(t)`` within a period, from the period's start ``w0`` to the
command ``u``): ``instant`` (``w = u``), ``ramp`` (linear from ``w0`` to ``u`` over the
period), ``ramp_limit`` (towards ``u`` at the acceleration limits, then held), ``lag``
(first order, ``w = u + (w0 - u) exp(-t / tau)``, ``tau = dt``). Without odometry
(``velocity`` not given to the filter) only the instant base is inside the assumptions.
With ``--odometry`` every cell given the velocity is searched again with the odometry pose
given too (``pose=``, as the ROS nodes pass it), in a frame of its own far from the origin and
turned so that the heading crosses the wrap at ``+-pi`` as the robot turns. With ``--latencies``
the cells are searched again with every scan that old: taken where the robot was that long
before the call, stamped then, and the filter told the time (``now``), as a ROS driver's scans
arrive. With ``--sweeps`` they are searched again with a turning lidar: every beam measured at its own time within the
lidar's ``scan_time``, from where the robot was then, the last one when the scan is taken, stamped with the first
one's time (``stated``: ``time_increment`` given, as ``sensor_msgs/LaserScan`` defines it; ``unstated``: given as 0,
as from a driver that does not state it, outside the guarantee). With ``--call-periods`` they are searched again with
the filter called every that many ``dt``, told the time: below 1 early calls (a node triggered by a faster lidar; each
command held shorter than planned), above 1 late calls it must plan for (an overloaded machine). The CBF and the MPC
run without their compute budgets, so that the same seed gives the same report on any machine under any load;
``--real-time`` keeps them (a call preempted past its budget then brakes or follows its last plan, as on a robot, and
the report depends on the load).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import functools
import itertools
import json
import math
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1]))

from benchmarks.common import SHIPPED, add_real_time_option, opt_in_settings, run_cli, where
from safenav._checks import argument_type, number
from safenav._optional import require
from safenav.errors import InvalidConfig
from safenav.experiments.runner import JobRunner, Progress, add_sweep_options, reproducible_settings, sweep_settings
from safenav.filters import filter_settings, make_filter, unescaped
from safenav.filters.body import BodyModel
from safenav.filters.mpc.config import REFERENCES
from safenav.filters.perception import START_BLIND_CLEARANCE
from safenav.geometry import Pose2D, unicycle_rollout, unicycle_step, wrap_angle
from safenav.robot import LidarSpec, RobotSpec, preset
from safenav.scan import LaserScan
from safenav.synthetic import Circle, Scene, Segment, cast

__all__ = [
    "BASES",
    "NOMINALS",
    "Episode",
    "Outcome",
    "run",
    "search",
]

BASES = ("instant", "ramp", "ramp_limit", "lag")
#: A turning lidar's sweeps (:attr:`Episode.sweep`).
SWEEPS = ("stated", "unstated")
"""Models of the base's velocity loop (see the module docstring)."""
NOMINALS = ("arc", "bang_bang", "aim_nearest", "spin_then_go", "reverse", "shuttle", "script", "goal")
"""Nominal policies an episode can use (``script`` replays a fixed command sequence, ``goal`` drives
to a point with safenav's go-to-goal policy)."""
SEARCHED_NOMINALS = NOMINALS[:-2]
"""Nominal policies the search drives the filter with."""
SUBSTEPS = 20
"""Exact unicycle sub-steps per control period."""
TOLERANCE = 0.01
"""A clearance below ``margin - TOLERANCE`` [m] counts as a violation."""


# ---------------------------------------------------------------------------------------------- episodes


@dataclass(frozen=True)
class Episode:
    """One adversarial episode: everything needed to replay it exactly.

    Attributes:
        robot: a preset's name, or a robot of your own as its fields (:meth:`RobotSpec.to_dict`).
        filter: filter name (``"cbf"``, ``"mpc"``).
        base: base model (one of :data:`BASES`).
        dt: control period [s].
        give_velocity: pass the measured velocity to the filter (odometry).
        latency: how old every scan is when the filter gets it [s]: taken where the robot was then (before the
            start, where a robot that had held the start velocity was), stamped then; the filter is told ``now``.
        odometry_frame: ``(x [m], y [m], yaw [rad])`` of the start pose in the odometry frame whose pose
            the filter is given (``pose=``, exact; its yaw wrapped into ``[-pi, pi)``); empty: no pose.
        circles: ``(x, y, radius)`` poles in the start pose's base frame [m].
        segments: ``(x0, y0, x1, y1)`` walls in the start pose's base frame [m].
        nominal: one of :data:`NOMINALS`.
        params: the nominal's parameters (see :func:`nominal_policy`).
        velocity: the base's velocity at the start ``(v [m/s], omega [rad/s])``.
        duration: simulated time [s].
        noise: range noise, uniform within ``+- noise`` [m] (inside the filters' ``2 noise_std``).
        seed: seed of the range noise.
        settings: filter settings passed to :func:`safenav.filters.make_filter`.
        period: how long each command is really held [s] (default ``dt``); the filter is told
            the time (``now``), so a longer period is a late call it must plan for.
        sweep: ``""``: the lidar takes every beam at once; ``"stated"``: it turns, beam ``i`` measured ``i
            time_increment`` after the first (``time_increment = scan_time / n_beams``), the last one when the scan is
            taken, the stamp the first one's time; ``"unstated"``: the same beams with ``time_increment`` given as 0
            (a driver that does not state it: outside the guarantee).
        escape: wrap the filter in :class:`~safenav.filters.escape.Escape`.
        passage: ``(period, duty)``: the adversary sets the filter's ``passage`` flag (the CBF's
            narrow look-ahead) for the first ``duty`` share of every ``period`` [s]; empty: never.
            With a ``narrow_body`` in the settings it sets ``narrow`` with it (as the escape does in a
            gap). The guarantee holds whatever a caller does with the flags. Not with ``escape`` (the
            escape sets them itself).
    """

    robot: str | dict[str, Any]
    filter: str
    base: str
    dt: float
    give_velocity: bool = True
    odometry_frame: tuple[float, ...] = ()
    latency: float = 0.0
    circles: tuple[tuple[float, float, float], ...] = ()
    segments: tuple[tuple[float, float, float, float], ...] = ()
    nominal: str = "arc"
    params: tuple[float, ...] = (0.5, 0.0)
    velocity: tuple[float, float] = (0.0, 0.0)
    duration: float = 4.0
    noise: float = 0.0
    seed: int = 0
    settings: dict[str, Any] = field(default_factory=dict)
    period: float | None = None
    sweep: str = ""
    escape: bool = False
    passage: tuple[float, ...] = ()

    def to_json(self) -> str:
        """One line that :func:`Episode.from_json` (and ``--replay``) turns back into this episode."""
        return json.dumps(dataclasses.asdict(self), separators=(",", ":"))

    @classmethod
    def from_json(cls, text: str) -> Episode:
        data = json.loads(text)
        for name in ("circles", "segments"):
            if name in data:
                data[name] = tuple(tuple(item) for item in data[name])
        for name in ("params", "velocity", "passage", "odometry_frame"):
            if name in data:
                data[name] = tuple(data[name])
        return cls(**data)

    def scene(self) -> Scene:
        return Scene(tuple(Segment((a, b), (c, d)) for a, b, c, d in self.segments),
                     tuple(Circle((x, y), r) for x, y, r in self.circles))


@dataclass(frozen=True)
class Outcome:
    """What happened in an :class:`Episode` (truth from the falsifier's own simulator).

    Attributes:
        min_clearance: smallest distance from the body disk to an obstacle over every sub-step [m].
        margin: the filter's margin [m].
        start_barrier: the filter's ``min_barrier`` on its first call [m].
        min_barrier: smallest ``min_barrier`` the filter reported [m].
        contact: the body touched an obstacle.
        violation_step: first period whose sub-steps went below ``margin - TOLERANCE`` (``None`` if none).
        statuses: periods per filter status.
        steps: periods simulated.
    """

    min_clearance: float
    margin: float
    start_barrier: float
    min_barrier: float
    contact: bool
    violation_step: int | None
    statuses: dict[str, int]
    steps: int

    hidden_at_start: bool = False
    start_status: str = "ok"
    deadlock_time: float = 0.0
    escape_steps: int = 0
    goal_distance: float | None = None

    @property
    def valid(self) -> bool:
        """The episode started inside the assumptions: clearance >= margin, barrier >= 0, a first answer
        that needs no slack (a robot already moving can still stop: starting at rest always can), and
        nothing hidden within ``START_BLIND_CLEARANCE`` of the body outside every field of view."""
        return self.start_barrier >= 0.0 and not self.hidden_at_start and self.start_status in ("ok", "late")

    @property
    def violated(self) -> bool:
        return self.valid and (self.contact or self.min_clearance < self.margin - TOLERANCE)

    @property
    def objective(self) -> float:
        """What the search minimises: clearance beyond the margin [m] (large when invalid)."""
        if not self.valid:
            return 1.0 - min(self.start_barrier, 0.0) + float(self.hidden_at_start)
        return self.min_clearance - self.margin


def robot_spec(robot: str | Mapping[str, Any]) -> RobotSpec:
    """The robot of an episode or a cell: a preset's name, or a robot's fields (:meth:`RobotSpec.to_dict`)."""
    return preset(robot) if isinstance(robot, str) else RobotSpec.from_dict(robot)


def robot_name(robot: str | Mapping[str, Any]) -> str:
    """A preset's name, or the ``name`` of a robot given by its fields."""
    return robot if isinstance(robot, str) else str(robot.get("name", "robot"))


def load_robots(paths: Sequence[str]) -> list[dict[str, Any]]:
    """Robots of your own from JSON files, each a robot's fields (:meth:`RobotSpec.to_dict`) or a list of them.

    Raises:
        InvalidConfig: a file does not describe robots (the message names the file and the field).
    """
    robots = []
    for path in paths:
        with open(path) as handle:
            data = json.load(handle)
        for item in data if isinstance(data, list) else [data]:
            try:
                RobotSpec.from_dict(item)
            except InvalidConfig as error:
                raise InvalidConfig(f"{path}: {error}") from None
            robots.append(dict(item))
    return robots


def hidden_at_start(robot: RobotSpec, scene: Scene, margin: float) -> bool:
    """Whether some obstacle lies within ``START_BLIND_CLEARANCE`` of the body (disk) at the start pose in
    a direction outside the lidar's field of view (occlusion does not count: the filters must handle it)."""
    reach = robot.radius + margin + START_BLIND_CLEARANCE
    samples = []
    for (x, y), radius in ((c.center, c.radius) for c in scene.circles):
        angles = np.linspace(0.0, 2.0 * math.pi, 181)
        samples.append(np.column_stack((x + radius * np.cos(angles), y + radius * np.sin(angles))))
    for segment in scene.segments:
        t = np.linspace(0.0, 1.0, 801)[:, None]
        samples.append(np.asarray(segment.start) + t * (np.asarray(segment.end) - np.asarray(segment.start)))
    if not samples:
        return False
    points = np.vstack(samples)
    points = points[np.hypot(points[:, 0], points[:, 1]) <= reach]
    if points.shape[0] == 0:
        return False
    lidar = robot.lidar
    mount = lidar.mount
    bearing = np.arctan2(points[:, 1] - mount.y, points[:, 0] - mount.x) - mount.yaw
    offset = np.mod(bearing - lidar.angle_min + 0.5 * lidar.angle_increment, 2.0 * math.pi)
    inside = offset <= (lidar.angle_max - lidar.angle_min) + lidar.angle_increment
    return bool(np.any(~inside))


def nominal_policy(episode: Episode, robot: RobotSpec) -> Callable[[float, LaserScan, Pose2D], np.ndarray]:
    """The nominal ``(t, scan, pose) -> (v, omega)`` of an episode.

    ``arc`` (v, omega): constant. ``bang_bang`` (v, omega, period): omega changes sign every
    ``period`` [s]. ``aim_nearest`` (v, gain): full speed at the nearest scan point, turning
    towards it. ``spin_then_go`` (omega, t_spin, v): spin for ``t_spin`` [s], then drive.
    ``reverse`` (v, omega): like ``arc`` (``v`` may be negative). ``shuttle`` (v_1, omega_1, t, v_2, omega_2):
    ``(v_1, omega_1)`` until ``t`` [s], then ``(v_2, omega_2)`` (forward, then back into space the lidar of a
    robot blind behind saw only on the way out). ``script`` (t_1, v_1, omega_1,
    t_2, v_2, omega_2, ...): ``(v_i, omega_i)`` until ``t_i`` [s], the last one after. ``goal``
    (x, y): :class:`~safenav.reference.GoToGoal` to that point of the start frame, with the true pose.
    """
    p = episode.params
    kind = episode.nominal
    if kind in ("arc", "reverse"):
        command = np.array([p[0], p[1]])
        return lambda t, scan, pose: command
    if kind == "shuttle":
        out, back = np.array([p[0], p[1]]), np.array([p[3], p[4]])
        return lambda t, scan, pose: out if t < p[2] else back
    if kind == "bang_bang":
        return lambda t, scan, pose: np.array([p[0], p[1] * (1.0 if int(t / max(p[2], 1e-3)) % 2 == 0 else -1.0)])
    if kind == "script":
        table = np.asarray(p, dtype=float).reshape(-1, 3)

        def script(t: float, scan: LaserScan, pose: Pose2D) -> np.ndarray:
            row = int(np.searchsorted(table[:, 0], t, side="right"))
            return table[min(row, len(table) - 1), 1:].copy()
        return script
    if kind == "goal":
        from safenav.reference import GoToGoal

        policy = GoToGoal(robot, goal=(p[0], p[1]))
        return lambda t, scan, pose: np.asarray(policy(scan, pose), dtype=float)
    if kind == "spin_then_go":
        return lambda t, scan, pose: np.array([0.0, p[0]]) if t < p[1] else np.array([p[2], 0.0])
    if kind == "aim_nearest":
        def aim(t: float, scan: LaserScan, pose: Pose2D) -> np.ndarray:
            points = scan.points()
            if len(points) == 0:
                return np.array([p[0], 0.0])
            nearest = points[np.argmin(np.hypot(points[:, 0], points[:, 1]))]
            return np.array([p[0], p[1] * math.atan2(nearest[1], nearest[0])])
        return aim
    raise ValueError(f"unknown nominal {kind!r}; expected one of {NOMINALS}")


def _velocity_profile(base: str, start: np.ndarray, command: np.ndarray, robot: RobotSpec, dt: float,
                      time_constant: float | None = None) -> np.ndarray:
    """The base's velocity at the middle of each of the :data:`SUBSTEPS` sub-steps, ``(SUBSTEPS + 1, 2)``.

    Row ``k < SUBSTEPS`` is the mean velocity over sub-step ``k`` (exact for every model, so the
    pose integrates exactly up to the arc within a sub-step); the last row is the end velocity.
    """
    h = dt / SUBSTEPS
    edges = np.arange(SUBSTEPS + 1) * h
    if base == "instant":
        rows = np.tile(command, (SUBSTEPS + 1, 1))
        return rows
    if base == "ramp":
        velocity = start + (command - start) * (edges / dt)[:, None]
        means = 0.5 * (velocity[:-1] + velocity[1:])
        return np.vstack((means, velocity[-1]))
    if base == "ramp_limit":
        rate = np.array([robot.a_max, robot.alpha_max])
        change = command - start
        reach = np.minimum(np.abs(change), rate * edges[:, None]) * np.sign(change)
        velocity = start + reach
        # The mean over a sub-step of a clipped ramp: integrate exactly (piecewise linear in time).
        means = np.empty((SUBSTEPS, 2))
        for axis in range(2):
            done = np.abs(change[axis]) / rate[axis]     # time at which the command is reached
            a, b = edges[:-1], edges[1:]
            split = np.clip(done, a, b)
            sign = math.copysign(1.0, change[axis]) if change[axis] else 0.0
            ramp_part = (start[axis] * (split - a) + sign * rate[axis] * 0.5 * (split**2 - a**2))
            hold_part = command[axis] * (b - split)
            means[:, axis] = (ramp_part + hold_part) / h
        return np.vstack((means, velocity[-1]))
    if base == "lag":
        tau = dt if time_constant is None else time_constant
        decay = np.exp(-edges / tau)
        velocity = command + (start - command) * decay[:, None]
        # Mean over [a, b] of u + (w0 - u) e^{-t/tau}: u + (w0 - u) tau (e^{-a/tau} - e^{-b/tau}) / h.
        means = command + (start - command) * (tau * (decay[:-1] - decay[1:]) / h)[:, None]
        return np.vstack((means, velocity[-1]))
    raise ValueError(f"unknown base {base!r}; expected one of {BASES}")


def _scan(robot: RobotSpec, scene: Scene, pose: Pose2D, noise: float, rng: np.random.Generator,
          stamp: float) -> LaserScan:
    lidar = robot.lidar
    template = lidar.scan()
    sensor = pose.compose(lidar.mount)
    ranges = cast((sensor.x, sensor.y), template.angles + sensor.yaw, scene)
    return template.with_ranges(_reported(ranges, lidar, noise, rng), stamp=stamp)


def _reported(ranges: np.ndarray, lidar: LidarSpec, noise: float, rng: np.random.Generator) -> np.ndarray:
    """Exact distances [m] as the lidar reports them: uniform noise within ``+- noise`` on every hit, ``+inf`` beyond
    ``range_max``, ``-inf`` nearer than ``range_min``."""
    finite = np.isfinite(ranges)
    if noise > 0.0:
        ranges[finite] += rng.uniform(-noise, noise, int(finite.sum()))
    ranges[ranges > lidar.range_max] = math.inf
    ranges[ranges < lidar.range_min] = -math.inf
    return ranges


def _swept_scan(robot: RobotSpec, scene: Scene, poses_at: Callable[[np.ndarray], np.ndarray], taken: float,
                noise: float, rng: np.random.Generator, *, stated: bool) -> LaserScan:
    """A turning lidar's scan whose last beam is measured at ``taken`` [s], each beam from where the robot was then
    (``poses_at``: the base poses ``(n, 3)`` at an array of times; as :func:`safenav.synthetic.swept_scan`, whose
    lidar turns once per ``scan_time``), with the range noise of :func:`_scan`; ``stated``: its ``time_increment``
    given (else 0, as from a driver that does not state it)."""
    lidar = robot.lidar
    step = lidar.scan_time / lidar.n_beams
    first = taken - (lidar.n_beams - 1) * step
    template = lidar.scan().replace(time_increment=step if stated else 0.0, scan_time=lidar.scan_time)
    base = poses_at(first + step * np.arange(lidar.n_beams))
    mount = lidar.mount
    cos_yaw, sin_yaw = np.cos(base[:, 2]), np.sin(base[:, 2])
    origins = np.column_stack((base[:, 0] + cos_yaw * mount.x - sin_yaw * mount.y,
                               base[:, 1] + sin_yaw * mount.x + cos_yaw * mount.y))
    ranges = cast(origins, template.angles + base[:, 2] + mount.yaw, scene)
    return template.with_ranges(_reported(ranges, lidar, noise, rng), stamp=first)


def _arcs(start: np.ndarray, velocity: np.ndarray, spans: np.ndarray) -> np.ndarray:
    """The poses ``(n, 3)`` after holding each ``velocity`` ``(n, 2)`` for ``spans`` ``(n,)`` [s] from each ``start``
    ``(n, 3)``: :func:`safenav.geometry.unicycle_step` of arrays (the yaw not wrapped)."""
    half = 0.5 * velocity[:, 1] * spans
    chord = velocity[:, 0] * spans * np.sinc(half / math.pi)
    heading = start[:, 2] + half
    return np.column_stack((start[:, 0] + chord * np.cos(heading), start[:, 1] + chord * np.sin(heading),
                            start[:, 2] + velocity[:, 1] * spans))


def _clearances(scene: Scene, centres: np.ndarray, radius: float) -> np.ndarray:
    """Distance from a disk of ``radius`` at each of ``centres`` ``(K, 2)`` to the nearest item [m]."""
    best = np.full(centres.shape[0], math.inf)
    segments = scene._segment_array
    if segments.size:
        a, b = segments[:, :2], segments[:, 2:]
        ab = b - a
        length2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300)
        relative = centres[:, None, :] - a[None]
        t = np.clip(np.einsum("kij,ij->ki", relative, ab) / length2, 0.0, 1.0)
        nearest = a[None] + t[..., None] * ab[None]
        best = np.minimum(best, np.min(np.hypot(*(centres[:, None, :] - nearest).transpose(2, 0, 1)), axis=1))
    circles = scene._circle_array
    if circles.size:
        gaps = np.hypot(centres[:, None, 0] - circles[None, :, 0], centres[:, None, 1] - circles[None, :, 1])
        best = np.minimum(best, np.min(gaps - circles[None, :, 2], axis=1))
    return best - radius


def _segment_distances(a0: np.ndarray, a1: np.ndarray, b0: np.ndarray, b1: np.ndarray) -> np.ndarray:
    """Distances between segments ``a0 a1`` and ``b0 b1`` (broadcast over leading axes) [m]; 0 when they cross."""

    def point_to_segment(p: np.ndarray, s0: np.ndarray, s1: np.ndarray) -> np.ndarray:
        d = s1 - s0
        t = np.clip(np.sum((p - s0) * d, axis=-1) / np.maximum(np.sum(d * d, axis=-1), 1e-300), 0.0, 1.0)
        return np.hypot(*np.moveaxis(p - (s0 + t[..., None] * d), -1, 0))

    def cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]

    da, db = a1 - a0, b1 - b0
    d1, d2 = cross(db, a0 - b0), cross(db, a1 - b0)
    d3, d4 = cross(da, b0 - a0), cross(da, b1 - a0)
    crossing = (d1 * d2 < 0.0) & (d3 * d4 < 0.0)
    distance = np.minimum(np.minimum(point_to_segment(a0, b0, b1), point_to_segment(a1, b0, b1)),
                          np.minimum(point_to_segment(b0, a0, a1), point_to_segment(b1, a0, a1)))
    return np.where(crossing, 0.0, distance)


def _footprint_clearances(scene: Scene, poses: np.ndarray, footprint: np.ndarray) -> np.ndarray:
    """Distance from the footprint polygon at each pose ``(K, 3)`` to the nearest item [m] (negative: overlap)."""
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    corners = np.stack((poses[:, None, 0] + c[:, None] * footprint[None, :, 0] - s[:, None] * footprint[None, :, 1],
                        poses[:, None, 1] + s[:, None] * footprint[None, :, 0] + c[:, None] * footprint[None, :, 1]),
                       axis=-1)                                          # (K, V, 2)
    edges0, edges1 = corners, np.roll(corners, -1, axis=1)
    best = np.full(poses.shape[0], math.inf)
    segments = scene._segment_array
    if segments.size:
        gaps = _segment_distances(edges0[:, :, None, :], edges1[:, :, None, :], segments[None, None, :, :2],
                                  segments[None, None, :, 2:])
        best = np.minimum(best, gaps.min(axis=(1, 2)))
    circles = scene._circle_array
    if circles.size:
        centres = circles[None, None, :, :2]
        gaps = _segment_distances(edges0[:, :, None, :], edges1[:, :, None, :], centres, centres)
        best = np.minimum(best, (gaps - circles[None, None, :, 2]).min(axis=(1, 2)))
    # A centre or a segment end inside the polygon is an overlap the edge distances miss.
    inside = np.zeros(poses.shape[0], dtype=bool)
    for x, y in ([*circles[:, :2].tolist(), *segments[:, :2].tolist(), *segments[:, 2:].tolist()]):
        local_x = c * (x - poses[:, 0]) + s * (y - poses[:, 1])
        local_y = -s * (x - poses[:, 0]) + c * (y - poses[:, 1])
        low, high = footprint.min(axis=0), footprint.max(axis=0)
        inside |= (local_x > low[0]) & (local_x < high[0]) & (local_y > low[1]) & (local_y < high[1])
    return np.where(inside, np.minimum(best, 0.0) - 1e-3, best)


def run(episode: Episode, *, record: bool = False) -> tuple[Outcome, list[dict[str, Any]]]:
    """Simulate ``episode``; returns its outcome and, with ``record``, one dict per period."""
    robot = robot_spec(episode.robot)
    dt = episode.dt
    safety = make_filter(episode.filter, robot, dt, **episode.settings)
    if episode.escape:
        from safenav.filters.escape import Escape

        safety = Escape(safety)
    # A narrow body (the CBF's default cover of the footprint) is used when its flag is set: by an escape, or by
    # the adversary when the settings name it. The guarantee is then the footprint's.
    inner = getattr(safety, "inner", safety)
    narrow = getattr(getattr(inner, "config", None), "narrow_body", None) is not None and (
        inner is not safety or "narrow_body" in episode.settings)
    margin = float(safety.margin)
    deadlock_time = 0.0
    escape_steps = 0
    scene = episode.scene()
    policy = nominal_policy(episode, robot)
    rng = np.random.default_rng(episode.seed)
    pose = Pose2D()
    frame = Pose2D(*episode.odometry_frame) if episode.odometry_frame else Pose2D()
    velocity = np.clip(np.asarray(episode.velocity, dtype=float), robot.lower, robot.upper)
    radius = robot.radius
    footprint = None
    if (episode.settings.get("body") in ("cover", "polygon") or narrow) and robot.footprint is not None:
        footprint = np.asarray(robot.footprint, dtype=float)   # the guarantee is then for the footprint

    def truth(poses: np.ndarray) -> np.ndarray:
        if footprint is None:
            return _clearances(scene, poses[:, :2], radius)
        return _footprint_clearances(scene, poses, footprint)

    min_clearance = float(truth(np.zeros((1, 3)))[0])
    contact = min_clearance < 0.0
    violation_step = None
    statuses: dict[str, int] = {}
    start_barrier = math.nan
    start_status = ""
    min_barrier = math.inf
    log: list[dict[str, Any]] = []
    period = episode.period if episode.period is not None else dt
    steps = round(episode.duration / period)
    h = period / SUBSTEPS
    clearance = min_clearance
    # Every sub-step's start pose and velocity, for where the robot was when a late scan was taken.
    path_poses: list[Pose2D] = []
    path_velocities: list[np.ndarray] = []
    path_blocks: list[np.ndarray] = []         # the same, a period's sub-steps per array (a turning lidar's scans)
    velocity_blocks: list[np.ndarray] = []
    velocity_start = velocity.copy()

    def pose_at(time: float) -> Pose2D:
        if time <= 0.0:     # before the start the robot held the start velocity, and got to the start pose
            return unicycle_step(Pose2D(), -float(velocity_start[0]), -float(velocity_start[1]), -time)
        index = min(int(time / h), len(path_poses) - 1)
        held = path_velocities[index]
        return unicycle_step(path_poses[index], float(held[0]), float(held[1]), time - index * h)

    def poses_at(times: np.ndarray) -> np.ndarray:
        """:func:`pose_at` of every time at once, ``(n, 3)`` (a turning lidar's beams)."""
        start, held = np.zeros((times.size, 3)), np.empty((times.size, 2))
        spans = -times
        before = times <= 0.0
        held[before] = -velocity_start
        after = ~before
        if after.any():
            index = np.minimum((times[after] / h).astype(np.intp), len(path_blocks) * SUBSTEPS - 1)
            start[after] = np.concatenate(path_blocks)[index]
            held[after] = np.concatenate(velocity_blocks)[index]
            spans[after] = times[after] - index * h
        return _arcs(start, held, spans)

    for step in range(steps):
        t = step * period
        taken = t - episode.latency
        if episode.sweep:
            scan = _swept_scan(robot, scene, poses_at, taken, episode.noise, rng, stated=episode.sweep == "stated")
        else:
            scan = _scan(robot, scene, pose if taken >= t else pose_at(taken), episode.noise, rng, taken)
        u_nom = policy(t, scan, pose)
        if episode.passage and not episode.escape:
            passage_period, duty = episode.passage
            safety.passage = (t % passage_period) < duty * passage_period
            safety.narrow = safety.passage and narrow
        odometry = None
        if episode.odometry_frame:
            odometry = frame.compose(pose)
            odometry = (odometry.x, odometry.y, float(wrap_angle(odometry.yaw)))
        result = safety.filter(u_nom, scan, velocity=velocity if episode.give_velocity else None, now=t,
                               pose=odometry)
        if step == 0:
            start_barrier = min(result.min_barrier, min_clearance - margin)
            start_status = result.status.value
        min_barrier = min(min_barrier, result.min_barrier)
        statuses[result.status.value] = statuses.get(result.status.value, 0) + 1
        if result.deadlock is not None:
            deadlock_time = max(deadlock_time, result.deadlock.time)
        escape_steps += bool(result.escape)
        command = np.asarray(result.u, dtype=float)
        profile = _velocity_profile(episode.base, velocity, command, robot, period, time_constant=dt)
        poses = unicycle_rollout(pose, profile[:SUBSTEPS], h)
        if episode.latency > 0.0:
            path_poses.extend(Pose2D(*row) for row in poses[:-1])
            path_velocities.extend(profile[:SUBSTEPS])
        if episode.sweep:
            path_blocks.append(poses[:-1])
            velocity_blocks.append(profile[:SUBSTEPS])
        pose = Pose2D(float(poses[-1, 0]), float(poses[-1, 1]), float(wrap_angle(poses[-1, 2])))
        clearances = truth(poses[1:])
        clearance = float(clearances[-1])
        lowest = float(clearances.min())
        min_clearance = min(min_clearance, lowest)
        contact = contact or lowest < 0.0
        if violation_step is None and lowest < margin - TOLERANCE:
            violation_step = step
        velocity = profile[-1].copy()
        if record:
            log.append(dict(step=step, t=t, u_nom=np.asarray(u_nom, dtype=float).tolist(), u=command.tolist(),
                            status=result.status.value, message=result.message, min_barrier=result.min_barrier,
                            escape=result.escape, deadlock=None if result.deadlock is None else result.deadlock.time,
                            clearance=clearance, pose=(pose.x, pose.y, wrap_angle(pose.yaw)),
                            velocity=velocity.tolist()))
        if contact and not record:
            break
    goal_distance = None
    if episode.nominal == "goal":
        goal_distance = math.hypot(episode.params[0] - pose.x, episode.params[1] - pose.y)
    outcome = Outcome(min_clearance, margin, float(start_barrier), float(min_barrier), contact, violation_step,
                      statuses, step + 1, hidden_at_start(robot, scene, margin), start_status, deadlock_time,
                      escape_steps, goal_distance)
    return outcome, log


# ---------------------------------------------------------------------------------------------- search space


def _unit(x: np.ndarray, i: int) -> float:
    """Coordinate ``i`` folded into [0, 1] (CMA-ES searches an unbounded space)."""
    value = x[i] % 2.0
    return float(value if value <= 1.0 else 2.0 - value)


GEOMETRIES = ("poles", "wall", "door", "poles_and_wall")
"""Obstacle layouts the search places around the start pose."""
N_COORDINATES = 20


def _pick(unit: float, options: Sequence[str]) -> str:
    return options[min(int(unit * len(options)), len(options) - 1)]


WALL_THICKNESS = 0.05
"""Walls are boxes this thick [m]: a wall of no thickness seen edge-on is narrower than any beam gap, which
the guarantee does not cover (A2, docs/safety.md); real walls are not."""


def _thick(start: tuple[float, float], end: tuple[float, float], normal: float
           ) -> list[tuple[float, float, float, float]]:
    """The four sides of a wall from ``start`` to ``end`` [m], ``WALL_THICKNESS`` thick away from the origin."""
    start_point, end_point = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
    offset = WALL_THICKNESS * np.array([math.cos(normal), math.sin(normal)])
    if np.dot(offset, 0.5 * (start_point + end_point)) < 0.0:
        offset = -offset     # thicken away from the robot, so the face it sees stays where it was drawn
    corners = [start_point, end_point, end_point + offset, start_point + offset]
    return [(*corners[i], *corners[(i + 1) % 4]) for i in range(4)]


def decode(x: np.ndarray, *, robot: str | dict[str, Any], filter_name: str, base: str, dt: float, give_velocity: bool,
           geometry: str | Sequence[str], nominal: str | Sequence[str], margin: float,
           settings: dict[str, Any] | None = None, give_pose: bool = False, latency: float = 0.0,
           call_period: float = 1.0, sweep: str = "") -> Episode:
    """Map a search vector (any reals; folded into [0, 1]) to an episode starting clear of every obstacle.

    ``geometry`` and ``nominal`` are either one name, or several among which coordinates 16
    and 17 of the vector choose (so one search covers them all). With ``give_pose`` the filter is
    given the odometry pose too, in a frame whose origin is up to 1 km from the start along each axis and whose
    heading starts within
    0.3 rad of the wrap at ``+-pi`` (coordinates 9-11, which also shape the door). ``latency``: every scan's age
    [s] (:attr:`Episode.latency`). ``call_period``: the filter is called every that many ``dt``
    (:attr:`Episode.period`). ``sweep``: :attr:`Episode.sweep`.
    """
    spec = robot_spec(robot)
    R = spec.radius
    u = [_unit(x, i) for i in range(N_COORDINATES)]
    if not isinstance(geometry, str):
        geometry = _pick(u[16], geometry)
    if not isinstance(nominal, str):
        nominal = _pick(u[17], nominal)
    keep_out = R + margin + 1e-3
    circles: list[tuple[float, float, float]] = []
    segments: list[tuple[float, float, float, float]] = []
    settings = dict(settings or {})
    if base == "lag":   # the guarantee covers a lagging base the filter is told about
        settings.setdefault("time_constant", dt)
    reach, smallest = sighting(robot, filter_name, dt, settings)

    def pole(distance_unit: float, bearing_unit: float, radius_unit: float) -> tuple[float, float, float]:
        # Thin poles just wider than the narrowest obstacle the filter claims to see in time (A2: the beam gap
        # 1 m away, or where the robot must see it to brake), up to 10 cm wider; out to 1.5 m, or as far as
        # that reach (a thin pole between two beams far ahead comes into view only near).
        radius = 0.5 * smallest + radius_unit * 0.1
        distance = keep_out + radius + distance_unit * max(1.5, reach)
        bearing = (bearing_unit * 2.0 - 1.0) * math.pi
        return (distance * math.cos(bearing), distance * math.sin(bearing), radius)

    if geometry in ("poles", "poles_and_wall"):
        circles.append(pole(u[0], u[1], u[2]))
        circles.append(pole(u[3], u[4], u[5]))
    if geometry in ("wall", "poles_and_wall"):
        # A long wall at a shallow or steep angle, its nearest point outside the margin.
        distance = keep_out + u[6] * 1.5
        normal = (u[7] * 2.0 - 1.0) * math.pi
        tangent = normal + 0.5 * math.pi
        cx, cy = distance * math.cos(normal), distance * math.sin(normal)
        tx, ty = 4.0 * math.cos(tangent), 4.0 * math.sin(tangent)
        segments.extend(_thick((cx - tx, cy - ty), (cx + tx, cy + ty), normal))
    if geometry == "door":
        # A wall with one door across the heading, its gap a little wider than the body needs.
        distance = keep_out + u[6] * 1.2
        angle = (u[7] - 0.5) * 0.8 * math.pi
        # (narrower than the disk needs when the filter has a narrower body for gaps: a door only it fits)
        half = R if not settings.get("narrow_body") else body_half_width(spec, settings["narrow_body"])
        width = 2.0 * (half + margin) + 0.02 + u[8] * 0.3
        offset = (u[9] - 0.5) * 0.4
        c, s = math.cos(angle), math.sin(angle)
        along = np.array([-s, c])
        centre = np.array([distance * c, distance * s]) + offset * along
        for sign in (-1.0, 1.0):
            near = centre + sign * 0.5 * width * along
            far = centre + sign * 4.0 * along
            segments.extend(_thick(tuple(near), tuple(far), angle))
        if u[10] > 0.5:   # a back wall behind the door
            back = centre + (0.4 + u[11]) * np.array([c, s])
            segments.extend(_thick(tuple(back - 3.0 * along), tuple(back + 3.0 * along), angle))
    v_scale = max(spec.v_max, -spec.v_min)
    if nominal == "arc":
        params: tuple[float, ...] = (spec.v_max * (0.2 + 0.8 * u[12]), spec.omega_max * (2.0 * u[13] - 1.0))
    elif nominal == "bang_bang":
        params = (spec.v_max * (0.2 + 0.8 * u[12]), spec.omega_max * (2.0 * u[13] - 1.0), 0.1 + 1.5 * u[14])
    elif nominal == "aim_nearest":
        params = (spec.v_max * (0.3 + 0.7 * u[12]), 0.5 + 4.0 * u[13])
    elif nominal == "spin_then_go":
        params = (spec.omega_max * (2.0 * u[13] - 1.0), 2.0 * u[14], spec.v_max * (0.2 + 0.8 * u[12]))
    elif nominal == "reverse":
        params = (spec.v_min * (0.2 + 0.8 * u[12]), spec.omega_max * (2.0 * u[13] - 1.0))
    elif nominal == "shuttle":
        params = (spec.v_max * (0.3 + 0.7 * u[12]), 0.3 * spec.omega_max * (2.0 * u[13] - 1.0), 0.5 + 2.5 * u[14],
                  spec.v_min * (0.5 + 0.5 * u[12]), spec.omega_max * (2.0 * u[13] - 1.0))
    else:
        raise ValueError(f"unknown nominal {nominal!r}")
    start_velocity = (0.0, 0.0)
    if give_velocity and u[15] > 0.5:   # start already moving, at up to half the limits
        start_velocity = ((u[15] - 0.5) * v_scale, (u[14] - 0.5) * spec.omega_max)
    # The filter's passage flag (the CBF's narrow look-ahead), switched by the adversary: never, or for a
    # share of every period of 0.05-2 s.
    passage = () if u[18] < 0.25 else (0.05 + 1.95 * u[19], (u[18] - 0.25) / 0.75)
    odometry_frame: tuple[float, ...] = ()
    if give_pose:
        odometry_frame = (2000.0 * (u[9] - 0.5), 2000.0 * (u[11] - 0.5),
                          (math.pi - 0.3 * u[10]) * (1.0 if u[10] > 0.5 else -1.0))
    return Episode(robot=robot, filter=filter_name, base=base, dt=dt, give_velocity=give_velocity,
                   odometry_frame=odometry_frame, latency=latency, sweep=sweep,
                   period=None if call_period == 1.0 else call_period * dt,
                   circles=tuple(circles), segments=tuple(segments), nominal=nominal, params=params,
                   velocity=start_velocity, duration=4.0, noise=spec.lidar.noise_std,
                   seed=int(1e6 * u[0]) % 10_000, settings=settings, passage=passage)


@dataclass(frozen=True)
class Found:
    """One evaluated episode of the search."""

    episode: Episode
    outcome: Outcome


def evaluate(episode: Episode) -> Outcome:
    """Simulate one episode of a search (a job for the process pool or Ray)."""
    return run(episode)[0]


def _search_value(outcome: Outcome) -> float:
    """What CMA-ES is told: the objective, tie-broken on the filter's own barrier so the search moves
    towards trouble even without contact."""
    return outcome.objective + 0.1 * max(min(outcome.min_barrier, 1.0), -1.0)


class CellSearch:
    """The search of one cell, a generation at a time: :meth:`ask` for episodes, :meth:`tell` their outcomes.

    The episodes asked depend only on the seed and on the outcomes told, so a search whose
    generations run on a process pool, on Ray or in this process, or resume from a results file,
    asks the same episodes and finds the same worst case.

    Args:
        cell: keyword arguments of :func:`decode` other than the vector and the margin.
        episodes: episodes to spend in this cell.
        seed: seed of the random starts and of CMA-ES.
        margin: the filter's margin [m] (the decoder keeps every obstacle outside it).
        optimiser: ``"cma"`` (CMA-ES restarted from seeded random points) or ``"random"`` (a
            generation is up to 8 random points).
    """

    RANDOM_GENERATION = 8

    def __init__(self, cell: dict[str, Any], *, episodes: int, seed: int, margin: float,
                 optimiser: str = "cma") -> None:
        self.cell = cell
        self.episodes = episodes
        self.margin = margin
        self.optimiser = optimiser
        self.found: list[Found] = []
        self._rng = np.random.default_rng(seed)
        self._strategy: Any = None
        self._candidates: list[np.ndarray] = []
        self._numpy_state: Any = None
        if optimiser == "cma":
            self._cma = require("cma", extra="bench", purpose="the falsifier's CMA-ES search")

    @property
    def done(self) -> bool:
        """Every episode of the cell has been told."""
        return len(self.found) >= self.episodes

    def ask(self) -> list[Episode]:
        """The next generation's episodes."""
        if self.optimiser == "random":
            count = min(self.RANDOM_GENERATION, self.episodes - len(self.found))
            self._candidates = [self._rng.uniform(0.0, 1.0, N_COORDINATES) for _ in range(count)]
        else:
            with self._own_numpy_random():
                while self._strategy is None or self._strategy.stop():   # a restart from a new seeded point
                    budget = self.episodes - len(self.found)
                    start = self._rng.uniform(0.0, 1.0, N_COORDINATES)
                    options = {"seed": int(self._rng.integers(1, 2**31 - 1)), "maxfevals": budget, "verbose": -9,
                               "popsize": min(8, max(4, budget // 4))}
                    self._strategy = self._cma.CMAEvolutionStrategy(start, 0.3, options)
                self._candidates = self._strategy.ask()
        return [decode(np.asarray(x, dtype=float), margin=self.margin, **self.cell) for x in self._candidates]

    def tell(self, episodes: Sequence[Episode], outcomes: Sequence[Outcome]) -> None:
        """The outcomes of the episodes of the last :meth:`ask`, in its order."""
        self.found.extend(Found(episode, outcome) for episode, outcome in zip(episodes, outcomes, strict=True))
        if self._strategy is not None:
            with self._own_numpy_random():
                self._strategy.tell(self._candidates, [_search_value(outcome) for outcome in outcomes])

    @contextlib.contextmanager
    def _own_numpy_random(self) -> Iterator[None]:
        """CMA-ES draws from numpy's global generator, seeded when a strategy starts: searches that take
        turns (:func:`search_cells`) each keep their own state of it, as if each ran alone."""
        outside = np.random.get_state()
        if self._numpy_state is not None:
            np.random.set_state(self._numpy_state)
        try:
            yield
        finally:
            self._numpy_state = np.random.get_state()
            np.random.set_state(outside)


def search(cell: dict[str, Any], *, episodes: int, seed: int, margin: float,
           optimiser: str = "cma", runner: JobRunner | None = None) -> list[Found]:
    """Search one cell (robot, filter, base, dt, geometry, nominal) for the worst episode.

    Args:
        cell: keyword arguments of :func:`decode` other than the vector and the margin.
        episodes: episodes to spend in this cell.
        seed: seed of the random start and of CMA-ES.
        margin: the filter's margin [m] (the decoder keeps every obstacle outside it).
        optimiser: ``"cma"`` (CMA-ES restarted from seeded random points) or ``"random"``.
        runner: runs each generation's episodes (a process pool, Ray); in this process when ``None``.

    Returns:
        Every evaluated episode.
    """
    return search_cells([CellSearch(cell, episodes=episodes, seed=seed, margin=margin, optimiser=optimiser)],
                        runner)[0]


def search_cells(searches: Sequence[CellSearch], runner: JobRunner | None = None,
                 finished: Callable[[int, list[Found]], None] | None = None) -> list[list[Found]]:
    """Run every search to its end, in rounds: each round one generation of every unfinished search, all
    of them one batch of jobs (so a cluster gets cells x population episodes at a time).

    Args:
        searches: the searches.
        runner: runs each round's episodes; in this process when ``None``.
        finished: called with a search's index and its episodes when it ends.

    Returns:
        Every evaluated episode of each search, in the order of ``searches``.
    """
    active = [index for index, state in enumerate(searches) if not state.done]
    while active:
        asked = {index: searches[index].ask() for index in active}
        batch = [episode for index in active for episode in asked[index]]
        outcomes = runner.map(evaluate, batch) if runner is not None else [evaluate(item) for item in batch]
        position = 0
        for index in active:
            count = len(asked[index])
            searches[index].tell(asked[index], outcomes[position:position + count])
            position += count
            if searches[index].done and finished is not None:
                finished(index, searches[index].found[:searches[index].episodes])
        active = [index for index in active if not searches[index].done]
    return [state.found[:state.episodes] for state in searches]


# ---------------------------------------------------------------------------------------------- command line


BODIES = ("disk", "polygon", "cover")
"""Body models searched: the circumscribed disk, and the cover of the footprint (its truth is then the polygon)."""


def _has_body(filter_name: str, robot: str | dict[str, Any], body: str) -> bool:
    spec = robot_spec(robot)
    if spec.footprint is None:
        return False
    try:
        make_filter(filter_name, spec, 0.05, body=body)
    except (TypeError, ValueError):
        return False
    return True


def body_half_width(spec: RobotSpec, body: str) -> float:
    """Half the width of the body model ``body`` of the CBF (its lateral extent) [m]."""
    return {"disk": BodyModel.disk, "polygon": BodyModel.polygon,
            "cover": lambda robot: BodyModel.cover(robot, 3)}[body](spec).half_width


def _cells(robots: Sequence[str | dict[str, Any]], filters: Sequence[str], bases: Sequence[str], dts: Sequence[float],
           geometries: Sequence[str], nominals: Sequence[str], bodies: Sequence[str] = ("disk",),
           mpc_references: Sequence[str | None] = (None,), mpc_lookahead: float = 0.0,
           min_obstacle_width: float | None = None, narrow_body: str | None = None,
           odometry: bool = False, latencies: Sequence[float] = (), real_time: bool = False,
           call_periods: Sequence[float] = (), sweeps: Sequence[str] = ()) -> list[dict[str, Any]]:
    """One search per robot, filter (and what the MPC tracks), body, period and base (with and without
    odometry for the instant base; with ``odometry`` each cell given the velocity again with the odometry pose
    too, after all the others; then every cell again with each of ``latencies`` [s] as the scans' age; then every
    cell again called every ``call_periods`` times ``dt``, then with each of ``sweeps``, :attr:`Episode.sweep`); the
    geometry and the nominal are searched inside each. With
    ``min_obstacle_width`` every CBF and MPC cell is told it (its poles are then from that wide); with
    ``narrow_body`` every CBF and MPC cell of a disk body on a robot with a footprint gets it (CBFConfig and
    MPCConfig.narrow_body; the MPC's only narrow body is the cover), and the adversary sets its ``narrow`` flag."""
    cells = []
    for robot in robots:
        for filter_name in filters:
            references = mpc_references if unescaped(filter_name) == "mpc" else (None,)
            for body, reference in itertools.product(bodies, references):
                if body != "disk" and not _has_body(filter_name, robot, body):
                    continue    # a round robot has no footprint to cover, or the filter has no such model
                settings = (({} if real_time else reproducible_settings(filter_name))
                            | ({} if body == "disk" else {"body": body})
                            | opt_in_settings(filter_name, mpc_reference=reference, mpc_lookahead=mpc_lookahead))
                if min_obstacle_width is not None and unescaped(filter_name) in ("cbf", "mpc"):
                    settings["min_obstacle_width"] = min_obstacle_width
                takes = unescaped(filter_name) == "cbf" or (unescaped(filter_name) == "mpc" and narrow_body == "cover")
                if narrow_body is not None and takes and body == "disk" and robot_spec(robot).footprint is not None:
                    settings["narrow_body"] = narrow_body
                for dt in dts:
                    for base in bases:
                        for give_velocity in ((True, False) if base == "instant" else (True,)):
                            cells.append(dict(robot=robot, filter_name=filter_name, base=base, dt=dt,
                                              give_velocity=give_velocity, geometry=tuple(geometries),
                                              nominal=tuple(nominals), settings=dict(settings)))
    if odometry:    # appended: the cells without the pose keep their indices (and so their seeds)
        cells += [dict(cell, give_pose=True) for cell in cells if cell["give_velocity"]]
    cells += [dict(cell, latency=float(latency)) for latency in latencies if latency > 0.0 for cell in list(cells)]
    cells += [dict(cell, call_period=float(factor)) for factor in call_periods if factor != 1.0
              for cell in list(cells)]
    cells += [dict(cell, sweep=sweep) for sweep in sweeps if sweep for cell in list(cells)]
    return cells


@functools.cache
def _sighting(robot: str, filter_name: str, dt: float, settings: str) -> tuple[float, float]:
    safety = make_filter(unescaped(filter_name), robot_spec(json.loads(robot)), dt,
                         **filter_settings(filter_name, **json.loads(settings)))
    return safety.horizon_reach(), safety.smallest_obstacle


def sighting(robot: str | dict[str, Any], filter_name: str, dt: float, settings: Mapping[str, Any]
             ) -> tuple[float, float]:
    """How far the robot must see an obstacle to brake clear of it, and the narrowest it sees by then [m]
    (``SafetyFilter.horizon_reach``, ``SafetyFilter.smallest_obstacle``: assumption A2); once per process."""
    return _sighting(json.dumps(robot, sort_keys=True), filter_name, dt, json.dumps(dict(settings), sort_keys=True))


def cell_margin(cell: dict[str, Any]) -> float:
    """The margin of a cell's filter [m] (a job: building an MPC takes a while)."""
    return make_filter(cell["filter_name"], robot_spec(cell["robot"]), cell["dt"], **cell.get("settings", {})).margin


def _cell_key(cell: dict[str, Any]) -> str:
    settings = cell.get("settings", {})
    return "/".join((robot_name(cell["robot"]), cell["filter_name"],
                     *([settings["body"]] if "body" in settings else []),
                     *([f"{settings['reference']}-reference"] if "reference" in settings else []),
                     *([f"lookahead-{settings['lookahead']:g}"] if "lookahead" in settings else []),
                     *([f"width-{settings['min_obstacle_width']:g}"] if "min_obstacle_width" in settings else []),
                     *([f"narrow-{settings['narrow_body']}"] if "narrow_body" in settings else []),
                     *(["pose"] if cell.get("give_pose") else []),
                     *([f"latency-{cell['latency']:g}"] if cell.get("latency") else []),
                     *([f"called-every-{cell['call_period']:g}dt"] if cell.get("call_period", 1.0) != 1.0 else []),
                     *([f"sweep-{cell['sweep']}"] if cell.get("sweep") else [])))


def _cell_line(index: int, cells: Sequence[dict[str, Any]], found: Sequence[Found]) -> str:
    label = {key: value for key, value in cells[index].items() if key not in ("geometry", "nominal") and value != {}}
    label["robot"] = robot_name(label["robot"])
    return f"[{index + 1}/{len(cells)}] {label} worst {min(f.outcome.objective for f in found):+.4f} m"


def _summary(cells: Sequence[dict[str, Any]], results: Sequence[list[Found]]) -> dict[str, dict[str, Any]]:
    """A summary per robot and filter."""
    summary: dict[str, dict[str, Any]] = {}
    for cell, found in zip(cells, results, strict=True):
        entry = summary.setdefault(_cell_key(cell), dict(episodes=0, valid=0, contacts=0, violations=0,
                                                         worst_clearance_minus_margin=math.inf))
        for item in found:
            entry["episodes"] += 1
            if item.outcome.valid:
                entry["valid"] += 1
                entry["contacts"] += int(item.outcome.contact)
                entry["violations"] += int(item.outcome.violated)
                entry["worst_clearance_minus_margin"] = min(entry["worst_clearance_minus_margin"],
                                                            item.outcome.min_clearance - item.outcome.margin)
    return summary


def main(argv: Sequence[str] | None = None, prog: str | None = None) -> int:
    parser = argparse.ArgumentParser(prog=prog or "falsify", description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=2000,
                        help="episodes in all, at least (spread over the cells, rounded up)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--robots", nargs="*", default=["rosbot", "puzzlebot", "m2wr"],
                        help="presets to search (none: only the robots of --robot-spec)")
    parser.add_argument("--robot-spec", nargs="+", default=[], metavar="PATH",
                        help="also search robots of your own: JSON files, each a robot's fields "
                             "(safenav.robot.RobotSpec.to_dict) or a list of them")
    parser.add_argument("--filters", nargs="+", default=["cbf", "mpc"])
    parser.add_argument("--bases", nargs="+", default=list(BASES), choices=BASES)
    parser.add_argument("--dts", nargs="+", type=float, default=[0.02, 0.05, 0.1])
    parser.add_argument("--geometries", nargs="+", default=list(GEOMETRIES), choices=GEOMETRIES)
    parser.add_argument("--nominals", nargs="+", default=list(SEARCHED_NOMINALS), choices=SEARCHED_NOMINALS)
    parser.add_argument("--bodies", nargs="+", default=list(BODIES), choices=BODIES)
    parser.add_argument("--mpc-reference", nargs="+", default=[None], choices=REFERENCES,
                        help="what the MPC cells track (each a cell of its own): nominal, cbf (default: the "
                             "filter's own: nominal for mpc, cbf for mpc+escape)")
    parser.add_argument("--mpc-lookahead", type=argument_type(number, low=0.0, high=10.0), default=0.0, metavar="L",
                        help="the MPC cells' look-ahead control disk [m] (MPCConfig.lookahead; default 0: none)")
    parser.add_argument("--min-obstacle-width", type=argument_type(number, low=0.0, low_open=True, high=10.0),
                        default=None, metavar="W",
                        help="tell the CBF and MPC cells the narrowest obstacle to see in time [m] "
                             "(CBFConfig/MPCConfig.min_obstacle_width; default: what the lidars resolve)")
    parser.add_argument("--narrow-body", default=None, choices=("cover", "polygon"),
                        help="name the CBF and MPC cells' body for gaps (disk body, robots with a footprint; "
                             "CBFConfig/MPCConfig.narrow_body, the default cover) and let the adversary set their "
                             "narrow flag with the passage flag (the MPC has only the cover)")
    parser.add_argument("--odometry", action="store_true",
                        help="also search every cell given the velocity with the odometry pose given too "
                             "(pose=, as the ROS nodes pass it; a frame far from the origin whose heading crosses "
                             "the wrap at +-pi)")
    parser.add_argument("--latencies", nargs="+", type=argument_type(number, low=0.0, high=1.0), default=[],
                        metavar="S", help="also search every cell with every scan this old [s] (taken where the "
                                          "robot was then, stamped then; the filter is told the time)")
    parser.add_argument("--call-periods", nargs="+", type=argument_type(number, low=0.05, high=10.0), default=[],
                        metavar="F", help="also search every cell with the filter called every F dt, told the time "
                                          "(F < 1: early calls, each command held shorter than planned; F > 1: late "
                                          "calls it must plan for)")
    parser.add_argument("--sweeps", nargs="+", default=[], choices=SWEEPS,
                        help="also search every cell with a turning lidar, each beam measured at its own time from "
                             "where the robot was then: 'stated' (time_increment given, as sensor_msgs/LaserScan "
                             "defines it), 'unstated' (given as 0: outside the guarantee)")
    add_real_time_option(parser)
    parser.add_argument("--optimiser", default="cma", choices=("cma", "random"))
    parser.add_argument("--worst", type=int, default=10, help="worst cases to print")
    add_sweep_options(parser)
    parser.add_argument("--json", help="write the summary and the worst cases here")
    parser.add_argument("--replay", help="replay one episode given as the JSON line printed by a search")
    return run_cli(parser, argv, _run)


def episodes_per_cell(episodes: int, cells: int) -> int:
    """Episodes each of ``cells`` cells gets so that they add up to at least ``episodes`` (and one each)."""
    return max(1, -(-episodes // cells))


def _run(args: argparse.Namespace) -> int:
    if args.replay:
        outcome, log = run(Episode.from_json(args.replay), record=True)
        for row in log:
            print(f"{row['step']:4d} t={row['t']:.2f} u_nom={np.round(row['u_nom'], 3)} u={np.round(row['u'], 3)} "
                  f"{row['status']:10s} H={row['min_barrier']:.4f} clearance={row['clearance']:.4f} "
                  f"{row['message']}")
        print(outcome)
        return 0 if not outcome.violated else 1
    cells = _cells([*args.robots, *load_robots(args.robot_spec)], args.filters, args.bases, args.dts, args.geometries,
                   args.nominals, args.bodies, args.mpc_reference, args.mpc_lookahead, args.min_obstacle_width,
                   args.narrow_body, args.odometry, args.latencies, args.real_time, args.call_periods, args.sweeps)
    per_cell = episodes_per_cell(args.episodes, len(cells))
    settings = {**sweep_settings(args), "progress": False, "ship": SHIPPED}
    start = time.perf_counter()
    print(f"{per_cell * len(cells)} episodes: {len(cells)} cells x {per_cell}, on {where(args)}", flush=True)
    with JobRunner(**settings, description="falsify") as runner, \
            Progress(per_cell * len(cells), "falsify", enabled=not args.no_progress) as progress:
        margins = runner.map(cell_margin, cells)
        searches = [CellSearch(cell, episodes=per_cell, seed=args.seed * 100_003 + index, margin=margin,
                               optimiser=args.optimiser)
                    for index, (cell, margin) in enumerate(zip(cells, margins, strict=True))]

        def finished(index: int, found: list[Found]) -> None:
            for _ in found:
                progress.update()
            print(_cell_line(index, cells, found), flush=True)

        results = search_cells(searches, runner, finished)
    if args.resume:
        print(f"resumed: {runner.reused} jobs taken from {args.results}")
    everything = [item for found in results for item in found]
    summary = _summary(cells, results)
    elapsed = time.perf_counter() - start
    print()
    print("| robot/filter | episodes | valid | contacts | below margin - 1 cm | worst clearance - margin [m] |")
    print("|---|---|---|---|---|---|")
    for key, entry in sorted(summary.items()):
        print(f"| {key} | {entry['episodes']} | {entry['valid']} | {entry['contacts']} | {entry['violations']} | "
              f"{entry['worst_clearance_minus_margin']:+.4f} |")
    valid = [f for f in everything if f.outcome.valid]
    valid.sort(key=lambda f: f.outcome.objective)
    print(f"\n{len(everything)} episodes in {elapsed:.0f} s; worst cases (replay with --replay '<line>'):")
    for item in valid[: args.worst]:
        print(f"{item.outcome.objective:+.4f} m  {item.episode.to_json()}")
    if args.json:
        with open(args.json, "w") as handle:
            json.dump(dict(episodes=len(everything), seconds=elapsed, summary=summary,
                           worst=[dict(objective=f.outcome.objective, episode=dataclasses.asdict(f.episode))
                                  for f in valid[: args.worst]]), handle, indent=1)
    return 1 if any(f.outcome.violated for f in everything) else 0


if __name__ == "__main__":
    # Run the module's own copy (``benchmarks.falsify``), not ``__main__``'s: the jobs and their outcomes
    # must be the classes a Ray worker and a resumed run import, whichever way the falsifier was started.
    from benchmarks import falsify

    raise SystemExit(falsify.main())
