"""Stop metrics (benchmarks/stop_metrics.py) on hand-computed scripted trajectories, no simulator."""

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from benchmarks.stop_metrics import (
    NAV2_LIMITS,
    StopJob,
    StopThresholds,
    first_sustained,
    label,
    main,
    passes,
    run_job,
    script,
    stop_metrics,
)
from safenav import InvalidConfig, preset

TIMES = np.round(np.arange(40) * 0.1, 10)    # commands every 0.1 s, 0.0 .. 3.9
NOMINAL = np.full(40, 0.5)


def scripted_speed():
    """Cruise at 0.5 m/s, stop from 1.3 s to 2.0 s, cruise again; one slow command (0.2) at 3.0 s."""
    speed = np.where((TIMES >= 1.3) & (TIMES <= 2.0), 0.0, 0.5)
    speed[TIMES == 3.0] = 0.2
    speed[TIMES == 3.1] = 0.3          # 60 % of nominal: not a slowdown
    return speed


def test_first_sustained_is_the_time_of_the_kth_consecutive_sample():
    condition = np.array([True, False, True, True, False, True, True, True])
    assert first_sustained(TIMES[:8], condition, 3) == pytest.approx(0.7)
    assert first_sustained(TIMES[:8], condition, 2) == pytest.approx(0.3)
    assert first_sustained(TIMES[:8], condition, 4) == math.inf


def test_each_metric_on_a_hand_computed_step_in():
    clearance = np.linspace(1.0, 0.05, 41)
    metrics = stop_metrics(TIMES, scripted_speed(), NOMINAL, clearance, window=(1.0, 2.0), visit=(0.85, 2.45),
                           startup=0.2)
    # window [1.0, 2.0]: stopped at 1.3, 1.4, 1.5: the third consecutive at 1.5 s
    assert metrics.time_to_stop == pytest.approx(0.5)
    # 11 commands in the window (1.0 .. 2.0), 8 of them stopped (1.3 .. 2.0); no walker distance: only stops hold
    assert metrics.hold_stop == pytest.approx(8 / 11)
    # resumes count from 2.0 + 0.2 s: 2.2, 2.3, 2.4 are >= 0.10 m/s, the third at 2.4 s
    assert metrics.time_to_resume == pytest.approx(0.4)
    # clear: from the start-up (0.2 s) to the visit minus the guard (0.65 s): 0.2 .. 0.6 (5 commands), and after
    # the visit plus the guard (2.65 s): 2.7 .. 3.9 (13); slowed below 50 %: only the 0.2 m/s at 3.0 s
    assert metrics.false_stops == pytest.approx(1 / 18)
    assert metrics.min_clearance == pytest.approx(0.05)


def test_a_robot_that_backs_or_turns_away_is_yielding():
    times = TIMES[:5]
    speed = np.full(5, 0.3)                                   # never stopped
    distance = np.array([1.0, 0.9, 0.9, 1.0, 1.1, 1.05])       # closes, holds, opens, opens, closes
    metrics = stop_metrics(times, speed, np.full(5, 0.5), distance, window=(0.0, 0.4), walker_distance=distance)
    assert metrics.hold_stop == pytest.approx(3 / 5)
    assert metrics.time_to_stop == math.inf
    # a 0.5 mm approach is within the 1 mm tolerance
    nearly = np.array([1.0, 0.9995, 0.999, 0.9985, 0.998, 0.9975])
    assert stop_metrics(times, speed, np.full(5, 0.5), nearly, window=(0.0, 0.4),
                        walker_distance=nearly).hold_stop == 1.0


def test_a_robot_that_never_resumes_and_an_episode_without_a_window():
    speed = np.where(TIMES >= 1.0, 0.0, 0.5)
    metrics = stop_metrics(TIMES, speed, NOMINAL, np.ones(40), window=(1.0, 2.0))
    assert metrics.time_to_resume == math.inf
    assert metrics.false_stops == pytest.approx(1.0 - 8 / (8 + 17))   # clear: 0.0..0.7 (8) and 2.3..3.9 (17)
    beside = stop_metrics(TIMES, np.where(TIMES < 2.0, 0.5, 0.1), NOMINAL, np.ones(40))
    assert math.isnan(beside.time_to_stop) and math.isnan(beside.hold_stop) and math.isnan(beside.time_to_resume)
    assert beside.false_stops == pytest.approx(20 / 40)


def test_thresholds_are_read_from_the_config():
    speed = np.where((TIMES >= 1.3) & (TIMES <= 2.0), 0.015, 0.5)
    assert stop_metrics(TIMES, speed, NOMINAL, np.ones(40), window=(1.0, 2.0)).time_to_stop == math.inf
    loose = StopThresholds(stop_speed=0.02, debounce=1)
    assert stop_metrics(TIMES, speed, NOMINAL, np.ones(40), window=(1.0, 2.0),
                        thresholds=loose).time_to_stop == pytest.approx(0.3)
    with pytest.raises(InvalidConfig, match=r"StopThresholds\.debounce"):
        StopThresholds(debounce=0)


