"""The Ray backend: the same specs give the same outcomes as the process pool; errors name what is wrong."""

import math
import os
from pathlib import Path

import pytest

from safenav import InvalidConfig, UnknownName
from safenav.experiments import cell_records, episode_specs, matrix, run_specs
from safenav.experiments.runner import reproducible_settings, run_jobs

TIMING = {"filter_p50_us", "filter_p99_us", "episode_wall_s"}


def _without_timing(records):
    return [{key: value for key, value in record.items() if key not in TIMING} for record in records]


@pytest.mark.sim
def test_ray_gives_the_process_pools_outcomes():
    ray = pytest.importorskip("ray", reason="Ray is not installed: pip install 'safenav[distributed]'")
    cells = matrix(scenarios=["stop_at_wall", "clutter_puzzlebot"], policies=["stop_at_wall_buggy", "random_walk"],
                   filters=["none", "cbf"])
    specs = episode_specs(cells, range(2), duration=2.0)
    pool = run_specs(specs, workers=2, progress=False)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        on_ray = run_specs(specs, workers=2, progress=False, backend="ray")
        # any callable, a built-in included, in the order of the items
        assert run_jobs(abs, [3, -1, -2], progress=False, backend="ray") == [3, 1, 2]
    finally:
        ray.shutdown()
    assert [outcome.spec for outcome in on_ray] == list(specs)
    assert _without_timing(cell_records(on_ray)) == _without_timing(cell_records(pool))
    for mine, theirs in zip(on_ray, pool, strict=True):
        assert mine.metrics.min_clearance == theirs.metrics.min_clearance
        assert mine.metrics.distance == theirs.metrics.distance


@pytest.mark.parametrize(("options", "error", "message"), [
    ({"backend": "dask"}, UnknownName, "dask"),
    ({"address": "auto"}, InvalidConfig, "address='auto' is for the Ray backend"),
    ({"workers": 0, "backend": "ray"}, InvalidConfig, "workers"),
])
def test_bad_backend_settings_are_clear_errors(options, error, message):
    with pytest.raises(error, match=message):
        run_jobs(abs, [1, -2], progress=False, **options)


def test_run_jobs_keeps_the_order_of_the_items_on_every_backend():
    assert run_jobs(abs, [3, -1, -2], workers=1, progress=False) == [3, 1, 2]
    assert run_jobs(abs, [3, -1, -2], workers=2, progress=False, cost=abs) == [3, 1, 2]



def test_joining_a_cluster_when_none_runs_is_a_clear_error():
    ray = pytest.importorskip("ray", reason="Ray is not installed: pip install 'safenav[distributed]'")
    if ray.is_initialized() or os.environ.get("RAY_ADDRESS") or Path("/tmp/ray/ray_current_cluster").exists():
        pytest.skip("a Ray cluster may be running on this machine: 'auto' would join it")
    with pytest.raises(InvalidConfig, match="no Ray cluster answers at address='auto'"):
        run_jobs(abs, [1], progress=False, backend="ray", address="auto")


def test_reproducible_settings_take_the_mpcs_compute_budget_away_only():
    assert reproducible_settings("mpc") == {"budget": math.inf}
    assert reproducible_settings("mpc+escape") == {"budget": math.inf}
    assert reproducible_settings("cbf") == {} and reproducible_settings("none") == {}
