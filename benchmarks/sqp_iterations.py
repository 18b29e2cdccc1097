"""The MPC's SQP: how many iterations its NLP solves take, and how many run to the iteration limit.

The direct SQP (:class:`safenav.filters.mpc.sqp.DirectSQP`) takes full steps from its warm start. Where they
shrink slowly, or turn back and forth round a cycle, it jumps to the fixed point the secant through its last two
iterates estimates (``secant``); with the jumps taken out (``full steps``) it takes every step as the QP gives it.
A solve that reaches the limit of iterations (30) returns its last iterate, after 7-15 ms.

Each scene's NLPs are recorded as the filter (no compute budget) solves them, then every recorded NLP is solved
again both ways, alternately, so that both solve the same problems:

* ``cluttered``: ``filter_latency``'s independent calls on random 30-obstacle worlds (``--scenes`` scenes,
  ``--per-scene`` nominal commands each, dt 0.05 s);
* ``wall 0.05`` / ``wall 0.02``: issue 18's closed loop (a wall just out of the path, the nominal turning into it
  at full speed, a base ramping at its limits) at that period;
* ``slack``: the falsifier's fast, slow-braking robot in its recorded episode (``tests/data/falsifier_robots.json``:
  a wall seen too late to brake clear of it, one slack of 0.12 m for every row).

Per scene and way: the NLP solves, SQP iterations (mean and largest), the solves at the limit, and the CPU time of a
solve (median and p99) and their ratio (the time with the jumps over the time without).

Run ``python -m benchmarks.sqp_iterations --help``::

    python -m benchmarks.sqp_iterations --json sqp.json
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

if __package__ in (None, ""):  # run as `python benchmarks/sqp_iterations.py`: import this checkout
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from benchmarks.common import markdown_table, write_json
from benchmarks.falsify import Episode, make_filter, robot_spec, run
from benchmarks.filter_latency import cluttered_cases, wall_episodes
from safenav.filters import MPCSafetyFilter
from safenav.filters.mpc import sqp
from safenav.robot import PRESET_NAMES, preset

#: The recorded episode of the ``slack`` scene.
FOUND = Path(__file__).resolve().parents[1] / "tests" / "data" / "falsifier_robots.json"
def recorded_nlps(drive: Callable[[], Any]) -> list[sqp.PlanNLP]:
    """The NLPs every direct SQP solves while ``drive()`` runs."""
    problems: list[sqp.PlanNLP] = []
    solve = sqp.DirectSQP.solve

    def solve_and_keep(self: sqp.DirectSQP, nlp: sqp.PlanNLP, *args: Any, **kwargs: Any) -> sqp.NLPOutcome:
        problems.append(nlp)
        return solve(self, nlp, *args, **kwargs)

    sqp.DirectSQP.solve = solve_and_keep    # type: ignore[method-assign]
    try:
        drive()
    finally:
        sqp.DirectSQP.solve = solve         # type: ignore[method-assign]
    return problems


def scene_problems(scene: str, robot_name: str, scenes: int, per_scene: int) -> tuple[sqp.DirectSQP, list[sqp.PlanNLP]]:
    """A solver of ``scene`` (as its filter builds it) and the NLPs its filter solves there."""
    if scene == "slack":
        found = json.loads(FOUND.read_text())
        episode = Episode.from_json(next(line for key, line in found.items() if key.startswith("fast_slow_braking")))
        problems = recorded_nlps(lambda: run(episode))
        return make_filter(episode.filter, robot_spec(episode.robot), episode.dt, **episode.settings).backend, problems
    robot = preset(robot_name)
    dt = 0.05 if scene == "cluttered" else float(scene.split()[1])

    def make() -> MPCSafetyFilter:
        return MPCSafetyFilter(robot, dt, budget=math.inf)

    if scene == "cluttered":
        cases = cluttered_cases(robot, scenes, per_scene, 0)

        def drive() -> None:
            safety = make()
            for scan, nominal in cases:
                safety.filter(nominal, scan)
    else:
        def drive() -> None:
            wall_episodes(robot, dt, make, 0, lambda *_: None)

    return make().backend, recorded_nlps(drive)


def solve_both(backend: sqp.DirectSQP, problems: Sequence[sqp.PlanNLP]) -> dict[str, list[tuple[int, str, float]]]:
    """Each problem solved with the jumps and with full steps, alternately: (iterations, status, CPU seconds)."""
    results: dict[str, list[tuple[int, str, float]]] = {"secant": [], "full steps": []}
    try:
        for nlp in problems:
            for way in results:
                backend.secant = way == "secant"
                started = time.process_time()
                outcome = backend.solve(nlp)
                results[way].append((outcome.iterations, outcome.status, time.process_time() - started))
    finally:
        backend.secant = True
    return results


def sqp_rows(robots: Sequence[str], scenes: Sequence[str], n_scenes: int, per_scene: int) -> list[dict[str, Any]]:
    rows = []
    for scene in scenes:
        for robot_name in (["fast_slow_braking"] if scene == "slack" else robots):
            backend, problems = scene_problems(scene, robot_name, n_scenes, per_scene)
            row: dict[str, Any] = {"robot": robot_name, "scene": scene, "solves": len(problems),
                                   "limit": backend.max_iter}
            for way, results in solve_both(backend, problems).items():
                iterations = np.array([r[0] for r in results])
                seconds = np.array([r[2] for r in results])
                row[way] = {"iterations_mean": float(iterations.mean()) if iterations.size else math.nan,
                            "iterations_max": int(iterations.max()) if iterations.size else 0,
                            "at_limit": sum(r[1] == "max_iter" for r in results),
                            "total_iterations": int(iterations.sum()),
                            "median_us": float(np.median(seconds) * 1e6) if seconds.size else math.nan,
                            "p99_us": float(np.percentile(seconds, 99) * 1e6) if seconds.size else math.nan,
                            "total_s": float(seconds.sum())}
            print(f"  {robot_name} {scene}: {len(problems)} NLP solves", flush=True)
            rows.append(row)
    return rows


def main(argv: Sequence[str] | None = None, prog: str = "sqp_iterations") -> int:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", nargs="+", default=list(PRESET_NAMES), choices=PRESET_NAMES)
    parser.add_argument("--scenes", nargs="+", default=["cluttered", "wall 0.05", "wall 0.02", "slack"],
                        choices=["cluttered", "wall 0.05", "wall 0.02", "wall 0.1", "slack"])
    parser.add_argument("--n-scenes", type=int, default=250, help="cluttered worlds (default: 250)")
    parser.add_argument("--per-scene", type=int, default=8, help="nominal commands per world (default: 8)")
    parser.add_argument("--json", metavar="PATH", help="write the results as JSON")
    args = parser.parse_args(argv)
    rows = sqp_rows(args.robots, args.scenes, args.n_scenes, args.per_scene)
    ways = ("full steps", "secant")
    print("\nSQP iterations per NLP solve (the same NLPs both ways), solves at the limit, CPU time of a solve [us]:")
    print(markdown_table(
        ["robot", "scene", "NLP solves", *(f"{way}: {what}" for way in ways for what in
                                           ("iterations mean", "max", "at limit", "median", "p99")),
         "time secant / full steps"],
        [[r["robot"], r["scene"], r["solves"],
          *(value for way in ways for value in (f"{r[way]['iterations_mean']:.2f}", r[way]["iterations_max"],
                                                r[way]["at_limit"], r[way]["median_us"], r[way]["p99_us"])),
          f"{r['secant']['total_s'] / max(r['full steps']['total_s'], 1e-12):.2f}"] for r in rows]))
    write_json(args.json, {"rows": rows, "config": vars(args)})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
