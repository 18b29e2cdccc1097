"""A PyBullet simulator of a lidar-driven differential-drive robot, with truth for metrics.

:class:`BulletSim` closes the loop (policy -> filter -> base -> world -> lidar): it builds a
:class:`~safenav.worlds.World` into PyBullet (headless ``p.DIRECT`` by default,
``SimConfig(gui=True)`` to watch), moves the robot, and returns what the robot would sense
plus the truth the metrics need::

    from safenav import preset
    from safenav.sim_bullet import BulletSim, SimConfig
    from safenav.worlds import tutorial_world

    with BulletSim(tutorial_world("stop_at_wall"), preset("rosbot"), seed=0) as sim:
        state = sim.reset()
        while state.scan.sector(-0.26, 0.26).min_range > 1.0:
            state = sim.step((0.5, 0.0))

Model, and why:

* **Obstacles** are ONE static triangle-mesh body: Bullet builds a bounding-volume
  hierarchy over it, the fastest shape to ray-cast (720 rays among 30 posts: about 0.4 ms as
  meshes, 3.4-5.7 ms as ``GEOM_CYLINDER`` primitives; one body per obstacle or per tile of
  the floor measured no faster). The mesh (:func:`~safenav.worlds.obstacle_mesh`) holds only
  the vertical sides of the prisms: rays are horizontal and never need the caps. Cylinders
  become circumscribed regular polygons that lie between the circle and a circle
  ``SimConfig.cylinder_tolerance`` (1 mm by default) larger: the lidar never reads a post
  long, reads it at most that much short along its normal, and a beam that grazes a post
  within the tolerance may hit the polygon where the circle would let it pass. Bullet
  reports hit fractions in single precision (about 1e-7 of ``range_max``), and its triangle
  ray test accepts hits up to 1e-4 of a face's width past the face's edge: a beam that grazes
  a corner may read the face it just misses (up to 25 µm past the corner of a 25 cm box).
* **Moving obstacles** (a :class:`~safenav.worlds.dynamic.DynamicWorld`'s movers) are one
  small mesh body each, put where their path says before every scan (and far below the floor
  while they do not exist); the truth clearance includes them at every physics step, exactly
  (:meth:`~safenav.worlds.dynamic.DynamicWorld.clearance_at`). They pass through the robot
  as the static obstacles do: contacts are recorded, not resolved.
* **Robot** is kinematic. A command ``(v, omega)`` is clipped to the velocity limits, and
  the base's velocity follows it by the model ``SimConfig.base`` (:mod:`safenav.base_models`:
  at the acceleration limits at every physics step by default, or at once, or a linear ramp
  over the period, or a first-order lag); the pose advances by the exact arc of
  :func:`~safenav.geometry.unicycle_step` at the mean velocity of each physics step.
  Contacts are detected, not resolved: a robot driven into a wall passes through it, and
  the collision is recorded. The robot's PyBullet body has a visual shape and no collision
  shape, so rays never hit it.
* **Lidars**: every lidar of ``robot.lidars`` (the main one, then
  :attr:`~safenav.robot.RobotSpec.extra_lidars`), all cast in one ``rayTestBatch`` per period, in the frame of
  the robot body, each from its true mount (``lidar.mount`` with ``SimConfig.mount_yaw_error`` added to its
  yaw) at its ``lidar.height``, one ray per beam, ``range_max`` long (with the compiled kernels,
  ``SimConfig.kernels``, a static world's rays are cast only to 1 cm past the exact box or circle each first
  meets, and again at full length when that misses: the same hits, their ranges to rounding, about 28 % less
  time a scan in cluttered worlds). Hits closer than ``range_min`` read ``-inf``, no hit reads ``+inf``
  (REP-117); a sensor inside an obstacle reads ``-inf`` on every beam. All beams of all lidars are cast at the
  same instant (no motion distortion). Each scan is returned in its lidar's own convention
  (:meth:`~safenav.robot.LidarSpec.scan`), with the *nominal* mount and the lidar's ``frame_id``:
  :attr:`SimState.scans` holds them all (main first), :attr:`SimState.scan` the main lidar's.
* **Truth**: the body clearance is exact and analytic (:meth:`World.clearance
  <safenav.worlds.World.clearance>` on the true circles and rectangles), evaluated at
  every physics step for the first-collision time. The body is the robot's convex footprint,
  turning with the heading (:meth:`World.footprint_clearance
  <safenav.worlds.World.footprint_clearance>`: what touches an obstacle, and what the filters
  guarantee, with their narrow body in gaps the circumscribed disk does not fit), or the
  circumscribed disk for a round robot, a concave footprint, or ``SimConfig(truth="disk")``.
  :meth:`BulletSim.bullet_clearance` measures the disk's with PyBullet's ``getClosestPoints``
  for cross-checks.

Noise and delays (all off by default except the preset's lidar noise), drawn from the
``sensor`` and ``actuation`` streams of the seed (:mod:`safenav.seeding`), so the same seed
gives the same episode:

* range noise: Gaussian, std ``SimConfig.range_noise`` [m] (each lidar's own
  ``noise_std`` when ``None``), added to every hit before the range limits apply;
* dropout: each beam reads ``NaN`` with probability ``SimConfig.dropout``;
* the main lidar draws its noise and dropout from the ``sensor`` stream itself, and extra
  lidar ``k`` (1, 2, ...) from child ``k`` of that stream (``stream(seed, "sensor").spawn``):
  adding a lidar leaves the main lidar's readings, and every one-lidar episode, unchanged;
* actuation noise: *relative*. Once per control period a factor ``1 + s * N(0, 1)`` is
  drawn for ``v`` and another for ``omega``, ``s = SimConfig.actuation_noise``; the executed
  velocity is the base model's velocity times these factors (wheel slip and calibration
  error: nothing moves when the command is zero);
* command latency: a command is executed ``command_latency`` control periods after
  :meth:`BulletSim.step` receives it (zeros before the first one arrives);
* scan latency: the scan delivered at a step was acquired ``scan_latency`` control
  periods earlier (the reset scan until then); ``scan.stamp`` stays the acquisition time.
  Every lidar of the robot is delayed alike.

PyBullet comes with the ``sim`` extra. It is imported when a :class:`BulletSim` is built (so
:class:`SimConfig` and the episode specs need no PyBullet); without it that raises
:class:`~safenav.errors.MissingDependency` with the line ``pip install "safenav[sim]"``. The
line PyBullet prints when it is imported ("pybullet build time: ...") is swallowed.

This module is longer than most (about 700 lines) because it is one class, the simulator, with
its config and state; the obstacle mesh lives in :mod:`safenav.worlds` and the base models in
:mod:`safenav.base_models`.
"""

