"""Moving obstacles: how fast the collision rate grows with the walkers' speed and number.

OUTSIDE THE GUARANTEE. Every filter's guarantee assumes a static world (``docs/safety.md``): a
barrier or a plan built from one scan says nothing about where a walker will be one period
later, and a walker can run into a robot that has stopped. This benchmark measures the
degradation, it does not test a promise.

Each episode is a preset's clutter arena (``clutter_<robot>``, the random-walk nominal, the world
drawn from the seed) with ``count`` walkers (0.2 m disks) pacing back and forth at ``speed``
between random points of the 5 m x 5 m square around the robot's start, where the random walk
stays (:func:`safenav.worlds.dynamic.patrols`; none within 1 m of the robot at the start).
Walkers pass through the static obstacles, not through the robot. A collision is any overlap of
the body with anything, static or moving. The table gives, per (robot, filter, speed, count),
the collision rate with its 95 % Wilson interval, how many collisions were with a walker, how
many of those found the robot standing (``|v| < 0.02`` m/s: the walker ran into it, which no
filter that only brakes or steers in a static-world model can prevent), and, with
``--margins``, whether a larger margin restores zero collisions.

Run ``python -m benchmarks.moving_obstacles --help`` (or ``safenav bench moving``).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

if __package__ in (None, ""):   # python benchmarks/moving_obstacles.py: import from this checkout
    sys.path[0] = str(Path(__file__).resolve().parents[1])

from benchmarks.common import markdown_table, names, numbers, run_cli, run_sweep, sweep_parser, where, write_json
from safenav._checks import argument_type, choice, integer, number, positive
from safenav.episode import EpisodeConfig, run_episode
from safenav.experiments import wilson_interval
from safenav.experiments.runner import reproducible_settings
from safenav.filters import FILTER_NAMES, default_margin, make_filter
from safenav.robot import PRESET_NAMES
from safenav.scenarios import scenario
from safenav.worlds.dynamic import DynamicWorld, patrols

WALKER_RADIUS = 0.2
"""Radius of a walker [m]."""

START_CLEAR = 1.0
"""No walker is closer than this to the robot's start at time 0 [m]."""

STANDING_SPEED = 0.02
"""A robot slower than this [m/s] when a walker touches it was standing: the walker ran into it."""

BEAT_HALF_WIDTH = 2.5
"""Walkers pace inside the square of this half-width around the robot's start [m] (a random walk stays near it)."""


@dataclass(frozen=True)
class MovingJob:
    """One episode: picklable, for the process pool and Ray."""

    robot: str
    filter: str
    speed: float
    count: int
    seed: int
    duration: float
    extra_margin: float = 0.0
    real_time: bool = False


def world_for(job: MovingJob) -> DynamicWorld:
    """The clutter arena of ``job.seed`` with its walkers."""
    task = scenario(f"clutter_{job.robot}")
    static = task.world(job.seed)
    x, y = static.start.x, static.start.y
    xmin, ymin, xmax, ymax = static.bounds
    area = (max(xmin, x - BEAT_HALF_WIDTH), max(ymin, y - BEAT_HALF_WIDTH), min(xmax, x + BEAT_HALF_WIDTH),
            min(ymax, y + BEAT_HALF_WIDTH))
    walkers = patrols(job.seed, job.count, bounds=area, speed=job.speed, duration=job.duration,
                      radius=WALKER_RADIUS, keep_clear=(static.start.x, static.start.y, START_CLEAR))
    return DynamicWorld(f"{static.name}+{job.count}x{job.speed:g}", static.obstacles, static.start, static.goal,
                        static.bounds, static.obstacle_height, walkers)


def run_job(job: MovingJob) -> dict[str, Any]:
    """Run one episode; whether it collided, with what, and its smallest clearance."""
    task = scenario(f"clutter_{job.robot}")
    robot = task.robot
    world = world_for(job)
    config = EpisodeConfig(duration=job.duration)
    options = {} if job.real_time else reproducible_settings(job.filter)
    if job.extra_margin:
        options["margin"] = default_margin(robot) + job.extra_margin
    safety_filter = make_filter(job.filter, robot, config.sim.control_dt, **options)
    policy = task.policy("random_walk", world, job.seed)
    started = time.perf_counter()
    result = run_episode(world, robot, policy, safety_filter, config=config, seed=job.seed, record=True)
    metrics = result.metrics
    with_walker = standing = False
    if metrics.collided:
        trajectory = result.trajectory
        pose = trajectory.pose[-1]
        static_clearance = world.clearance(pose, robot.radius)
        with_walker = static_clearance > world.clearance_at(pose, robot.radius, trajectory.time[-1])
        standing = with_walker and abs(trajectory.velocity[-1][0]) < STANDING_SPEED
    return {**asdict(job), "collided": metrics.collided, "with_walker": bool(with_walker),
            "robot_standing": bool(standing),
            "collision_time": metrics.collision_time, "min_clearance": metrics.min_clearance,
            "distance": metrics.distance, "wall_time": time.perf_counter() - started}