def test_passes_compares_with_the_collision_monitors_thresholds():
    row = {"time_to_stop": 0.6, "hold_stop": 0.9, "time_to_resume": 0.6, "false_stops_step_in": 0.05,
           "false_stops_pass_beside": math.nan, "collisions": 0}
    assert passes(row)
    assert not passes({**row, "hold_stop": 0.89})
    assert not passes({**row, "time_to_stop": math.inf})
    assert not passes({**row, "collisions": 1})
    assert NAV2_LIMITS == {"time_to_stop": 0.6, "hold_stop": 0.90, "time_to_resume": 0.6, "false_stops": 0.05}


@pytest.mark.parametrize("robot", ["rosbot", "puzzlebot", "m2wr"])
def test_the_step_in_window_is_when_the_walker_overlaps_the_path(robot):
    plan = script(StopJob(robot, "none", "step_in", seed=3, gap=0.5))
    reach = preset(robot).radius + 0.25
    start, end = plan.window
    assert abs(plan.walker.position(start)[1]) == pytest.approx(reach)
    assert abs(plan.walker.position(end)[1]) == pytest.approx(reach)
    assert abs(plan.walker.position(0.5 * (start + end))[1]) == pytest.approx(0.0)
    beside = script(StopJob(robot, "none", "pass_beside", seed=3, pass_gap=0.3))
    assert beside.window is None
    assert abs(beside.walker.position(2.0)[1]) == pytest.approx(reach + 0.3)


@pytest.mark.sim
def test_a_tiny_run_prints_the_table_and_writes_the_json(tmp_path, capsys):
    path = tmp_path / "stop.json"
    assert main(["--filters", "cbf", "--quick", "--workers", "1", "--no-progress", "--json", str(path)]) == 0
    assert "| ROS 2 collision monitor test |" in capsys.readouterr().out
    written = json.loads(path.read_text())
    (row,) = written["rows"]
    assert (row["filter"], row["robot"], row["collisions"]) == ("cbf", "rosbot", 0)
    assert {episode["episode"] for episode in written["episodes"]} == {"step_in", "pass_beside"}


def test_the_script_form_runs_from_anywhere(tmp_path):
    script_path = Path(__file__).resolve().parents[2] / "benchmarks" / "stop_metrics.py"
    done = subprocess.run([sys.executable, str(script_path), "--help"], cwd=tmp_path, capture_output=True, text=True,
                          check=False)
    assert done.returncode == 0 and "time-to-stop" in done.stdout


@pytest.mark.sim
@pytest.mark.parametrize("robot", ["rosbot", "puzzlebot"])
def test_the_mpc_tracking_the_cbf_stops_within_the_collision_monitors_time_and_the_plain_one_does_not(robot):
    """A walker steps in 0.25 m ahead: the plain MPC keeps its speed until its plan must brake (0.74-1.22 s);
    tracking the CBF's answer (``reference="cbf"``) it brakes when the CBF does, within Nav2's 0.6 s."""
    plain = run_job(StopJob(robot, "mpc", "step_in", seed=0, gap=0.25))
    tracked = run_job(StopJob(robot, "mpc", "step_in", seed=0, gap=0.25, mpc_reference="cbf"))
    assert plain["time_to_stop"] > NAV2_LIMITS["time_to_stop"]
    assert tracked["time_to_stop"] <= NAV2_LIMITS["time_to_stop"]
    assert tracked["hold_stop"] >= NAV2_LIMITS["hold_stop"]
    assert not tracked["collided"] and tracked["min_clearance"] > plain["min_clearance"]
    assert label(tracked) == "mpc (cbf reference)" and label(plain) == "mpc"


def test_an_unknown_mpc_reference_is_a_usage_error(capsys):
    assert main(["--filters", "mpc", "--mpc-reference", "zones", "--quick", "--no-progress"]) == 2
    assert "zones" in capsys.readouterr().err


def test_the_mpc_lookahead_is_its_own_row_label():
    assert label({"filter": "mpc", "mpc_reference": "nominal", "mpc_lookahead": 0.1}) == "mpc (look-ahead 0.1 m)"
    assert label({"filter": "mpc+escape", "mpc_reference": "nominal", "mpc_lookahead": 0.2}) == \
        "mpc+escape (nominal reference, look-ahead 0.2 m)"
    # The MPC + escape tracks the CBF of its own (ESCAPE_PRESETS): only another reference is named.
    assert label({"filter": "mpc+escape", "mpc_reference": "cbf"}) == "mpc+escape"
    assert label({"filter": "mpc", "mpc_reference": "cbf"}) == "mpc (cbf reference)"
    assert label({"filter": "cbf", "mpc_lookahead": 0.1}) == "cbf"
