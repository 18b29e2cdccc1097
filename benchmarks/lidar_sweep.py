"""A turning lidar's sweep: where the filters see the points, how they stop, what it costs a call.

A lidar that turns measures beam ``i`` of a scan ``i * time_increment`` after its stamp, each from where the
base is then (``sensor_msgs/LaserScan``). The filters move a scan of known age into the current base frame beam
by beam (``stated``: ``time_increment`` given); given as 0 (``unstated``, a driver that does not state it, and how
every scan was moved before the thirty-second session) the whole scan is moved by its stamp's age. Three tables:

* **points**: each preset at its top speed and yaw rate in a 3 x 2.4 m room, a scan cast beam by beam along its
  path (:func:`safenav.synthetic.swept_scan`) and given 20 ms after the sweep ends with the velocity: how far the
  points a call sees lie from where their obstacles are now, within ``--within`` of the base (median and largest);
* **stop**: each preset driven straight at a wall 1.5 m ahead at its top speed by both filters, in the falsifier's
  simulator (a base ramping at its limits, dt 0.05 s), the lidar taking every beam at once, ``stated`` and
  ``unstated``: the smallest clearance less the margin (the guarantee: at least 0);
* **cost**: the CPU time of a call on the same scans ``stated`` and ``unstated`` (the base turning on the spot in the
  room at 0.5 rad/s either way, every scan cast along its path, the velocity measured with a little noise),
  alternating, the median over ``--calls`` calls.

Run ``python -m benchmarks.lidar_sweep --help``::

    python -m benchmarks.lidar_sweep --json sweep.json
"""

from __future__ import annotations

import argparse
import itertools
import math
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

if __package__ in (None, ""):  # run as `python benchmarks/lidar_sweep.py`: import this checkout
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from benchmarks.common import markdown_table, write_json
from benchmarks.falsify import Episode, run
from safenav.experiments.runner import reproducible_settings
from safenav.filters import CBFSafetyFilter, MPCSafetyFilter
from safenav.filters.perception import beam_points
from safenav.geometry import Pose2D, unicycle_step
from safenav.robot import PRESET_NAMES, RobotSpec, preset
from safenav.scan import LaserScan
from safenav.synthetic import Circle, Scene, Segment, swept_scan

#: Time from the end of the sweep to the call [s] (the driver's and the middleware's).
DELIVERY = 0.02
FILTERS = {"cbf": CBFSafetyFilter, "mpc": MPCSafetyFilter}


def room() -> Scene:
    """A room 3 x 2.4 m round the start, a box corner and a pole near it."""
    corners = [(-1.5, -1.2), (1.5, -1.2), (1.5, 1.2), (-1.5, 1.2)]
    walls = tuple(Segment(corners[i], corners[(i + 1) % 4]) for i in range(4))
    return Scene(segments=(*walls, Segment((0.6, 0.5), (1.0, 0.5)), Segment((0.6, 0.5), (0.6, 0.9))),
                 circles=(Circle((0.7, -0.45), 0.08),))


def true_points(robot: RobotSpec, scan: LaserScan, pose_at: Callable[[float], Pose2D], now: float) -> np.ndarray:
    """Each obstacle beam's hit of a turning lidar's ``scan`` (beam by beam, along ``pose_at``: the base pose at a
    time), where it is in the base frame at ``now`` [m], the scan's obstacle beams in order."""
    index, ranges = scan.obstacle_beams()
    times = scan.stamp + scan.beam_times
    world = np.empty((index.size, 2))
    for row, (beam, distance) in enumerate(zip(index, ranges, strict=True)):
        sensor = pose_at(float(times[beam])).compose(robot.lidar.mount)
        direction = sensor.yaw + scan.angles[beam]
        world[row] = sensor.x + distance * math.cos(direction), sensor.y + distance * math.sin(direction)
    return pose_at(now).to_local(world)


def point_errors(robots: Sequence[str], within: float) -> list[dict[str, Any]]:
    """How far the points a call sees lie from their obstacles, the whole scan moved by its stamp's age or each beam
    by its own."""
    rows = []
    for name in robots:
        robot = preset(name)
        v, omega = robot.v_max, robot.omega_max

        def pose_at(t: float, v: float = v, omega: float = omega) -> Pose2D:
            return unicycle_step(Pose2D(-0.3, 0.1, 0.4), v, omega, t)

        scan = swept_scan(robot, room(), pose_at, stamp=0.0)
        now = robot.lidar.scan_time + DELIVERY
        truth = true_points(robot, scan, pose_at, now)
        near = np.hypot(*truth.T) <= within
        row: dict[str, Any] = dict(robot=name, v=v, omega=omega, sweep_time=robot.lidar.scan_time,
                                   points=int(near.sum()))
        for label, given in (("unstated", scan.replace(time_increment=0.0)), ("stated", scan)):
            safety = CBFSafetyFilter(robot, 0.05)
            seen = beam_points(safety.current_scans(given, velocity=(v, omega), now=now), safety.body)
            error = np.hypot(*(seen - truth).T)[near]
            row[label] = dict(median_m=float(np.median(error)), max_m=float(error.max()))
        rows.append(row)
    return rows


