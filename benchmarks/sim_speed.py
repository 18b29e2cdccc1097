"""Speed of the PyBullet simulator: control steps per second and the cost of one lidar scan.

One *control step* is one physics step plus one scan (``SimConfig(control_dt=dt, physics_dt=dt)``),
with the exact-clearance truth and the ``SimState`` bookkeeping included. The benchmark runs it
in seeded random worlds (``random_world(seed, robot, n_obstacles=30)``: a walled 10 x 10 m
arena with 30 boxes and cylinders) and in an empty world, which is the floor: the same scan
code and the same ``rayTestBatch`` call with nothing to hit. It measures

* ``step``: ``BulletSim.step`` (physics step + scan + truth);
* ``scan``: ``BulletSim.scan`` at the poses the robot visited (one ``rayTestBatch`` and the
  conversion to a ``LaserScan``);
* ``raw``: the bare ``pybullet.rayTestBatch`` call with world-frame rays from those poses, every ray
  ``range_max`` long (the simulator, with numba's kernels, casts each ray only to just past the obstacle it
  first meets: the share of rays so shortened, and of those cast again at full length, is printed),

with ``numThreads=1`` (one core) and ``numThreads=0`` (all cores), and the aggregate rate of
one single-threaded simulator per core running side by side. Times are per call; the table
gives medians and 99th percentiles over every call of every world, and ratios of the random
world to the empty-world floor measured in the same run.

Run::

    python benchmarks/sim_speed.py                    # the table
    python benchmarks/sim_speed.py --json speed.json  # and the numbers as JSON
"""

from __future__ import annotations

import sys
from pathlib import Path

if __package__ in (None, ""):   # python benchmarks/NAME.py: import from this checkout
    sys.path[0] = str(Path(__file__).resolve().parents[1])

import argparse
import datetime
import json
import os
import platform
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from typing import Any

import numpy as np

from safenav import PRESET_NAMES, Pose2D, preset
from safenav._checks import argument_type, choice, integer
from safenav.sim_bullet import BulletSim, SimConfig, import_pybullet
from safenav.worlds import World, random_world

COMMAND = (0.3, 0.6)
"""The command held during the run [m/s, rad/s]: circles of 0.5 m radius around the start."""


def _percentiles(samples: Sequence[float]) -> dict[str, float]:
    array = np.asarray(samples) * 1e3
    return {"median_ms": float(np.median(array)), "p99_ms": float(np.percentile(array, 99)),
            "mean_ms": float(np.mean(array)), "n": int(array.size)}


def _raw_rays(robot_name: str, poses: Sequence[Pose2D]) -> list[tuple[list[list[float]], list[list[float]]]]:
    """World-frame ``rayTestBatch`` arguments for a scan from each base pose."""
    robot = preset(robot_name)
    lidar = robot.lidar
    angles = lidar.scan().angles
    batches = []
    for pose in poses:
        sensor = pose.compose(lidar.mount)
        directions = angles + sensor.yaw
        origin = [sensor.x, sensor.y, lidar.height]
        ends = np.column_stack((sensor.x + lidar.range_max * np.cos(directions),
                                sensor.y + lidar.range_max * np.sin(directions),
                                np.full(angles.size, lidar.height)))
        batches.append(([origin] * angles.size, ends.tolist()))
    return batches


def measure(world: World, robot_name: str, threads: int, steps: int, warmup: int,
            poses: Sequence[Pose2D] | None = None) -> dict[str, Any]:
    """Time ``steps`` control steps, then a scan and a raw ray batch at each visited pose (or at ``poses``)."""
    robot = preset(robot_name)
    dt = 0.01
    config = SimConfig(control_dt=dt, physics_dt=dt, num_threads=threads)
    step_times: list[float] = []
    visited: list[Pose2D] = []
    with BulletSim(world, robot, config, seed=0) as sim:
        sim.reset()
        for _ in range(warmup):
            sim.step(COMMAND)
        clock = time.perf_counter
        for _ in range(steps):
            start = clock()
            state = sim.step(COMMAND)
            step_times.append(clock() - start)
            visited.append(state.pose)
        scan_poses = list(visited if poses is None else poses)
        scan_times = []
        for pose in scan_poses:
            start = clock()
            sim.scan(pose)
            scan_times.append(clock() - start)
        raw_times = []
        client = sim.client_id
        bullet = import_pybullet()
        for ray_from, ray_to in _raw_rays(robot_name, scan_poses):
            start = clock()
            bullet.rayTestBatch(ray_from, ray_to, numThreads=threads, physicsClientId=client)
            raw_times.append(clock() - start)
        counts = dict(sim.ray_counts)
    return {"step": step_times, "scan": scan_times, "raw": raw_times, "poses": [tuple(p) for p in visited],
            "rays": counts}


