"""Ray's overhead: the same sweep on the local process pool and on a local Ray, with 1 and 2 workers.

The sweep is a reduced collision matrix (by default the random walk through clutter on every
preset and the go-to-goal through clutter, the CBF, 2 seeds: 8 episodes of 30-40 s simulated,
realistic lengths, not short test episodes). Every configuration (backend x workers) runs it
``--repeats`` times, interleaved (repeat 1 of every configuration, then repeat 2, ...) so that a
change in the machine's load falls on all of them alike. Measured per run:

* start-up: ``ray.init`` (Ray only), then a warm-up of one 0.5 s episode per worker (Ray's
  workers are new processes importing safenav, PyBullet and casadi; the pool's are forked from a
  process that has them) [s];
* ``wall``: the sweep's wall-clock time on the warm workers, first job submitted to last result [s];
* ``episodes``: the sum of the episodes' own times, measured inside the workers [s];
* overhead per episode: ``(workers x wall - episodes) / n`` [s], and as a share of the mean
  episode time: everything that is not an episode (scheduling, shipping specs and results, the
  tail where a worker waits for the last episode); also with the start-up added to ``wall``,
  which is what a sweep this short costs (a long sweep spreads it over more episodes); the
  issue's goal is <= 5 % at 2 workers;
* Ray vs the pool: ``wall_ray / wall_pool - 1`` at the same number of workers;
* scaling efficiency: ``wall(1 worker) / (2 x wall(2 workers))`` per backend.

Medians over the repeats. The tables also give the load average at the start of each
configuration (the machine may be shared: say so next to the numbers). Every configuration
must give the same collision table: the benchmark checks it and fails otherwise.

Run ``python -m benchmarks.ray_overhead --help`` (or ``safenav bench ray_overhead``); on a shared
machine run it under ``nice``.
"""

from __future__ import annotations

import sys
from pathlib import Path

if __package__ in (None, ""):   # python benchmarks/NAME.py: import from this checkout
    sys.path[0] = str(Path(__file__).resolve().parents[1])

import argparse
import os
import statistics
import time
from collections.abc import Sequence
from typing import Any

from benchmarks.common import markdown_table, names, numbers, run_cli, write_json
from safenav._checks import argument_type, choice, integer, positive, writable_file
from safenav._optional import require
from safenav.experiments import EpisodeSpec, cell_records, episode_specs, matrix, outcome_table, run_spec
from safenav.experiments.runner import BACKENDS, JobRunner, spec_cost

DEFAULT_CELLS = ("clutter_rosbot", "clutter_puzzlebot", "clutter_m2wr", "goal_rosbot")
"""The reduced matrix's scenarios (random walk through clutter on every preset, go-to-goal through clutter)."""

DEFAULT_POLICIES = ("random_walk", "go_to_goal")


def build_parser(prog: str = "ray_overhead") -> argparse.ArgumentParser:
    """The benchmark's options."""
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenarios", type=names, default=list(DEFAULT_CELLS), metavar="A,B",
                        help=f"comma-separated scenarios (default: {','.join(DEFAULT_CELLS)})")
    parser.add_argument("--policies", type=names, default=list(DEFAULT_POLICIES), metavar="A,B",
                        help=f"comma-separated policies (default: {','.join(DEFAULT_POLICIES)})")
    parser.add_argument("--filters", type=names, default=["cbf"], metavar="A,B",
                        help="comma-separated filters (default: cbf)")
    parser.add_argument("--seeds", type=argument_type(integer, low=1), default=2,
                        help="seeds per cell (default: 2)")
    parser.add_argument("--duration", type=argument_type(positive), default=None,
                        help="episode length [s] (default: each scenario's own, 30-40 s)")
    parser.add_argument("--workers", type=numbers(integer, low=1), default=[1, 2], metavar="A,B",
                        help="comma-separated worker counts (default: 1,2)")
    parser.add_argument("--backends", type=names, default=list(BACKENDS), metavar="A,B",
                        help=f"comma-separated backends (default: {','.join(BACKENDS)})")
    parser.add_argument("--repeats", type=argument_type(integer, low=1), default=3,
                        help="runs of every configuration; medians are reported (default: 3)")
    parser.add_argument("--json", metavar="PATH", help="write every run and the medians as JSON")
    return parser


def main(argv: Sequence[str] | None = None, prog: str = "ray_overhead") -> int:
    """Run every configuration; print the tables; write the JSON asked for: exit code 0, or 2 on bad usage."""
    return run_cli(build_parser(prog), argv, _run)


