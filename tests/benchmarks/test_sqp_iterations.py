"""The SQP iterations benchmark (``python -m benchmarks.sqp_iterations``)."""

from __future__ import annotations

import json

from benchmarks.sqp_iterations import main


def test_the_table_prints_and_the_secant_solves_the_same_nlps_in_fewer_iterations(tmp_path, capsys):
    path = tmp_path / "sqp.json"
    assert main(["--robots", "puzzlebot", "--scenes", "wall 0.05", "--json", str(path)]) == 0
    out = capsys.readouterr().out
    assert "| puzzlebot | wall 0.05 |" in out and "time secant / full steps" in out
    row = json.loads(path.read_text())["rows"][0]
    assert row["solves"] > 200 and row["limit"] == 30
    secant, full = row["secant"], row["full steps"]
    assert secant["total_iterations"] < full["total_iterations"]
    assert secant["at_limit"] == 0 and secant["iterations_max"] < full["iterations_max"]
