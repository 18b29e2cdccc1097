"""The ``safenav`` command line: the demo, single episodes and the benchmarks.

Commands:
  demo    the three tutorial robots, naive vs CBF-filtered vs MPC-filtered: a table and a PNG
  run     one episode with a summary, optionally a PNG, a GIF or the PyBullet GUI
  bench   the benchmarks (collisions, latency, sim), from a safenav checkout

Run ``safenav COMMAND --help`` for the options of each command.
"""

from __future__ import annotations

import argparse
import importlib
import math
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

from safenav.errors import InvalidConfig, SafeNavError, UnknownName

if TYPE_CHECKING:
    from safenav.experiments import EpisodeOutcome

TUTORIAL_WORLDS = ("stop_at_wall", "obstacle_avoidance", "wall_follower")
"""Worlds of ``safenav run --world`` that are a tutorial scenario of their own."""

RANDOM_WORLDS = ("clutter", "goal")
"""Worlds of ``safenav run --world`` drawn from the seed (one scenario per robot: ``clutter_rosbot``, ...)."""

BENCHMARKS = {"collisions": "collision_rates", "latency": "filter_latency", "sim": "sim_speed",
              "robustness": "robustness", "soak": "soak", "braking": "braking"}
"""``safenav bench NAME``: the module of ``benchmarks/`` that runs it."""

