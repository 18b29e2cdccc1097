"""The braking benchmark's late-call table (``python -m benchmarks.braking --late``)."""

from __future__ import annotations

import pytest

from benchmarks.braking import LATE_FILTERS, late_calls, main
from safenav import preset


def test_with_every_call_braking_each_filter_stops_within_the_braking_distance_plus_the_first_calls_excess():
    robot, dt = preset("rosbot"), 0.05
    rows = late_calls(periods=(1, 3), dt=dt)
    assert [(row["filter"], row["calls_every"]) for row in rows] == [(f, m) for f in LATE_FILTERS for m in (1, 3)]
    braking = robot.v_max**2 / (2.0 * robot.a_max)
    for row in rows:
        assert row["status"] == "stale"
        # The first call plans for dt (it cannot know the next comes late); every later one for the period held.
        assert row["distance"] <= braking + robot.v_max * (row["calls_every"] - 1) * dt + 1e-9, row
        assert row["distance"] >= braking - 0.01, row
    assert {row["calls"] for row in rows if row["calls_every"] == 3} == {6}


def test_the_late_table_prints_and_writes_json(tmp_path, capsys):
    path = tmp_path / "late.json"
    assert main(["--late", "--json", str(path)]) == 0
    assert "| cbf | 3 dt |" in capsys.readouterr().out
    assert path.read_text().startswith("{")


def test_the_help_names_the_late_table(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    assert "--late" in capsys.readouterr().out
