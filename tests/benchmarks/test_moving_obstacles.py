"""The moving-obstacle sweep's worlds and table (benchmarks/moving_obstacles.py), without running episodes."""

import json
import math

import pytest

from benchmarks.moving_obstacles import BEAT_HALF_WIDTH, START_CLEAR, MovingJob, main, summarise, world_for
from safenav.experiments import wilson_interval


def test_the_walkers_pace_around_the_start_at_the_speed_and_leave_it_clear():
    job = MovingJob("puzzlebot", "cbf", speed=0.7, count=5, seed=2, duration=10.0)
    world = world_for(job)
    assert world == world_for(job)
    assert len(world.movers) == 5 and world.obstacles     # the clutter is still there
    start = world.start
    for walker in world.movers:
        assert walker.max_speed == pytest.approx(0.7)
        for moment in (0.0, 3.3, 9.9):
            x, y = walker.position(moment)
            assert abs(x - start.x) <= BEAT_HALF_WIDTH and abs(y - start.y) <= BEAT_HALF_WIDTH
        assert math.hypot(walker.position(0.0)[0] - start.x, walker.position(0.0)[1] - start.y) >= START_CLEAR


def test_summarise_counts_collisions_with_the_wilson_interval():
    def record(seed, collided, walker=False, standing=False, clearance=0.1):
        return {"robot": "rosbot", "filter": "cbf", "extra_margin": 0.0, "speed": 1.0, "count": 4, "seed": seed,
                "collided": collided, "with_walker": walker, "robot_standing": standing, "min_clearance": clearance}

    records = [record(0, True, True, True, -0.02), record(1, True, True, False, -0.05), record(2, False),
               record(3, False), {**record(0, False), "speed": 0.5}]
    rows = summarise(records)
    assert [(row["speed"], row["episodes"]) for row in rows] == [(0.5, 1), (1.0, 4)]
    fast = rows[1]
    assert (fast["collisions"], fast["with_walker"], fast["robot_standing"]) == (2, 2, 1)
    assert fast["rate"] == 0.5
    assert (fast["ci_low"], fast["ci_high"]) == wilson_interval(2, 4)
    assert fast["min_clearance"] == -0.05


def test_a_margin_for_a_filter_without_one_is_a_clear_error(capsys):
    assert main(["--filters", "zones", "--margins", "0,0.1"]) == 2
    assert "unknown filter with a margin (--margins) 'zones'" in capsys.readouterr().err


@pytest.mark.sim
def test_a_tiny_sweep_writes_its_rows(tmp_path, capsys):
    path = tmp_path / "moving.json"
    assert main(["--robots", "rosbot", "--filters", "cbf", "--speeds", "1.0", "--counts", "2", "--seeds", "2",
                 "--duration", "2", "--workers", "1", "--no-progress", "--json", str(path)]) == 0
    assert "OUTSIDE THE GUARANTEE" in capsys.readouterr().out
    written = json.loads(path.read_text())
    (row,) = written["rows"]
    assert (row["robot"], row["filter"], row["count"], row["speed"], row["episodes"]) == ("rosbot", "cbf", 2, 1.0, 2)
