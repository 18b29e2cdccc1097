"""The MPC that tracks a CBF's answer (``reference="cbf"``): it brakes when the CBF does, and only its cost changed.

Attack first: the reference only moves the plan's target, so every answer must still pass the
MPC's own verification; closed loops with the adversary's base models and geometries (the
falsifier's simulator) must keep the margin, and a target the plan cannot follow (the CBF's
answer to a robot already moving fast at a wall) must not loosen anything.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.falsify import TOLERANCE, Episode, run
from safenav import UnknownName, preset
from safenav.errors import SafeNavError
from safenav.filters import (
    ESCAPE_PRESETS,
    CBFSafetyFilter,
    FilterStatus,
    MPCConfig,
    MPCSafetyFilter,
    escaped,
    filter_settings,
    make_filter,
)
from safenav.filters.escape import Escape
from safenav.synthetic import Scene, Segment, synthetic_scan

DT = 0.05


def _wall_ahead(robot_name: str, distance: float):
    robot = preset(robot_name)
    x = robot.radius + distance
    return robot, synthetic_scan(robot, Scene.of(Segment((x, -2.0), (x, 2.0))))


@pytest.mark.parametrize("robot_name", ["rosbot", "puzzlebot", "m2wr"])
def test_with_the_cbf_reference_the_mpc_brakes_when_the_cbf_does(robot_name):
    # A wall 0.3 m ahead of the body at cruising speed: the plain MPC can still stop later and keeps
    # the nominal (its fast path); the CBF brakes now, and the MPC tracking it brakes with it.
    robot, scan = _wall_ahead(robot_name, 0.3)
    cruise = 0.5 * robot.v_max
    nominal, velocity = np.array([cruise, 0.0]), np.array([cruise, 0.0])
    plain = MPCSafetyFilter(robot, DT, budget=math.inf).filter(nominal, scan, velocity=velocity)
    braking = CBFSafetyFilter(robot, DT).filter(nominal, scan, velocity=velocity)
    tracked = MPCSafetyFilter(robot, DT, budget=math.inf, reference="cbf").filter(nominal, scan, velocity=velocity)
    assert np.array_equal(plain.u, nominal)
    assert braking.u[0] < cruise - 1e-3
    assert tracked.u[0] == pytest.approx(braking.u[0], abs=1e-6)
    assert np.array_equal(tracked.u_nom, nominal)                  # the result is told against the nominal
    assert tracked.reason is not None and "cbf reference" in tracked.reason.detail
    assert tracked.status in (FilterStatus.OK, FilterStatus.RECOVERING)


def test_the_reference_is_reset_with_the_filter_and_follows_the_passage_flag():
    robot, scan = _wall_ahead("rosbot", 0.5)
    safety = MPCSafetyFilter(robot, DT, budget=math.inf, reference="cbf")
    assert "reference='cbf'" in repr(safety) and "reference='nominal'" in repr(MPCSafetyFilter(robot, DT))
    safety.passage = True
    safety.filter([0.3, 0.0], scan, velocity=[0.3, 0.0])
    assert safety.reference is not None and safety.reference.passage and safety.reference.lookahead == 0.0
    safety.reset()
    assert not safety.reference.passage and safety.reference._called is False


def test_an_unknown_reference_is_refused_with_the_known_ones():
    with pytest.raises(UnknownName, match="nominal") as caught:
        MPCConfig(reference="zones")
    assert isinstance(caught.value, SafeNavError) and isinstance(caught.value, ValueError)


@pytest.mark.parametrize(("robot", "base", "dt"), [
    ("rosbot", "ramp_limit", 0.05), ("puzzlebot", "instant", 0.05), ("m2wr", "ramp", 0.1), ("rosbot", "lag", 0.02),
])
def test_tracking_the_cbf_keeps_the_mpcs_guarantee_in_closed_loop(robot, base, dt):
    # Full speed along an arc into a corner, the adversary's base models: only the target moved,
    # so the MPC's own plan checks hold the margin as without the reference.
    settings = {"reference": "cbf", "time_constant": 0.04} if base == "lag" else {"reference": "cbf"}
    outcome, log = run(Episode(robot=robot, filter="mpc", base=base, dt=dt, nominal="arc", params=(1.0, 0.6),
                               segments=((1.0, -2.0, 1.0, 2.0), (-1.0, 1.2, 2.0, 1.2)), duration=6.0,
                               settings=settings), record=True)
    assert outcome.valid and not outcome.contact
    assert outcome.min_clearance >= outcome.margin - TOLERANCE, (outcome.min_clearance, outcome.margin)
    assert any("cbf reference" in row["message"] for row in log)


def test_the_escape_wraps_the_mpc_with_its_reference():
    robot, scan = _wall_ahead("rosbot", 0.2)
    escape = Escape(MPCSafetyFilter(robot, DT, budget=math.inf, reference="cbf"))
    result = escape.filter([0.4, 0.0], scan, velocity=[0.0, 0.0])
    assert np.all(np.isfinite(result.u)) and result.u[0] <= 0.4


def test_the_mpc_escape_preset_tracks_the_cbf_unless_told_otherwise():
    # The "+escape" preset of the MPC (CLI, ROS node, gym shield, benchmarks): it tracks the CBF, so that it
    # steers round an obstacle the nominal aims at instead of braking in front of it; the plain MPC tracks the
    # nominal, and a reference the caller gives wins over the preset.
    robot = preset("rosbot")
    assert filter_settings("mpc+escape") == {"reference": "cbf"} == dict(ESCAPE_PRESETS["mpc"])
    assert filter_settings("mpc") == {} and filter_settings("cbf+escape") == {}
    assert filter_settings("mpc+escape", reference="nominal", horizon_time=2.0) == {
        "reference": "nominal", "horizon_time": 2.0}
    wrapped = make_filter("mpc+escape", robot, DT)
    assert isinstance(wrapped, Escape) and wrapped.inner.config.reference == "cbf"
    assert isinstance(wrapped.inner.reference, CBFSafetyFilter)
    assert make_filter("mpc", robot, DT).config.reference == "nominal"
    assert make_filter("mpc+escape", robot, DT, reference="nominal").inner.reference is None
    with pytest.raises(UnknownName, match="mpc\\+escap"):
        filter_settings("mpc+escap")
    # The one rule the CLI, the ROS node and the shield name the escaped filter by.
    assert [escaped(name) for name in ("mpc", "cbf+escape", "zones", "none")] == [
        "mpc+escape", "cbf+escape", "zones+escape", "none"]
    with pytest.raises(UnknownName, match="'rrt'"):
        escaped("rrt")


def test_the_mpc_escape_preset_takes_the_m2wr_round_the_clutter_to_its_goal():
    # goal_m2wr, seed 10: the MPC + escape tracking the nominal brakes in front of each obstacle the go-to-goal
    # aims through and times out after its escapes (BENCHMARKS.md, "The MPC + escape tracks the CBF"); the
    # preset, tracking the CBF, steers round them, within the MPC's own constraints, to the goal.
    from safenav.experiments.runner import reproducible_settings, run_spec
    from safenav.experiments.specs import EpisodeSpec

    outcome = run_spec(EpisodeSpec("goal_m2wr", "go_to_goal", "mpc+escape", 10,
                                   filter_options=reproducible_settings("mpc+escape")))
    metrics = outcome.metrics
    assert metrics.goal_reached and not metrics.collided and metrics.fallbacks == 0
    assert metrics.min_clearance > 0.0 and metrics.escapes_started >= 1
