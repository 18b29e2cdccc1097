"""The CBF's narrow body: a cover of the footprint for the gaps its circumscribed disk does not fit."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from safenav import Pose2D, UnknownName, preset, unicycle_step
from safenav.filters import CBFSafetyFilter, FilterStatus
from safenav.filters.body import polygon_distance
from safenav.filters.escape import Escape
from safenav.synthetic import Circle, Scene, Segment, synthetic_scan
from tests.filters.test_cbf import full_residual

DT = 0.05


def footprint_clearance(robot, scene: Scene, pose: Pose2D) -> float:
    """The footprint's true distance to the scene's walls and poles at ``pose`` [m] (sampled every 2 mm, which
    overstates a distance of 5 cm by at most 0.01 mm)."""
    points = _outline(scene)
    near = np.hypot(points[:, 0] - pose.x, points[:, 1] - pose.y) < robot.radius + 0.5
    if not near.any():
        return math.inf
    return float(polygon_distance(np.asarray(robot.footprint), pose.to_local(points[near])).min())


@functools.lru_cache(maxsize=8)
def _outline(scene: Scene) -> np.ndarray:
    points = []
    for segment in scene.segments:
        start, end = np.asarray(segment.start, dtype=float), np.asarray(segment.end, dtype=float)
        count = max(2, int(np.hypot(*(end - start)) / 0.002))
        points.append(start + np.linspace(0.0, 1.0, count)[:, None] * (end - start))
    for circle in scene.circles:
        angles = np.linspace(0.0, 2.0 * math.pi, 2000, endpoint=False)
        points.append(np.asarray(circle.center) + circle.radius * np.column_stack((np.cos(angles), np.sin(angles))))
    return np.vstack(points)


def checker_for(robot, filt: CBFSafetyFilter) -> CBFSafetyFilter:
    """A filter with one shape: the body and look-ahead ``filt``'s last answer used."""
    body = "cover" if filt.rows_body.name.startswith("cover") else filt.rows_body.name
    return CBFSafetyFilter(robot, DT, body=body, lookahead=filt.lookahead, min_lookahead=filt.lookahead)


def narrow_corridor(robot, filt: CBFSafetyFilter, extra: float = 0.04) -> tuple[Scene, float]:
    """Two walls along the heading from 0.8 m to 1.6 m ahead, ``2 narrow_half_width + extra`` apart."""
    half = filt.narrow_half_width + 0.5 * extra
    return Scene.of(Segment((0.8, half), (1.6, half)), Segment((0.8, -half), (1.6, -half))), 2.0 * half


def test_the_narrow_body_is_the_cover_of_a_robot_with_a_footprint_and_none_of_a_round_one():
    m2wr = CBFSafetyFilter(preset("m2wr"), DT, narrow_body="cover")
    assert m2wr.config.narrow_body == "cover" and m2wr.rows_body.name == "disk"
    # The cover's end disks reach beyond the circumscribed disk along the axis: the stopping reach, the horizon
    # and the memory are measured from the farther of the two.
    assert m2wr.reach == pytest.approx(1 / 6 + math.hypot(0.25 / 3, 0.15)) and m2wr.reach > m2wr.body.reach
    assert m2wr.narrow_half_width == pytest.approx(math.hypot(0.25 / 3, 0.15) + m2wr.margin)
    assert m2wr.narrow_half_width < m2wr.corridor_half_width
    assert CBFSafetyFilter(preset("m2wr"), DT).config.narrow_body == "cover"    # the default
    plain = CBFSafetyFilter(preset("m2wr"), DT, narrow_body=None)
    assert plain.narrow_half_width == plain.corridor_half_width and plain.reach == plain.body.reach
    round_robot = CBFSafetyFilter(preset("puzzlebot"), DT, narrow_body="cover")
    assert round_robot.config.narrow_body is None and round_robot.narrow_half_width == round_robot.corridor_half_width
    assert CBFSafetyFilter(preset("m2wr"), DT, body="cover", narrow_body="cover").config.narrow_body is None
    assert CBFSafetyFilter(preset("m2wr"), DT, body="polygon").config.narrow_body is None      # no narrower
    with pytest.raises(UnknownName, match="triangle"):
        CBFSafetyFilter(preset("m2wr"), DT, narrow_body="triangle")


