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

Run ``python -m benchmarks.braking --help`` (or ``safenav bench braking``).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

if __package__ in (None, ""):  # run as `python benchmarks/braking.py`: import this checkout
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import markdown_table, write_json
from safenav.episode import EpisodeConfig, run_episode
from safenav.experiments import wilson_interval
from safenav.filters import CBFSafetyFilter, make_filter
from safenav.reference import StopAtWall
from safenav.robot import preset
from safenav.scenarios import scenario

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


def main(argv: Sequence[str] | None = None, prog: str = "braking") -> int:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=20, help="seeded starts (default: 20)")
    parser.add_argument("--accel", type=float, default=0.75, help="acceleration limit [m/s^2] (default: 0.75)")
    parser.add_argument("--speed", type=float, default=1.0, help="nominal speed [m/s] (default: 1.0)")
    parser.add_argument("--json", metavar="PATH", help="write the results as JSON")
    args = parser.parse_args(argv)
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