DEMO_FILTERS = ("none", "cbf", "mpc")
"""What ``safenav demo`` compares."""


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (``safenav: error: ...``) and exit with code 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def positive_int(text: str) -> int:
    """An argparse type: an integer >= 1."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text}")
    return value


def positive_float(text: str) -> float:
    """An argparse type: a finite number > 0."""
    value = float(text)
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {text}")
    return value


def _say(message: str) -> None:
    print(message, flush=True)


# ---------------------------------------------------------------------------------------------- demo


def _demo(args: argparse.Namespace) -> int:
    from safenav import experiments

    filters, missing = experiments.available_filters(DEMO_FILTERS)
    for name, reason in missing.items():
        _say(f"note: the {name!r} filter is not available here ({reason}); it is left out")
    seeds = list(range(args.seed, args.seed + args.seeds))
    cells = [experiments.Cell(name, policy, filter_name)
             for name, policy in experiments.DEMO_CASES for filter_name in filters]
    specs = experiments.episode_specs(cells, seeds, args.duration, record_seeds=[args.seed])
    _say(f"safenav demo: the three tutorial robots, {' vs '.join(experiments.FILTER_LABELS[f] for f in filters)}; "
         f"{len(specs)} episodes (seeds {seeds[0]}..{seeds[-1]}) on {args.workers or os.cpu_count()} processes")
    start = time.perf_counter()
    outcomes = experiments.run_specs(specs, args.workers, progress=not args.no_progress)
    records = experiments.cell_records(outcomes)
    _say("")
    _say(experiments.outcome_table(records, ["scenario", "robot", "policy", "filter", "episodes", "collisions",
                                             "clearance min / p5 / median [m]", "progress [m]", "stuck [s]",
                                             "intervention"]))
    _say("")
    _say("clearance: smallest distance between the body and an obstacle (negative: overlap); progress: "
         "distance travelled; stuck: time the nominal wanted to move and the robot did not.")
    totals = []
    for name in filters:
        group = [r for r in records if r["filter"] == name]
        totals.append(f"{experiments.FILTER_LABELS[name]} {sum(r['collisions'] for r in group)} of "
                      f"{sum(r['episodes'] for r in group)}")
    _say("episodes that collided: " + ", ".join(totals))
    panels = [[o for o in outcomes if o.spec.seed == args.seed and (o.spec.scenario, o.spec.policy) == case]
              for case in experiments.DEMO_CASES]
    figure = experiments.overlay_figure(panels, title=f"safenav demo: the same start (seed {args.seed}), "
                                                      f"{' vs '.join(experiments.FILTER_LABELS[f] for f in filters)}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out)
    _say(f"wrote {out.resolve()} (trajectories of seed {args.seed}, one panel per tutorial) "
         f"in {time.perf_counter() - start:.0f} s")
    return 0


# ---------------------------------------------------------------------------------------------- run


def _scenario_name(world: str, robot: str | None) -> str:
    from safenav.robot import PRESET_NAMES

    if world in TUTORIAL_WORLDS:
        return world
    if world in RANDOM_WORLDS:
        return f"{world}_{robot or PRESET_NAMES[0]}"
    raise UnknownName("world", world, TUTORIAL_WORLDS + RANDOM_WORLDS)


def _run(args: argparse.Namespace) -> int:
    from safenav import experiments
    from safenav.filters import FILTER_NAMES
    from safenav.robot import PRESET_NAMES

    if args.robot is not None and args.robot not in PRESET_NAMES:
        raise UnknownName("robot", args.robot, PRESET_NAMES)
    if args.filter not in FILTER_NAMES:
        raise UnknownName("filter", args.filter, FILTER_NAMES)
    name = _scenario_name(args.world, args.robot)
    task = experiments.scenario_for(name, args.robot, args.policy)
    policy = args.policy or task.policies[0]
    _, missing = experiments.available_filters([args.filter])
    if missing:
        raise InvalidConfig(f"the {args.filter!r} filter is not available here ({missing[args.filter]})")
    spec = experiments.EpisodeSpec(name, policy, args.filter, args.seed, args.duration, robot=args.robot,
                                   record=args.plot is not None or args.gif is not None,
                                   record_scans=args.gif is not None, gui=args.gui)
    duration = task.duration if args.duration is None else args.duration
    _say(f"{task.robot_name} in world {args.world!r} (scenario {name}, seed {args.seed}), policy {policy}, "
         f"filter {args.filter}, up to {duration:g} s")
    outcome = experiments.run_spec(spec)
    _print_summary(outcome)
    world = task.world(args.seed)
    title = f"{name}, seed {args.seed}\n{policy} + filter {args.filter}"
    if args.plot is not None:
        from safenav.render import plot_episode

        hit = experiments.collision_point(outcome)
        plot_episode(world, task.robot, outcome.trajectory.pose, collisions=None if hit is None else [hit],
                     path=args.plot, title=title)
        _say(f"wrote {Path(args.plot).resolve()}")
    if args.gif is not None:
        from safenav.render import save_gif

        trajectory = outcome.trajectory
        stride = max(1, math.ceil(len(trajectory.pose) / 150))
        fps = 10.0
        speed = fps * stride * (trajectory.time[1] - trajectory.time[0]) if len(trajectory.time) > 1 else 1.0
        frames = save_gif(args.gif, world, task.robot, trajectory.pose, [*trajectory.scans, None], fps=fps,
                          stride=stride, title=title)
        _say(f"wrote {Path(args.gif).resolve()} ({frames} frames, {speed:.1f}x real time)")
    return 0


def _print_summary(outcome: EpisodeOutcome) -> None:
    metrics = outcome.metrics
    lines = [("simulated", f"{metrics.time:.2f} s in {metrics.steps} control periods "
                           f"({outcome.wall_time:.1f} s of wall time)")]
    lines.append(("collided", f"yes, at {metrics.collision_time:.2f} s" if metrics.collided else "no"))
    lines.append(("min clearance", f"{metrics.min_clearance:.3f} m"))
    lines.append(("distance", f"{metrics.distance:.2f} m"))
    if metrics.goal_reached is not None:
        reached = f"reached at {metrics.time_to_goal:.1f} s" if metrics.goal_reached else "not reached"
        lines.append(("goal", f"{reached}, progress {metrics.goal_progress:.2f} m"))
    lines.append(("intervention", f"mean {metrics.mean_intervention:.3f}, max {metrics.max_intervention:.3f} "
                                  "(||u - u_nom||, m/s and rad/s)"))
    fraction = metrics.stuck_time / metrics.time if metrics.time > 0 else 0.0
    lines.append(("stuck time", f"{metrics.stuck_time:.1f} s ({100 * fraction:.0f} %)"))
    lines.append(("filter statuses", ", ".join(f"{k} {v}" for k, v in sorted(metrics.statuses.items()))))
    lines.append(("fallbacks", str(metrics.fallbacks)))
    if metrics.filter_times.size:
        lines.append(("filter time", f"p50 {metrics.filter_p50_us:.0f} us, p99 {metrics.filter_p99_us:.0f} us"))
    width = max(len(label) for label, _ in lines)
    for label, value in lines:
        _say(f"  {label + ':':{width + 1}s} {value}")


# ---------------------------------------------------------------------------------------------- bench


def load_benchmark(module: str, roots: Sequence[str | os.PathLike[str]] | None = None) -> ModuleType:
    """Import ``benchmarks.<module>`` from a safenav checkout (the benchmarks are not part of the wheel).

    Args:
        module: the module name in ``benchmarks/`` (``"collision_rates"``, ``"filter_latency"``, ``"sim_speed"``).
        roots: folders to look in, first match wins; by default the current directory, then the
            folder that holds the ``safenav`` package (an editable install or a source tree).

    Raises:
        InvalidConfig: no root holds ``benchmarks/<module>.py``.
    """
    if roots is None:
        roots = (Path.cwd(), Path(__file__).resolve().parents[1])
    for root in map(Path, roots):
        if (root / "benchmarks" / "__init__.py").is_file() and (root / "benchmarks" / f"{module}.py").is_file():
            if str(root) not in sys.path:
                sys.path.insert(0, str(root))
            return importlib.import_module(f"benchmarks.{module}")
    raise InvalidConfig(f"the benchmarks are not installed with the package: run `safenav bench` from a safenav "
                        f"checkout (a folder holding benchmarks/{module}.py)")


def _bench(args: argparse.Namespace) -> int:
    module = load_benchmark(BENCHMARKS[args.benchmark])
    return int(module.main(list(args.arguments), prog=f"safenav bench {args.benchmark}"))


# ---------------------------------------------------------------------------------------------- parser


def build_parser() -> argparse.ArgumentParser:
    """The ``safenav`` argument parser (one sub-command per job)."""
    from safenav.filters import FILTER_NAMES
    from safenav.reference import POLICY_NAMES
    from safenav.robot import PRESET_NAMES

    formatter = argparse.RawDescriptionHelpFormatter
    parser = _Parser(prog="safenav", description=__doc__, formatter_class=formatter)
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_Parser)

    demo = commands.add_parser(
        "demo", help="the three tutorials: naive vs CBF vs MPC, a table and a PNG",
        description="The three tutorial scenarios -- stop_at_wall with the published (buggy) controller, "
                    "obstacle_avoidance and wall_follower -- each run naive, CBF-filtered and MPC-filtered "
                    "on the same seeds. Prints a table of collisions, clearance and progress, and writes one PNG "
                    "with the trajectories of the first seed side by side.")
    demo.add_argument("--seed", metavar="S", type=int, default=0,
                      help="first seed; its trajectories are drawn (default: 0)")
    demo.add_argument("--seeds", metavar="N", type=positive_int, default=5,
                      help="seeds per scenario and filter (default: 5)")
    demo.add_argument("--out", metavar="PNG", default="safenav-demo.png",
                      help="the PNG to write (default: ./safenav-demo.png)")
    demo.add_argument("--workers", metavar="N", type=positive_int, default=None,
                      help="processes running episodes (default: one per core)")
    demo.add_argument("--duration", metavar="T", type=positive_float, default=None,
                      help="episode length [s] (default: each scenario's own: 12, 40 and 60 s)")
    demo.add_argument("--no-progress", action="store_true", help="no progress bar")
    demo.set_defaults(handler=_demo)

    run = commands.add_parser(
        "run", formatter_class=formatter, help="one episode with a summary (and a PNG, a GIF or the GUI)",
        description="Run one closed-loop episode in PyBullet and print what happened.\n\n"
                    "Worlds: the tutorial worlds stop_at_wall, obstacle_avoidance, wall_follower (the start is\n"
                    "perturbed by the seed), clutter (a random 10 x 10 m arena with 30 obstacles drawn from the\n"
                    "seed) and goal (the same with a goal to reach). --robot defaults to the tutorial's robot\n"
                    "(rosbot, puzzlebot, m2wr) or to rosbot in a random world; --policy defaults to the world's\n"
                    "first policy (stop_at_wall, obstacle_avoidance, wall_follower, random_walk, go_to_goal).")
    run.add_argument("--robot", metavar="R", help=f"robot preset: {', '.join(PRESET_NAMES)}")
    run.add_argument("--world", metavar="W", default="stop_at_wall",
                     help=f"world: {', '.join(TUTORIAL_WORLDS + RANDOM_WORLDS)} (default: stop_at_wall)")
    run.add_argument("--policy", metavar="P", help=f"nominal policy: {', '.join(POLICY_NAMES)}")
    run.add_argument("--filter", metavar="F", default="cbf",
                     help=f"safety filter: {', '.join(FILTER_NAMES)} (default: cbf)")
    run.add_argument("--seed", metavar="S", type=int, default=0,
                     help="seed of the world, the start and the noise (default: 0)")
    run.add_argument("--duration", metavar="T", type=positive_float, default=None,
                     help="episode length [s] (default: the world's own)")
    run.add_argument("--gui", action="store_true", help="watch it in the PyBullet GUI (real time)")
    run.add_argument("--plot", metavar="PNG", help="write a top-down picture of the episode")
    run.add_argument("--gif", metavar="GIF", help="write an animation with the lidar rays")
    run.set_defaults(handler=_run)

    bench = commands.add_parser(
        "bench", formatter_class=formatter, help="the benchmarks: collisions, latency, sim, robustness, soak, braking",
        description="Run a benchmark from a safenav checkout (the benchmarks are not part of the wheel):\n\n"
                    "  collisions  collision rates, scenario x policy x filter (benchmarks/collision_rates.py)\n"
                    "  latency     time of one filter call per QP back-end (benchmarks/filter_latency.py)\n"
                    "  sim         speed of the PyBullet simulator (benchmarks/sim_speed.py)\n"
                    "  robustness  collisions under sensor and actuator faults (benchmarks/robustness.py)\n"
                    "  soak        one long episode: leaks, drift, failures (benchmarks/soak.py)\n"
                    "  braking     weak brakes at speed: velocity-level vs acceleration-aware filters "
                    "(benchmarks/braking.py)\n\n"
                    "Everything after the name goes to the benchmark: safenav bench collisions --help.")
    bench.add_argument("benchmark", choices=tuple(BENCHMARKS), metavar="NAME",
                       help=f"one of: {', '.join(BENCHMARKS)}")
    bench.add_argument("arguments", nargs=argparse.REMAINDER, help="the benchmark's own options")
    bench.set_defaults(handler=_bench)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``safenav`` command line; returns the exit code (2 on bad usage)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.handler(args))
    except SafeNavError as error:
        print(f"safenav: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
