"""Soak: one long episode of a random walk through a safety filter in clutter.

Checks what a long deployment needs: no collision, no solver failure (calls that ran out of
their compute budget, which a loaded machine causes, are counted apart), memory that does
not grow (resident set size, and optionally Python allocations with tracemalloc), and
per-step time that does not creep up (the median of the first and of the last thousand
steps, after a warm-up). Run ``python -m benchmarks.soak --help``.
"""

from __future__ import annotations

import sys
from pathlib import Path

if __package__ in (None, ""):   # python benchmarks/NAME.py: import from this checkout
    sys.path[0] = str(Path(__file__).resolve().parents[1])

import argparse
import gc
import math
import os
import time
import tracemalloc
from collections.abc import Sequence
from typing import Any

import numpy as np

from benchmarks.common import markdown_table, run_cli, write_json
from safenav._checks import argument_type, choice, integer
from safenav.episode import EpisodeConfig, run_episode
from safenav.errors import InvalidConfig
from safenav.filters import FILTER_NAMES, make_filter
from safenav.reference import RandomWalk
from safenav.robot import PRESET_NAMES, preset
from safenav.sim_bullet import SimConfig
from safenav.worlds import random_world

WINDOW = 1000
"""Steps in each of the windows whose step times are compared (by default)."""


def resident_bytes() -> int:
    """Current resident set size of this process [bytes] (Linux ``/proc``; 0 elsewhere)."""
    try:
        with open("/proc/self/statm") as statm:
            return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


def soak(steps: int = 20_000, *, robot_name: str = "rosbot", filter_name: str = "cbf", seed: int = 0,
         warmup: int = 500, window: int = WINDOW, trace_python: bool = False) -> dict[str, Any]:
    """Run the soak and return its measurements.

    Args:
        steps: control periods in the episode.
        robot_name: robot preset.
        filter_name: filter name (see :func:`safenav.filters.make_filter`).
        seed: seed of the world, the random walk and the simulator.
        warmup: steps after which the memory baseline is taken.
        window: steps in each window whose step times are compared.
        trace_python: also track Python allocations with tracemalloc (slower).

    Raises:
        InvalidConfig: fewer steps than the warm-up and two windows.
    """
    if steps < warmup + 2 * window:
        raise InvalidConfig(f"soak: steps={steps} must be at least warmup + 2 x window = {warmup + 2 * window}")
    robot = preset(robot_name)
    world = random_world(seed, robot, n_obstacles=30)
    config = EpisodeConfig(duration=steps * 0.05, sim=SimConfig(control_dt=0.05))
    safety_filter = make_filter(filter_name, robot, config.sim.control_dt)
    step_times = np.zeros(steps)
    memory: dict[str, float] = {}
    clock = [time.perf_counter()]
    deadline = [0]      # calls that gave up at their compute budget

    def observe(index: int, state: Any, result: Any) -> None:
        now = time.perf_counter()
        step_times[index] = now - clock[0]
        clock[0] = now
        deadline[0] += result.timed_out
        if index == warmup:
            gc.collect()
            memory["rss_start"] = resident_bytes()
            if trace_python:
                memory["python_start"] = tracemalloc.get_traced_memory()[0]

    if trace_python:
        tracemalloc.start()
    start = time.perf_counter()
    metrics = run_episode(world, robot, RandomWalk(robot, hold_steps=20), safety_filter, config=config,
                          seed=seed, callback=observe).metrics
    wall = time.perf_counter() - start
    gc.collect()
    memory["rss_end"] = resident_bytes()
    if trace_python:
        memory["python_end"] = tracemalloc.get_traced_memory()[0]
        tracemalloc.stop()
    done = metrics.steps
    first = step_times[warmup:warmup + window]
    last = step_times[done - window:done]
    # Median of every window after the warm-up, and the least-squares trend through them.
    windows = [float(np.median(step_times[start:start + window]) * 1e6)
               for start in range(warmup, done - window + 1, window)]
    trend = float(np.polyfit(np.arange(len(windows)), windows, 1)[0]) if len(windows) > 1 else 0.0
    return {
        "robot": robot_name, "filter": filter_name, "seed": seed, "steps": done, "wall_s": wall,
        "collided": metrics.collided, "collision_time": metrics.collision_time,
        "min_clearance": metrics.min_clearance, "margin": getattr(safety_filter, "margin", math.nan),
        "fallbacks": metrics.fallbacks - deadline[0], "deadline_fallbacks": deadline[0],
        "statuses": metrics.statuses, "distance": metrics.distance,
        "first_window_median_us": float(np.median(first) * 1e6), "last_window_median_us": float(np.median(last) * 1e6),
        "first_window_p99_us": float(np.percentile(first, 99) * 1e6),
        "last_window_p99_us": float(np.percentile(last, 99) * 1e6),
        "window_medians_us": [round(value, 1) for value in windows],
        "trend_us_per_window": trend,
        "filter_p50_us": metrics.filter_p50_us, "filter_p99_us": metrics.filter_p99_us,
        "rss_start_mb": memory["rss_start"] / 2**20, "rss_end_mb": memory["rss_end"] / 2**20,
        **({"python_start_mb": memory["python_start"] / 2**20, "python_end_mb": memory["python_end"] / 2**20}
           if trace_python else {}),
    }


def main(argv: Sequence[str] | None = None, prog: str = "soak") -> int:
    """Run the soak and print its measurements.

    Returns:
        The exit code: 0 when the episode stayed clean, 1 after a collision or a solver's fallback (not one at the
        compute budget), 2 on bad usage.
    """
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=argument_type(integer, low=1), default=20_000,
                        help="control periods (default: 20000)")
    parser.add_argument("--robot", type=argument_type(choice, name="robot", text=True, known=PRESET_NAMES),
                        default="rosbot", help="robot preset (default: rosbot)")
    parser.add_argument("--filter", type=argument_type(choice, name="filter", text=True, known=FILTER_NAMES),
                        default="cbf", help="filter (default: cbf)")
    parser.add_argument("--seed", type=argument_type(integer, low=0), default=0)
    parser.add_argument("--warmup", type=argument_type(integer, low=0), default=500,
                        help="steps before the memory baseline (default: 500)")
    parser.add_argument("--window", type=argument_type(integer, low=1), default=WINDOW,
                        help=f"steps per compared window (default: {WINDOW})")
    parser.add_argument("--tracemalloc", action="store_true", help="also track Python allocations (slower)")
    parser.add_argument("--json", metavar="PATH", help="write the results as JSON")
    return run_cli(parser, argv, _report)


def _report(args: argparse.Namespace) -> int:
    result = soak(args.steps, robot_name=args.robot, filter_name=args.filter, seed=args.seed,
                  warmup=args.warmup, window=args.window, trace_python=args.tracemalloc)
    rows = [[key, value if not isinstance(value, float) else round(value, 4)] for key, value in result.items()]
    print(markdown_table(["measure", "value"], rows))
    write_json(args.json, {"soak": result, "config": vars(args)})
    return 0 if not result["collided"] and result["fallbacks"] == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
