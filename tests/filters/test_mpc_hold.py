"""The MPC filter held in front of an obstacle: it stands still, and it moves again as soon as a plan can.

Held at its margin with a nominal that drives on, the tracking cost used to take every millimetre
of room at once and reverse in the next period: the command alternated about +-0.03 m/s for as
long as the obstacle stayed, so the robot never counted as stopped (issue 19's stop metrics).
Simulator-free closed loops with a base that ramps at its acceleration limits (as PyBullet's).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from safenav import Pose2D, preset
from safenav.filters import FilterStatus
from safenav.synthetic import Circle, Scene, synthetic_scan, wall
from tests.filters.test_mpc import mpc, ramp

#: |v| at most this counts as stopped [m/s] (the stop speed of the collision monitor's metrics).
STOP_SPEED = 0.01
CRUISE = {"rosbot": 0.5, "puzzlebot": 0.2, "m2wr": 0.5}


def drive(filt, scene, u_nom, steps, pose=None, velocity=None):
    """Closed loop of ``steps`` periods; the commands, statuses, final pose and velocity, and the worst clearance."""
    robot = filt.robot
    pose = Pose2D() if pose is None else pose
    velocity = np.zeros(2) if velocity is None else velocity
    commands, statuses, worst = [], [], math.inf
    for _ in range(steps):
        result = filt.filter(u_nom, synthetic_scan(robot, scene, pose), velocity=velocity)
        commands.append(result.u)
        statuses.append(result.status)
        pose, velocity, clearance = ramp(robot, pose, velocity, result.u, scene)
        worst = min(worst, clearance)
    return np.array(commands), statuses, pose, velocity, worst


@pytest.mark.parametrize(("name", "obstacle"), [
    ("rosbot", wall(1.0)),
    ("puzzlebot", wall(0.6)),
    ("m2wr", wall(1.0)),
    ("rosbot", Circle((1.2, 0.1), 0.25)),    # a person standing slightly off the path
])
def test_held_in_front_of_an_obstacle_the_command_stands_still(name, obstacle):
    robot = preset(name)
    filt = mpc(robot)
    scene = Scene.of(obstacle)
    commands, statuses, _, _, worst = drive(filt, scene, np.array([CRUISE[name], 0.0]), 100)
    held = commands[60:, 0]                  # from 3 s on the robot stands in front of the obstacle
    assert np.max(np.abs(held)) <= STOP_SPEED, f"commands while held: {held.round(4).tolist()}"
    signs = np.sign(held[np.abs(held) > 1e-9])
    assert np.count_nonzero(np.diff(signs)) == 0, f"v changes sign while held: {held.round(4).tolist()}"
    assert all(status in (FilterStatus.OK, FilterStatus.RECOVERING) for status in statuses)
    assert worst >= filt.margin - 1e-4


def test_a_held_robot_drives_on_when_the_obstacle_leaves_and_turns_when_asked():
    robot = preset("rosbot")
    filt = mpc(robot)
    blocked = Scene.of(wall(1.0))
    commands, _, pose, velocity, _ = drive(filt, blocked, np.array([0.5, 0.0]), 80)
    assert np.all(np.abs(commands[-20:, 0]) <= STOP_SPEED)
    # Asked to turn away, it turns at once: standing still is held only while no plan makes progress.
    turning, _, _, _, worst = drive(filt, blocked, np.array([0.3, 2.0]), 10, pose, velocity)
    assert turning[-1, 1] > 1.0 and worst >= filt.margin - 1e-4
    # The obstacle gone, the nominal comes back within the acceleration limits.
    filt.reset()
    free, _, _, _, _ = drive(filt, Scene.of(wall(8.0)), np.array([0.5, 0.0]), 10, pose, velocity)
    assert free[-1, 0] == pytest.approx(0.5)


def test_the_held_stop_is_a_verified_plan_that_ends_stopped():
    robot = preset("rosbot")
    filt = mpc(robot)
    scene = Scene.of(wall(1.0))
    _, _, pose, velocity, _ = drive(filt, scene, np.array([0.5, 0.0]), 80)
    scan = synthetic_scan(robot, scene, pose)
    result = filt.filter((0.5, 0.0), scan, velocity=velocity)
    assert abs(result.u[0]) <= STOP_SPEED and result.solver == "sqp+daqp"
    assert result.reason is not None and "held" in result.reason.detail
    commands = result.plan[1:, 3:]
    check = filt.check_plan(filt.build_problem((0.5, 0.0), scan, velocity), commands)
    assert check.limits <= 1e-9 and check.clearance >= -1e-6
    assert np.all(commands[-1] == 0.0)


def test_turning_on_the_spot_to_find_a_way_round_the_linear_command_does_not_reverse():
    """A person just off the path: the plan turns on the spot before driving round, and the linear
    command stays at zero meanwhile instead of alternating about it."""
    robot = preset("rosbot")
    filt = mpc(robot)
    scene = Scene.of(Circle((1.2, 0.2), 0.25))
    commands, statuses, pose, _, worst = drive(filt, scene, np.array([0.5, 0.0]), 100)
    arrived = commands[35:]
    assert np.all(arrived[:, 0] >= 0.0), f"reversing commands: {arrived[:, 0].round(4).tolist()}"
    on_the_spot = (arrived[:, 0] == 0.0) & (np.abs(arrived[:, 1]) > 0.1)
    assert np.count_nonzero(on_the_spot) >= 10                            # turns on the spot, then drives off
    assert abs(pose.y) > 0.3 and worst >= filt.margin - 1e-4              # and it gets round
    assert all(status in (FilterStatus.OK, FilterStatus.RECOVERING) for status in statuses)