def stops(robots: Sequence[str]) -> list[dict[str, Any]]:
    """Each preset straight at a wall 1.5 m ahead at its top speed: the smallest clearance less the margin [m]."""
    wall = ((1.5, -3.0, 1.5, 3.0), (1.5, 3.0, 1.6, 3.0), (1.6, 3.0, 1.6, -3.0), (1.6, -3.0, 1.5, -3.0))
    rows = []
    for name in robots:
        for filter_name in FILTERS:
            row: dict[str, Any] = dict(robot=name, filter=filter_name)
            for sweep in ("", "stated", "unstated"):
                episode = Episode(robot=name, filter=filter_name, base="ramp_limit", dt=0.05, give_velocity=True,
                                  segments=wall, nominal="arc", params=(preset(name).v_max, 0.0), duration=4.0,
                                  settings=reproducible_settings(filter_name), sweep=sweep)
                outcome, _ = run(episode)
                row[sweep or "at once"] = outcome.min_clearance - outcome.margin
            rows.append(row)
    return rows


def costs(robots: Sequence[str], calls: int, turns: Sequence[float] = (0.5, -0.5)) -> list[dict[str, Any]]:
    """CPU time of a call [s] on a turning lidar's scans, the sweep stated and unstated (alternating): the base turning
    on the spot in the room at each of ``turns`` [rad/s] (against the lidar's spin, a full turn leaves a wedge at its
    seam and the call recalls its memory), every scan cast along its path and given ``DELIVERY`` after its sweep."""
    rows = []
    rng = np.random.default_rng(0)
    for name, omega in itertools.product(robots, turns):
        robot = preset(name)
        v, dt = 0.0, 0.05

        def pose_at(t: float, v: float = v, omega: float = omega) -> Pose2D:
            return unicycle_step(Pose2D(-0.3, 0.1, 0.4), v, omega, t)

        scans = []
        for call in range(calls):
            stamp = call * dt - DELIVERY - robot.lidar.scan_time
            scans.append(swept_scan(robot, room(), pose_at, stamp))
        for filter_name, kind in FILTERS.items():
            times: dict[str, list[float]] = {"unstated": [], "stated": []}
            safety = {label: kind(robot, dt) for label in times}
            for call, scan in enumerate(scans):
                noise = rng.normal(0.0, 1e-3, 2)       # measured velocities are never exactly constant
                for label in times:
                    given = scan if label == "stated" else scan.replace(time_increment=0.0)
                    start = time.process_time()
                    safety[label].filter((v, omega), given, velocity=(v + noise[0], omega + noise[1]), now=call * dt)
                    times[label].append(time.process_time() - start)
            warm = calls // 10
            rows.append(dict(robot=name, filter=filter_name, omega=omega, calls=calls - warm,
                             **{label: float(np.median(samples[warm:])) for label, samples in times.items()}))
    return rows


def main(argv: Sequence[str] | None = None, prog: str = "lidar_sweep") -> int:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", nargs="+", default=list(PRESET_NAMES), choices=PRESET_NAMES)
    parser.add_argument("--within", type=float, default=1.0, help="the points table's reach from the base [m] "
                                                                 "(default: 1)")
    parser.add_argument("--calls", type=int, default=400, help="calls of the cost table per filter (default: 400)")
    parser.add_argument("--json", metavar="PATH", help="write the results as JSON")
    args = parser.parse_args(argv)
    points = point_errors(args.robots, args.within)
    print(f"points within {args.within:g} m of the base, each preset at its top speed and yaw rate, the scan given "
          f"{DELIVERY * 1e3:g} ms after its sweep [mm]:")
    print(markdown_table(["robot", "v, omega", "sweep [s]", "points", "unstated: median", "max", "stated: median",
                          "max"],
                         [[r["robot"], f"{r['v']:g} m/s, {r['omega']:g} rad/s", f"{r['sweep_time']:g}", r["points"],
                           f"{1e3 * r['unstated']['median_m']:.1f}", f"{1e3 * r['unstated']['max_m']:.1f}",
                           f"{1e3 * r['stated']['median_m']:.2g}", f"{1e3 * r['stated']['max_m']:.2g}"]
                          for r in points]))
    stop_rows = stops(args.robots)
    print("\nstraight at a wall 1.5 m ahead at the top speed, smallest clearance less the margin [mm]:")
    print(markdown_table(["robot", "filter", "every beam at once", "stated", "unstated"],
                         [[r["robot"], r["filter"], f"{1e3 * r['at once']:+.1f}", f"{1e3 * r['stated']:+.1f}",
                           f"{1e3 * r['unstated']:+.1f}"] for r in stop_rows]))
    cost_rows = costs(args.robots, args.calls)
    print("\nCPU time of a call, median [us] (the base turning on the spot in the room; the same scans):")
    print(markdown_table(["robot", "filter", "omega [rad/s]", "calls", "unstated", "stated", "stated / unstated"],
                         [[r["robot"], r["filter"], f"{r['omega']:+g}", r["calls"], f"{1e6 * r['unstated']:.0f}",
                           f"{1e6 * r['stated']:.0f}", f"{r['stated'] / r['unstated']:.2f}"] for r in cost_rows]))
    write_json(args.json, {"points": points, "stops": stop_rows, "costs": cost_rows, "config": vars(args)})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
