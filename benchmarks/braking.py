"""Braking: a fast robot with weak brakes heads for a wall; which filters stop it in time?

A ROSbot whose deceleration is limited to ``--accel`` (0.75 m/s^2 by default, half the
preset's) is commanded straight at the stop-at-wall tutorial's wall at full speed (the
published buggy controller at ``--speed``). Compared, on the same seeded starts:

* ``none``: the naive robot;
* ``cbf, acceleration ignored``: the CBF with ``gamma = 1`` and no velocity feedback, the
  textbook velocity-level filter that assumes the base can stop at once;
* ``cbf``: the CBF as shipped (``gamma`` from the acceleration limit, odometry velocity,
  braking caps);
* ``mpc``: the predictive filter, whose plans end stopped.

``--late`` measures instead how far each filter (and the zones) lets the ROSbot run from full speed when every
call brakes (every scan stale) and the calls come ``m`` periods apart, the filter told the time (``now``): a base
ramping at its acceleration limits in ten sub-steps a period; the braking distance at ``a_max`` beside it. No
simulator: the scans are synthetic and only their age matters.

Run ``python -m benchmarks.braking --help`` (or ``safenav bench braking``)::

    python -m benchmarks.braking --seeds 20
    python -m benchmarks.braking --late
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

if __package__ in (None, ""):  # run as `python benchmarks/braking.py`: import this checkout
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from benchmarks.common import markdown_table, write_json
from safenav.episode import EpisodeConfig, run_episode
from safenav.experiments import wilson_interval
from safenav.filters import CBFSafetyFilter, make_filter
from safenav.reference import StopAtWall
from safenav.robot import preset
from safenav.scenarios import scenario
from safenav.synthetic import Scene, synthetic_scan

VARIANTS = ("none", "cbf, acceleration ignored", "cbf", "mpc")


def run(seeds: int, accel: float, speed: float) -> list[dict[str, Any]]:
    robot = preset("rosbot").replace(a_max=accel)
    task = scenario("stop_at_wall")
    rows = []
    for variant in VARIANTS:
        episodes = []
        for seed in range(seeds):
            world = task.world(seed)
            config = EpisodeConfig(duration=10.0, give_velocity=variant != "cbf, acceleration ignored")
            if variant == "cbf, acceleration ignored":
                safety_filter = CBFSafetyFilter(robot, config.sim.control_dt, gamma=1.0)
            else:
                safety_filter = make_filter(variant, robot, config.sim.control_dt)
            policy = StopAtWall.tutorial_bug(speed=speed)
            episodes.append(run_episode(world, robot, policy, safety_filter, config=config, seed=seed).metrics)
        collisions = sum(m.collided for m in episodes)
        rows.append({"variant": variant, "episodes": seeds, "collisions": collisions,
                     "collision_rate_ci": list(wilson_interval(collisions, seeds)),
                     "min_clearance": min(m.min_clearance for m in episodes),
                     "collided_seeds": [seed for seed, m in enumerate(episodes) if m.collided]})
    return rows


LATE_FILTERS = ("cbf", "mpc", "zones")
"""The filters :func:`late_calls` times (every one brakes through :meth:`SafetyFilter.filter`'s checks)."""


def late_calls(periods: Sequence[int] = (1, 2, 3, 4), filters: Sequence[str] = LATE_FILTERS, dt: float = 0.05,
               substeps: int = 10) -> list[dict[str, Any]]:
    """The ROSbot from full speed, every scan stale: the distance [m] it runs until it stands, calls ``m`` periods
    apart (each command held ``m dt``), for each filter and each ``m`` of ``periods``; with the statuses of every
    call and the speed it ended at [m/s]."""
    robot = preset("rosbot")
    scan = synthetic_scan(robot, Scene.of())
    rows = []
    for name in filters:
        for m in periods:
            safety = make_filter(name, robot, dt)
            velocity, travelled, now, calls = np.array([robot.v_max, 0.0]), 0.0, 0.0, 0
            statuses = set()
            while velocity[0] > 0.0 and calls < 1000:
                result = safety.filter(velocity, scan, velocity=velocity, now=now, scan_age=2.0 * safety.scan_timeout)
                statuses.add(result.status.value)
                for _ in range(substeps * m):
                    velocity = robot.clip(result.u, velocity, dt / substeps)
                    travelled += float(velocity[0]) * dt / substeps
                now += m * dt
                calls += 1
            rows.append({"filter": name, "calls_every": m, "distance": travelled, "calls": calls,
                         "braking_distance": robot.v_max**2 / (2.0 * robot.a_max), "status": result.status.value,
                         "statuses": sorted(statuses), "speed": float(velocity[0])})
    return rows


def main(argv: Sequence[str] | None = None, prog: str = "braking") -> int:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=20, help="seeded starts (default: 20)")
    parser.add_argument("--accel", type=float, default=0.75, help="acceleration limit [m/s^2] (default: 0.75)")
    parser.add_argument("--speed", type=float, default=1.0, help="nominal speed [m/s] (default: 1.0)")
    parser.add_argument("--late", action="store_true",
                        help="instead: the distance to stop from full speed when every call brakes and the calls "
                             "come 1-4 periods apart")
    parser.add_argument("--json", metavar="PATH", help="write the results as JSON")
    args = parser.parse_args(argv)
    if args.late:
        rows = late_calls()
        print("rosbot from 1 m/s, every scan stale (every call brakes), calls m periods apart, told the time; "
              "a base ramping at its acceleration limits")
        print(markdown_table(["filter", "calls every", "distance to stop [m]", "braking at a_max [m]", "calls"],
                             [[r["filter"], f"{r['calls_every']} dt", f"{r['distance']:.3f}",
                               f"{r['braking_distance']:.3f}", str(r["calls"])] for r in rows]))
        write_json(args.json, {"late": rows})
        return 0
    rows = run(args.seeds, args.accel, args.speed)
    print(f"rosbot with a_max = {args.accel} m/s^2 at {args.speed} m/s towards a wall 3 m ahead, "
          f"{args.seeds} seeded starts")
    print(markdown_table(["filter", "collisions", "95% CI", "min clearance [m]"],
                         [[r["variant"], f"{r['collisions']}/{r['episodes']}",
                           f"[{r['collision_rate_ci'][0]:.2f}, {r['collision_rate_ci'][1]:.2f}]",
                           f"{r['min_clearance']:.3f}"] for r in rows]))
    write_json(args.json, {"rows": rows, "config": vars(args)})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