from __future__ import annotations

import collections
import contextlib
import ctypes
import math
import operator
import os
import sys
import time
import weakref
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from types import ModuleType
from typing import Any, NamedTuple

import numpy as np

from safenav._checks import boolean, choice, integer, number, positive
from safenav._kernels import KERNELS
from safenav._optional import require
from safenav.base_models import BASE_MODELS, period_velocities
from safenav.errors import InvalidCommand, InvalidConfig, SimulatorError
from safenav.geometry import Pose2D, counter_clockwise, is_convex, unicycle_step
from safenav.robot import LidarSpec, RobotSpec, as_command
from safenav.scan import LaserScan
from safenav.seeding import generator, stream
from safenav.worlds import World, obstacle_mesh
from safenav.worlds.dynamic import DynamicWorld
from safenav.worlds.shapes import COMPILED_GAPS, RayFan

__all__ = ["BulletSim", "SimConfig", "SimState", "SimulatorError", "gui_problem", "import_pybullet", "obstacle_mesh"]


@contextlib.contextmanager
def _output_swallowed() -> Iterator[None]:
    """Send what C code prints on the standard output and error (file descriptors 1, 2) to the null device."""
    try:
        sys.stdout.flush()
        sys.stderr.flush()
        saved = [os.dup(1), os.dup(2)]
    except (OSError, ValueError, AttributeError):   # no real standard streams (an embedded interpreter)
        yield
        return
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        os.dup2(null, 2)
        yield
    finally:
        with contextlib.suppress(OSError, AttributeError, TypeError):   # TypeError: no C library handle (Windows)
            ctypes.CDLL(None).fflush(None)   # C stdio buffers what goes to a pipe: flush it while it is swallowed
        for fd, copy in zip((1, 2), saved, strict=True):
            os.dup2(copy, fd)
            os.close(copy)
        os.close(null)


def import_pybullet() -> ModuleType:
    """PyBullet, imported without the "pybullet build time" line it prints (inside progress bars, in logs).

    Imported when a simulator is built, not with this module: configs, states and everything that
    only describes episodes work without PyBullet installed.

    Raises:
        MissingDependency: PyBullet is not installed (the message gives ``pip install "safenav[sim]"``).
    """
    loaded = sys.modules.get("pybullet")
    if loaded is not None:
        return loaded
    with _output_swallowed():
        return require("pybullet", extra="sim", purpose="the PyBullet simulator")


_OBSTACLE_RGBA = (0.55, 0.55, 0.55, 1.0)
_ROBOT_RGBA = (0.17, 0.63, 0.17, 1.0)
_GOAL_RGBA = (0.58, 0.40, 0.74, 0.8)
_MOVER_RGBA = (0.84, 0.15, 0.16, 1.0)
_ABSENT_DEPTH = -1000.0   # [m]: where a moving obstacle that does not exist waits, out of every ray's reach
_HIT_FRACTION = operator.itemgetter(2)   # rayTestBatch: (object id, link, hit fraction, position, normal)
_RAY_BATCH_LIMIT = 16384   # pybullet.MAX_RAY_INTERSECTION_BATCH_SIZE: rays rayTestBatch takes in one call

#: What body the simulator's exact clearance is measured for (:attr:`SimConfig.truth`).
TRUTH_BODIES = ("auto", "disk", "footprint")


def _truth_footprint(robot: RobotSpec, truth: str) -> np.ndarray | None:
    """The convex footprint ``(V, 2)`` [m] the truth ``truth`` measures (:attr:`SimConfig.truth`); ``None`` for
    the circumscribed disk (``"disk"``, a round robot, or ``"auto"`` with a concave footprint)."""
    if truth == "disk" or robot.footprint is None:
        return None
    if is_convex(robot.footprint):
        return np.asarray(robot.footprint, dtype=float)
    if truth == "auto":
        return None
    raise InvalidConfig(f"SimConfig(truth='footprint') needs a convex footprint, got {robot.footprint!r}; "
                        "use truth='disk' (its circumscribed disk) for a concave one")


class _CastLidar(NamedTuple):
    """One lidar as the simulator casts it: its rays' place in the batch, true mount and noise."""

    lidar: LidarSpec
    beams: slice
    """Its rays in the one batch of every lidar's rays."""
    true_mount: Pose2D
    """The nominal mount with ``SimConfig.mount_yaw_error`` added to its yaw."""
    mount_offset: float
    """Distance from the base origin to the lidar [m]."""
    range_noise: float
    """Std of the Gaussian range noise [m]."""
    in_footprint: bool
    """Whether the lidar lies inside the footprint the truth measures (then, with the footprint clear of every
    obstacle, so is the lidar)."""
    template: LaserScan
    """Its scan layout (``lidar.scan()``), validated once: every scan is this with new readings."""


def _inside_convex(polygon: np.ndarray, point: tuple[float, float]) -> bool:
    """Whether ``point`` lies inside or on the convex ``polygon`` ``(V, 2)`` (either orientation)."""
    ordered = counter_clockwise(polygon)
    edges = np.roll(ordered, -1, axis=0) - ordered
    offsets = np.asarray(point, dtype=float) - ordered
    return bool(np.all(edges[:, 0] * offsets[:, 1] - edges[:, 1] * offsets[:, 0] >= 0.0))


