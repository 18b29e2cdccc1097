"""The turning-lidar benchmark (``python -m benchmarks.lidar_sweep``)."""

from __future__ import annotations

import json

from benchmarks.lidar_sweep import main


def test_the_sweep_tables_print_and_the_points_are_where_their_obstacles_are_only_when_the_sweep_is_stated(
        tmp_path, capsys):
    path = tmp_path / "sweep.json"
    assert main(["--robots", "puzzlebot", "--calls", "10", "--json", str(path)]) == 0
    out = capsys.readouterr().out
    assert "| puzzlebot | 0.4 m/s, 2 rad/s | 0.1 |" in out and "stated / unstated" in out
    data = json.loads(path.read_text())
    points = data["points"][0]
    assert points["points"] > 0
    assert points["stated"]["max_m"] < 1e-9 < 0.01 < points["unstated"]["max_m"]
    for row in data["stops"]:
        assert row["stated"] >= 0.0 and row["at once"] >= 0.0, row
    assert {row["filter"] for row in data["costs"]} == {"cbf", "mpc"}
