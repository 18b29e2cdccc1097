"""The MPC's look-ahead control disk: it shapes the plan (brakes early, turns round what is ahead),
it is never part of the guarantee.

A plan that tracks the nominal has no reason to move sideways in front of an obstacle straight
ahead: with the body's disk about the base origin a turn does not change any clearance, so the
plan that stops is the optimum and the robot stands there for as long as the nominal points at
the obstacle (issue 13). A disk ahead of the body moves sideways when the robot turns, as a
barrier filter's look-ahead point does, and the plan turns to go round. Simulator-free closed
loops with a base that ramps at its acceleration limits.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from safenav import Pose2D, preset
from safenav.filters import FilterStatus, MPCConfig
from safenav.synthetic import Circle, Scene, synthetic_scan
from tests.filters.test_mpc import mpc
from tests.filters.test_mpc_hold import drive

#: A pillar slightly left of the path, 1 m ahead: the nominal drives straight at it.
PILLAR = Circle((1.0, 0.04), 0.2)


@pytest.mark.parametrize("name", ["rosbot", "puzzlebot", "m2wr"])
def test_with_a_look_ahead_the_plan_goes_round_a_pillar_it_would_stand_in_front_of(name):
    robot = preset(name)
    scene = Scene.of(PILLAR)
    nominal = np.array([0.8 * robot.v_max, 0.0])
    steps = round(8.0 / 0.05)
    # Without the look-ahead (the default) the robot stops in front of the pillar and stays there.
    _, _, stuck, _, worst = drive(mpc(robot), scene, nominal, steps)
    assert stuck.x < 1.0 and worst >= 0.0
    # With it, the plan turns and passes the pillar, keeping the body's margin all the way.
    filt = mpc(robot, lookahead=0.1)
    _, statuses, passed, _, worst = drive(filt, scene, nominal, steps)
    assert passed.x > PILLAR.center[0] + PILLAR.radius, f"ended at {passed}"   # beyond the pillar
    assert worst >= filt.margin - 1e-4
    assert all(status in (FilterStatus.OK, FilterStatus.RECOVERING) for status in statuses)


def test_the_control_disk_is_planned_but_never_verified_nor_reported_as_the_barrier():
    robot = preset("rosbot")
    filt = mpc(robot, lookahead=0.1)
    plain = mpc(robot)
    # A point inside the control disk's radius but outside the body's: the body is clear.
    scene = Scene.of(Circle((robot.radius + filt.margin + 0.16, 0.0), 0.01))
    scan = synthetic_scan(robot, scene, Pose2D())
    problem = filt.build_problem(np.array([0.5, 0.0]), scan, velocity=np.zeros(2))
    assert filt.offsets.shape == (2, 2) and filt.offsets[1, 0] == pytest.approx(0.1)
    assert np.all(np.isneginf(problem.guaranteed[:, 1]))             # never verified
    assert np.all(problem.radii[:, 1] > 0.0)                         # but planned
    assert problem.min_barrier == pytest.approx(plain.build_problem(np.array([0.5, 0.0]), scan,
                                                                    velocity=np.zeros(2)).min_barrier)
    result = filt.filter(np.array([0.5, 0.0]), scan, velocity=np.zeros(2))
    assert result.status is FilterStatus.OK and result.u[0] >= 0.0


def test_through_a_passage_and_for_remembered_points_the_control_disk_is_dropped():
    robot = preset("m2wr")                     # a 180-degree lidar: the memory keeps what goes behind
    filt = mpc(robot, lookahead=0.1)
    scene = Scene.of(Circle((0.6, 0.0), 0.05))
    scan = synthetic_scan(robot, scene, Pose2D())
    ahead = filt.build_problem(np.array([0.3, 0.0]), scan, velocity=np.zeros(2))
    assert np.any(ahead.radii[:, 1] > 0.0)
    filt.passage = True
    narrow = filt.build_problem(np.array([0.3, 0.0]), scan, velocity=np.zeros(2))
    assert np.all(narrow.radii[:, 1] == 0.0) and np.all(narrow.floor[:, 1] == 0.0)
    np.testing.assert_array_equal(narrow.radii[:, 0], ahead.radii[:, 0])   # the body's rows unchanged
    filt.passage = False
    # Turn the robot away on the spot: the pillar leaves the field of view and is remembered.
    _, _, behind, velocity, _ = drive(filt, scene, np.array([0.0, 1.5]), 50)
    assert abs(abs(behind.yaw) - math.pi) < 0.6
    away = synthetic_scan(robot, scene, behind)
    assert away.points().shape[0] == 0 or np.min(np.hypot(*away.points().T)) > 5.0   # nothing near is seen now
    problem = filt.build_problem(np.array([-0.3, 0.0]), away, velocity=velocity)
    assert problem.points.shape[0] > 0                               # the remembered pillar, behind
    assert np.all(problem.radii[:, 1] == 0.0) and np.all(problem.radii[:, 0] > 0.0)


def test_the_lookahead_setting_is_checked():
    with pytest.raises(ValueError, match="lookahead"):
        MPCConfig(lookahead=-0.1)
