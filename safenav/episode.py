"""One closed-loop episode: world, robot, nominal policy, optional safety filter, in the simulator.

At every control period the policy maps the main lidar's scan (and the pose, for
goal-seeking policies) to ``u_nom``, the filter (if any) maps ``u_nom`` and the scan (every
lidar's scan on a robot with several) and the measured velocity to ``u``, and the simulator
holds ``u`` for one period. The filter sees only what a real robot would: the scans and the
odometry velocity. The metrics use the simulator's
truth::

    from safenav import preset
    from safenav.episode import run_episode
    from safenav.filters import CBFSafetyFilter
    from safenav.reference import StopAtWall
    from safenav.worlds import tutorial_world

    robot = preset("rosbot")
    result = run_episode(tutorial_world("stop_at_wall"), robot, StopAtWall.tutorial_bug(),
                         CBFSafetyFilter(robot, 0.05), seed=0)
    result.metrics.collided, result.metrics.min_clearance

Liveness (:func:`liveness`, in :class:`EpisodeMetrics`) is measured on the commands, with the
filters' own stall test (:func:`safenav.filters.base.progress`): a period *stalls* when the
nominal asks to move (more than ``STILL`` of a velocity limit) and the command sent keeps less
than ``STALL_PROGRESS`` of the nominal's progress. For a plain filter a run of stalled periods
is what the filter reports as :attr:`~safenav.filters.FilterResult.deadlock`, except that a
blip of progress shorter than :data:`RESUME_TIME` does not end a deadlock here. With an
escape wrapper (:class:`~safenav.filters.Escape`) a period in which the escape drives is not a
stall while the escape works, but every period of an escape that fails (the nominal still
stalls :data:`RESUME_TIME` after it hands back, or it is still escaping when the episode ends
short of the goal) is deadlocked, joined to the stall that started it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from safenav._checks import boolean, positive
from safenav.errors import InvalidConfig
from safenav.filters import FilterResult, FilterStatus, SafetyFilter
from safenav.filters.base import STALL_PROGRESS, STILL
from safenav.geometry import Pose2D, wrap_angle
from safenav.reference import Policy
from safenav.robot import RobotSpec
from safenav.scan import LaserScan
from safenav.sim_bullet import BulletSim, SimConfig, SimState
from safenav.worlds import World

__all__ = ["EpisodeConfig", "EpisodeMetrics", "EpisodeResult", "Liveness", "Trajectory", "liveness", "run_episode",
           "stalled", "stationary"]

RESUME_TIME = 0.25
"""Progress along the nominal must last this long to end a deadlock, and must resume within it after an
escape for the escape to count as a success [s] (see :func:`liveness`)."""

REVERSAL_DEADBAND = 1e-3
"""Commanded speeds within this of zero [m/s] neither start nor end a sign of ``v`` (chatter count)."""


@dataclass(frozen=True)
class EpisodeConfig:
    """How an episode runs and what counts as stuck or arrived.

    Attributes:
        duration: simulated time limit [s].
        sim: simulator settings (control period, physics step, noise, latency).
        stop_on_collision: end the episode at the first collision.
        give_velocity: pass the measured (odometry) velocity to the filter, so it respects
            the acceleration limits; ``False`` tests a filter that ignores them.
        give_pose: also pass the simulator's pose as the odometry pose (``pose=``), as the ROS
            nodes pass ``/odom``'s: remembered points are then carried exactly instead of by the
            velocity's dead reckoning, whose error bound grows with every change of the velocity.
        goal_tolerance: the goal counts as reached within this distance of the base [m].
        stop_at_goal: end the episode once the goal is reached.
        stuck_speed: the robot counts as not moving while, over the last ``stuck_window``, its
            base got less than this far per second from where it was [m/s] and turned less than
            ``stuck_turn`` per second from how it faced (see :func:`stationary`).
        stuck_turn: see ``stuck_speed`` [rad/s].
        stuck_window: how far back ``stuck_speed`` and ``stuck_turn`` look [s]: a robot that shakes
            back and forth, or left and right, in front of an obstacle does not move.
        deadlock_time: a run of stalled periods (see :func:`liveness`) counts as deadlocked
            time once it lasts this long [s]: the filters' default ``deadlock_time``.
    """

    duration: float = 30.0
    sim: SimConfig = field(default_factory=SimConfig)
    stop_on_collision: bool = True
    give_velocity: bool = True
    give_pose: bool = False
    goal_tolerance: float = 0.3
    stop_at_goal: bool = True
    stuck_speed: float = 0.02
    stuck_turn: float = 0.05
    stuck_window: float = 1.0
    deadlock_time: float = 1.5

    def __post_init__(self) -> None:
        for name in ("duration", "goal_tolerance", "stuck_speed", "stuck_turn", "stuck_window", "deadlock_time"):
            object.__setattr__(self, name, positive(f"EpisodeConfig.{name}", getattr(self, name)))
        for name in ("stop_on_collision", "give_velocity", "give_pose", "stop_at_goal"):
            object.__setattr__(self, name, boolean(f"EpisodeConfig.{name}", getattr(self, name)))
        if not isinstance(self.sim, SimConfig):
            raise InvalidConfig(f"EpisodeConfig.sim must be a SimConfig, got {self.sim!r}")

    @property
    def steps(self) -> int:
        """Control periods in a full-length episode."""
        return round(self.duration / self.sim.control_dt)

    def replace(self, **changes: Any) -> EpisodeConfig:
        """A copy with some fields changed (validated)."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class EpisodeMetrics:
    """What happened in one episode (truth from the simulator).

    Attributes:
        steps: control periods run.
        time: simulated time [s].
        collided: the body overlapped an obstacle at some physics step.
        collision_time: time of the first overlap [s], or ``None``.
        min_clearance: smallest body clearance over every physics step [m].
        distance: path length travelled [m].
        mean_intervention: mean ``||u - u_nom||`` over the periods, in ``(m/s, rad/s)``.
        max_intervention: largest ``||u - u_nom||``.
        goal_reached: whether the goal was reached (``None`` without a goal).
        time_to_goal: when it was reached [s] (``None`` if not).
        goal_progress: start distance to the goal minus the final one [m] (``None`` without a goal).
        stuck_time: time during which the nominal asked to move but the robot did not [s]
            (:attr:`EpisodeConfig.stuck_speed`).
        fallbacks: periods in which the filter braked, or followed its stored plan, because its optimiser
            failed or could not answer within its compute budget (status ``fallback``).
        statuses: how many periods ended with each filter status.
        filter_times: wall time of every filter call [s] (empty without a filter).
        deadlock_time: total length of the deadlocks that lasted at least
            ``EpisodeConfig.deadlock_time`` [s] (see :func:`liveness`).
        longest_deadlock: the longest deadlock [s].
        escapes_started: escapes an escape wrapper started.
        escapes_succeeded: escapes after which the nominal made progress again (or that reached the goal).
        escape_time: time during which an escape replaced the nominal [s].
        omega_chatter: mean ``|omega_k - omega_(k-1)| / dt`` of the commands sent [rad/s^2].
        v_reversals: sign changes of the commanded ``v`` per second [1/s] (speeds within
            :data:`REVERSAL_DEADBAND` of zero keep the previous sign).
        nominal_omega_chatter: ``omega_chatter`` of the nominal's commands [rad/s^2].
        escape_omega_chatter: ``omega_chatter`` while an escape drove [rad/s^2]; NaN without one.
    """

    steps: int
    time: float
    collided: bool
    collision_time: float | None
    min_clearance: float
    distance: float
    mean_intervention: float
    max_intervention: float
    goal_reached: bool | None
    time_to_goal: float | None
    goal_progress: float | None
    stuck_time: float
    fallbacks: int
    statuses: dict[str, int]
    filter_times: np.ndarray
    deadlock_time: float = 0.0
    longest_deadlock: float = 0.0
    escapes_started: int = 0
    escapes_succeeded: int = 0
    escape_time: float = 0.0
    omega_chatter: float = 0.0
    v_reversals: float = 0.0
    nominal_omega_chatter: float = 0.0
    escape_omega_chatter: float = math.nan

    @property
    def filter_p50_us(self) -> float:
        """Median filter call time [us] (NaN without a filter)."""
        return float(np.median(self.filter_times) * 1e6) if self.filter_times.size else math.nan

    @property
    def filter_p99_us(self) -> float:
        """99th percentile of the filter call time [us] (NaN without a filter)."""
        return float(np.percentile(self.filter_times, 99) * 1e6) if self.filter_times.size else math.nan


