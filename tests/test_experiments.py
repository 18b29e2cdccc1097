"""Experiments: the Wilson interval, aggregation by hand, determinism across workers, the collision benchmark."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from safenav import InvalidConfig, UnknownName
from safenav.cli import load_benchmark
from safenav.episode import EpisodeMetrics
from safenav.experiments import (
    Cell,
    EpisodeSpec,
    cell_record,
    cell_records,
    episode_specs,
    matrix,
    outcome_table,
    run_specs,
    scenario_for,
    wilson_interval,
)
from safenav.filters import FILTER_NAMES
from safenav.scenarios import SCENARIO_NAMES, scenario

collision_rates = load_benchmark("collision_rates", roots=[Path(__file__).resolve().parents[1]])

# ---------------------------------------------------------------------------------------------- Wilson


@pytest.mark.parametrize(("successes", "trials", "low", "high"), [
    (0, 10, 0.0, 0.2775),
    (5, 10, 0.2366, 0.7634),
    (10, 10, 0.7225, 1.0),
    (1, 20, 0.0089, 0.2361),
    (0, 1, 0.0, 0.7935),
    (30, 100, 0.2189, 0.3958),
])
def test_wilson_interval_matches_published_values(successes, trials, low, high):
    assert wilson_interval(successes, trials) == pytest.approx((low, high), abs=5e-4)


def test_wilson_interval_is_symmetric_and_contains_the_rate():
    for trials in (1, 7, 26):
        for successes in range(trials + 1):
            low, high = wilson_interval(successes, trials)
            assert 0.0 <= low <= successes / trials <= high <= 1.0
            mirrored = wilson_interval(trials - successes, trials)
            assert mirrored == pytest.approx((1.0 - high, 1.0 - low), abs=1e-12)


@pytest.mark.parametrize(("successes", "trials"), [(0, 0), (3, 2), (-1, 5)])
def test_wilson_interval_rejects_impossible_counts(successes, trials):
    with pytest.raises(InvalidConfig, match=f"{successes}/{trials}"):
        wilson_interval(successes, trials)


# ---------------------------------------------------------------------------------------------- aggregation


def metrics(*, collided=False, min_clearance=0.2, distance=1.0, intervention=0.0, goal=None, time_to_goal=None,
            progress=None, stuck=0.0, time=10.0, fallbacks=0, filter_times=(), statuses=None) -> EpisodeMetrics:
    """Synthetic metrics of one episode."""
    return EpisodeMetrics(
        steps=int(time / 0.05), time=time, collided=collided, collision_time=5.0 if collided else None,
        min_clearance=min_clearance, distance=distance, mean_intervention=intervention,
        max_intervention=2 * intervention, goal_reached=goal, time_to_goal=time_to_goal, goal_progress=progress,
        stuck_time=stuck, fallbacks=fallbacks, statuses=statuses or {"none": int(time / 0.05)},
        filter_times=np.asarray(filter_times, dtype=float),
    )


def test_cell_record_aggregates_by_hand():
    episodes = [
        metrics(collided=True, min_clearance=-0.02, distance=2.0, intervention=0.1, stuck=1.0, fallbacks=1,
                filter_times=[1e-6, 2e-6], statuses={"ok": 3, "fallback": 1}),
        metrics(min_clearance=0.30, distance=4.0, intervention=0.3, stuck=3.0, time=5.0,
                filter_times=[3e-6, 4e-6, 5e-6], statuses={"ok": 2, "slack": 4}),
        metrics(min_clearance=0.10, distance=6.0, intervention=0.2, fallbacks=2, filter_times=[6e-6],
                statuses={"ok": 5}),
    ]
    record = cell_record(Cell("clutter_rosbot", "random_walk", "cbf"), "rosbot", episodes, seeds=[4, 5, 6],
                         wall_times=[1.0, 2.0, 4.5])
    assert (record["scenario"], record["robot"], record["policy"], record["filter"]) == \
           ("clutter_rosbot", "rosbot", "random_walk", "cbf")
    assert (record["episodes"], record["collisions"]) == (3, 1)
    assert record["collision_rate"] == pytest.approx(1 / 3)
    assert record["collision_rate_ci"] == pytest.approx(list(wilson_interval(1, 3)))
    assert record["min_clearance"] == pytest.approx({"min": -0.02, "p5": -0.02 + 0.1 * 0.12, "median": 0.10})
    assert record["intervention"] == pytest.approx(0.2)
    assert record["distance"] == record["progress"] == pytest.approx(4.0)
    assert record["progress_kind"] == "distance"
    assert record["goal_success"] is None and record["time_to_goal"] is None
    assert record["stuck_time"] == pytest.approx(4.0 / 3)
    assert record["stuck_fraction"] == pytest.approx((0.1 + 0.6 + 0.0) / 3)
    assert record["fallbacks"] == 3
    assert record["filter_calls"] == 6
    assert record["filter_p50_us"] == pytest.approx(3.5)
    assert record["filter_p99_us"] == pytest.approx(5.95)
    assert record["statuses"] == {"fallback": 1, "ok": 10, "slack": 4}
    assert record["seeds"] == [4, 5, 6] and record["collided_seeds"] == [4]
    assert record["episode_wall_s"] == pytest.approx(2.5)
    json.dumps(record, allow_nan=False)


def test_cell_record_of_goal_task_without_filter():
    episodes = [metrics(goal=True, time_to_goal=8.0, progress=5.0, distance=6.0),
                metrics(goal=False, progress=1.0, distance=2.0),
                metrics(goal=True, time_to_goal=12.0, progress=5.0, distance=7.0),
                metrics(goal=True, time_to_goal=30.0, progress=5.0, distance=9.0)]
    record = cell_record(Cell("goal_m2wr", "go_to_goal", "none"), "m2wr", episodes)
    assert record["progress_kind"] == "goal_progress"
    assert record["progress"] == pytest.approx(4.0)
    assert record["distance"] == pytest.approx(6.0)
    assert record["goal_success"] == pytest.approx(0.75) and record["goal_reached"] == 3
    assert record["time_to_goal"] == pytest.approx({"mean": 50 / 3, "median": 12.0})
    assert record["filter_calls"] == 0
    assert record["filter_p50_us"] is None and record["filter_p99_us"] is None
    assert record["seeds"] == [0, 1, 2, 3] and record["episode_wall_s"] is None
    assert record["collisions"] == 0 and record["collision_rate_ci"][0] == 0.0


def test_cell_record_needs_episodes():
    with pytest.raises(InvalidConfig, match="no episodes"):
        cell_record(Cell("stop_at_wall", "stop_at_wall", "none"), "rosbot", [])


# ---------------------------------------------------------------------------------------------- specs


def test_matrix_covers_every_scenario_and_policy_in_registry_order():
    cells = matrix()
    pairs = list(dict.fromkeys((cell.scenario, cell.policy) for cell in cells))
    assert pairs == [(name, policy) for name in SCENARIO_NAMES for policy in scenario(name).policies]
    assert len(cells) == len(FILTER_NAMES) * len(pairs)
    assert [cell.filter for cell in cells[:4]] == ["none", "zones", "cbf", "mpc"]


def test_matrix_selects_policies_across_scenarios():
    cells = matrix(policies=["random_walk"], filters=["cbf"])
    assert [cell.scenario for cell in cells] == ["clutter_rosbot", "clutter_puzzlebot", "clutter_m2wr"]
    assert {cell.policy for cell in cells} == {"random_walk"}


@pytest.mark.parametrize(("call", "error", "message"), [
    (lambda: matrix(scenarios=["moon"]), UnknownName, "unknown scenario 'moon'; expected one of: clutter_m2wr"),
    (lambda: matrix(policies=["dance"]), UnknownName, "unknown policy 'dance'; expected one of: go_to_goal"),
    (lambda: matrix(filters=["magic"]), UnknownName, r"unknown filter .magic.; expected one of: cbf, cbf\+escape, mpc"),
    (lambda: matrix(scenarios=["stop_at_wall"], policies=["go_to_goal"]), InvalidConfig, "no scenario"),
    (lambda: scenario_for("stop_at_wall", robot="r2d2"), UnknownName, "unknown robot 'r2d2'"),
    (lambda: scenario_for("wall_follower", policy="go_to_goal"), InvalidConfig, "needs a world with a goal"),
])
def test_bad_selections_say_what_is_known(call, error, message):
    with pytest.raises(error, match=message):
        call()


def test_scenario_for_swaps_the_robot_and_allows_another_policy():
    task = scenario_for("stop_at_wall", robot="puzzlebot", policy="random_walk")
    assert task.robot.name == "puzzlebot"
    assert "random_walk" in task.policies and "stop_at_wall" in task.policies
    assert task.world(3) == scenario("stop_at_wall").world(3)
    same = scenario_for("stop_at_wall")
    assert (same.robot_name, same.policies, same.duration) == ("rosbot", scenario("stop_at_wall").policies, 12.0)


def test_episode_specs_are_in_cell_then_seed_order():
    cells = [Cell("stop_at_wall", "stop_at_wall", "none"), Cell("stop_at_wall", "stop_at_wall", "cbf")]
    specs = episode_specs(cells, range(3), duration=2.0, record_seeds=[1])
    assert [(s.filter, s.seed) for s in specs] == [("none", 0), ("none", 1), ("none", 2),
                                                   ("cbf", 0), ("cbf", 1), ("cbf", 2)]
    assert [s.record for s in specs] == [False, True, False] * 2
    assert {s.duration for s in specs} == {2.0}


def test_outcome_table_columns():
    record = cell_record(Cell("stop_at_wall", "stop_at_wall_buggy", "none"), "rosbot",
                         [metrics(collided=True, min_clearance=-0.02), metrics(min_clearance=0.5)])
    table = outcome_table([record], ["scenario", "filter", "collisions", "rate [95% CI]"])
    assert table.splitlines() == ["| scenario | filter | collisions | rate [95% CI] |", "|---|---|---|---|",
                                  "| stop_at_wall | none | 1 | 0.50 [0.09, 0.91] |"]
    with pytest.raises(UnknownName, match="unknown table column 'colour'"):
        outcome_table([record], ["colour"])


@pytest.mark.parametrize("workers", [1, 2])
def test_bad_names_fail_before_any_episode(workers):
    specs = [EpisodeSpec("stop_at_wall", "stop_at_wall", "none", seed=0, duration=0.5),
             EpisodeSpec("stop_at_wall", "stop_at_wall", "magic", seed=0, duration=0.5)]
    with pytest.raises(UnknownName, match="unknown filter 'magic'"):
        run_specs(specs, workers=workers, progress=False)


@pytest.mark.sim
@pytest.mark.parametrize("workers", [1, 2])
def test_an_episode_that_fails_fails_the_run(workers):
    specs = [EpisodeSpec("stop_at_wall", "stop_at_wall", "none", seed=0, duration=0.5),
             EpisodeSpec("stop_at_wall", "stop_at_wall", "none", seed=1, duration=-1.0)]
    with pytest.raises(InvalidConfig, match=r"EpisodeConfig\.duration must be a finite number > 0, got -1\.0"):
        run_specs(specs, workers=workers, progress=False)


def test_run_specs_rejects_bad_worker_counts():
    with pytest.raises(InvalidConfig, match="workers"):
        run_specs([], workers=0)


# ---------------------------------------------------------------------------------------------- simulated

TIMING = {"filter_p50_us", "filter_p99_us", "episode_wall_s"}


@pytest.mark.sim
def test_outcomes_do_not_depend_on_the_number_of_workers():
    cells = matrix(scenarios=["stop_at_wall", "clutter_puzzlebot"], policies=["stop_at_wall_buggy", "random_walk"],
                   filters=["none", "cbf"])
    specs = episode_specs(cells, range(2), duration=3.0)
    serial = cell_records(run_specs(specs, workers=1, progress=False))
    parallel = cell_records(run_specs(specs, workers=2, progress=False))
    strip = [[{k: v for k, v in record.items() if k not in TIMING} for record in records]
             for records in (serial, parallel)]
    assert strip[0] == strip[1]
    assert outcome_table(serial) == outcome_table(parallel)
    assert [(r["scenario"], r["policy"], r["filter"]) for r in serial] == \
           [(c.scenario, c.policy, c.filter) for c in cells]
    assert {r["episodes"] for r in serial} == {2}


@pytest.mark.sim
def test_a_recorded_spec_returns_its_trajectory():
    spec = EpisodeSpec("stop_at_wall", "stop_at_wall", "none", seed=0, duration=1.0, record=True)
    (outcome,) = run_specs([spec], workers=1, progress=False)
    assert outcome.robot == "rosbot"
    assert outcome.trajectory is not None and len(outcome.trajectory.pose) == outcome.metrics.steps + 1 == 21


REQUIRED_KEYS = {"scenario", "robot", "policy", "filter", "episodes", "collisions", "collision_rate",
                 "min_clearance", "intervention", "progress", "goal_success", "stuck_time", "fallbacks",
                 "filter_p50_us", "filter_p99_us"}


@pytest.mark.sim
def test_quick_collision_benchmark(tmp_path, capsys):
    out = tmp_path / "rates.json"
    code = collision_rates.main(["--quick", "--json", str(out), "--csv", str(tmp_path / "rates.csv"),
                                 "--plots", str(tmp_path / "plots"), "--no-progress"])
    assert code == 0
    report = json.loads(out.read_text())
    cells = report["cells"]
    assert cells and all(set(cell) >= REQUIRED_KEYS for cell in cells)
    assert report["config"]["quick"] is True and report["config"]["episodes"] == sum(c["episodes"] for c in cells)
    naive = [cell for cell in cells if cell["filter"] == "none"]
    cbf = [cell for cell in cells if cell["filter"] == "cbf"]
    assert any(cell["collisions"] > 0 for cell in naive)
    assert cbf and all(cell["collisions"] == 0 for cell in cbf), [c for c in cbf if c["collisions"]]
    assert all(cell["filter_p50_us"] is None for cell in naive)
    assert all(cell["filter_p50_us"] > 0 and cell["filter_p99_us"] >= cell["filter_p50_us"] for cell in cbf)
    stdout = capsys.readouterr().out
    assert "| stop_at_wall | rosbot | stop_at_wall_buggy | none |" in stdout
    with (tmp_path / "rates.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == len(cells) and "min_clearance_p5" in rows[0] and "collision_rate_ci_high" in rows[0]
    pngs = sorted((tmp_path / "plots").glob("*.png"))
    assert {p.name for p in pngs} >= {"collision_rates.png", "clearance_histogram.png",
                                      "trajectories_stop_at_wall.png"}
    for png in pngs:
        with Image.open(png) as image:
            image.verify()


def test_benchmark_rejects_unknown_names(capsys):
    assert collision_rates.main(["--scenarios", "moon", "--filters", "none"]) == 2
    error = capsys.readouterr().err.strip()
    assert error.startswith("collision_rates: error: unknown scenario 'moon'; expected one of:")
    assert "\n" not in error