def test_through_a_gap_only_the_narrow_body_fits_with_the_flag_and_back_to_the_disk_after():
    """A corridor 2 (cover half-width + margin) + 4 cm wide, 20 cm narrower than the disk needs. With ``narrow``
    set (as the escape does through a gap) the m2wr drives through on the cover's rows, every answer keeping every
    row of the shape it used and saying so, the footprint never nearer than the margin; once out and the flag
    cleared, the disk's rows come back. Without the flag the disk stops in front of the corridor."""
    robot = preset("m2wr")
    filt = CBFSafetyFilter(robot, DT, narrow_body="cover", budget=math.inf)     # every status checked: the math,
    held = CBFSafetyFilter(robot, DT, narrow_body="cover", budget=math.inf)     # not the machine's load
    scene, width = narrow_corridor(robot, filt)
    assert width < 2.0 * filt.corridor_half_width - 0.2

    def check(result, scan, velocity):
        assert result.status is FilterStatus.OK
        assert np.all(full_residual(checker_for(robot, filt), result.u_nom, scan, velocity, result.u) <= 1e-6)
        if result.modified and filt.rows_body.name != "disk":
            assert "cover3 body, look-ahead 0 m (a narrow gap)" in result.message

    pose, shapes, worst, held_pose, held_velocity = corridor_run(robot, scene, filt, held, lambda f: f.rows_body,
                                                                 check)
    assert worst >= filt.margin - 1e-9
    assert pose.x > 2.4 and shapes[0] == "cover3" and shapes[-1] == "disk"
    assert held_pose.x < 0.8 and abs(held_velocity[0]) < 0.02 and held.rows_body.name == "disk"


def corridor_run(robot, scene: Scene, filt, held, body_of, check):
    """400 periods of the nominal (0.4, 0) through ``scene`` (the corridor of :func:`narrow_corridor`): ``filt``
    with ``narrow`` and ``passage`` set until 1.9 m ahead, ``check(result, scan, velocity)`` on each of its answers;
    ``held`` beside it with ``passage`` only. Returns ``filt``'s final pose, the name of the body of each answer
    (``body_of(filt)``), the footprint's smallest true clearance [m], and ``held``'s final pose and velocity."""
    pose, velocity = Pose2D(), np.zeros(2)
    held_pose, held_velocity = Pose2D(), np.zeros(2)
    bodies, worst = [], math.inf
    for _ in range(400):
        filt.narrow = filt.passage = pose.x < 1.9
        scan = synthetic_scan(robot, scene, pose)
        result = filt.filter((0.4, 0.0), scan, velocity=velocity)
        check(result, scan, velocity)
        bodies.append(body_of(filt).name)
        worst = min(worst, footprint_clearance(robot, scene, pose))
        velocity = result.u.copy()
        pose = advance(pose, velocity)
        held.passage = True
        stopped = held.filter((0.4, 0.0), synthetic_scan(robot, scene, held_pose), velocity=held_velocity)
        held_velocity = stopped.u.copy()
        held_pose = advance(held_pose, held_velocity)
    return pose, bodies, worst, held_pose, held_velocity


def advance(pose: Pose2D, u: np.ndarray) -> Pose2D:
    """``pose`` after one period of the command ``u`` [m/s, rad/s], in ten exact unicycle steps."""
    for _ in range(10):
        pose = unicycle_step(pose, float(u[0]), float(u[1]), DT / 10)
    return pose


def test_the_narrow_body_is_taken_only_where_its_own_barrier_holds():
    """A pole straight ahead, outside the disk's margin but inside the cover's (its front disk reaches 4.7 cm
    beyond the circumscribed disk): with ``narrow`` set the filter keeps the disk's rows (taking the cover would
    start inside its margin), and takes the cover once the pole is out of its way."""
    robot = preset("m2wr")
    filt = CBFSafetyFilter(robot, DT, narrow_body="cover", budget=math.inf)
    cover_reach = filt.reach + filt.margin
    gap = 0.5 * (robot.radius + filt.margin + cover_reach)      # between the two reaches along the axis
    pole = Scene.of(Circle((gap + 0.01, 0.0), 0.01))
    filt.narrow = filt.passage = True
    result = filt.filter((0.0, 0.0), synthetic_scan(robot, pole), velocity=np.zeros(2))
    assert filt.rows_body.name == "disk" and filt.lookahead == 0.0 and result.status is FilterStatus.OK
    result = filt.filter((0.0, 0.0), synthetic_scan(robot, Scene.of(Circle((1.5, 0.0), 0.01))), velocity=np.zeros(2))
    assert filt.rows_body.name == "cover3" and result.status is FilterStatus.OK
    filt.reset()
    assert filt.rows_body.name == "disk" and filt.lookahead == 0.1 and not filt.narrow


