"""Running specs: failures fail the run, outcomes do not depend on the number of workers, progress."""

import io
import re

import pytest

from safenav import InvalidConfig, UnknownName
from safenav.experiments import EpisodeSpec, Progress, cell_records, episode_specs, matrix, outcome_table, run_specs
from safenav.experiments.runner import reproducible_specs
from safenav.scenarios import scenario


def test_bad_names_fail_before_any_episode():
    """A spec is checked when it is made, so a run never starts with a name it cannot build."""
    with pytest.raises(UnknownName, match="unknown filter 'magic'"):
        run_specs([EpisodeSpec("stop_at_wall", "stop_at_wall", "none", seed=0, duration=0.5),
                   EpisodeSpec("stop_at_wall", "stop_at_wall", "magic", seed=0, duration=0.5)], progress=False)


@pytest.mark.sim
@pytest.mark.parametrize("workers", [1, 2])
def test_an_episode_that_fails_fails_the_run(workers):
    """Filter settings are checked by the filter, inside the episode (in a worker with 2 workers)."""
    specs = [EpisodeSpec("stop_at_wall", "stop_at_wall", "none", seed=0, duration=0.5),
             EpisodeSpec("stop_at_wall", "stop_at_wall", "cbf", seed=1, duration=0.5, filter_options={"margin": -1.0})]
    with pytest.raises(InvalidConfig, match=r"margin.*-1\.0"):
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
    specs = reproducible_specs(episode_specs(cells, range(2), duration=3.0))     # not the machine's load
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
    assert outcome.world == scenario("stop_at_wall").world(0)   # the world it ran in, for pictures
    assert tuple(outcome.trajectory.pose[0]) == tuple(outcome.world.start)
    assert outcome.collision_point() is None


def _progress_lines(total: int, updates: int) -> list[str]:
    stream = io.StringIO()   # not a terminal
    with Progress(total, "episodes", stream=stream) as progress:
        for _ in range(updates):
            progress.update()
    return stream.getvalue().splitlines()


def test_progress_off_a_terminal_is_a_plain_line_at_every_tenth():
    lines = _progress_lines(40, 40)
    assert [line.split(",")[0] for line in lines] == [f"episodes: {4 * k}/40 ({10 * k} %)" for k in range(1, 11)]
    assert all(re.fullmatch(r"episodes: \d+/40 \(\d+ %\), \d+ s", line) for line in lines)
    assert "\r" not in "".join(lines)
    assert _progress_lines(3, 3) == [line for line in _progress_lines(3, 3) if line.startswith("episodes: ")]
    assert len(_progress_lines(3, 3)) == 3


def test_progress_can_be_silent():
    stream = io.StringIO()
    with Progress(10, "episodes", stream=stream, enabled=False) as progress:
        for _ in range(10):
            progress.update()
    assert stream.getvalue() == "" and progress.done == 10