def _worker(args: tuple[int, str, int, int, int]) -> list[float]:
    """One process: a single-threaded simulator stepping in a random world; returns its step times [s]."""
    seed, robot_name, obstacles, steps, warmup = args
    world = random_world(seed, preset(robot_name), n_obstacles=obstacles)
    return measure(world, robot_name, 1, steps, warmup, poses=[])["step"]


def run(args: argparse.Namespace) -> dict[str, Any]:
    load_before = list(os.getloadavg())
    robot = preset(args.robot)
    seeds = list(range(args.worlds))
    rows: dict[str, dict[str, Any]] = {}
    for threads in args.threads:
        label = "1 thread" if threads == 1 else ("all cores" if threads == 0 else f"{threads} threads")
        world_samples: dict[str, list[float]] = {"step": [], "scan": [], "raw": []}
        rays = {"cast": 0, "shortened": 0, "recast": 0}
        empty_samples: dict[str, list[float]] = {"step": [], "scan": [], "raw": []}
        for seed in seeds:
            world = random_world(seed, robot, n_obstacles=args.obstacles)
            result = measure(world, args.robot, threads, args.steps, args.warmup)
            poses = [Pose2D(*p) for p in result["poses"]]
            empty = World("empty", (), start=world.start, bounds=world.bounds)
            floor = measure(empty, args.robot, threads, args.steps, args.warmup, poses=poses)
            for key in world_samples:
                world_samples[key].extend(result[key])
                empty_samples[key].extend(floor[key])
            for key in rays:
                rays[key] += result["rays"][key]
        rows[label] = {
            "numThreads": threads,
            "random": {key: _percentiles(values) for key, values in world_samples.items()},
            "empty": {key: _percentiles(values) for key, values in empty_samples.items()},
            "rays": rays,
        }
        random_stats, empty_stats = rows[label]["random"], rows[label]["empty"]
        rows[label]["steps_per_second"] = 1e3 / random_stats["step"]["median_ms"]
        rows[label]["throughput_steps_per_second"] = 1e3 / random_stats["step"]["mean_ms"]   # preemption included
        rows[label]["scan_ratio"] = random_stats["scan"]["median_ms"] / empty_stats["scan"]["median_ms"]
        rows[label]["raw_ratio"] = random_stats["raw"]["median_ms"] / empty_stats["raw"]["median_ms"]
    parallel = None
    if args.processes > 1:
        jobs = [(seed % max(args.worlds, 1), args.robot, args.obstacles, args.steps, args.warmup)
                for seed in range(args.processes)]
        with ProcessPoolExecutor(max_workers=args.processes, mp_context=get_context("spawn")) as pool:
            results = list(pool.map(_worker, jobs))
        medians = [float(np.median(times)) for times in results]
        means = [float(np.mean(times)) for times in results]
        parallel = {"processes": args.processes, "total_steps": sum(len(times) for times in results),
                    "aggregate_steps_per_second": sum(1.0 / m for m in medians),
                    "aggregate_throughput_steps_per_second": sum(1.0 / m for m in means),
                    "per_process_steps_per_second": [1.0 / m for m in medians],
                    "per_process_step": [_percentiles(times) for times in results]}
    return {
        "benchmark": "sim_speed",
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "command": "python " + " ".join(sys.argv),
        "robot": args.robot,
        "obstacles": args.obstacles,
        "worlds": seeds,
        "steps_per_world": args.steps,
        "beams": robot.lidar.n_beams,
        "range_max_m": robot.lidar.range_max,
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
                    "pybullet_api": import_pybullet().getAPIVersion(), "load_average_before": load_before,
                    "load_average_after": list(os.getloadavg())},
        "rows": rows,
        "parallel": parallel,
    }