def gui_problem() -> str | None:
    """Why the PyBullet GUI cannot open here, or ``None`` when it can (as far as can be told without opening it).

    On Linux the GUI needs an X display; without ``DISPLAY`` PyBullet would take the whole
    process down instead of raising.
    """
    if sys.platform.startswith("linux") and not os.environ.get("DISPLAY"):
        return ("the PyBullet GUI needs a display and DISPLAY is not set; run without the GUI "
                "(write a picture or a GIF instead), or under xvfb-run")
    return None


@dataclass(frozen=True)
class SimConfig:
    """Settings of :class:`BulletSim`; validated on construction.

    Attributes:
        control_dt: control period [s]: :meth:`BulletSim.step` holds a command this long.
        physics_dt: integration step [s]; ``control_dt`` must be a whole multiple of it.
        range_noise: std of the Gaussian range noise [m]; ``None`` takes the preset's
            ``lidar.noise_std``.
        dropout: probability that a beam reads ``NaN``, in ``[0, 1)``.
        actuation_noise: std of the *relative* noise on the executed ``(v, omega)``
            (0.05 means 5 %), one draw per control period and axis.
        command_latency: control periods between a command and its execution.
        scan_latency: control periods between a scan's acquisition and its delivery.
        mount_yaw_error: true lidar yaw minus the yaw the scan reports [rad].
        gui: open the PyBullet GUI instead of running headless.
        gui_realtime: with the GUI, pace the simulation to the wall clock.
        num_threads: threads for ``rayTestBatch`` (0 = all cores).
        cylinder_tolerance: largest gap between a cylinder and the polygon the lidar sees [m].
        base: how the base's velocity follows a command (:mod:`safenav.base_models`):

            * ``"ramp_limit"`` (default): it tracks the command at the acceleration limits,
              updated at every physics step;
            * ``"instant"``: it equals the command at once;
            * ``"ramp"``: it moves linearly from the period's start velocity to the command
              over the whole control period, whatever the acceleration;
            * ``"lag"``: first-order lag ``dv/dt = (command - v) / base_time_constant``,
              integrated exactly over each physics step.
        base_time_constant: time constant of the ``"lag"`` base [s]; ``control_dt`` when ``None``.
        truth: what body the exact clearance (:meth:`BulletSim.clearance`, collisions, ``min_clearance``)
            is measured for: ``"footprint"`` (the robot's convex ``footprint`` polygon, turning with the
            heading: what touches an obstacle, and the guarantee of the filters, which keep it clear with
            their disk, or with the cover of the footprint in a narrow gap; a robot without a footprint is
            round, and keeps its disk), ``"disk"`` (the circumscribed disk of radius ``robot.radius``), or
            ``"auto"`` (default): the footprint when it is convex, else the disk (a concave footprint's
            exact clearance is not implemented; its circumscribed disk over-reports contacts).
        kernels: how the body's exact clearance (footprint or disk) is computed, and how far the rays are cast:
            ``"auto"`` (default: numba's compiled loops when numba is installed, ``pip install "safenav[fast]"``;
            ``SAFENAV_KERNELS=numpy`` or ``numba`` decides for a whole process), ``"numba"`` or ``"numpy"`` (the
            reference: full-length rays); the same clearances, the same hits, the ranges to Bullet's rounding
            (3e-13 m measured). A closed loop amplifies such differences: an episode driven by a filter is the
            same for the same seed and setting, and its continuous outcomes (rarely a discrete one) may differ
            between the two settings.
    """

    control_dt: float = 0.05
    physics_dt: float = 0.01
    range_noise: float | None = None
    dropout: float = 0.0
    actuation_noise: float = 0.0
    command_latency: int = 0
    scan_latency: int = 0
    mount_yaw_error: float = 0.0
    gui: bool = False
    gui_realtime: bool = True
    num_threads: int = 1
    cylinder_tolerance: float = 0.001
    base: str = BASE_MODELS[0]
    base_time_constant: float | None = None
    truth: str = "auto"
    kernels: str = "auto"

    def __post_init__(self) -> None:
        put = object.__setattr__
        put(self, "control_dt", positive("SimConfig.control_dt", self.control_dt))
        put(self, "physics_dt", positive("SimConfig.physics_dt", self.physics_dt))
        ratio = self.control_dt / self.physics_dt
        if ratio < 1.0 - 1e-9 or abs(ratio - round(ratio)) > 1e-6 * ratio:
            raise InvalidConfig(f"SimConfig.control_dt={self.control_dt!r} must be a whole multiple of "
                                f"physics_dt={self.physics_dt!r} (ratio {ratio:.6g})")
        if self.range_noise is not None:
            put(self, "range_noise", number("SimConfig.range_noise", self.range_noise, low=0.0))
        put(self, "dropout", number("SimConfig.dropout", self.dropout, low=0.0, high=1.0, high_open=True))
        put(self, "actuation_noise", number("SimConfig.actuation_noise", self.actuation_noise, low=0.0))
        put(self, "command_latency", integer("SimConfig.command_latency", self.command_latency, low=0))
        put(self, "scan_latency", integer("SimConfig.scan_latency", self.scan_latency, low=0))
        put(self, "mount_yaw_error", number("SimConfig.mount_yaw_error", self.mount_yaw_error, low=-math.pi,
                                            high=math.pi))
        put(self, "gui", boolean("SimConfig.gui", self.gui))
        put(self, "gui_realtime", boolean("SimConfig.gui_realtime", self.gui_realtime))
        put(self, "num_threads", integer("SimConfig.num_threads", self.num_threads, low=0))
        put(self, "kernels", choice("SimConfig.kernels", self.kernels, KERNELS))
        put(self, "cylinder_tolerance", positive("SimConfig.cylinder_tolerance", self.cylinder_tolerance))
        put(self, "base", choice("base model (SimConfig.base)", self.base, BASE_MODELS))
        if self.base_time_constant is not None:
            put(self, "base_time_constant", positive("SimConfig.base_time_constant", self.base_time_constant))
        put(self, "truth", choice("clearance body (SimConfig.truth)", self.truth, TRUTH_BODIES))

    @property
    def time_constant(self) -> float:
        """Time constant of the ``"lag"`` base [s]: ``base_time_constant``, or ``control_dt`` when that is ``None``."""
        return self.control_dt if self.base_time_constant is None else self.base_time_constant

    @property
    def substeps(self) -> int:
        """Physics steps per control period."""
        return round(self.control_dt / self.physics_dt)