@dataclass(frozen=True)
class Liveness:
    """How an episode's commands kept the robot going (see :func:`liveness`).

    Attributes:
        deadlock_time: total length of the deadlocks of at least the minimum length [s].
        longest_deadlock: the longest deadlock, whatever its length [s].
        escapes_started: escapes started (runs of periods in which an escape drove).
        escapes_succeeded: escapes after which progress along the nominal resumed within
            :data:`RESUME_TIME` of handing back, or during which the goal was reached.
        escape_time: time during which an escape drove [s].
        omega_chatter: mean ``|omega_k - omega_(k-1)| / dt`` of the commands [rad/s^2].
        v_reversals: sign changes of the commanded ``v`` per second [1/s].
        nominal_omega_chatter: the same mean over the nominal's commands (pairs of finite ones) [rad/s^2]:
            the chatter the nominal brings along the path the robot took.
        escape_omega_chatter: the same mean over the pairs of consecutive periods in which an escape
            drove [rad/s^2]; NaN when there are none.
    """

    deadlock_time: float
    longest_deadlock: float
    escapes_started: int
    escapes_succeeded: int
    escape_time: float
    omega_chatter: float
    v_reversals: float
    nominal_omega_chatter: float = 0.0
    escape_omega_chatter: float = math.nan


def stalled(nominal: np.ndarray, commands: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Which periods stall: the nominal asks to move and the command keeps too little of its progress.

    The filters' own test (:meth:`SafetyFilter.filter` reports a deadlock after a run of them):
    both commands as fractions of the velocity limits ``scale``, the nominal clipped to them;
    the nominal asks to move when one of its parts exceeds ``STILL``; the command keeps
    ``(u . n) / |n|^2`` of its progress, and less than ``STALL_PROGRESS`` stalls. A non-finite
    nominal does not ask to move.

    Args:
        nominal: ``(T, 2)`` nominal commands ``(v [m/s], omega [rad/s])``.
        commands: ``(T, 2)`` commands sent.
        scale: the velocity limits ``(v_max [m/s], omega_max [rad/s])``.

    Returns:
        ``(T,)`` booleans.
    """
    scale = np.abs(np.asarray(scale, dtype=float))
    nominal = np.asarray(nominal, dtype=float).reshape(-1, 2)
    commands = np.asarray(commands, dtype=float).reshape(-1, 2)
    finite = np.all(np.isfinite(nominal), axis=1)
    wanted = np.clip(np.where(finite[:, None], nominal, 0.0), -scale, scale) / scale
    size = np.sum(wanted * wanted, axis=1)
    moves = finite & (np.max(np.abs(wanted), axis=1) > STILL)
    kept = np.sum(commands / scale * wanted, axis=1) / np.where(size > 0.0, size, 1.0)
    return moves & (kept < STALL_PROGRESS)


def stationary(poses: np.ndarray, times: np.ndarray, speed: float, turn: float, window: float) -> np.ndarray:
    """Whether the robot stood at each pose, by where it was ``window`` [s] earlier.

    The robot stood at pose ``k`` when, against the pose at ``max(times[k] - window, times[0])``,
    its base is at most ``speed`` times the time between them away and faces at most ``turn`` times
    that time away.

    Args:
        poses: ``(K, 3)`` base poses ``(x, y, yaw)`` [m, m, rad], in time order.
        times: ``(K,)`` their times [s], increasing.
        speed: [m/s].
        turn: [rad/s].
        window: how far back [s] (the first pose compares with itself and stands).

    Returns:
        ``(K,)`` booleans. The speed over a window rather than at an instant: a robot shaking back
        and forth, or left and right, in front of an obstacle (its speed changing sign a few times a
        second) gets nowhere, and stands.
    """
    poses, times = np.asarray(poses, dtype=float).reshape(-1, 3), np.asarray(times, dtype=float).ravel()
    start = np.searchsorted(times, times - window - 1e-9)
    span = times - times[start]
    travelled = np.hypot(*(poses[:, :2] - poses[start, :2]).T)
    turned = np.abs(wrap_angle(poses[:, 2] - poses[start, 2]))
    return (travelled <= speed * span) & (turned <= turn * span)


def _runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """The ``[start, stop)`` index ranges of the runs of true values."""
    padded = np.concatenate(([False], np.asarray(flags, dtype=bool), [False]))
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def _resumes(stall: np.ndarray, escaping: np.ndarray, stop: int, ramp: int) -> bool:
    """Whether progress resumes after the escape that ends before period ``stop``: a period that does not
    stall, before another escape and at most ``ramp`` periods after it."""
    for index in range(stop, min(stop + ramp + 1, len(stall))):
        if escaping[index]:
            return False
        if not stall[index]:
            return True
    return False


def liveness(nominal: np.ndarray, commands: np.ndarray, escaping: np.ndarray, dt: float, scale: np.ndarray, *,
             goal_reached: bool = False, min_deadlock: float = 1.5, resume_time: float = RESUME_TIME) -> Liveness:
    """Deadlocks, escapes and chatter of one episode, from its per-period commands.

    * A period *stalls* by :func:`stalled` (the filters' own test).
    * An *escape* is a run of periods in which an escape wrapper drove (``escaping``). It
      *succeeds* when progress along the nominal resumes right after it: a period that does not
      stall comes within ``resume_time`` of its end, before another escape (the base may need
      a period or two at its acceleration limits to turn from the escape's heading towards
      the nominal's); or when it was still running as the episode ended at the goal.
    * A period is *deadlocked* when it stalls and no escape drives, or when it belongs to an
      escape that failed; so is every period of a gap shorter than ``resume_time`` between two
      deadlocked ones (progress has to last to end a deadlock: a nominal that flips between
      turning and driving gets one period of progress now and then, which resets the filters'
      own stall count, and its robot stays put). A *deadlock* is a run of deadlocked periods;
      ``deadlock_time`` adds those that last at least ``min_deadlock``.
    * Chatter: the mean ``|Δomega| / dt`` between consecutive commands, and the sign changes of
      ``v`` per second, where ``|v| <=`` :data:`REVERSAL_DEADBAND` keeps the previous sign (so
      forward, stop, reverse is one change); the same mean over the nominal's commands (what the
      nominal itself asks for along the robot's path: a robot that drives through clutter meets
      more turns than one that stands), and over the pairs of periods in which an escape drove.

    Args:
        nominal: ``(T, 2)`` nominal commands, one per period.
        commands: ``(T, 2)`` commands sent.
        escaping: ``(T,)`` whether an escape replaced the nominal in each period.
        dt: the control period [s].
        scale: the velocity limits ``(v_max [m/s], omega_max [rad/s])``.
        goal_reached: whether the episode ended at its goal.
        min_deadlock: shortest run of deadlocked periods that counts in ``deadlock_time`` [s].
        resume_time: shortest run of progress that ends a deadlock [s].
    """
    commands = np.asarray(commands, dtype=float).reshape(-1, 2)
    escaping = np.asarray(escaping, dtype=bool).reshape(-1)
    steps = len(commands)
    stall = stalled(nominal, commands, scale)
    deadlocked = stall & ~escaping
    escapes = _runs(escaping)
    succeeded = 0
    shortest_resume = round(resume_time / dt)
    for start, stop in escapes:
        if _resumes(stall, escaping, stop, shortest_resume) or (stop == steps and goal_reached):
            succeeded += 1
        else:
            deadlocked[start:stop] = True
    for start, stop in _runs(~deadlocked):
        if start > 0 and stop < steps and stop - start < shortest_resume:
            deadlocked[start:stop] = True     # a blip of progress does not end a deadlock
    lengths = np.array([stop - start for start, stop in _runs(deadlocked)], dtype=float) * dt
    speed = commands[:, 0]
    signs = np.sign(speed[np.abs(speed) > REVERSAL_DEADBAND])
    turn_change = np.abs(np.diff(commands[:, 1])) / dt
    nominal_turns = np.asarray(nominal, dtype=float).reshape(-1, 2)[:, 1]
    nominal_change = np.abs(np.diff(nominal_turns)) / dt
    nominal_change = nominal_change[np.isfinite(nominal_change)]
    escaping_pairs = escaping[1:] & escaping[:-1]
    return Liveness(
        deadlock_time=float(lengths[lengths >= min_deadlock - 1e-9].sum()),
        longest_deadlock=float(lengths.max()) if lengths.size else 0.0,
        escapes_started=len(escapes),
        escapes_succeeded=succeeded,
        escape_time=float(np.count_nonzero(escaping)) * dt,
        omega_chatter=float(np.mean(turn_change)) if steps > 1 else 0.0,
        v_reversals=float(np.count_nonzero(np.diff(signs))) / (steps * dt) if steps else 0.0,
        nominal_omega_chatter=float(np.mean(nominal_change)) if nominal_change.size else 0.0,
        escape_omega_chatter=float(np.mean(turn_change[escaping_pairs])) if escaping_pairs.any() else math.nan,
    )


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Per-step record of an episode (row ``k`` of the state arrays is after ``k`` periods).

    Attributes:
        time: ``(T + 1,)`` simulated times [s].
        pose: ``(T + 1, 3)`` poses ``(x, y, yaw)`` [m, m, rad].
        velocity: ``(T + 1, 2)`` measured ``(v, omega)``.
        clearance: ``(T + 1,)`` body clearance [m] (truth).
        u_nom: ``(T, 2)`` nominal commands.
        u: ``(T, 2)`` commands sent (``u_nom`` without a filter).
        status: ``(T,)`` filter status per period (``"none"`` without a filter).
        policy_state: ``(T,)`` the policy's state name per period.
        scans: the scans the policy saw, when recorded (``T`` of them), else empty.
    """

    time: np.ndarray
    pose: np.ndarray
    velocity: np.ndarray
    clearance: np.ndarray
    u_nom: np.ndarray
    u: np.ndarray
    status: tuple[str, ...]
    policy_state: tuple[str, ...]
    scans: tuple[LaserScan, ...] = ()


@dataclass(frozen=True, eq=False)
class EpisodeResult:
    """Metrics of an episode, and its trajectory when it was recorded."""

    metrics: EpisodeMetrics
    trajectory: Trajectory | None = None


def run_episode(
    world: World,
    robot: RobotSpec,
    policy: Policy,
    safety_filter: SafetyFilter | None = None,
    *,
    config: EpisodeConfig | None = None,
    seed: int = 0,
    record: bool = False,
    record_scans: bool = False,
    callback: Callable[[int, SimState, FilterResult | None], None] | None = None,
) -> EpisodeResult:
    """Run one episode and measure it.

    The simulator, the policy and the filter are reset first; the simulator's noise
    and the policy's randomness draw from their own streams of ``seed``
    (:mod:`safenav.seeding`), so the same arguments give the same episode.

    Args:
        world: the world (obstacles, start, optional goal).
        robot: the robot.
        policy: the nominal policy (reset here with ``seed``).
        safety_filter: the filter between policy and wheels, or ``None`` for the naive robot.
        config: episode settings; the filter's ``dt`` should equal ``config.sim.control_dt``.
        seed: the episode's seed (the simulator takes its ``sensor`` and ``actuation``
            streams, the policy gets it in :meth:`~safenav.reference.Policy.reset`).
        record: also return the per-step :class:`Trajectory`.
        record_scans: keep the scans in the trajectory too (for animations).
        callback: called after every period with the step index, the new simulator state
            and the filter's result (``None`` without a filter); for logging, live plots or
            soak measurements.

    Raises:
        InvalidConfig: the filter's period differs from the control period.
    """
    config = config or EpisodeConfig()
    dt = config.sim.control_dt
    if safety_filter is not None and abs(safety_filter.dt - dt) > 1e-12:
        raise InvalidConfig(f"filter dt={safety_filter.dt!r} differs from the control period {dt!r}; "
                            "make the filter with the episode's control_dt")
    policy.reset(seed)
    if safety_filter is not None:
        safety_filter.reset()
    with BulletSim(world, robot, config.sim, seed=seed) as sim:
        state = sim.reset()
        goal = world.goal
        start_goal_distance = _distance(state.pose, goal) if goal is not None else None
        poses, velocities, times, clearances = [state.pose], [state.velocity], [state.time], [state.clearance]
        nominal_log, command_log, status_log, policy_log, scan_log = [], [], [], [], []
        escaping_log: list[bool] = []
        filter_times: list[float] = []
        statuses: dict[str, int] = {}
        min_clearance = state.clearance
        wants_log: list[bool] = []
        time_to_goal = None
        for _ in range(config.steps):
            scan = state.scan
            u_nom = np.asarray(policy(scan, state.pose), dtype=float)
            result = None
            if safety_filter is None:
                u, status = u_nom, "none"
            else:
                sensed = state.scans if len(state.scans) > 1 else scan   # every lidar's scan, matched by frame_id
                result = safety_filter.filter(u_nom, sensed, velocity=state.velocity if config.give_velocity else None,
                                              pose=state.pose if config.give_pose else None, now=state.time)
                filter_times.append(result.filter_time)
                u, status = result.u, result.status.value
            statuses[status] = statuses.get(status, 0) + 1
            wants_log.append(abs(u_nom[0]) > config.stuck_speed or abs(u_nom[1]) > config.stuck_turn)
            state = sim.step(u)
            min_clearance = min(min_clearance, state.min_clearance)
            poses.append(state.pose)
            velocities.append(state.velocity)
            times.append(state.time)
            clearances.append(state.clearance)
            nominal_log.append(u_nom)
            command_log.append(np.asarray(u, dtype=float))
            escaping_log.append(result is not None and bool(result.escape))
            status_log.append(status)
            policy_log.append(policy.state)
            if record_scans:
                scan_log.append(scan)
            if callback is not None:
                callback(len(command_log) - 1, state, result)
            if goal is not None and time_to_goal is None and _distance(state.pose, goal) <= config.goal_tolerance:
                time_to_goal = state.time
            if config.stop_on_collision and state.first_collision_time is not None:
                break
            if config.stop_at_goal and time_to_goal is not None:
                break
        first_collision = state.first_collision_time

    pose_array = np.array(poses, dtype=float)
    nominal = np.array(nominal_log, dtype=float).reshape(-1, 2)
    commands = np.array(command_log, dtype=float).reshape(-1, 2)
    intervention = np.hypot(*(commands - nominal).T) if len(commands) else np.zeros(0)
    stood = stationary(pose_array, np.array(times), config.stuck_speed, config.stuck_turn, config.stuck_window)[1:]
    stuck_steps = int(np.count_nonzero(np.array(wants_log, dtype=bool) & stood))
    goal_reached = None if goal is None else time_to_goal is not None
    lively = liveness(nominal, commands, np.array(escaping_log, dtype=bool), dt, robot.upper,
                      goal_reached=bool(goal_reached), min_deadlock=config.deadlock_time)
    metrics = EpisodeMetrics(
        steps=len(command_log),
        time=float(times[-1]),
        collided=first_collision is not None,
        collision_time=first_collision,
        min_clearance=float(min_clearance),
        distance=float(np.sum(np.hypot(*np.diff(pose_array[:, :2], axis=0).T))),
        mean_intervention=float(intervention.mean()) if intervention.size else 0.0,
        max_intervention=float(intervention.max()) if intervention.size else 0.0,
        goal_reached=goal_reached,
        time_to_goal=time_to_goal,
        goal_progress=None if goal is None else start_goal_distance - _distance(poses[-1], goal),
        stuck_time=stuck_steps * dt,
        fallbacks=statuses.get(FilterStatus.FALLBACK.value, 0),
        statuses=statuses,
        filter_times=np.array(filter_times, dtype=float),
        **dataclasses.asdict(lively),
    )
    trajectory = None
    if record:
        trajectory = Trajectory(
            time=np.array(times), pose=pose_array, velocity=np.array(velocities, dtype=float).reshape(-1, 2),
            clearance=np.array(clearances), u_nom=nominal, u=commands, status=tuple(status_log),
            policy_state=tuple(policy_log), scans=tuple(scan_log),
        )
    return EpisodeResult(metrics, trajectory)


def _distance(pose: Pose2D, goal: tuple[float, float]) -> float:
    return math.hypot(pose[0] - goal[0], pose[1] - goal[1])