def run_once(specs: Sequence[EpisodeSpec], backend: str, workers: int) -> dict[str, Any]:
    """One run of the sweep: its times, and its outcomes' collision table (to check it is the same everywhere).

    The pool or Ray is started, then warmed with one short episode per worker (Ray's workers are
    new processes that import safenav, PyBullet and casadi on their first task; the pool's are
    forked from this process, which has imported them), then the sweep runs on the same workers.
    """
    load = os.getloadavg()[0]
    ray_start = 0.0
    ray = None
    warm_up = [EpisodeSpec(specs[0].scenario, specs[0].policy, specs[0].filter, seed=1000 + index, duration=0.5)
               for index in range(workers)]
    started = time.perf_counter()
    if backend == "ray":
        ray = require("ray", extra="distributed", purpose="the Ray backend")
        ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False, configure_logging=False)
        ray_start = time.perf_counter() - started
    try:
        with JobRunner(workers, backend=backend, progress=False) as runner:
            warm = time.perf_counter()
            runner.map(run_spec, warm_up)
            sweep = time.perf_counter()
            outcomes = runner.map(run_spec, specs, cost=spec_cost)
            ended = time.perf_counter()
    finally:
        if ray is not None:
            ray.shutdown()
    episode_time = sum(outcome.wall_time for outcome in outcomes)
    wall, start_up = ended - sweep, sweep - warm

    def share(seconds: float) -> float:
        """Time not spent in episodes, per episode, as a share of the mean episode time."""
        return (workers * seconds - episode_time) / episode_time

    return {"backend": backend, "workers": workers, "load": load, "ray_start": ray_start, "start_up": start_up,
            "wall": wall, "episode_time": episode_time,
            "overhead_per_episode": (workers * wall - episode_time) / len(specs),
            "overhead_share": share(wall), "overhead_share_with_start": share(wall + start_up + ray_start),
            "table": outcome_table(cell_records(outcomes))}


def summarise(runs: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Medians per (backend, workers), with Ray's cost against the pool and each backend's scaling efficiency."""
    keys = list(dict.fromkeys((run["backend"], run["workers"]) for run in runs))
    rows = []
    for backend, workers in keys:
        mine = [run for run in runs if (run["backend"], run["workers"]) == (backend, workers)]
        row: dict[str, Any] = {"backend": backend, "workers": workers, "runs": len(mine)}
        for field in ("load", "ray_start", "start_up", "wall", "episode_time", "overhead_per_episode",
                      "overhead_share", "overhead_share_with_start"):
            row[field] = statistics.median(run[field] for run in mine)
        row["wall_min"], row["wall_max"] = min(run["wall"] for run in mine), max(run["wall"] for run in mine)
        rows.append(row)
    by_key = {(row["backend"], row["workers"]): row for row in rows}
    for row in rows:
        pool = by_key.get(("process", row["workers"]))
        row["vs_pool"] = row["wall"] / pool["wall"] - 1.0 if pool is not None else float("nan")
        single, double = by_key.get((row["backend"], 1)), by_key.get((row["backend"], 2))
        row["scaling_efficiency"] = (single["wall"] / (2.0 * double["wall"])
                                     if single is not None and double is not None else float("nan"))
    return rows


def table(rows: Sequence[dict[str, Any]]) -> str:
    """The markdown table of the medians."""
    return markdown_table(
        ["backend", "workers", "runs", "load at start", "ray.init [s]", "warm-up [s]", "sweep wall [s] (min-max)",
         "episode time [s]", "overhead / episode [s]", "overhead share", "with start-up", "vs pool",
         "scaling efficiency 1->2"],
        [[r["backend"], r["workers"], r["runs"], f"{r['load']:.1f}",
          f"{r['ray_start']:.1f}" if r["backend"] == "ray" else "-", f"{r['start_up']:.1f}",
          f"{r['wall']:.1f} ({r['wall_min']:.1f}-{r['wall_max']:.1f})", f"{r['episode_time']:.1f}",
          f"{r['overhead_per_episode']:.2f}", f"{100 * r['overhead_share']:.1f} %",
          f"{100 * r['overhead_share_with_start']:.1f} %",
          f"{100 * r['vs_pool']:+.1f} %" if r["vs_pool"] == r["vs_pool"] else "-",
          f"{100 * r['scaling_efficiency']:.0f} %" if r["scaling_efficiency"] == r["scaling_efficiency"] else "-"]
         for r in rows])


def _run(args: argparse.Namespace) -> int:
    if args.json is not None:
        writable_file("--json", args.json)
    backends = [choice("backend", name, BACKENDS) for name in args.backends]
    specs = episode_specs(matrix(args.scenarios, args.policies, args.filters), range(args.seeds), args.duration)
    configurations = [(backend, int(workers)) for backend in backends for workers in args.workers]
    print(f"{len(specs)} episodes x {len(configurations)} configurations x {args.repeats} repeats; "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs", flush=True)
    runs = []
    for repeat in range(args.repeats):
        for backend, workers in configurations:
            run = run_once(specs, backend, workers)
            runs.append({**run, "repeat": repeat})
            print(f"repeat {repeat + 1}: {backend} x {workers}: {run['wall']:.1f} s wall after "
                  f"{run['ray_start'] + run['start_up']:.1f} s of start-up, {run['episode_time']:.1f} s of episodes, "
                  f"overhead {100 * run['overhead_share']:.1f} % ({100 * run['overhead_share_with_start']:.1f} % with "
                  f"start-up), load {run['load']:.1f}", flush=True)
    tables = {run["table"] for run in runs}
    if len(tables) != 1:
        print(f"ray_overhead: error: the configurations gave {len(tables)} different collision tables", file=sys.stderr)
        return 1
    rows = summarise(runs)
    print()
    print(f"medians over {args.repeats} repeats; the sweep (its collision table is the same in every run):")
    print(runs[0]["table"])
    print()
    print(table(rows))
    write_json(args.json, {"rows": rows, "runs": [{k: v for k, v in run.items() if k != "table"} for run in runs],
                           "table": runs[0]["table"], "specs": len(specs), "config": vars(args)})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
