"""``benchmarks/ros_latency.py`` runs in its script form from another folder, on a domain no other test holds."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from tests.ros.graph import ROOT, ros_marks

pytestmark = ros_marks("ros2")


def test_a_tiny_latency_run_answers_every_scan_and_splits_the_filter_from_the_rest(graphs, tmp_path: Path) -> None:
    graph = graphs("ros2")          # reserves a DDS domain id
    out = tmp_path / "latency.json"
    result = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "ros_latency.py"), "--messages", "40",
                             "--filters", "cbf", "--scenes", "5", "--domain", graph.env["ROS_DOMAIN_ID"],
                             "--logs", str(tmp_path), "--json", str(out)],
                            cwd=tmp_path, env=graph.env, capture_output=True, text=True, timeout=180, check=False)
    assert result.returncode == 0, result.stderr + (tmp_path / "ros_latency_cbf.log").read_text()
    assert "| cbf | " in result.stdout and "outside filter p50 ms" in result.stdout
    (run,) = json.loads(out.read_text())["results"]
    assert run["missing_replies"] <= 2 and run["in_node"]["n"] >= 35, run
    in_node, compute, outside = run["in_node"], run["filter_time"], run["outside_filter"]
    assert 0.0 < compute["p50_ms"] < in_node["p50_ms"] and 0.0 < outside["p50_ms"] < in_node["p50_ms"]