@dataclass(frozen=True, eq=False)
class SimState:
    """What the simulator reports after a reset or a step.

    ``scan`` is what the robot senses, ``velocity`` stands for its odometry and ``pose``
    for the localisation a goal-seeking policy needs. ``clearance``, ``collided``,
    ``first_collision_time`` and ``min_clearance`` are truth for metrics and tests:
    safety filters must never read them.

    Attributes:
        time: simulated time since the reset [s].
        pose: pose of the base [m, m, rad].
        velocity: actual ``(v [m/s], omega [rad/s])`` over the last physics step (read-only).
        scan: the main lidar's delivered scan; ``stamp`` is its acquisition time [s] and
            ``mount`` the nominal ``robot.lidar.mount``.
        clearance: signed body clearance to the nearest obstacle [m] (negative: overlap).
        collided: the body overlaps an obstacle now.
        first_collision_time: time of the first physics step with an overlap since the reset [s].
        min_clearance: smallest clearance over the physics steps of the last control period [m].
        command: the command the base tracked during the last period, after clipping to the
            velocity limits and the command latency [m/s, rad/s] (read-only).
        steps: control periods since the reset.
        scans: the delivered scans of every lidar of ``robot.lidars``, main first (``scan`` is
            ``scans[0]``), with one stamp and each its lidar's nominal mount and ``frame_id``.
    """

    time: float
    pose: Pose2D
    velocity: np.ndarray
    scan: LaserScan
    clearance: float
    collided: bool
    first_collision_time: float | None
    min_clearance: float
    command: np.ndarray
    steps: int
    scans: tuple[LaserScan, ...]


def _disconnect(bullet: ModuleType, client: int) -> None:
    with contextlib.suppress(bullet.error):   # already gone
        bullet.disconnect(physicsClientId=client)


