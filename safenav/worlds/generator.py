"""Seeded worlds: random arenas, a room split by a wall with one door, a U-shaped dead end.

* :func:`random_world`: walls around, obstacles of mixed shapes, corridors, narrow passages,
  a reachable goal;
* :func:`door_world`: a walled room split by a wall with one door of a given width, the start
  in front of the wall and the goal behind it;
* :func:`dead_end_world`: a walled room with a U-shaped trap whose mouth faces the start and
  whose closed end hides the goal.

Each draws everything from the ``world`` stream of its seed (:mod:`safenav.seeding`), so
``random_world(seed, robot)`` is the world of episode ``seed``; :func:`reachable` checks on a
grid that the body disk can get from one point to another.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from safenav._checks import integer, number, pair
from safenav.errors import InvalidConfig
from safenav.geometry import Pose2D
from safenav.robot import RobotSpec
from safenav.seeding import generator
from safenav.worlds.shapes import WALL_THICKNESS, Box, Cylinder, Obstacle, Wall, gap, primitive, room
from safenav.worlds.world import World

__all__ = ["GRID_RESOLUTION", "START_CLEARANCE", "dead_end_world", "door_world", "random_world", "reachable"]

START_CLEARANCE = 0.3
"""Body clearance that :func:`random_world` keeps free around the start and the goal [m]."""

GRID_RESOLUTION = 0.04
"""Cell size of the grid on which :func:`random_world` checks that the goal is reachable [m]."""


class _Placer:
    """Accepts obstacles one by one if they keep a gap to everything placed so far."""

    def __init__(self, min_gap: float) -> None:
        self.min_gap = min_gap
        self.obstacles: list[Obstacle] = []
        self._primitives: list[Box | Cylinder] = []
        self._reach: list[tuple[float, float, float]] = []   # centre and circumscribed radius

    def fits(self, candidate: Obstacle) -> bool:
        shape = primitive(candidate)
        cx, cy = shape.center
        reach = shape.radius
        for other, (ox, oy, oreach) in zip(self._primitives, self._reach, strict=True):
            if math.hypot(cx - ox, cy - oy) - reach - oreach >= self.min_gap:
                continue
            if gap(shape, other) < self.min_gap:
                return False
        return True

    def add(self, *obstacles: Obstacle) -> None:
        for obstacle in obstacles:
            shape = primitive(obstacle)
            self.obstacles.append(obstacle)
            self._primitives.append(shape)
            self._reach.append((*shape.center, shape.radius))


def random_world(
    seed: int,
    robot: RobotSpec,
    *,
    n_obstacles: int = 30,
    size: tuple[float, float] = (10.0, 10.0),
    min_gap: float | None = None,
    corridors: int = 0,
    narrow_passages: int = 0,
    goal: bool = False,
    obstacle_size: tuple[float, float] = (0.2, 0.8),
    max_tries: int = 2000,
) -> World:
    """A seeded random arena: walls around, obstacles of mixed shapes, corridors and narrow passages.

    The arena's free interior is ``[-w/2, w/2] x [-h/2, h/2]`` for ``size = (w, h)``,
    closed by walls. The builder places, in this order, all from the ``world`` stream of
    ``seed`` (:func:`safenav.seeding.generator`) so the same arguments give the same world:

    1. ``narrow_passages`` dividing walls across the longer side, evenly spaced (with
       jitter), each with one door ``2 * robot.radius + U(0.12, 0.3)`` m wide;
    2. ``corridors`` corridors: two parallel walls ``U(1.5, 3)`` m long (at most half the
       shorter side) with ``2 * robot.radius + U(0.25, 0.5)`` m between them, at a random
       position and heading;
    3. the start pose (random position and heading) with at least
       :data:`START_CLEARANCE` of body clearance, in the first strip when there are
       dividers; with ``goal=True`` the goal, as clear, at least half the shorter side away
       from the start (in the last strip when there are dividers);
    4. ``n_obstacles`` obstacles, each a box (sides ``U(*obstacle_size)``, random yaw) or a
       cylinder (diameter ``U(*obstacle_size)``) with equal odds, that keep the start and
       goal clear.

    Every obstacle keeps at least ``min_gap`` from every other obstacle and wall (the two
    walls of a corridor, and a divider where it meets the arena, excepted), so with the
    default ``min_gap`` the robot fits between any two obstacles. The obstacle density is
    ``n_obstacles / (w * h)``; ``obstacle_size`` sets how much of the floor they cover.
    With ``goal=True`` the goal is checked to be reachable by the body disk (a 4-connected
    path on a :data:`GRID_RESOLUTION` grid whose cells keep half a cell of clearance); a
    world that fails the check is drawn again from the same generator.

    Args:
        seed: the episode's seed, an integer >= 0 (the world draws from its ``world`` stream).
        robot: the robot the world is for (its radius sets gaps, doors and clearances).
        n_obstacles: number of free-standing obstacles.
        size: free interior ``(w, h)`` of the arena [m].
        min_gap: smallest free gap between two obstacles or an obstacle and a wall [m];
            default ``2 * robot.radius + 0.1``.
        corridors: number of corridors.
        narrow_passages: number of dividing walls, each with a narrow door.
        goal: whether to place a reachable goal.
        obstacle_size: smallest and largest obstacle extent (box side, cylinder diameter) [m].
        max_tries: random placements tried per item before giving up.

    Returns:
        The world, named ``"random-<seed>"``.

    Raises:
        InvalidConfig: an argument is out of range, or the items do not fit (the message
            says which and what to change).
    """
    seed = integer("random_world: seed", seed, low=0)
    robot = _robot("random_world", robot)
    n_obstacles = integer("random_world: n_obstacles", n_obstacles, low=0)
    corridors = integer("random_world: corridors", corridors, low=0)
    narrow_passages = integer("random_world: narrow_passages", narrow_passages, low=0)
    max_tries = integer("random_world: max_tries", max_tries, low=1)
    width, height = pair("random_world: size", size, low=0.0, low_open=True)
    radius = robot.radius
    if min(width, height) < 4.0 * radius + 2.0 * START_CLEARANCE:
        raise InvalidConfig(f"random_world: size must be at least {4.0 * radius + 2.0 * START_CLEARANCE:.2f} m "
                            f"on each side for robot {robot.name!r}, got {size!r}")
    min_gap = 2.0 * radius + 0.1 if min_gap is None else number("random_world: min_gap", min_gap, low=0.0)
    smallest, largest = pair("random_world: obstacle_size", obstacle_size)
    if not 0.0 < smallest <= largest:
        raise InvalidConfig(f"random_world: obstacle_size must be (smallest, largest) with 0 < smallest <= largest "
                            f"[m], got {obstacle_size!r}")
    if narrow_passages:
        strip = max(width, height) / (narrow_passages + 1)
        needed = 2.0 * max(min_gap, 2.0 * (radius + START_CLEARANCE)) + WALL_THICKNESS
        if strip < needed:
            raise InvalidConfig(f"random_world: {narrow_passages} narrow passages leave strips of {strip:.2f} m; "
                                f"expected at least {needed:.2f} m (fewer passages or a larger size)")
    rng = generator(seed, "world")
    for _ in range(20):
        world = _draw_world(rng, seed, robot, n_obstacles, width, height, min_gap, corridors, narrow_passages,
                            goal, (smallest, largest), max_tries)
        if world.goal is None or reachable(world, radius, world.start, world.goal):
            return world
    raise InvalidConfig(f"random_world: no reachable goal in 20 worlds drawn with seed {seed}; "
                        f"min_gap={min_gap!r} may be too small for robot radius {radius!r}")


def _draw_world(rng: np.random.Generator, seed: int, robot: RobotSpec, n_obstacles: int, width: float,
                height: float, min_gap: float, corridors: int, narrow_passages: int, with_goal: bool,
                obstacle_size: tuple[float, float], max_tries: int) -> World:
    radius = robot.radius
    t = WALL_THICKNESS
    hx, hy = 0.5 * width, 0.5 * height
    placer = _Placer(min_gap)
    placer.add(*_arena(width, height))

    # 1. Dividers across the longer side (x when width >= height), each with a narrow door.
    along_x = width >= height
    long_half, short_half = (hx, hy) if along_x else (hy, hx)
    strip = 2.0 * long_half / (narrow_passages + 1)

    def oriented(u: float, v: float) -> tuple[float, float]:
        return (u, v) if along_x else (v, u)

    dividers: list[float] = []
    for i in range(narrow_passages):
        u = -long_half + strip * (i + 1) + rng.uniform(-0.1, 0.1) * strip
        door = 2.0 * radius + rng.uniform(0.12, 0.3)
        limit = short_half - 0.5 * door - t
        v = 0.8 * rng.uniform(-limit, limit)
        low = Wall(oriented(u, -short_half), oriented(u, v - 0.5 * door - 0.5 * t))
        high = Wall(oriented(u, v + 0.5 * door + 0.5 * t), oriented(u, short_half))
        placer.add(low, high)
        dividers.append(u)

    # 2. Corridors: two parallel walls at a random place and heading.
    for i in range(corridors):
        for _ in range(max_tries):
            length = rng.uniform(1.5, 3.0) * min(1.0, min(width, height) / 6.0)
            inner = 2.0 * radius + rng.uniform(0.25, 0.5)
            yaw = rng.uniform(0.0, math.pi)
            cx, cy = rng.uniform(-hx, hx), rng.uniform(-hy, hy)
            c, s = math.cos(yaw), math.sin(yaw)
            offset = 0.5 * (inner + t)
            half_length = 0.5 * (length - t)
            pair = tuple(
                Wall((cx - c * half_length - s * side, cy - s * half_length + c * side),
                     (cx + c * half_length - s * side, cy + s * half_length + c * side))
                for side in (offset, -offset)
            )
            if all(placer.fits(w) for w in pair):
                placer.add(*pair)
                break
        else:
            raise InvalidConfig(f"random_world: could not place corridor {i + 1} of {corridors} in "
                                f"{width:g} x {height:g} m with min_gap={min_gap:g} m after {max_tries} tries")

    # 3. Start (and goal) with clearance, in the first (and last) strip when there are dividers.
    structure = World("structure", tuple(placer.obstacles))

    def free_point(what: str, low_u: float, high_u: float, away_from: tuple[float, float] | None) -> np.ndarray:
        margin = radius + START_CLEARANCE
        for _ in range(max_tries):
            point = np.array(oriented(rng.uniform(low_u + margin, high_u - margin),
                                      rng.uniform(-short_half + margin, short_half - margin)))
            if structure.clearance(point, radius) < START_CLEARANCE:
                continue
            if away_from is not None and math.dist(point, away_from) < 0.5 * min(width, height):
                continue
            return point
        raise InvalidConfig(f"random_world: no free {what} in {width:g} x {height:g} m after {max_tries} tries")

    first_strip = (-long_half, dividers[0] - 0.5 * t) if dividers else (-long_half, long_half)
    last_strip = (dividers[-1] + 0.5 * t, long_half) if dividers else (-long_half, long_half)
    start_xy = free_point("start", *first_strip, None)
    start = Pose2D(float(start_xy[0]), float(start_xy[1]), float(rng.uniform(-math.pi, math.pi)))
    goal_xy = free_point("goal", *last_strip, (start.x, start.y)) if with_goal else None
    keep_clear = [start_xy] + ([goal_xy] if goal_xy is not None else [])

    # 4. Free-standing obstacles of mixed shapes.
    smallest, largest = obstacle_size
    for i in range(n_obstacles):
        for _ in range(max_tries):
            center = (float(rng.uniform(-hx, hx)), float(rng.uniform(-hy, hy)))
            candidate: Obstacle
            if rng.random() < 0.5:
                candidate = Box(center, (float(rng.uniform(smallest, largest)), float(rng.uniform(smallest, largest))),
                                yaw=float(rng.uniform(0.0, math.pi)))
            else:
                candidate = Cylinder(center, 0.5 * float(rng.uniform(smallest, largest)))
            if any(candidate.signed_distance(np.array([p]))[0] < radius + START_CLEARANCE for p in keep_clear):
                continue
            if placer.fits(candidate):
                placer.add(candidate)
                break
        else:
            raise InvalidConfig(
                f"random_world: could not place obstacle {i + 1} of {n_obstacles} in {width:g} x {height:g} m with "
                f"min_gap={min_gap:g} m after {max_tries} tries; lower n_obstacles, obstacle_size or min_gap"
            )

    goal = None if goal_xy is None else (float(goal_xy[0]), float(goal_xy[1]))
    return World(f"random-{seed}", tuple(placer.obstacles), start=start, goal=goal, bounds=_bounds(width, height))


def _arena(width: float, height: float) -> tuple[Wall, ...]:
    """The four walls round a free interior ``[-w/2, w/2] x [-h/2, h/2]`` [m]."""
    hx, hy, half_wall = 0.5 * width, 0.5 * height, 0.5 * WALL_THICKNESS
    return room((-hx - half_wall, -hy - half_wall), (hx + half_wall, -hy - half_wall),
                (hx + half_wall, hy + half_wall), (-hx - half_wall, hy + half_wall))


def _bounds(width: float, height: float, margin: float = 0.3) -> tuple[float, float, float, float]:
    """The region to draw: the arena of free interior ``width x height`` and its walls, ``margin`` round [m]."""
    hx, hy = 0.5 * width + WALL_THICKNESS + margin, 0.5 * height + WALL_THICKNESS + margin
    return (-hx, -hy, hx, hy)


Box2 = tuple[tuple[float, float], tuple[float, float]]
"""A rectangle as its ``x`` range and its ``y`` range [m]."""


def _room_arguments(owner: str, seed: int, robot: RobotSpec, size: tuple[float, float],
                    smallest: tuple[float, float]) -> tuple[int, RobotSpec, float, float]:
    """The checked seed, robot and room size ``(w, h)`` of a room builder; at least ``smallest`` [m]."""
    seed = integer(f"{owner}: seed", seed, low=0)
    robot = _robot(owner, robot)
    width, height = pair(f"{owner}: size", size, low=0.0, low_open=True)
    if width < smallest[0] or height < smallest[1]:
        raise InvalidConfig(f"{owner}: size must be at least ({smallest[0]:g}, {smallest[1]:g}) m, got {size!r}")
    return seed, robot, width, height


def _seeded_room(name: str, seed: int, inside: tuple[Wall, ...], size: tuple[float, float], *, start_box: Box2,
                 goal_box: Box2) -> World:
    """A walled room of free interior ``size`` holding ``inside``, with a start and a goal drawn from the seed.

    From the ``world`` stream of ``seed``: the start's ``x`` and ``y`` uniform in ``start_box`` and
    its heading uniform in ``[-pi, pi)``, then the goal's ``x`` and ``y`` uniform in ``goal_box``.
    """
    rng = generator(seed, "world")
    (x_low, x_high), (y_low, y_high) = start_box
    start = Pose2D(float(rng.uniform(x_low, x_high)), float(rng.uniform(y_low, y_high)),
                   float(rng.uniform(-math.pi, math.pi)))
    (x_low, x_high), (y_low, y_high) = goal_box
    goal = (float(rng.uniform(x_low, x_high)), float(rng.uniform(y_low, y_high)))
    return World(name, _arena(*size) + inside, start=start, goal=goal, bounds=_bounds(*size))


def door_world(seed: int, robot: RobotSpec, door_width: float, *, size: tuple[float, float] = (6.0, 5.0)) -> World:
    """A walled room split across by a wall with one door; the start in front of it, the goal behind it.

    The room's free interior is ``[-w/2, w/2] x [-h/2, h/2]`` for ``size = (w, h)``. The
    dividing wall (:data:`~safenav.worlds.WALL_THICKNESS` thick) stands on ``x = 0`` from wall
    to wall, with one door of exactly ``door_width`` between its two jambs, centred on
    ``y = 0``: the door is the only way from one half to the other. From the ``world`` stream
    of ``seed`` (:mod:`safenav.seeding`), in this order:

    * the start: ``x`` uniform in ``[-w/2 + 0.7, -1.0]``, ``y`` uniform in ``[-0.8, 0.8]``
      (in front of the door, not always in line with it), heading uniform in ``[-pi, pi)``;
    * the goal: ``x`` uniform in ``[1.0, w/2 - 0.7]``, ``y`` uniform in ``[-0.8, 0.8]``.

    Args:
        seed: the episode's seed, an integer >= 0.
        robot: the robot the world is for (its body must fit through the door).
        door_width: free width of the door between the jambs [m], wider than the body
            (``2 * robot.radius``) and narrower than the room.
        size: free interior ``(w, h)`` of the room [m], at least 4 x 2 m.

    Returns:
        The world, named ``"door-<seed>"``.

    Raises:
        InvalidConfig: a bad seed, robot or size, or a door the body does not fit through or
            wider than the room allows (the message names the value and what was expected).
    """
    seed, robot, width, height = _room_arguments("door_world", seed, robot, size, (4.0, 2.0))
    door_width = number("door_world: door_width", door_width, low=2.0 * robot.radius, high=height - 1.0,
                        low_open=True)
    hy, half_wall = 0.5 * height, 0.5 * WALL_THICKNESS
    jamb = 0.5 * door_width + half_wall   # a wall's end is squared off half a thickness past its end point
    divider = (Wall((0.0, -hy - half_wall), (0.0, -jamb)), Wall((0.0, jamb), (0.0, hy + half_wall)))
    return _seeded_room(f"door-{seed}", seed, divider, (width, height), start_box=((-0.5 * width + 0.7, -1.0),
                                                                                 (-0.8, 0.8)),
                        goal_box=((1.0, 0.5 * width - 0.7), (-0.8, 0.8)))


def dead_end_world(seed: int, robot: RobotSpec, *, mouth_width: float | None = None, depth: float = 1.2,
                   size: tuple[float, float] = (8.0, 6.0)) -> World:
    """A walled room with a U-shaped trap between the start and the goal: its mouth faces the start.

    The room's free interior is ``[-w/2, w/2] x [-h/2, h/2]`` for ``size = (w, h)``. The trap
    is three walls round the free pocket ``[-depth/2, depth/2] x [-mouth_width/2, mouth_width/2]``:
    its closed end just beyond ``x = depth / 2`` and two arms that end at ``x = -depth / 2``. A robot that drives
    straight from the start to the goal runs into the closed end; the way round is outside
    the arms. From the ``world`` stream of ``seed`` (:mod:`safenav.seeding`), in this order:

    * the start: ``x`` uniform in ``[-w/2 + 0.8, -w/2 + 2]``, ``y`` uniform in ``[-0.3, 0.3]``,
      heading uniform in ``[-pi, pi)``;
    * the goal: ``x`` uniform in ``[w/2 - 2, w/2 - 0.8]``, ``y`` uniform in ``[-0.3, 0.3]``.

    Args:
        seed: the episode's seed, an integer >= 0.
        robot: the robot the world is for.
        mouth_width: free width inside the trap [m]; default ``4 * robot.radius + 0.4`` (room
            to drive in and to turn round).
        depth: length of the arms, from the mouth to the closed end [m].
        size: free interior ``(w, h)`` of the room [m], at least 6 x 4 m.

    Returns:
        The world, named ``"dead-end-<seed>"``.

    Raises:
        InvalidConfig: an argument out of range (the message names it and what was expected).
    """
    seed, robot, width, height = _room_arguments("dead_end_world", seed, robot, size, (6.0, 4.0))
    mouth_width = 4.0 * robot.radius + 0.4 if mouth_width is None else mouth_width
    mouth_width = number("dead_end_world: mouth_width", mouth_width, low=2.0 * robot.radius,
                         high=height - 4.0 * robot.radius - 1.0, low_open=True)
    depth = number("dead_end_world: depth", depth, low=0.0, high=0.5 * width - 2.5, low_open=True)
    arm = 0.5 * (mouth_width + WALL_THICKNESS)   # centre lines of the arms
    back, mouth = 0.5 * (depth + WALL_THICKNESS), -0.5 * (depth - WALL_THICKNESS)   # inside: depth long
    trap = room((mouth, arm), (back, arm), (back, -arm), (mouth, -arm), closed=False)
    return _seeded_room(f"dead-end-{seed}", seed, trap, (width, height),
                        start_box=((-0.5 * width + 0.8, -0.5 * width + 2.0), (-0.3, 0.3)),
                        goal_box=((0.5 * width - 2.0, 0.5 * width - 0.8), (-0.3, 0.3)))


def _robot(owner: str, robot: RobotSpec) -> RobotSpec:
    if not isinstance(robot, RobotSpec):
        raise InvalidConfig(f"{owner}: robot must be a RobotSpec, got {robot!r}")
    return robot


def reachable(world: World, radius: float, start: Sequence[float], goal: Sequence[float]) -> bool:
    """Whether a disk of ``radius`` can move from ``start`` to ``goal`` without touching an obstacle.

    Conservative: cells of a :data:`GRID_RESOLUTION` grid over ``world.bounds`` are free
    when the disk at their centre keeps half a cell of clearance, and two 4-neighbour free
    cells are joined by a segment every point of which keeps clearance >= 0 (clearance is
    1-Lipschitz). A passage narrower than the disk plus about one cell may be missed.

    Args:
        world: the world.
        radius: radius of the disk [m].
        start: start position ``(x, y, ...)`` [m].
        goal: goal position ``(x, y)`` [m].
    """
    from scipy import ndimage  # here: 0.1 s of import that only the reachability check needs

    xmin, ymin, xmax, ymax = world.bounds
    xs = np.arange(xmin, xmax + GRID_RESOLUTION, GRID_RESOLUTION)
    ys = np.arange(ymin, ymax + GRID_RESOLUTION, GRID_RESOLUTION)
    free = np.empty((ys.size, xs.size), dtype=bool)
    for row, y in enumerate(ys):
        points = np.column_stack((xs, np.full(xs.size, y)))
        free[row] = world.signed_distance(points) - radius >= 0.5 * GRID_RESOLUTION
    labels, _ = ndimage.label(free)

    def cell(x: float, y: float) -> int:
        column = int(np.clip(round((x - xmin) / GRID_RESOLUTION), 0, xs.size - 1))
        row = int(np.clip(round((y - ymin) / GRID_RESOLUTION), 0, ys.size - 1))
        return int(labels[row, column])

    start_label, goal_label = cell(start[0], start[1]), cell(goal[0], goal[1])
    return start_label != 0 and start_label == goal_label