def summarise(records: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per (robot, filter, extra margin, speed, count): collisions, rate, Wilson interval."""
    groups: dict[tuple[Any, ...], list[dict[str, Any]]] = {}
    for record in records:
        key = (record["robot"], record["filter"], record["extra_margin"], record["speed"], record["count"])
        groups.setdefault(key, []).append(record)
    rows = []
    for (robot, name, extra, speed, count), group in sorted(
            groups.items(), key=lambda item: (PRESET_NAMES.index(item[0][0]), FILTER_NAMES.index(item[0][1]),
                                              *item[0][2:])):
        collisions = sum(r["collided"] for r in group)
        low, high = wilson_interval(collisions, len(group))
        rows.append({"robot": robot, "filter": name, "extra_margin": extra, "speed": speed, "count": count,
                     "episodes": len(group), "collisions": collisions,
                     "with_walker": sum(r["with_walker"] for r in group),
                     "robot_standing": sum(r["robot_standing"] for r in group), "rate": collisions / len(group),
                     "ci_low": low, "ci_high": high, "min_clearance": min(r["min_clearance"] for r in group)})
    return rows


def table(rows: Sequence[dict[str, Any]]) -> str:
    """The markdown table."""
    return markdown_table(
        ["robot", "filter", "extra margin [m]", "walkers", "speed [m/s]", "collisions", "with a walker",
         "of which standing", "rate",
         "95 % CI", "min clearance [m]"],
        [[r["robot"], r["filter"], f"{r['extra_margin']:.2f}", r["count"], f"{r['speed']:.1f}",
          f"{r['collisions']}/{r['episodes']}", r["with_walker"], r["robot_standing"], f"{100 * r['rate']:.0f} %",
          f"[{100 * r['ci_low']:.0f}, {100 * r['ci_high']:.0f}] %", f"{r['min_clearance']:.3f}"] for r in rows])


def build_parser(prog: str = "moving_obstacles") -> argparse.ArgumentParser:
    """The benchmark's options."""
    return sweep_parser(prog, __doc__, _add_options, real_time=True)


def _add_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--robots", type=names, default=list(PRESET_NAMES), metavar="A,B",
                        help=f"comma-separated presets (default: {','.join(PRESET_NAMES)})")
    parser.add_argument("--filters", type=names, default=["zones", "cbf", "mpc"], metavar="A,B",
                        help="comma-separated filters (default: zones,cbf,mpc)")
    parser.add_argument("--speeds", type=numbers(positive), default=[0.3, 0.6, 1.0, 1.5], metavar="A,B",
                        help="comma-separated walker speeds [m/s] (default: 0.3,0.6,1.0,1.5)")
    parser.add_argument("--counts", type=numbers(integer, low=0), default=[1, 4], metavar="A,B",
                        help="comma-separated walker counts (default: 1,4)")
    parser.add_argument("--margins", type=numbers(number, low=0.0), default=[0.0], metavar="A,B",
                        help="comma-separated extra margins [m] on each filter's default (default: 0)")
    parser.add_argument("--seeds", type=argument_type(integer, low=1), default=5,
                        help="seeds per cell (default: 5)")
    parser.add_argument("--duration", type=argument_type(positive), default=20.0,
                        help="episode length [s] (default: 20)")
    parser.add_argument("--quick", action="store_true", help="rosbot, cbf, speeds 0.5 and 1.5, 4 walkers, 2 seeds")


def main(argv: Sequence[str] | None = None, prog: str = "moving_obstacles") -> int:
    """Run the sweep; print the table; write the JSON asked for: exit code 0, or 2 on bad usage."""
    return run_cli(build_parser(prog), argv, _run)


def _run(args: argparse.Namespace) -> int:
    if args.quick:
        args.robots, args.filters, args.speeds, args.counts, args.seeds = ["rosbot"], ["cbf"], [0.5, 1.5], [4], 2
    robots = [choice("robot", name, PRESET_NAMES) for name in args.robots]
    filters = [choice("filter", name, FILTER_NAMES) for name in args.filters]
    if any(args.margins):
        filters_with_margin = [name for name in FILTER_NAMES if name.split("+")[0] in ("cbf", "mpc")]
        for name in filters:
            choice("filter with a margin (--margins)", name, filters_with_margin)
    jobs = [MovingJob(robot, name, speed, int(count), seed, args.duration, extra, args.real_time)
            for robot in robots for name in filters for extra in args.margins for speed in args.speeds
            for count in args.counts for seed in range(args.seeds)]
    print(f"{len(jobs)} episodes of {args.duration:g} s: {len(robots)} robots x {len(filters)} filters x "
          f"{len(args.margins)} margins x {len(args.speeds)} speeds x {len(args.counts)} counts x {args.seeds} seeds, "
          f"on {where(args)}")
    records, wall = run_sweep(args, run_job, jobs, description="moving obstacles",
                              cost=lambda job: job.duration * (3.0 if job.filter.startswith("mpc") else 1.0))
    rows = summarise(records)
    print("OUTSIDE THE GUARANTEE (it assumes a static world): collision rate with moving walkers, "
          f"{wall:.0f} s wall")
    print(table(rows))
    write_json(args.json, {"rows": rows, "episodes": records, "config": vars(args), "wall_time": wall})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
