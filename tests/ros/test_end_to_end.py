"""Three processes over real middleware: the simulator, the buggy tutorial controller, the safety node.

The first tutorial's controller reads beam 360 as "front"; on the ROSbot that beam looks
backward, so the controller drives into the wall 3 m ahead. With the safety node between the
controller and the simulated base (``cmd_vel_in`` -> ``cmd_vel``) the robot must stop short of
the wall over 20 s of real time; wired straight to the base it must hit it. Both stacks run at
once, each in its own graph. Contact is the simulator's truth, which no node sees.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.ros.graph import MIDDLEWARES_ROS1_SLOW

DURATION = 20.0   # [s] simulated, in real time


@pytest.mark.parametrize("middleware", MIDDLEWARES_ROS1_SLOW)
def test_buggy_controller_hits_the_wall_alone_and_stops_short_of_it_behind_the_filter(graphs, middleware: str,
                                                                                      tmp_path: Path) -> None:
    filtered, alone = graphs(middleware), graphs(middleware)
    reports = {"filtered": tmp_path / "filtered.json", "alone": tmp_path / "alone.json"}
    sims = {}
    for label, graph in (("filtered", filtered), ("alone", alone)):
        sims[label] = graph.spawn("sim", "sim", "--world", "stop_at_wall", "--robot", "rosbot",
                                  "--duration", str(DURATION), "--stop-on-contact", "--report", str(reports[label]))
    filtered.spawn("policy", "policy", "stop_at_wall_buggy", "--robot", "rosbot")
    filtered.spawn("node", params={"robot": "rosbot", "filter": "cbf"})
    alone.spawn("policy", "policy", "stop_at_wall_buggy", "--robot", "rosbot", "--output", "cmd_vel")
    for label, graph in (("alone", alone), ("filtered", filtered)):
        assert sims[label].wait(timeout=DURATION + 60) == 0, graph.log("sim")
    outcome = {label: json.loads(path.read_text()) for label, path in reports.items()}

    alone_run, filtered_run = outcome["alone"], outcome["filtered"]
    assert alone_run["first_collision_time"] is not None, (alone_run, alone.log("policy"))
    assert filtered_run["time"] >= DURATION - 1e-6
    assert filtered_run["first_collision_time"] is None, (filtered_run, filtered.log("node"))
    assert filtered_run["min_clearance"] > 0.0
    # The filter let the controller do its job: the robot drove most of the 2.85 m to the wall.
    assert filtered_run["distance"] > 2.0, (filtered_run, filtered.log("node"))