class BulletSim:
    """A differential-drive robot with a 2D lidar in a :class:`~safenav.worlds.World`, in PyBullet.

    Gymnasium-like: :meth:`reset` returns the first :class:`SimState`, :meth:`step` holds
    a command for one control period and returns the next. Use it as a context manager
    (or call :meth:`close`) to release the PyBullet connection.

    Args:
        world: the world to build.
        robot: the robot (body radius, limits, lidars: every one of ``robot.lidars`` is cast).
        config: simulator settings.
        seed: the episode's seed (:mod:`safenav.seeding`): range noise and dropout draw from
            its ``sensor`` stream (extra lidars from that stream's children), actuation noise
            from its ``actuation`` stream; ``None`` draws fresh entropy.

    Raises:
        InvalidConfig: a bad argument, or a lidar that scans above the obstacles.
        SimulatorError: the GUI was asked for on Linux without a display (``DISPLAY`` unset).
    """

    def __init__(self, world: World, robot: RobotSpec, config: SimConfig = SimConfig(), *,
                 seed: int | None = None) -> None:
        if not isinstance(world, World):
            raise InvalidConfig(f"BulletSim: world must be a safenav.worlds.World, got {world!r}")
        if not isinstance(robot, RobotSpec):
            raise InvalidConfig(f"BulletSim: robot must be a RobotSpec, got {robot!r}")
        if not isinstance(config, SimConfig):
            raise InvalidConfig(f"BulletSim: config must be a SimConfig, got {config!r}")
        for lidar in robot.lidars:
            if lidar.height >= world.obstacle_height:
                raise InvalidConfig(f"BulletSim: lidar {lidar.frame_id!r} scans at {lidar.height} m, above the "
                                    f"obstacles of world {world.name!r} ({world.obstacle_height} m); "
                                    "expected a lower lidar")
        problem = gui_problem() if config.gui else None
        if problem is not None:
            raise SimulatorError(problem)
        self.world = world
        self.robot = robot
        self.config = config
        self._seed(seed)
        self._bullet = pybullet = import_pybullet()
        self._client = pybullet.connect(pybullet.GUI if config.gui else pybullet.DIRECT)
        if self._client < 0:
            raise SimulatorError("could not connect to PyBullet" + (" (GUI needs a display)" if config.gui else ""))
        self._finalizer = weakref.finalize(self, _disconnect, self._bullet, self._client)
        self._obstacle_body = self._build_obstacles()
        self._movers = world.movers if isinstance(world, DynamicWorld) else ()
        self._footprint = _truth_footprint(robot, config.truth)
        # The body's exact clearance (footprint or disk), and rays shortened to just past what they first meet (see
        # _short_rays): compiled when the setting selects numba's kernels.
        shortened = bool(world.obstacles) and not self._movers
        compiled = COMPILED_GAPS.select(config.kernels) if self._footprint is not None or world.obstacles else None
        self._gap_kernels = compiled    # the truth's clearance (footprint or disk)
        self._ray_kernels = compiled if shortened else None
        self.ray_counts = {"cast": 0, "shortened": 0, "recast": 0}
        """Rays cast so far, how many of them shortened to where they first meet an obstacle, and how many of those
        cast again at full length (:meth:`_short_rays`)."""
        self._mover_bodies = [self._build_mover(mover.shape) for mover in self._movers]
        self._robot_body = self._build_robot()
        self._probe = pybullet.createCollisionShape(pybullet.GEOM_SPHERE, radius=robot.radius,
                                                    physicsClientId=self._client)
        self._build_rays()
        self._last_cast: tuple[Pose2D | None, np.ndarray] = (None, np.ones(len(self._ray_starts)))
        if config.gui:
            self._set_up_gui()
        self._state: SimState | None = None

    # ------------------------------------------------------------------ construction

    def _seed(self, seed: int | None) -> None:
        extra = len(self.robot.extra_lidars)
        children = stream(seed, "sensor").spawn(extra) if extra else []
        self._sensor_rngs = [generator(seed, "sensor"), *(np.random.default_rng(child) for child in children)]
        self._actuation_rng = generator(seed, "actuation")

    def _build_obstacles(self) -> int | None:
        if not self.world.obstacles:
            return None
        pybullet, client = self._bullet, self._client
        vertices, indices = obstacle_mesh(self.world, tolerance=self.config.cylinder_tolerance)
        shape = pybullet.createCollisionShape(pybullet.GEOM_MESH, vertices=vertices.tolist(),
                                              indices=indices.ravel().tolist(), physicsClientId=client)
        visual_vertices, visual_indices = obstacle_mesh(self.world, tolerance=self.config.cylinder_tolerance,
                                                        caps=True)
        visual = pybullet.createVisualShape(pybullet.GEOM_MESH, vertices=visual_vertices.tolist(),
                                            indices=visual_indices.ravel().tolist(), rgbaColor=_OBSTACLE_RGBA,
                                            physicsClientId=client)
        if shape < 0 or visual < 0:
            raise SimulatorError(f"PyBullet could not build the obstacle mesh of world {self.world.name!r}")
        return pybullet.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=shape, baseVisualShapeIndex=visual,
                                        physicsClientId=client)

    def _build_mover(self, shape: Any) -> int:
        """One body per moving obstacle: its prism around the body origin, moved before every scan."""
        pybullet, client = self._bullet, self._client
        footprint = World("mover", (shape,), obstacle_height=self.world.obstacle_height)
        vertices, indices = obstacle_mesh(footprint, tolerance=self.config.cylinder_tolerance)
        collision = pybullet.createCollisionShape(pybullet.GEOM_MESH, vertices=vertices.tolist(),
                                                  indices=indices.ravel().tolist(), physicsClientId=client)
        if collision < 0:
            raise SimulatorError(f"PyBullet could not build the mesh of the moving obstacle {shape!r}")
        visual = -1
        if self.config.gui:
            visual_vertices, visual_indices = obstacle_mesh(footprint, tolerance=self.config.cylinder_tolerance,
                                                            caps=True)
            visual = pybullet.createVisualShape(pybullet.GEOM_MESH, vertices=visual_vertices.tolist(),
                                                indices=visual_indices.ravel().tolist(), rgbaColor=_MOVER_RGBA,
                                                physicsClientId=client)
        return pybullet.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=collision,
                                        baseVisualShapeIndex=visual, physicsClientId=client)

    def _place_movers(self, time: float) -> None:
        """Put every moving obstacle where it is at ``time`` [s]; one that does not exist goes far below the floor."""
        for mover, body in zip(self._movers, self._mover_bodies, strict=True):
            x, y = mover.position(time)
            z = 0.0 if mover.present(time) else _ABSENT_DEPTH
            self._bullet.resetBasePositionAndOrientation(body, [x, y, z], [0.0, 0.0, 0.0, 1.0],
                                                         physicsClientId=self._client)

    def _build_robot(self) -> int:
        """A body with a visual shape only: it carries the lidar frame and shows the robot in the GUI."""
        robot, client, pybullet = self.robot, self._client, self._bullet
        visual = pybullet.createVisualShapeArray(
            shapeTypes=[pybullet.GEOM_CYLINDER, pybullet.GEOM_BOX],
            radii=[robot.radius, 0.0],
            lengths=[robot.height, 0.0],
            halfExtents=[[0.0, 0.0, 0.0], [0.5 * robot.radius, 0.015, 0.01]],
            visualFramePositions=[[0.0, 0.0, 0.5 * robot.height], [0.5 * robot.radius, 0.0, robot.height + 0.01]],
            rgbaColors=[list(_ROBOT_RGBA), [0.1, 0.1, 0.1, 1.0]],
            physicsClientId=client,
        )
        return pybullet.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=-1, baseVisualShapeIndex=visual,
                                        physicsClientId=client)

    def _build_rays(self) -> None:
        """Ray end points in the robot body frame, every lidar's through its true mount, one per beam."""
        starts, ends, cast = [], [], []
        for lidar in self.robot.lidars:
            mount, first, template = lidar.mount, len(starts), lidar.scan()
            directions = template.angles + mount.yaw + self.config.mount_yaw_error
            starts += [[mount.x, mount.y, lidar.height]] * lidar.n_beams
            ends += np.column_stack((mount.x + lidar.range_max * np.cos(directions),
                                     mount.y + lidar.range_max * np.sin(directions),
                                     np.full(lidar.n_beams, lidar.height))).tolist()
            cast.append(_CastLidar(
                lidar=lidar, beams=slice(first, first + lidar.n_beams),
                true_mount=Pose2D(mount.x, mount.y, mount.yaw + self.config.mount_yaw_error),
                mount_offset=math.hypot(mount.x, mount.y),
                range_noise=lidar.noise_std if self.config.range_noise is None else self.config.range_noise,
                in_footprint=self._footprint is not None and _inside_convex(self._footprint, (mount.x, mount.y)),
                template=template,
            ))
        self._cast_lidars = tuple(cast)
        self._ray_starts = np.array(starts, dtype=float).reshape(-1, 3)
        self._ray_ends = np.array(ends, dtype=float).reshape(-1, 3)
        along = self._ray_ends[:, :2] - self._ray_starts[:, :2]
        lengths = np.hypot(along[:, 0], along[:, 1])
        self._rays = RayFan(
            mounts=np.array([(c.true_mount.x, c.true_mount.y, c.lidar.angle_min + c.true_mount.yaw) for c in cast]),
            increments=np.array([c.lidar.angle_increment for c in cast]),
            counts=np.array([c.lidar.n_beams for c in cast], dtype=np.intp),
            directions=np.ascontiguousarray(along / lengths[:, None]), lengths=lengths)
        # The rays' directions in three dimensions (horizontal), for a shortened ray's end point.
        self._ray_directions = np.column_stack((self._rays.directions, np.zeros(len(lengths))))

    def _set_up_gui(self) -> None:
        pybullet, client = self._bullet, self._client
        xmin, ymin, xmax, ymax = self.world.bounds
        floor = pybullet.createVisualShape(pybullet.GEOM_BOX,
                                           halfExtents=[0.5 * (xmax - xmin), 0.5 * (ymax - ymin), 0.005],
                                           rgbaColor=[0.92, 0.92, 0.88, 1.0], physicsClientId=client)
        pybullet.createMultiBody(0.0, -1, floor, basePosition=[0.5 * (xmin + xmax), 0.5 * (ymin + ymax), -0.005],
                                 physicsClientId=client)
        if self.world.goal is not None:
            marker = pybullet.createVisualShape(pybullet.GEOM_SPHERE, radius=0.1, rgbaColor=_GOAL_RGBA,
                                                physicsClientId=client)
            pybullet.createMultiBody(0.0, -1, marker, basePosition=[*self.world.goal, 0.1], physicsClientId=client)
        pybullet.configureDebugVisualizer(pybullet.COV_ENABLE_GUI, 0, physicsClientId=client)
        pybullet.resetDebugVisualizerCamera(cameraDistance=0.8 * max(xmax - xmin, ymax - ymin), cameraYaw=0.0,
                                            cameraPitch=-70.0,
                                            cameraTargetPosition=[0.5 * (xmin + xmax), 0.5 * (ymin + ymax), 0.0],
                                            physicsClientId=client)

    # ------------------------------------------------------------------ properties

    @property
    def client_id(self) -> int:
        """The PyBullet physics client id (for extra queries; do not move the bodies)."""
        return self._client

    @property
    def obstacle_body(self) -> int | None:
        """PyBullet id of the static obstacle mesh, ``None`` in a world without obstacles."""
        return self._obstacle_body

    @property
    def state(self) -> SimState:
        """The latest state.

        Raises:
            SimulatorError: before the first :meth:`reset`.
        """
        if self._state is None:
            raise SimulatorError("BulletSim has no state yet; call reset() first")
        return self._state

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` was called."""
        return not self._finalizer.alive

    # ------------------------------------------------------------------ truth

    def clearance(self, pose: Pose2D | Sequence[float] | None = None, time: float | None = None) -> float:
        """Exact signed body clearance at ``pose`` (the current pose by default) [m].

        Args:
            pose: the base pose (or, with the disk truth, its position) [m, m, rad].
            time: where the moving obstacles are [s]; the current time by default.
        """
        return self._truth(self.state.pose if pose is None else pose, self.state.time if time is None else time)

    def _truth(self, pose: Pose2D | Sequence[float], time: float) -> float:
        """Exact signed body clearance at ``pose`` with the moving obstacles where they are at ``time`` [m]."""
        if self._footprint is not None:
            if len(pose) != 3:
                raise InvalidConfig(f"BulletSim.clearance: with SimConfig(truth='footprint') the pose needs its yaw "
                                    f"(x [m], y [m], yaw [rad]): the footprint turns with it; got {tuple(pose)!r}")
            return self._truths([Pose2D(*pose)], [time])[0]
        return self._disk_truth(pose, time)

    def _disk_truth(self, position: Pose2D | Sequence[float], time: float) -> float:
        """Exact signed clearance of the body disk at ``position`` at ``time`` [m]."""
        if self._movers:
            return self.world.clearance_at(position, self.robot.radius, time)
        return self.world.clearance(position, self.robot.radius, self._gap_kernels)

    def _truths(self, poses: Sequence[Pose2D], times: Sequence[float]) -> list[float]:
        """:meth:`_truth` at each of ``poses`` and ``times``; in a static world in one evaluation (the same values)."""
        if self._footprint is not None:
            placed = np.array([(pose.x, pose.y, pose.yaw) for pose in poses], dtype=float).reshape(-1, 3)
            if self._movers:
                return [float(self.world.footprint_clearance_at(row[None], self._footprint, time)[0])
                        for row, time in zip(placed, times, strict=True)]
            return self.world.footprint_clearance(placed, self._footprint, self._gap_kernels).tolist()
        if self._movers:
            return [self._disk_truth(pose, time) for pose, time in zip(poses, times, strict=True)]
        positions = np.array([(pose.x, pose.y) for pose in poses], dtype=float).reshape(-1, 2)
        return (self.world.signed_distance(positions, self._gap_kernels) - self.robot.radius).tolist()

    def bullet_clearance(self, pose: Pose2D | Sequence[float] | None = None, max_distance: float = 2.0) -> float:
        """Body clearance at ``pose`` measured by PyBullet's ``getClosestPoints`` [m].

        A sphere of the body radius at the lidar height is tested against the obstacle
        mesh; on vertical prisms that equals the clearance of the body disk, up to the
        cylinder polygon tolerance (the polygon is larger, so the value is smaller).
        For cross-checks of :meth:`clearance`; moving obstacles are not included.

        Args:
            pose: the base pose (or position); the current pose by default.
            max_distance: only obstacles closer than this are considered [m].

        Returns:
            The smallest signed distance found, ``inf`` when nothing is within ``max_distance``.
        """
        self._check_open()
        if self._obstacle_body is None:
            return math.inf
        position = self.state.pose if pose is None else pose
        pybullet = self._bullet
        points = pybullet.getClosestPoints(bodyA=-1, bodyB=self._obstacle_body, distance=float(max_distance),
                                           collisionShapeA=self._probe,
                                           collisionShapePositionA=[float(position[0]), float(position[1]),
                                                                    self.robot.lidar.height],
                                           physicsClientId=self._client)
        return min((point[8] for point in points), default=math.inf)

    # ------------------------------------------------------------------ lidar

    def scan(self, pose: Pose2D | Sequence[float] | None = None, *, stamp: float | None = None) -> LaserScan:
        """Cast one scan of the main lidar with the base at ``pose`` (the current pose by default).

        Time does not advance. Every lidar is cast and draws its noise (see :meth:`scans`);
        the main lidar's scan is returned.

        Args:
            pose: the base pose [m, m, rad].
            stamp: acquisition time to put in the scan [s]; the current time by default
                (``None`` before the first reset).
        """
        return self.scans(pose, stamp=stamp)[0]

    def scans(self, pose: Pose2D | Sequence[float] | None = None, *,
              stamp: float | None = None) -> tuple[LaserScan, ...]:
        """Cast one scan of every lidar of ``robot.lidars`` (main first) with the base at ``pose``.

        Time does not advance. Noise and dropout are drawn from the simulator's generators,
        as in :meth:`step`.

        Args:
            pose: the base pose [m, m, rad]; the current pose by default.
            stamp: acquisition time to put in the scans [s]; the current time by default
                (``None`` before the first reset).
        """
        self._check_open()
        if pose is None:
            pose = self.state.pose
        if stamp is None and self._state is not None:
            stamp = self._state.time
        return self._cast(Pose2D(*pose), stamp)

    def _cast(self, pose: Pose2D, stamp: float | None, clearance: float | None = None) -> tuple[LaserScan, ...]:
        """One ray batch from every true mount with the base at ``pose``; ``clearance`` at ``pose`` if known."""
        fractions = self._hit_fractions(pose, 0.0 if stamp is None else stamp)
        return tuple(self._readings(cast, rng, fractions[cast.beams], pose, stamp, clearance)
                     for cast, rng in zip(self._cast_lidars, self._sensor_rngs, strict=True))

    def _hit_fractions(self, pose: Pose2D, time: float) -> np.ndarray:
        """Every ray's hit fraction (1 for none) with the base at ``pose`` and the movers where they are at ``time``.

        In a world without moving obstacles the rays of the same pose hit the same points: a base that
        has not moved (exactly the same pose: stopped, or held by the filter) reuses the last batch's
        fractions instead of casting again; the noise is drawn afresh as always, so the scans and the
        random streams are those of a new cast (about a fifth of the periods of the collision sweep).
        """
        if not self._movers and pose == self._last_cast[0]:
            return self._last_cast[1]
        half_yaw = 0.5 * pose.yaw
        pybullet = self._bullet
        if self._movers:
            self._place_movers(time)
        pybullet.resetBasePositionAndOrientation(self._robot_body, [pose.x, pose.y, 0.0],
                                                 [0.0, 0.0, math.sin(half_yaw), math.cos(half_yaw)],
                                                 physicsClientId=self._client)
        if self._ray_kernels is None:
            fractions = self._ray_batch(self._ray_starts, self._ray_ends)
            self.ray_counts["cast"] += fractions.size
        else:
            fractions = self._short_rays(pose)
        fractions.flags.writeable = False
        self._last_cast = (pose, fractions)
        return fractions

    def _short_rays(self, pose: Pose2D) -> np.ndarray:
        """Every ray's hit fraction (of its full length), the rays cast only as far as they must reach.

        A ray's cost in PyBullet grows with its length (the mesh's tree is walked along all of it), and most of
        a lidar's rays end far short of ``range_max``. Each ray is cast to just past where it first meets the
        exact boxes and circles of the world (:meth:`~safenav.worlds.World.ray_reach`; the mesh's polygon of a
        cylinder holds the circle, so it is met no farther along): a ray that hits within that length hits
        exactly what the full ray hits first; one that does not (it starts inside an obstacle, it grazes a
        corner) is cast again at full length. The hit fraction is then rescaled to the full length: the same
        ranges as full rays to Bullet's rounding (3.3e-13 m measured; ``tests/test_sim_bullet.py`` allows 1e-6 m,
        single precision).
        """
        rays = self._rays
        lengths = rays.lengths
        reach = self.world.ray_reach(pose, rays, self._ray_kernels)
        shortened = reach < lengths
        ends = self._ray_directions * reach[:, None]
        ends += self._ray_starts
        fractions = self._ray_batch(self._ray_starts, ends)
        missed = shortened & (fractions >= 1.0)
        fractions = np.where(shortened, fractions * reach / lengths, fractions)
        counts = self.ray_counts
        counts["cast"] += lengths.size
        counts["shortened"] += int(np.count_nonzero(shortened))
        counts["recast"] += int(np.count_nonzero(missed))
        if missed.any():
            fractions[missed] = self._ray_batch(self._ray_starts[missed], self._ray_ends[missed])
        return fractions

    def _ray_batch(self, starts: Any, ends: Any) -> np.ndarray:
        """``rayTestBatch`` over the rays ``starts`` -> ``ends`` (the robot's body frame), in batches it accepts:
        their hit fractions, 1 for none."""
        pybullet = self._bullet
        hits: list[Any] = []
        for first in range(0, len(starts), _RAY_BATCH_LIMIT):
            last = first + _RAY_BATCH_LIMIT
            hits += pybullet.rayTestBatch(starts[first:last], ends[first:last], numThreads=self.config.num_threads,
                                          parentObjectUniqueId=self._robot_body, physicsClientId=self._client)
        return np.fromiter(map(_HIT_FRACTION, hits), dtype=float, count=len(starts))

    def _readings(self, cast: _CastLidar, rng: np.random.Generator, fraction: np.ndarray, pose: Pose2D,
                  stamp: float | None, clearance: float | None) -> LaserScan:
        """One lidar's scan from its rays' hit fractions: sensor-inside, noise, range limits, dropout."""
        lidar = cast.lidar
        n = lidar.n_beams
        ranges = np.where(fraction < 1.0, fraction * lidar.range_max, math.inf)
        if self._sensor_inside(cast, pose, clearance, 0.0 if stamp is None else stamp):
            ranges[:] = -math.inf   # rays from inside a closed mesh would report its far side
        if cast.range_noise > 0.0:
            ranges += cast.range_noise * rng.standard_normal(n)   # +-inf stay +-inf
        ranges[ranges > lidar.range_max] = math.inf
        ranges[ranges < lidar.range_min] = -math.inf
        if self.config.dropout > 0.0:
            ranges[rng.random(n) < self.config.dropout] = math.nan
        return cast.template.with_ranges(ranges, stamp=stamp)

    def _sensor_inside(self, cast: _CastLidar, pose: Pose2D, clearance: float | None, time: float) -> bool:
        """Whether the lidar sits inside an obstacle at ``time`` (only possible when the body overlaps one)."""
        if clearance is not None and (clearance >= 0.0 if cast.in_footprint else
                                      self._footprint is None and clearance >= cast.mount_offset - self.robot.radius):
            return False
        sensor = pose.compose(cast.true_mount)
        return self._disk_truth((sensor.x, sensor.y), time) + self.robot.radius < 0.0

    # ------------------------------------------------------------------ episode

    def reset(self, seed: int | None = None, start: Pose2D | Sequence[float] | None = None) -> SimState:
        """Put the robot at rest at ``start`` (the world's start by default) and scan.

        Args:
            seed: reseed the noise from this episode seed (as the constructor does); ``None``
                continues the current generator (so a sequence of episodes after one seeded
                reset is reproducible).
            start: the start pose [m, m, rad].

        Returns:
            The state at time 0. It may already be in collision if ``start`` is.
        """
        self._check_open()
        if seed is not None:
            self._seed(seed)
        pose = self.world.start if start is None else Pose2D(*(float(v) for v in start))
        config = self.config
        self._pose = pose
        self._tracked = np.zeros(2)
        self._velocity = np.zeros(2)
        self._physics_steps = 0
        self._steps = 0
        self._commands = collections.deque([np.zeros(2)] * config.command_latency)
        clearance = self._truth(pose, 0.0)
        self._first_collision = 0.0 if clearance < 0.0 else None
        scans = self._cast(pose, 0.0, clearance)
        self._scans = collections.deque([scans] * (config.scan_latency + 1), maxlen=config.scan_latency + 1)
        self._wall_start = time.perf_counter()
        self._state = self._make_state(scans, clearance, clearance, np.zeros(2))
        return self._state

    def step(self, u: Any) -> SimState:
        """Hold the command ``u = (v [m/s], omega [rad/s])`` for one control period.

        Raises:
            InvalidCommand: ``u`` is not a pair of finite numbers.
            SimulatorError: before :meth:`reset` or after :meth:`close`.
        """
        self._check_open()
        if self._state is None:
            raise SimulatorError("BulletSim.step() before reset(); call reset() first")
        command = as_command(u)
        if not np.all(np.isfinite(command)):
            raise InvalidCommand(f"u must be finite, got {tuple(command)}")
        robot, config = self.robot, self.config
        command = robot.clip(command)
        if config.command_latency:
            self._commands.append(command)
            command = self._commands.popleft()
        factor = None
        if config.actuation_noise > 0.0:
            factor = 1.0 + config.actuation_noise * self._actuation_rng.standard_normal(2)
        dt = config.physics_dt
        ends, means = period_velocities(config.base, robot, self._tracked, command, period=config.control_dt,
                                         substeps=config.substeps, time_constant=config.time_constant)
        executed = means if factor is None else means * factor
        pose = self._pose
        poses = []
        for v, omega in executed.tolist():
            pose = unicycle_step(pose, v, omega, dt)
            poses.append(pose)
        first = self._physics_steps + 1
        self._physics_steps += len(poses)
        if not self._movers and all(moved == self._pose for moved in poses):
            clearances = [self._state.clearance] * len(poses)     # at rest in a static world: nothing changed
        else:
            clearances = self._truths(poses, [(first + k) * dt for k in range(len(poses))])
        min_clearance = min(clearances)
        clearance = clearances[-1]
        if self._first_collision is None:
            hit = next((k for k, value in enumerate(clearances) if value < 0.0), None)
            if hit is not None:
                self._first_collision = (first + hit) * dt
        # The base model carries on from the velocity it reached; the noise factor is not part of its state.
        self._pose, self._tracked = pose, ends[-1]
        self._velocity = ends[-1] if factor is None else ends[-1] * factor
        self._steps += 1
        now = self._physics_steps * dt
        self._scans.append(self._cast(pose, now, clearance))
        if config.gui and config.gui_realtime:
            lag = self._wall_start + now - time.perf_counter()
            if lag > 0.0:
                time.sleep(lag)
        self._state = self._make_state(self._scans[0], clearance, min_clearance, command)
        return self._state

    def _make_state(self, scans: tuple[LaserScan, ...], clearance: float, min_clearance: float,
                    command: np.ndarray) -> SimState:
        velocity = np.array(self._velocity, dtype=float)
        velocity.flags.writeable = False
        command = np.array(command, dtype=float)
        command.flags.writeable = False
        return SimState(
            time=self._physics_steps * self.config.physics_dt,
            pose=self._pose,
            velocity=velocity,
            scan=scans[0],
            clearance=clearance,
            collided=clearance < 0.0,
            first_collision_time=self._first_collision,
            min_clearance=min_clearance,
            command=command,
            steps=self._steps,
            scans=scans,
        )

    # ------------------------------------------------------------------ lifetime

    def _check_open(self) -> None:
        if not self._finalizer.alive:
            raise SimulatorError("BulletSim is closed")

    def close(self) -> None:
        """Disconnect from PyBullet; safe to call twice."""
        self._finalizer()

    def __enter__(self) -> BulletSim:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def __repr__(self) -> str:
        status = "closed" if self.closed else f"t={self._state.time:.3f} s" if self._state else "not reset"
        return f"BulletSim(world={self.world.name!r}, robot={self.robot.name!r}, {status})"