def print_table(report: dict[str, Any]) -> None:
    machine = report["machine"]
    print(f"safenav simulator speed: {report['robot']}, {report['beams']} beams of {report['range_max_m']:g} m, "
          f"random worlds with {report['obstacles']} obstacles (seeds {report['worlds'][0]}..{report['worlds'][-1]}), "
          f"{report['steps_per_world']} steps each; {machine['cpus']} cpus, load average "
          f"{machine['load_average_before'][0]:.2f} before, {machine['load_average_after'][0]:.2f} after")
    header = (f"{'rayTestBatch':12s} {'world':7s} | {'step med':>9s} {'p99':>7s} {'steps/s':>8s} | "
              f"{'scan med':>9s} {'p99':>7s} {'x floor':>7s} | {'raw med':>8s} {'p99':>7s} {'x floor':>7s}")
    print(header)
    print("-" * len(header))
    for label, row in report["rows"].items():
        for kind in ("random", "empty"):
            stats = row[kind]
            step, scan, raw = stats["step"], stats["scan"], stats["raw"]
            ratio_scan = f"{row['scan_ratio']:.2f}" if kind == "random" else "1"
            ratio_raw = f"{row['raw_ratio']:.2f}" if kind == "random" else "1"
            print(f"{label:12s} {kind:7s} | {step['median_ms']:7.3f}ms {step['p99_ms']:5.2f}ms "
                  f"{1e3 / step['median_ms']:8.0f} | {scan['median_ms']:7.3f}ms {scan['p99_ms']:5.2f}ms "
                  f"{ratio_scan:>7s} | "
                  f"{raw['median_ms']:6.3f}ms {raw['p99_ms']:5.2f}ms {ratio_raw:>7s}")
    throughput = ", ".join(f"{row['throughput_steps_per_second']:.0f} ({label})"
                           for label, row in report["rows"].items())
    print(f"random-world throughput by mean step time (preemption included): {throughput} steps/s")
    for label, row in report["rows"].items():
        rays = row["rays"]
        shortened = rays["shortened"] / max(rays["cast"], 1)
        recast = rays["recast"] / max(rays["shortened"], 1)
        print(f"random-world rays ({label}): {rays['cast']} cast by the simulator, {100 * shortened:.1f} % shortened "
              f"to where they first meet an obstacle, {100 * recast:.2f} % of those cast again at full length")
    parallel = report["parallel"]
    if parallel:
        rates = ", ".join(f"{rate:.0f}" for rate in parallel["per_process_steps_per_second"])
        print(f"{parallel['processes']} processes x 1 thread side by side, random worlds: "
              f"{parallel['aggregate_steps_per_second']:.0f} steps/s in total by median step ({rates} each), "
              f"{parallel['aggregate_throughput_steps_per_second']:.0f} by mean step")
    print("steps/s = 1 / median step time; 'x floor' = random-world median / empty-world median, same run")


def build_parser(prog: str = "sim_speed") -> argparse.ArgumentParser:
    """The benchmark's options."""
    count = argument_type(integer, low=1)
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", type=argument_type(choice, name="robot", text=True, known=PRESET_NAMES),
                        default="rosbot", help="robot preset (default: rosbot)")
    parser.add_argument("--obstacles", type=argument_type(integer, low=0), default=30,
                        help="obstacles per random world (default: 30)")
    parser.add_argument("--worlds", type=count, default=5, help="random worlds, seeds 0..N-1 (default: 5)")
    parser.add_argument("--steps", type=count, default=1000, help="timed control steps per world (default: 1000)")
    parser.add_argument("--warmup", type=argument_type(integer, low=0), default=50,
                        help="untimed steps first (default: 50)")
    parser.add_argument("--threads", type=argument_type(integer, low=0), nargs="+", default=[1, 0],
                        help="rayTestBatch numThreads values to run (0 = all cores; default: 1 0)")
    parser.add_argument("--processes", type=count, default=os.cpu_count() or 1,
                        help="single-threaded simulators run side by side for the aggregate rate "
                             "(default: the number of cpus; 1 skips it)")
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON to PATH")
    return parser


def main(argv: Sequence[str] | None = None, prog: str = "sim_speed") -> int:
    """Measure, print the table, write the JSON asked for; returns the exit code (2 on bad usage)."""
    args = build_parser(prog).parse_args(argv)
    report = run(args)
    print_table(report)
    if args.json:
        target = Path(args.json)
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(json.dumps(report, indent=2, allow_nan=False) + "\n", encoding="utf-8")
        print(f"wrote {target}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
