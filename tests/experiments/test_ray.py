"""The Ray backend: the same specs give the same outcomes as the process pool; errors name what is wrong.

Every sweep with ``--backend ray`` (collisions, robustness, stop, moving, falsify) runs its jobs
through :class:`~safenav.experiments.runner.JobRunner`; the tests here run a handful of episodes of
each kind on one local Ray (``ray.init(num_cpus=2)``) and compare them with the process pool.
"""

import dataclasses
import json
import math
import os
from pathlib import Path

import pytest

from safenav import InvalidConfig, UnknownName
from safenav.experiments import EpisodeSpec, cell_records, episode_specs, matrix, run_specs
from safenav.experiments.runner import JobRunner, reproducible_settings, reproducible_specs, run_jobs

# One worker runs every test here, in this order (pytest-xdist's loadgroup): the first asserts that no cluster
# answers, and the module's local Ray of another worker would.
pytestmark = pytest.mark.xdist_group("ray")

TIMING = {"filter_p50_us", "filter_p99_us", "episode_wall_s"}
NO_RAY = "Ray is not installed: pip install 'safenav[distributed]'"


def _without_timing(records):
    return [{key: value for key, value in record.items() if key not in TIMING} for record in records]


# First: the module's local Ray below would answer 'auto'.
def test_joining_a_cluster_when_none_runs_is_a_clear_error():
    ray = pytest.importorskip("ray", reason=NO_RAY)
    if ray.is_initialized() or os.environ.get("RAY_ADDRESS") or Path("/tmp/ray/ray_current_cluster").exists():
        pytest.skip("a Ray cluster may be running on this machine: 'auto' would join it")
    with pytest.raises(InvalidConfig, match="no Ray cluster answers at address='auto'"):
        run_jobs(abs, [1], progress=False, backend="ray", address="auto")


@pytest.fixture(scope="module")
def local_ray():
    """One local Ray with 2 CPUs for every test of this module (starting Ray takes seconds)."""
    ray = pytest.importorskip("ray", reason=NO_RAY)
    if ray.is_initialized():
        pytest.skip("a Ray is already initialised in this process")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()


@pytest.mark.sim
def test_ray_gives_the_process_pools_outcomes(local_ray):
    cells = matrix(scenarios=["stop_at_wall", "clutter_puzzlebot"], policies=["stop_at_wall_buggy", "random_walk"],
                   filters=["none", "cbf"])
    specs = reproducible_specs(episode_specs(cells, range(2), duration=2.0))     # not the machine's load
    pool = run_specs(specs, workers=2, progress=False)
    on_ray = run_specs(specs, workers=2, progress=False, backend="ray")
    # any callable, a built-in included, in the order of the items
    assert run_jobs(abs, [3, -1, -2], progress=False, backend="ray") == [3, 1, 2]
    assert local_ray.is_initialized(), "a Ray the caller started is left running"
    assert [outcome.spec for outcome in on_ray] == list(specs)
    assert _without_timing(cell_records(on_ray)) == _without_timing(cell_records(pool))
    for mine, theirs in zip(on_ray, pool, strict=True):
        assert mine.metrics.min_clearance == theirs.metrics.min_clearance
        assert mine.metrics.distance == theirs.metrics.distance


@pytest.mark.sim
def test_the_collision_benchmark_on_ray_prints_the_process_pools_tables(local_ray, tmp_path, capsys):
    from benchmarks import collision_rates

    # Not the MPC: the collision matrix runs it with its compute budget, so on a loaded machine a late call
    # changes its episode on any backend (run twice on the pool, it can differ too).
    argv = ["--scenarios", "stop_at_wall,clutter_rosbot", "--filters", "none,zones,cbf,cbf+escape", "--seeds", "2",
            "--duration", "1.5", "--workers", "2", "--no-progress"]
    tables = {}
    for backend in ("process", "ray"):
        path = tmp_path / f"{backend}.json"
        assert collision_rates.main([*argv, "--backend", backend, "--json", str(path)]) == 0
        printed = capsys.readouterr().out
        tables[backend] = (printed.split("\n", 1)[1].split("wall-clock")[0],   # every table but the timings
                           _without_timing(json.loads(path.read_text())["cells"]))
    assert "| stop_at_wall | rosbot | stop_at_wall_buggy | none |" in tables["ray"][0]
    assert tables["ray"] == tables["process"]


UNLIMITED = reproducible_settings("cbf")


def test_falsifier_generations_on_ray_search_what_the_serial_search_finds(local_ray):
    from benchmarks.falsify import GEOMETRIES, SEARCHED_NOMINALS, CellSearch, search_cells

    # The CBF without its compute budget: then an episode depends on its seed only, not on the machine's load.
    cells = [dict(robot="rosbot", filter_name="cbf", base="ramp", dt=0.05, give_velocity=True, settings=UNLIMITED),
             dict(robot="m2wr", filter_name="cbf", base="lag", dt=0.1, give_velocity=True, settings=UNLIMITED)]

    def searches():
        return [CellSearch(dict(cell, geometry=GEOMETRIES, nominal=SEARCHED_NOMINALS), episodes=10, seed=index,
                           margin=0.05) for index, cell in enumerate(cells)]

    serial = search_cells(searches())
    with JobRunner(2, backend="ray", progress=False) as runner:
        on_ray = search_cells(searches(), runner)
    assert [len(found) for found in on_ray] == [10, 10]
    assert [[(f.episode, f.outcome) for f in found] for found in on_ray] == \
           [[(f.episode, f.outcome) for f in found] for found in serial]


@pytest.mark.parametrize(("options", "error", "message"), [
    ({"backend": "dask"}, UnknownName, "dask"),
    ({"address": "auto"}, InvalidConfig, "address='auto' is for the Ray backend"),
    ({"workers": 0, "backend": "ray"}, InvalidConfig, "workers"),
    ({"resume": True}, InvalidConfig, "resume=True needs the results file"),
])
def test_bad_backend_settings_are_clear_errors(options, error, message):
    with pytest.raises(error, match=message):
        run_jobs(abs, [1, -2], progress=False, **options)


def test_run_jobs_keeps_the_order_of_the_items_on_every_backend():
    assert run_jobs(abs, [3, -1, -2], workers=1, progress=False) == [3, 1, 2]
    assert run_jobs(abs, [3, -1, -2], workers=2, progress=False, cost=abs) == [3, 1, 2]


def test_reproducible_settings_take_the_compute_budgets_away_only():
    for name in ("mpc", "mpc+escape", "cbf", "cbf+escape"):
        assert reproducible_settings(name) == {"budget": math.inf}
    assert reproducible_settings("zones") == {} and reproducible_settings("none") == {}
    own = EpisodeSpec("goal_rosbot", "go_to_goal", "cbf", seed=3, filter_options={"margin": 0.05, "budget": 0.01})
    zones = EpisodeSpec("stop_at_wall", "stop_at_wall", "zones", seed=0, filter_options={"stop_distance": 0.3})
    assert reproducible_specs([own, zones]) == [
        dataclasses.replace(own, filter_options={"margin": 0.05, "budget": math.inf}), zones]   # the rest kept
