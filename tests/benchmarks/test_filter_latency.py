"""benchmarks/filter_latency.py: its paths run and report what they time (small sizes; numbers in BENCHMARKS.md)."""

import json
from pathlib import Path

import pytest

import safenav
from benchmarks import filter_latency
from safenav import preset
from safenav.robot import PRESET_NAMES


def test_real_recordings_time_the_filter_on_every_scan_of_every_recording(lidar_data, monkeypatch):
    """The recordings' lidars are not the preset's: each is timed on a robot carrying the recording's own lidar
    (until 2026-11-27 the strict scan check rejected the first scan and ``--real`` raised)."""
    from safenav.datasets import load_recording, recording_files

    monkeypatch.setenv("SAFENAV_LIDAR_DATA", str(lidar_data))
    rows = filter_latency.real_recordings(preset("rosbot"), "daqp", per_scan=1, seed=0)
    files = recording_files(lidar_data)
    assert [row["recording"] for row in rows] == list(files)
    for row in rows:
        scans = len(load_recording(files[row["recording"]]))
        assert row["scans"] == scans and row["end_to_end"]["n"] == scans
        assert row["end_to_end"]["median_us"] > 0.0
        assert sum(row["statuses"].values()) == scans and row["statuses"].get("fallback", 0) == 0


def test_the_default_run_writes_its_tables_as_json(tmp_path, capsys):
    path = tmp_path / "latency.json"
    assert filter_latency.main(["--scenes", "3", "--per-scene", "2", "--solvers", "daqp", "--baseline-calls", "4",
                                "--json", str(path)]) == 0
    results = json.loads(path.read_text())
    assert results["cbf"]["daqp"]["end_to_end"]["median_us"] > 0.0
    assert results["baseline"]["end_to_end"]["median_us"] > 0.0
    assert "speed-up vs baseline" in capsys.readouterr().out


def test_the_reach_table_times_every_preset_in_every_scene(tmp_path):
    path = tmp_path / "reach.json"
    assert filter_latency.main(["--only-reach", "--reach-calls", "3", "--json", str(path)]) == 0
    rows = json.loads(path.read_text())["reach"]
    scenes = list(filter_latency.reach_scenes(preset("rosbot")))
    assert [(row["robot"], row["scene"]) for row in rows] == [(name, scene) for name in PRESET_NAMES
                                                              for scene in scenes]
    for row in rows:
        assert row["end_to_end"]["n"] == 3 and row["late_scan"]["n"] == 3 and sum(row["statuses"].values()) == 3
        assert (row["points"] == 0) == (row["scene"] == "nothing in range")
        assert not row["modified"] or row["scene"].startswith("wall")


def test_the_startup_table_times_every_phase_of_a_fresh_process_of_this_tree(tmp_path):
    path = tmp_path / "startup.json"
    assert filter_latency.main(["--only-startup", "--startup-runs", "2", "--json", str(path)]) == 0
    measured = json.loads(path.read_text())["startup"]
    assert measured["runs"] == 2 and Path(measured["safenav"]).resolve() == Path(safenav.__file__).resolve().parent
    phases = measured["phases"]
    assert list(phases) == list(filter_latency.STARTUP_PHASES)
    assert all(0.0 < times["median_s"] <= times["max_s"] for times in phases.values())
    assert phases["total"]["median_s"] >= max(times["median_s"] for name, times in phases.items() if name != "total")


def test_the_gc_table_measures_a_full_collection_in_fresh_processes(tmp_path):
    path = tmp_path / "gc.json"
    assert filter_latency.main(["--only-gc", "--json", str(path)]) == 0
    rows = {(row["kernels"], row["frozen"]): row for row in json.loads(path.read_text())["gc"]}
    assert set(rows) == set(filter_latency.GC_SETTINGS)
    for kernels in ("numpy", "numba"):
        built, frozen = rows[kernels, False], rows[kernels, True]
        assert built["frozen_objects"] == 0 and built["visited"] > 10_000
        assert frozen["frozen_objects"] > 10_000 and frozen["visited"] < 0.05 * built["visited"]
    assert rows["numba", False]["visited"] > rows["numpy", False]["visited"]


def test_the_deadline_scenario_times_every_filter_at_the_budget_asked(tmp_path, monkeypatch):
    monkeypatch.setattr(filter_latency, "WALL_GAPS", (0.06,))
    monkeypatch.setattr(filter_latency, "DEADLINE_DURATION", 1.0)
    path = tmp_path / "deadline.json"
    assert filter_latency.main(["--only-deadline", "--deadline-robots", "m2wr", "--deadline-dts", "0.05",
                                "--deadline-budget", "0.1", "--json", str(path)]) == 0
    rows = json.loads(path.read_text())["deadline"]
    assert [row["filter"] for row in rows] == ["cbf", "mpc", "mpc (cbf reference)"]
    for row in rows:
        assert row["budget_s"] == pytest.approx(0.005) and row["budget_fraction"] == 0.1
        assert row["calls"]["n"] == 2 * 20 == sum(row["statuses"].values())
        assert 0 <= row["deadline_fallbacks"] <= row["statuses"].get("fallback", 0)
    assert "baseline" in rows[0]


def test_the_mpc_table_times_its_nlp_solves_apart_by_slack(tmp_path, capsys):
    """``--mpc`` times every NLP solve of the MPC's solving calls, one slack for every row or a slack per point."""
    path = tmp_path / "mpc.json"
    assert filter_latency.main(["--robot", "m2wr", "--scenes", "6", "--per-scene", "10", "--solvers", "daqp",
                                "--baseline-calls", "2", "--mpc", "--mpc-calls", "60", "--json", str(path)]) == 0
    mpc = json.loads(path.read_text())["mpc"]
    solves = mpc["nlp_solves"]
    assert mpc["qp_calls"]["n"] > 0 and solves["all"]["n"] >= mpc["qp_calls"]["n"]
    assert solves["all"]["n"] == solves["shared"]["n"] + solves["per_point"]["n"]
    assert solves["per_solving_call"] == pytest.approx(solves["all"]["n"] / mpc["qp_calls"]["n"])
    assert solves["all"]["max_us"] >= solves["all"]["p99_us"] >= solves["all"]["median_us"] > 0.0
    assert "the MPC's NLP solves" in capsys.readouterr().out
