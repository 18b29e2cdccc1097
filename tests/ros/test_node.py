"""The safety node over real middleware: braking, stale scans, ~/enable, malformed scans, point clouds.

The probe (``probe.py``, its own process) publishes scans of the ROSbot's lidar (and point
clouds) and a forward command at 20 Hz and records the nodes' ``cmd_vel`` and ``~/state``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from tests.ros.clouds import cloud_parameters
from tests.ros.graph import MIDDLEWARES, MIDDLEWARES_ROS1_SLOW

CONTROL_PERIOD = 0.05
#: The probe's scans are static (nothing moves the robot), so over the wall phases a deadlock builds
#: up and the escape (on by default) would turn in place: the braking tests run the filter alone, and
#: the escape has its own test below.
FILTER_ALONE = {"escape": False}
SCAN_TIMEOUT = 0.5
SETTLE = 0.3        # [s] after a phase starts before its outputs must show the new behaviour
DELIVERY = 0.3      # [s] allowance for discovery-free delivery and scheduling on a loaded machine


def _outputs_after(phase: dict, seconds: float) -> list[list[float]]:
    return [o for o in phase["outputs"] if o[0] >= phase["begin"] + seconds]


def _statuses(phase: dict) -> set[str]:
    return {state["status"] for state in phase["states"]}


@pytest.mark.parametrize("middleware", MIDDLEWARES_ROS1_SLOW)
def test_node_brakes_times_out_passes_through_and_survives_malformed_scans(graphs, middleware: str,
                                                                          tmp_path: Path) -> None:
    """And a misspelt parameter stops another node at once with one line that names it."""
    graph = graphs(middleware)
    node = graph.spawn("node", params={**FILTER_ALONE, "robot": "rosbot", "filter": "cbf", "odom_topic": "",
                                       "scan.timeout": SCAN_TIMEOUT, "cmd_vel_timeout": 5.0,
                                       "control_period": CONTROL_PERIOD})
    misspelt = graph.spawn("misspelt", params={"robot": "rosbot", "scan_timout": 1.0}, node_name="misspelt")
    out = tmp_path / "probe.json"
    probe = graph.run("probe", [sys.executable, "tests/ros/probe.py", middleware, str(out)])
    assert probe.wait(timeout=120) == 0, graph.log("probe") + graph.log("node")
    phases = json.loads(out.read_text())
    context = graph.log("node")

    assert "ok" in _statuses(phases["discovery"]), context

    # Free space: the nominal passes bit for bit, every period.
    free = _outputs_after(phases["free"], SETTLE)
    assert len(free) >= 10, context
    assert all(o[1:] == [0.5, 0.0] for o in free)
    assert not any(s["intervened"] for s in phases["free"]["states"] if s["t"] >= phases["free"]["begin"] + SETTLE)

    # A wall 0.4 m ahead: the filter slows the forward command, and says it intervened.
    wall = _outputs_after(phases["wall"], SETTLE)
    assert wall and all(0.0 <= o[1] <= 0.3 for o in wall), wall
    assert "ok" in _statuses(phases["wall"])
    assert all(s["intervened"] for s in phases["wall"]["states"] if s["t"] >= phases["wall"]["begin"] + SETTLE)

    # The scan stops: within the timeout one zero command, then silence; the state says stale.
    stale, last_scan = phases["stale"], phases["wall"]["last_scan"]
    zeros = [o for o in stale["outputs"] if o[1:] == [0.0, 0.0]]
    assert len(zeros) == 1, stale["outputs"]
    assert zeros[0][0] - last_scan <= SCAN_TIMEOUT + 2 * CONTROL_PERIOD + DELIVERY
    assert all(o[0] <= zeros[0][0] for o in stale["outputs"])
    assert "stale" in _statuses(stale)
    assert any("timeout" in s["reason"] for s in stale["states"] if s["status"] == "stale")

    # ~/enable false: the command passes through unchanged, with a warning in the state.
    assert "disabled" in phases["enable_off_answer"]
    disabled = _outputs_after(phases["disabled"], SETTLE)
    assert disabled and all(o[1:] == [0.5, 0.0] for o in disabled)
    assert "disabled" in _statuses(phases["disabled"])
    assert "enabled" in phases["enable_on_answer"]
    assert "ok" in _statuses(phases["wall_again"])

    # Malformed scans brake and are reported; the node lives on and recovers.
    for name, field in (("wrong_lengths", "ranges"), ("nan_angles", "angle_min")):
        phase = phases[name]
        bad = [s for s in phase["states"] if s["status"] == "bad_message"]
        assert bad and field in bad[-1]["reason"], phase["states"][-3:]
        assert all(o[1:] == [0.0, 0.0] for o in _outputs_after(phase, SETTLE)), phase["outputs"]
    assert [0.0, 0.0] in [o[1:] for o in phases["wrong_lengths"]["outputs"]]
    recovered = _outputs_after(phases["recovered"], SETTLE)
    assert "ok" in _statuses(phases["recovered"])
    assert recovered and all(0.0 < o[1] <= 0.3 for o in recovered)
    assert node.poll() is None, context
    assert context.count("braking: source 'scan': malformed message") == 2, context   # once per cause


    assert misspelt.wait(timeout=30) == 2
    said = [line for line in graph.log("misspelt").splitlines() if line.startswith(f"safenav-{middleware}: ")]
    assert len(said) == 1 and said[0].startswith(f"safenav-{middleware}: unknown parameter 'scan_timout'; "
                                                 f"expected one of: "), graph.log("misspelt")


@pytest.mark.parametrize("middleware", MIDDLEWARES_ROS1_SLOW)
def test_point_cloud_sources_brake_for_a_wall_only_the_cloud_sees_and_survive_a_malformed_cloud(
        graphs, middleware: str, tmp_path: Path) -> None:
    """Two nodes on one ``cloud`` topic: a LaserScan plus a depth-camera cloud, and a 3D-lidar cloud alone."""
    graph = graphs(middleware)
    common = {**FILTER_ALONE, "robot": "rosbot", "filter": "cbf", "odom_topic": "", "cmd_vel_timeout": 5.0,
              "control_period": CONTROL_PERIOD}
    nodes = {"node": graph.spawn("node", params={**common, "sources": ["scan", "cloud"],
                                                 **cloud_parameters("cloud", full_turn=False)}),
             "cloud_only": graph.spawn("cloud_only", node_name="cloud_only", params={
                 **common, "sources": ["cloud"], "cmd_vel_out_topic": "cmd_vel_cloud_only",
                 **cloud_parameters("cloud", full_turn=True)})}
    out = tmp_path / "probe.json"
    probe = graph.run("probe", [sys.executable, "tests/ros/probe.py", middleware, str(out), "cloud"])
    assert probe.wait(timeout=120) == 0, graph.log("probe") + graph.log("node") + graph.log("cloud_only")
    phases = json.loads(out.read_text())

    for label, process in nodes.items():
        context = graph.log(label)
        seen = {name: phases[name] if label == "node" else {"begin": phases[name]["begin"], **phases[name][label]}
                for name in ("discovery", "free", "wall", "malformed", "recovered")}
        assert "ok" in _statuses(seen["discovery"]), context

        # Free space (floor points under the band, nothing in it): the nominal passes bit for bit.
        free = _outputs_after(seen["free"], SETTLE)
        assert len(free) >= 10 and all(o[1:] == [0.5, 0.0] for o in free), (label, free, context)

        # A wall 0.4 m ahead in the cloud only (the scan stays free): the forward command is slowed.
        wall = _outputs_after(seen["wall"], SETTLE)
        assert wall and all(0.0 <= o[1] <= 0.3 for o in wall), (label, wall)
        settled = [s for s in seen["wall"]["states"] if s["t"] >= seen["wall"]["begin"] + SETTLE]
        assert settled and all(s["intervened"] for s in settled), (label, settled[-3:])
        assert "ok" in _statuses(seen["wall"])     # (a tick a little late on a loaded machine says "late")
        assert all(s["binding"] == "barrier" for s in settled if s["status"] == "ok"), (label, settled[-3:])

        # A malformed cloud brakes (zero once, then silence) and names the field; the node lives on.
        bad = [s for s in seen["malformed"]["states"] if s["status"] == "bad_message"]
        assert bad and "PointCloud2.data" in bad[-1]["reason"], (label, seen["malformed"]["states"][-3:])
        assert [0.0, 0.0] in [o[1:] for o in seen["malformed"]["outputs"]], (label, seen["malformed"]["outputs"])
        assert all(o[1:] == [0.0, 0.0] for o in _outputs_after(seen["malformed"], SETTLE))
        recovered = _outputs_after(seen["recovered"], SETTLE)
        assert "ok" in _statuses(seen["recovered"])
        assert recovered and all(0.0 < o[1] <= 0.3 for o in recovered), (label, recovered)
        assert process.poll() is None, context
        # Logged once (lines of the node's own logger; rospy may echo them through its rosout logger too).
        warned = [line for line in context.splitlines()
                  if line.startswith("[WARN]") and "braking: source 'cloud': malformed message" in line]
        assert len(warned) == 1, context


@pytest.mark.parametrize("middleware", MIDDLEWARES)
def test_the_escape_is_on_by_default_and_the_escape_parameter_turns_it_off(graphs, middleware: str,
                                                                          tmp_path: Path) -> None:
    """Two nodes against a wall at the margin: the default one escapes (and says so in ``~/state``), the
    one with ``escape: false`` holds still and reports the deadlock."""
    graph = graphs(middleware)
    common = {"odom_topic": "", "cmd_vel_timeout": 5.0}
    nodes = {"node": graph.spawn("node", params=common),
             "no_escape": graph.spawn("no_escape", node_name="no_escape", params={
                 **common, "escape": False, "cmd_vel_out_topic": "cmd_vel_no_escape"})}
    out = tmp_path / "probe.json"
    probe = graph.run("probe", [sys.executable, "tests/ros/probe.py", middleware, str(out), "escape"])
    assert probe.wait(timeout=120) == 0, graph.log("probe") + graph.log("node") + graph.log("no_escape")
    phases = json.loads(out.read_text())
    wall = {"node": phases["wall"], "no_escape": {"begin": phases["wall"]["begin"], **phases["wall"]["no_escape"]}}
    for label, process in nodes.items():
        assert process.poll() is None, graph.log(label)
        assert all(s["escape_enabled"] == (label == "node") for s in wall[label]["states"]), label

    escaping = [s for s in wall["node"]["states"] if s["escape"]]
    assert escaping, (wall["node"]["states"][-3:], graph.log("node"))
    assert all(s["binding"] == "escape" and s["u_nom"] == [0.5, 0.0] for s in escaping)
    assert "following the obstacle" in escaping[0]["escape"] or "backing out" in escaping[0]["escape"]
    after = [o for o in wall["node"]["outputs"] if o[0] >= escaping[0]["t"]]
    assert after and any(abs(o[2]) > 0.1 for o in after), after          # it turns away from the wall

    held = wall["no_escape"]["states"]
    assert held and not any(s["escape"] for s in held), held[-3:]
    assert held[-1]["deadlock"] is not None and held[-1]["deadlock"] >= 1.0, held[-3:]
    assert all(abs(o[2]) < 1e-9 for o in wall["no_escape"]["outputs"])  # the filter alone never turns
