"""Deadlock detection and the escape wrapper: it finds a way round, and only ever through the filter."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks.falsify import TOLERANCE, Episode, run
from safenav import InvalidConfig, preset
from safenav.filters import CBFSafetyFilter, MPCSafetyFilter, ZonesFilter, check_filter
from safenav.filters.base import progress
from safenav.filters.escape import Escape, EscapeConfig
from safenav.synthetic import Circle, Scene, synthetic_scan, wall

WALL = ((1.0, -1.5, 1.0, 1.5),)     # 3 m wide, 1 m ahead; the goal 3 m ahead, straight behind it


def goal_behind_the_wall(robot: str, filter_name: str, escape: bool, **settings) -> Episode:
    segments = WALL if robot != "m2wr" else ((1.2, -1.5, 1.2, 1.5),)
    return Episode(robot=robot, filter=filter_name, base="ramp_limit", dt=0.05, segments=segments, nominal="goal",
                   params=(3.0, 0.0), duration=40.0, escape=escape, settings=settings)


def test_a_deadlock_in_front_of_a_wide_wall_is_reported_within_the_configured_time():
    outcome, log = run(goal_behind_the_wall("rosbot", "cbf", escape=False, deadlock_time=1.0), record=True)
    robot = preset("rosbot")
    first = next(index for index, row in enumerate(log) if row["deadlock"] is not None)
    # The nominal pushes straight into the wall: the report comes 1 s after the commands stalled
    # (kept less than a tenth of the nominal's progress), counting the first stalled period.
    start = first
    while start > 0 and progress(np.array(log[start - 1]["u"]), np.array(log[start - 1]["u_nom"]),
                                 robot.upper) < 0.1:
        start -= 1
    assert log[first]["t"] - log[start]["t"] == pytest.approx(1.0 - 0.05, abs=1e-6)
    assert log[first]["deadlock"] == pytest.approx(1.0, abs=1e-6)
    assert outcome.goal_distance > 2.0 and outcome.deadlock_time > 20.0     # and it never gets out alone
    assert not outcome.contact


def test_a_nominal_that_flips_to_a_feasible_turn_now_and_then_does_not_hide_the_deadlock():
    """A go-to-goal at its heading threshold flips between driving into the wall and turning: one period
    of progress a second must not reset the deadlock clock (before: it did, and the escape never started)."""
    robot = preset("rosbot")
    safety = CBFSafetyFilter(robot, 0.05, deadlock_time=1.5)
    scan = synthetic_scan(robot, Scene.of(wall(robot.radius + safety.margin + 0.2)))
    velocity = np.zeros(2)
    reported = None
    for step in range(100):
        nominal = (0.0, 1.0) if step % 20 == 19 else (robot.v_max, 0.0)    # a turn, one period a second
        result = safety.filter(nominal, scan, velocity=velocity)
        velocity = result.u.copy()
        if result.deadlock is not None and reported is None:
            reported = step
    assert reported is not None and reported * 0.05 <= 2.5, reported


@pytest.mark.parametrize("robot", ["rosbot", "puzzlebot", "m2wr"])
@pytest.mark.parametrize("filter_name", ["cbf", "mpc"])
def test_with_the_escape_the_robot_goes_round_and_reaches_the_goal(robot, filter_name):
    outcome, log = run(goal_behind_the_wall(robot, filter_name, escape=True), record=True)
    assert not outcome.contact and outcome.min_clearance >= outcome.margin - TOLERANCE
    assert outcome.goal_distance < 0.3
    escaping = [row for row in log if row["escape"]]
    assert escaping and all(row["status"] in ("ok", "recovering", "slack", "late") for row in escaping)
    assert all("escape" in row["message"] for row in escaping)


@pytest.mark.parametrize("make", [
    lambda robot, dt: Escape(CBFSafetyFilter(robot, dt)),
    lambda robot, dt: Escape(MPCSafetyFilter(robot, dt)),
    lambda robot, dt: Escape(ZonesFilter(robot, dt)),
], ids=["cbf", "mpc", "zones"])
def test_the_escape_wrapper_meets_the_filter_contract(make):
    check_filter(make)


@st.composite
def scenes(draw):
    items = [wall(draw(st.floats(0.3, 1.5)), draw(st.floats(-0.4, 0.4)))]
    for _ in range(draw(st.integers(0, 4))):
        bearing = draw(st.floats(-math.pi, math.pi))
        distance = draw(st.floats(0.4, 2.0))
        items.append(Circle((distance * math.cos(bearing), distance * math.sin(bearing)), draw(st.floats(0.03, 0.3))))
    return Scene.of(*items)


@settings(max_examples=60)
@given(scenes(), st.sampled_from(["rosbot", "puzzlebot", "m2wr"]), st.floats(-0.3, 0.3))
def test_every_escaped_command_keeps_every_row_of_the_filter(scene, name, turn):
    """Whatever the escape asks, what comes out satisfies every row an independent filter builds."""
    robot = preset(name)
    escape = Escape(CBFSafetyFilter(robot, 0.05, deadlock_time=0.1))
    checker = CBFSafetyFilter(robot, 0.05)
    scan = synthetic_scan(robot, scene)
    velocity = np.zeros(2)
    for _ in range(30):
        result = escape.filter((robot.v_max, turn), scan, velocity=velocity)
        if result.escape:
            rows = checker.rows(scan, velocity, reduce=False)
            z = np.concatenate((result.u, np.maximum(np.abs(result.u), np.abs(velocity))))
            slack = result.slack / 0.05 if result.status.value == "slack" else 0.0
            assert np.all(rows.take(rows.hard).G @ z <= rows.take(rows.hard).h + 1e-6)
            bound = rows.h
            if result.status.value in ("slack", "recovering"):
                # inside the margin a barrier row may be held at "not approached" (right side 0)
                bound = np.where(rows.family == 0, np.maximum(rows.h, 0.0), rows.h)
            assert np.all(rows.G @ z <= bound + slack + 1e-6)
            assert np.array_equal(result.u_nom, [robot.v_max, turn])   # the original nominal is reported
        velocity = result.u.copy()        # the base reaches each command; the scan stays (static robot view)


def test_bad_settings_are_rejected_and_only_filters_are_wrapped():
    with pytest.raises(InvalidConfig, match=r"EscapeConfig.speed must be a finite number > 0 and <= 1, got 0"):
        EscapeConfig(speed=0)
    with pytest.raises(InvalidConfig, match="Escape wraps a SafetyFilter"):
        Escape("cbf")
