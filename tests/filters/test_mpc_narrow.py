"""The MPC's narrow body: the plan of the footprint's cover through the gaps its circumscribed disk does not fit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from safenav import UnknownName, preset
from safenav.filters import CBFSafetyFilter, FilterStatus, MPCSafetyFilter
from safenav.synthetic import Circle, Scene, synthetic_scan
from tests.filters.test_cbf_narrow import DT, corridor_run, door_run, narrow_corridor


def mpc(robot, **settings) -> MPCSafetyFilter:
    """Without the wall-clock budget: the answers do not depend on the machine's load."""
    return MPCSafetyFilter(robot, DT, budget=math.inf, **settings)


def test_the_mpcs_narrow_body_is_the_cover_of_a_robot_with_a_footprint_and_none_of_a_round_one():
    m2wr = mpc(preset("m2wr"))
    assert m2wr.config.narrow_body == "cover" and m2wr.narrow_planner is not None
    assert m2wr.narrow_planner.body.name == "cover3" and m2wr.plan_body.name == "disk"
    assert m2wr.narrow_planner.margin == m2wr.margin and m2wr.reach > m2wr.body.reach
    assert m2wr.narrow_half_width == pytest.approx(CBFSafetyFilter(preset("m2wr"), DT).narrow_half_width)
    for plain in (mpc(preset("puzzlebot")), mpc(preset("m2wr"), body="cover"), mpc(preset("m2wr"), narrow_body=None)):
        assert plain.narrow_planner is None and plain.narrow_half_width == plain.corridor_half_width
    with pytest.raises(UnknownName, match="polygon"):
        mpc(preset("m2wr"), narrow_body="polygon")


def test_the_mpc_plans_the_cover_through_a_gap_only_it_fits_and_the_disk_after():
    """The corridor of the CBF's test, 20 cm narrower than the disk needs: with ``narrow`` set the m2wr drives
    through on the cover's plans (verified like every plan; the footprint's true clearance never under the
    margin), says so, and plans for the disk again once out; without the flag the disk stops in front."""
    robot = preset("m2wr")
    filt, held = mpc(robot), mpc(robot)
    scene, _ = narrow_corridor(robot, CBFSafetyFilter(robot, DT))

    def check(result, scan, velocity):
        assert result.status is FilterStatus.OK
        if result.modified and filt.plan_body.name != "disk":
            assert "cover3 body (a narrow gap)" in result.message

    pose, bodies, worst, held_pose, held_velocity = corridor_run(robot, scene, filt, held, lambda f: f.plan_body,
                                                                 check)
    assert worst >= filt.margin - 1e-9
    assert pose.x > 2.4 and bodies[0] == "cover3" and bodies[-1] == "disk"
    assert held_pose.x < 0.8 and abs(held_velocity[0]) < 0.02 and held.plan_body.name == "disk"


def test_the_mpc_takes_the_narrow_body_only_where_its_barrier_holds():
    """A pole straight ahead between the disk's reach and the cover's: with ``narrow`` set the MPC keeps the
    disk's plans, and takes the cover's once the pole is out of its way; a reset forgets it."""
    robot = preset("m2wr")
    filt = mpc(robot)
    gap = 0.5 * (robot.radius + filt.margin + filt.reach + filt.margin)
    filt.narrow = filt.passage = True
    result = filt.filter((0.0, 0.0), synthetic_scan(robot, Scene.of(Circle((gap + 0.01, 0.0), 0.01))),
                         velocity=np.zeros(2))
    assert filt.plan_body.name == "disk" and result.status is FilterStatus.OK
    result = filt.filter((0.0, 0.0), synthetic_scan(robot, Scene.of(Circle((1.5, 0.0), 0.01))), velocity=np.zeros(2))
    assert filt.plan_body.name == "cover3" and result.status is FilterStatus.OK
    filt.reset()
    assert filt.plan_body.name == "disk" and not filt.narrow


def test_the_escape_drives_the_mpc_through_a_door_only_the_cover_fits():
    """The CBF's door test with the MPC: through the door on the cover's plans, to the goal, the footprint never
    nearer than the margin; with the disk alone the escape finds no door."""
    half = CBFSafetyFilter(preset("m2wr"), DT).narrow_half_width + 0.02
    pose, worst, gaps, margin, goal = door_run("cover", half, make=MPCSafetyFilter, budget=math.inf)
    assert math.hypot(*(np.array(pose[:2]) - goal)) < 0.3 and gaps[:1] == [True] and worst >= margin - 1e-9
    pose, worst, gaps, margin, goal = door_run(None, half, make=MPCSafetyFilter, budget=math.inf)
    assert pose.x < 1.5 and gaps == [] and worst >= margin - 1e-9
