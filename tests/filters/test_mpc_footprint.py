"""The MPC filter with a cover of the footprint by disks (``body="cover"``): geometry, doors, corridors.

The truth here is the footprint polygon (the walls sampled every 2 mm, the exact unicycle in 10
sub-steps of a base ramping at its limits): the guarantee is clearance from the polygon, which
the disks cover.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_mpc import scattered

from safenav import Pose2D, preset, unicycle_step
from safenav.filters import FilterStatus, MPCSafetyFilter
from safenav.filters.body import BodyModel, polygon_distance
from safenav.filters.mpc.plan import disk_centres
from safenav.reference import GoToGoal
from safenav.synthetic import Circle, Scene, Segment, synthetic_scan

DT = 0.05
#: Disks of the cover per robot: the m2wr's 0.5 x 0.3 m body needs five for a door 5 cm wider than it.
DISKS = {"rosbot": 3, "m2wr": 5}


def cover_filter(name: str, **settings) -> MPCSafetyFilter:
    return MPCSafetyFilter(preset(name), DT, body="cover", n_disks=DISKS[name], budget=math.inf, **settings)


def wall_samples(scene: Scene, step: float = 0.002) -> np.ndarray:
    pieces = []
    for segment in scene.segments:
        start, end = np.asarray(segment.start), np.asarray(segment.end)
        count = max(2, int(np.hypot(*(end - start)) / step) + 1)
        pieces.append(start + np.linspace(0.0, 1.0, count)[:, None] * (end - start))
    return np.vstack(pieces)


def footprint_clearance(robot, pose: Pose2D, samples: np.ndarray) -> float:
    """Distance from the footprint polygon at ``pose`` to the sampled walls [m]."""
    local = pose.to_local(samples)
    near = local[np.hypot(local[:, 0], local[:, 1]) < 1.0]
    return float(polygon_distance(np.asarray(robot.footprint), near).min()) if near.size else math.inf


def drive(robot, safety, scene: Scene, waypoints, duration: float) -> tuple[bool, float, dict[str, int]]:
    """Go-to-goal through ``waypoints`` with the filter in the loop; whether the last was reached, the
    smallest footprint clearance and the statuses."""
    samples = wall_samples(scene)
    pose, velocity = Pose2D(), np.zeros(2)
    policies = [GoToGoal(robot, goal=point) for point in waypoints]
    target, worst, statuses = 0, math.inf, {}
    for _ in range(round(duration / DT)):
        while target < len(waypoints) - 1 and math.dist((pose.x, pose.y), waypoints[target]) < 0.15:
            target += 1
        scan = synthetic_scan(robot, scene, pose)
        result = safety.filter(policies[target](scan, pose), scan, velocity=velocity)
        statuses[result.status.value] = statuses.get(result.status.value, 0) + 1
        for _ in range(10):
            velocity = robot.clip(result.u, velocity, DT / 10)
            pose = unicycle_step(pose, float(velocity[0]), float(velocity[1]), DT / 10)
            worst = min(worst, footprint_clearance(robot, pose, samples))
        if math.dist((pose.x, pose.y), waypoints[-1]) < 0.15:
            return True, worst, statuses
    return False, worst, statuses


def passage_width(robot, margin: float, extra: float) -> float:
    """Body width + 2 margin + ``extra`` [m] (issue 14's door)."""
    return 2.0 * float(np.max(np.abs(np.asarray(robot.footprint)[:, 1]))) + 2.0 * margin + extra


# ------------------------------------------------------------------ geometry


@pytest.mark.parametrize("name", ["rosbot", "m2wr"])
def test_the_cover_disks_inflated_radii_cover_their_motion_between_knots(name):
    """For every disk and random twists within the limits: with both ends of a period exactly ``r_d``
    from a point placed on the bulge side, the disk's centre never comes nearer than
    ``rho_d + margin + e_act_d`` in between (the rest of ``r_d`` covers the base's deviation)."""
    safety = cover_filter(name)
    robot = safety.robot
    rng = np.random.default_rng(4)
    offsets, radii = safety.offsets, safety.inflated_radii
    assert offsets.shape[0] == DISKS[name] and np.any(offsets[:, 0] != 0.0)
    times = np.linspace(0.0, DT, 201)
    for _ in range(300):
        v = rng.uniform(robot.v_min, robot.v_max)
        omega = rng.uniform(-robot.omega_max, robot.omega_max)
        poses = np.array([unicycle_step(Pose2D(), v, omega, t) for t in times])
        centres = disk_centres(poses, offsets)                      # (T, D, 2)
        for d in range(offsets.shape[0]):
            path = centres[:, d]
            chord = path[-1] - path[0]
            length = float(np.hypot(*chord))
            if length < 1e-9:
                continue
            middle = 0.5 * (path[0] + path[-1])
            normal = np.array([-chord[1], chord[0]]) / length
            bulge = np.sign(np.dot(path[len(path) // 2] - middle, normal)) or 1.0
            point = middle + bulge * normal * math.sqrt(radii[d] ** 2 - 0.25 * length**2)
            assert np.hypot(*(path[[0, -1]] - point).T) == pytest.approx(radii[d])
            nearest = float(np.min(np.hypot(*(path - point).T)))
            assert nearest >= safety.body.radii[d] + safety.margin + safety.actuator_errors[d] - 1e-12


def test_the_cover_covers_the_footprint():
    for name, disks in DISKS.items():
        body = BodyModel.cover(preset(name), disks)
        corners = np.asarray(preset(name).footprint)
        inside = np.hypot(corners[:, None, 0] - body.centres[None, :, 0],
                          corners[:, None, 1] - body.centres[None, :, 1]) <= body.radii[None] + 1e-12
        assert np.all(inside.any(axis=1))


def test_a_plan_keeps_every_disk_of_the_cover_clear():
    """A wall beside the body and a nominal turning into it: the disks nearest to it bind, and the whole
    footprint keeps the margin at every knot of the plan. (The ROSbot: its lidar sees the wall beside
    it; the m2wr's would not, and its start assumption keeps unseen space clear.)"""
    name = "rosbot"
    safety = cover_filter(name)
    robot = safety.robot
    side = float(np.max(np.asarray(robot.footprint)[:, 1]))
    scene = Scene.of(Segment((-3.0, -(side + safety.margin + 0.015)), (3.0, -(side + safety.margin + 0.015))),
                     Circle((0.9, 0.05), 0.1))
    scan = synthetic_scan(robot, scene)
    result = safety.filter((robot.v_max, -robot.omega_max), scan, velocity=(0.5 * robot.v_max, 0.0))
    assert result.status is FilterStatus.OK and result.solver
    problem = safety.build_problem(result.u_nom, scan, (0.5 * robot.v_max, 0.0))
    check = safety.check_plan(problem, result.plan[1:, 3:])
    assert check.clearance >= -1e-6 and check.distances.shape == (problem.points.shape[0], DISKS[name])
    assert result.n_constraints == len(result.constraint_points) * safety.horizon * DISKS[name]
    samples = wall_samples(scene)
    for pose in result.plan[:, :3]:
        assert footprint_clearance(robot, Pose2D(*pose), samples) >= safety.margin


# ------------------------------------------------------------------ passages


@pytest.mark.parametrize("name", ["rosbot", "m2wr"])
def test_a_door_five_centimetres_wider_than_body_and_margins_is_passed(name):
    """Issue 14's door (ROSbot 0.34 m, m2wr 0.44 m) on a straight approach: through, no contact,
    the footprint never nearer than the margin."""
    safety = cover_filter(name)
    robot = safety.robot
    half = 0.5 * passage_width(robot, safety.margin, 0.05)
    scene = Scene.of(Segment((1.0, half), (1.0, 3.0)), Segment((1.0, -half), (1.0, -3.0)))
    passed, worst, statuses = drive(robot, safety, scene, [(2.5, 0.0)], duration=10.0)
    assert passed, statuses
    assert worst >= safety.margin


@pytest.mark.parametrize(("name", "extra", "passes"), [("rosbot", 0.05, False), ("rosbot", 0.10, True),
                                                       ("m2wr", 0.05, False)])
def test_a_corridor_with_a_right_angle_keeps_the_footprint_clear(name, extra, passes):
    """A corridor with a 90-degree left turn, driven by a waypoint nominal. Safe at every width; the
    ROSbot gets round the corner at 10 cm over body width + 2 margin, not at 5 cm (its disks are
    0.38 m long where the body is 0.20 m), and the m2wr at 5 cm cannot: no rigid 0.50 x 0.30 m body
    turns a 0.44 m corridor keeping 4.4 cm from both walls (at 45 degrees it needs 2 (sqrt(2) w - W)
    >= L with w the width less both margins: 0.39 m < 0.50 m)."""
    safety = cover_filter(name)
    robot = safety.robot
    half = 0.5 * passage_width(robot, safety.margin, extra)
    corner = 1.5
    scene = Scene.of(Segment((-1.0, -half), (corner + half, -half)),
                     Segment((corner + half, -half), (corner + half, 3.0)),
                     Segment((-1.0, half), (corner - half, half)), Segment((corner - half, half), (corner - half, 3.0)))
    passed, worst, statuses = drive(robot, safety, scene, [(corner, 0.0), (corner, 2.5)], duration=12.0)
    assert passed is passes, statuses
    assert worst >= safety.margin - 0.01


# ------------------------------------------------------------------ properties


@st.composite
def cluttered(draw):
    name = draw(st.sampled_from(["rosbot", "m2wr"]))
    robot = preset(name)
    scene = scattered(draw, count=(1, 6), distance=(0.35, 1.5), radius=0.3, side=0.8)
    u_nom = np.array([draw(st.floats(0.0, robot.v_max)), draw(st.floats(-robot.omega_max, robot.omega_max))])
    velocity = np.array([draw(st.floats(0.0, robot.v_max)), draw(st.floats(-robot.omega_max, robot.omega_max))])
    return name, scene, u_nom, velocity


FILTERS: dict[str, MPCSafetyFilter] = {}


@settings(max_examples=60)
@given(cluttered())
def test_cover_results_are_verified_against_every_point_and_every_disk(case):
    name, scene, u_nom, velocity = case
    if name not in FILTERS:
        FILTERS[name] = cover_filter(name)
    safety = FILTERS[name]
    safety.reset()
    robot = safety.robot
    scan = synthetic_scan(robot, scene)
    result = safety.filter(u_nom, scan, velocity=velocity)
    assert np.all(np.isfinite(result.u)) and result.status is not FilterStatus.FALLBACK
    if result.status is FilterStatus.BRAKING:
        return
    problem = safety.build_problem(u_nom, scan, velocity)
    check = safety.check_plan(problem, result.plan[1:, 3:])
    assert check.limits <= 1e-7
    assert check.clearance >= (-result.slack if result.status is FilterStatus.SLACK else 0.0) - 1e-6