def door_run(narrow_body: str | None, door_half: float, duration: float = 25.0, make=CBFSafetyFilter, **settings):
    """The m2wr, go-to-goal 3.5 m ahead, behind a wall 1.5 m ahead with a door of half-width ``door_half`` [m]
    centred 1 m to the left, with the escape round ``make``: the final pose, the footprint's smallest clearance
    [m], whether and when the filter's ``narrow`` flag was set (the first call of a gap with and without it), the
    margin and the goal. It checks that the escape hands back from a gap only once the filter left its narrow body."""
    robot = preset("m2wr")
    goal = np.array([3.5, 0.0])
    inner = make(robot, DT, narrow_body=narrow_body, **settings)
    safety = Escape(inner)
    scene = Scene.of(Segment((1.5, -8.0), (1.5, 1.0 - door_half)), Segment((1.5, 1.0 + door_half), (1.5, 8.0)))
    pose, velocity, worst, gaps, handing = Pose2D(), np.zeros(2), math.inf, [], False
    for _ in range(round(duration / DT)):
        to_goal = pose.to_local(goal[None])[0]
        if math.hypot(*to_goal) < 0.3:
            break
        bearing = math.atan2(to_goal[1], to_goal[0])
        u_nom = (0.5 * robot.v_max * max(math.cos(bearing), 0.0), float(np.clip(2.0 * bearing, -1.0, 1.0)))
        scan = synthetic_scan(robot, scene, pose)
        result = safety.filter(u_nom, scan, velocity=velocity, pose=pose)
        if result.escape and "gap" in result.escape and (not gaps or gaps[-1] != inner.narrow):
            gaps.append(inner.narrow)
        # The escape hands back from a gap only once the filter has left its narrow body.
        assert not (handing and not result.escape and inner.narrowed)
        handing = bool(result.escape) and "gap" in result.escape
        velocity = result.u.copy()
        pose = advance(pose, velocity)
        worst = min(worst, footprint_clearance(robot, scene, pose))
    return pose, worst, gaps, inner.margin, goal


def test_the_escape_looks_for_gaps_the_narrow_body_fits_and_drives_the_m2wr_through_a_door_only_it_fits():
    """A door 4 cm wider than the cover needs (20 cm narrower than the disk needs): the go-to-goal nominal stalls
    at the wall, the escape finds no gap the disk fits, finds the door with the narrow body's width, drives
    through it with ``narrow`` set and hands back; the footprint never comes nearer than the margin. With the disk
    alone the escape finds no door (its corridor is too wide) and never gets there."""
    half = CBFSafetyFilter(preset("m2wr"), DT).narrow_half_width + 0.02
    pose, worst, gaps, margin, goal = door_run("cover", half)
    assert math.hypot(*(np.array(pose[:2]) - goal)) < 0.3 and gaps[:1] == [True] and worst >= margin - 1e-9
    pose, worst, gaps, margin, goal = door_run(None, half)
    assert pose.x < 1.5 and gaps == [] and worst >= margin - 1e-9


def test_in_the_simulators_door_the_disks_gap_is_driven_first_and_the_narrow_body_takes_over_where_it_is_held():
    """Issue 13's door for the m2wr in the simulator (seed 3: 2 (R + margin) + 5 cm, the lidar's 1 cm range noise,
    which the filter's margin allows for on both sides): the escape finds the door with the disk's width and drives
    it with the disk's rows, the filter holds the disk at the posts, and the escape goes on through the same door
    with the narrow body, to the goal, without contact."""
    from safenav.episode import EpisodeConfig, run_episode
    from safenav.scenarios import scenario
    from safenav.sim_bullet import SimConfig

    task = scenario("door_m2wr")
    world = task.world(3)
    safety = Escape(CBFSafetyFilter(task.robot, DT, budget=math.inf))
    gaps: list[bool] = []

    def watch(index, state, result):
        if result is not None and result.escape and "gap" in result.escape:
            narrow = "(a narrow gap)" in result.message
            if not gaps or gaps[-1] != narrow:
                gaps.append(narrow)

    result = run_episode(world, task.robot, task.policy("go_to_goal", world, 3), safety,
                         config=EpisodeConfig(duration=task.duration, sim=SimConfig(control_dt=DT)), seed=3,
                         callback=watch)
    assert result.metrics.goal_reached and not result.metrics.collided
    assert gaps[:2] == [False, True]
