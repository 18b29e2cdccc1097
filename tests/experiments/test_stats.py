"""Statistics: the Wilson interval against published values, cell records aggregated by hand."""

import json

import pytest

from safenav import InvalidConfig
from safenav.experiments import Cell, cell_record, wilson_interval
from tests.experiments.outcomes import metrics


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


def test_cell_record_counts_deadlocks_escapes_and_chatter_by_hand():
    episodes = [
        metrics(deadlock_time=6.0, longest_deadlock=6.0, escapes=(2, 1), escape_time=4.0, omega_chatter=1.0,
                v_reversals=0.5, nominal_omega_chatter=0.5, escape_omega_chatter=0.25),
        metrics(deadlock_time=3.0, longest_deadlock=5.0, omega_chatter=2.0),      # exactly 5 s is not over it
        metrics(escapes=(1, 1), escape_time=2.0, v_reversals=1.0, nominal_omega_chatter=1.5, escape_omega_chatter=0.75),
        metrics(deadlock_time=12.0, longest_deadlock=9.5, escapes=(3, 0), escape_time=9.0, omega_chatter=3.0,
                v_reversals=2.5, nominal_omega_chatter=2.0, escape_omega_chatter=2.0),
    ]
    record = cell_record(Cell("door_rosbot", "go_to_goal", "cbf+escape"), "rosbot", episodes, seeds=[3, 4, 5, 6])
    assert (record["deadlocked_episodes"], record["deadlock_rate"]) == (2, 0.5)
    assert record["deadlock_rate_ci"] == pytest.approx(list(wilson_interval(2, 4)))
    assert record["deadlocked_seeds"] == [3, 6]
    assert record["deadlock_time"] == pytest.approx(21.0 / 4)
    assert record["deadlock_time_total"] == pytest.approx(21.0)
    assert (record["escapes_started"], record["escapes_succeeded"]) == (6, 2)
    assert record["escape_time"] == pytest.approx(15.0 / 4)
    assert record["omega_chatter"] == pytest.approx(6.0 / 4)
    assert record["v_reversals"] == pytest.approx(4.0 / 4)
    assert record["nominal_omega_chatter"] == pytest.approx(4.0 / 4)
    assert record["escape_omega_chatter"] == pytest.approx(3.0 / 3)     # over the three episodes that escaped
    json.dumps(record, allow_nan=False)
    calm = cell_record(Cell("door_rosbot", "go_to_goal", "cbf"), "rosbot", [metrics(), metrics()])
    assert calm["escape_omega_chatter"] is None                          # no escape: no number, and valid JSON
    json.dumps(calm, allow_nan=False)
