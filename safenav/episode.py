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
from safenav.geometry import Pose2D
from safenav.reference import Policy
from safenav.robot import RobotSpec
from safenav.scan import LaserScan
from safenav.sim_bullet import BulletSim, SimConfig, SimState
from safenav.worlds import World

__all__ = ["EpisodeConfig", "EpisodeMetrics", "EpisodeResult", "Trajectory", "run_episode"]


@dataclass(frozen=True)
class EpisodeConfig:
    """How an episode runs and what counts as stuck or arrived.

    Attributes:
        duration: simulated time limit [s].
        sim: simulator settings (control period, physics step, noise, latency).
        stop_on_collision: end the episode at the first collision.
        give_velocity: pass the measured (odometry) velocity to the filter, so it respects
            the acceleration limits; ``False`` tests a filter that ignores them.
        goal_tolerance: the goal counts as reached within this distance of the base [m].
        stop_at_goal: end the episode once the goal is reached.
        stuck_speed: below this linear [m/s] and ``stuck_turn`` angular [rad/s] speed the
            robot counts as not moving.
        stuck_turn: see ``stuck_speed`` [rad/s].
    """

    duration: float = 30.0
    sim: SimConfig = field(default_factory=SimConfig)
    stop_on_collision: bool = True
    give_velocity: bool = True
    goal_tolerance: float = 0.3
    stop_at_goal: bool = True
    stuck_speed: float = 0.02
    stuck_turn: float = 0.05

    def __post_init__(self) -> None:
        for name in ("duration", "goal_tolerance", "stuck_speed", "stuck_turn"):
            object.__setattr__(self, name, positive(f"EpisodeConfig.{name}", getattr(self, name)))
        for name in ("stop_on_collision", "give_velocity", "stop_at_goal"):
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
        stuck_time: time during which the nominal asked to move but the robot did not [s].
        fallbacks: periods in which the filter braked because its optimiser failed.
        statuses: how many periods ended with each filter status.
        filter_times: wall time of every filter call [s] (empty without a filter).
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

    @property
    def filter_p50_us(self) -> float:
        """Median filter call time [us] (NaN without a filter)."""
        return float(np.median(self.filter_times) * 1e6) if self.filter_times.size else math.nan

    @property
    def filter_p99_us(self) -> float:
        """99th percentile of the filter call time [us] (NaN without a filter)."""
        return float(np.percentile(self.filter_times, 99) * 1e6) if self.filter_times.size else math.nan


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
        filter_times: list[float] = []
        statuses: dict[str, int] = {}
        min_clearance = state.clearance
        stuck_steps = 0
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
                                              now=state.time)
                filter_times.append(result.filter_time)
                u, status = result.u, result.status.value
            statuses[status] = statuses.get(status, 0) + 1
            wants_to_move = abs(u_nom[0]) > config.stuck_speed or abs(u_nom[1]) > config.stuck_turn
            state = sim.step(u)
            moving = abs(state.velocity[0]) > config.stuck_speed or abs(state.velocity[1]) > config.stuck_turn
            stuck_steps += wants_to_move and not moving
            min_clearance = min(min_clearance, state.min_clearance)
            poses.append(state.pose)
            velocities.append(state.velocity)
            times.append(state.time)
            clearances.append(state.clearance)
            nominal_log.append(u_nom)
            command_log.append(np.asarray(u, dtype=float))
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
    metrics = EpisodeMetrics(
        steps=len(command_log),
        time=float(times[-1]),
        collided=first_collision is not None,
        collision_time=first_collision,
        min_clearance=float(min_clearance),
        distance=float(np.sum(np.hypot(*np.diff(pose_array[:, :2], axis=0).T))),
        mean_intervention=float(intervention.mean()) if intervention.size else 0.0,
        max_intervention=float(intervention.max()) if intervention.size else 0.0,
        goal_reached=None if goal is None else time_to_goal is not None,
        time_to_goal=time_to_goal,
        goal_progress=None if goal is None else start_goal_distance - _distance(poses[-1], goal),
        stuck_time=stuck_steps * dt,
        fallbacks=statuses.get(FilterStatus.FALLBACK.value, 0),
        statuses=statuses,
        filter_times=np.array(filter_times, dtype=float),
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
