"""Throughput of safenav's Gymnasium environments: steps per second in vector environments.

Steps ``safenav/GoToGoal-v0`` (by default; ``--env``) with random actions under
``gymnasium.vector.SyncVectorEnv`` (every environment in this process, one after the other)
and ``AsyncVectorEnv`` (one worker process per environment), with 1, 2 and 4 environments,
unshielded and behind ``SafetyShield(env, "cbf")``. Episodes end and reset as in training
(autoreset), so the cost of drawing and building new worlds is included.

For every configuration it reports the aggregate rate (environment steps per wall-clock
second over the timed vector steps) and the latency of one vector step (median, p99, max):
an agent waits that long for every batch of observations.

Run::

    nice python -m benchmarks.gym_throughput --json gym_throughput.json
    python benchmarks/gym_throughput.py --steps 100 --envs 1 2   # quicker
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

if __package__ in (None, ""):  # run as `python benchmarks/gym_throughput.py`: import this checkout
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from benchmarks.common import markdown_table, write_json
from safenav._checks import argument_type, integer
from safenav._optional import require
from safenav.robot import PRESET_NAMES

positive_int = argument_type(integer, low=1)


def _maker(env_id: str, robot: str | None, shielded: bool, info_scan: bool) -> Any:
    def make() -> Any:
        import gymnasium

        import safenav.gym

        env = gymnasium.make(env_id, info_scan=info_scan, **({"robot": robot} if robot else {}))
        return safenav.gym.SafetyShield(env, "cbf") if shielded else env

    return make


def measure(env_id: str, robot: str | None, mode: str, n_envs: int, shielded: bool, steps: int, warmup: int,
            info_scan: bool) -> dict[str, Any]:
    """Step one vector environment ``warmup + steps`` times; time the last ``steps``."""
    gymnasium = require("gymnasium", extra="gym", purpose="the Gymnasium throughput benchmark")
    import safenav.gym  # noqa: F401 - registers the ids in this process

    vector_class = gymnasium.vector.SyncVectorEnv if mode == "sync" else gymnasium.vector.AsyncVectorEnv
    vector = vector_class([_maker(env_id, robot, shielded, info_scan) for _ in range(n_envs)])
    vector.action_space.seed(0)
    vector.reset(seed=0)
    latencies = []
    episodes = 0
    for index in range(warmup + steps):
        action = vector.action_space.sample()
        start = time.perf_counter()
        _, _, terminated, truncated, _ = vector.step(action)
        if index >= warmup:
            latencies.append(time.perf_counter() - start)
            episodes += int(np.count_nonzero(terminated | truncated))
    vector.close()
    times = np.asarray(latencies)
    return {
        "mode": mode, "n_envs": n_envs, "shielded": shielded, "vector_steps": steps,
        "steps_per_second": n_envs * steps / float(times.sum()),
        "step_median_ms": float(np.median(times) * 1e3), "step_p99_ms": float(np.percentile(times, 99) * 1e3),
        "step_max_ms": float(times.max() * 1e3), "episodes_ended": episodes,
    }


def run(args: argparse.Namespace) -> dict[str, Any]:
    results = []
    for shielded in (False, True):
        for mode in args.modes:
            for n_envs in args.envs:
                result = measure(args.env, args.robot, mode, n_envs, shielded, args.steps, args.warmup,
                                 not args.no_info_scan)
                print(f"  {mode:5s} x{n_envs} {'shielded' if shielded else 'plain':8s} "
                      f"{result['steps_per_second']:7.0f} steps/s", flush=True)
                results.append(result)
    return {"env": args.env, "robot": args.robot, "info_scan": not args.no_info_scan, "steps": args.steps,
            "warmup": args.warmup, "results": results}


def print_table(report: dict[str, Any]) -> None:
    rows = [[result["mode"], result["n_envs"], "CBF" if result["shielded"] else "none",
             f"{result['steps_per_second']:.0f}", result["step_median_ms"], result["step_p99_ms"],
             result["step_max_ms"], result["episodes_ended"]] for result in report["results"]]
    print(f"\n{report['env']} ({report['robot'] or 'default robot'}), random actions, {report['steps']} timed vector "
          f"steps after {report['warmup']}; info scan {'on' if report['info_scan'] else 'off'}")
    print(markdown_table(["vector env", "envs", "shield", "env steps / s", "step median [ms]", "step p99 [ms]",
                          "step max [ms]", "episodes ended"], rows))


def build_parser(prog: str = "gym_throughput") -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="safenav/GoToGoal-v0", help="environment id (default: safenav/GoToGoal-v0)")
    parser.add_argument("--robot", choices=PRESET_NAMES, help="robot preset (default: the task's)")
    parser.add_argument("--envs", type=positive_int, nargs="+", default=[1, 2, 4],
                        help="numbers of environments (default: 1 2 4)")
    parser.add_argument("--modes", choices=["sync", "async"], nargs="+", default=["sync", "async"],
                        help="vector environment classes (default: sync async)")
    parser.add_argument("--steps", type=positive_int, default=1000, help="timed vector steps (default: 1000)")
    parser.add_argument("--warmup", type=int, default=50, help="untimed vector steps first (default: 50)")
    parser.add_argument("--no-info-scan", action="store_true", help="leave the scan out of info (less to pickle)")
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON to PATH")
    return parser


def main(argv: Sequence[str] | None = None, prog: str = "gym_throughput") -> int:
    args = build_parser(prog).parse_args(argv)
    report = run(args)
    print_table(report)
    write_json(args.json, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
