"""The ``safenav`` command line: the demo, single episodes and the benchmarks.

Commands:
  demo    the three tutorial robots, naive vs CBF-filtered vs MPC-filtered: a table and a PNG
  run     one episode with a summary, optionally a PNG, a GIF or the PyBullet GUI
  bench   the benchmarks, from a safenav checkout (they are not part of the wheel)

Where safenav drives a robot on its own (demo, run) the filter is wrapped in the deadlock escape
(safenav.filters.escape.Escape, whose commands pass through the filter); --no-escape turns it off.

Run ``safenav COMMAND --help`` for the options of each command.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import math
import os
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import MappingProxyType, ModuleType
from typing import TYPE_CHECKING

from safenav import __version__
from safenav._checks import argument_type, choice, integer, number, positive, writable_file
from safenav.errors import InvalidConfig, SafeNavError

if TYPE_CHECKING:
    from safenav.experiments import EpisodeOutcome

BENCHMARKS: Mapping[str, str] = MappingProxyType({
    "collisions": "collision_rates", "latency": "filter_latency", "sim": "sim_speed",
    "robustness": "robustness", "soak": "soak", "braking": "braking", "stop": "stop_metrics",
    "moving": "moving_obstacles"})
"""Short names of ``safenav bench NAME`` and the module of ``benchmarks/`` each runs; every other
module of a checkout's ``benchmarks/`` runs under its own name."""

DEMO_FILTERS = ("none", "cbf", "mpc")
"""What ``safenav demo`` compares in the three tutorials (each filter with the deadlock escape unless
``--no-escape``; see :func:`escaped`)."""

DEMO_ESCAPE_CASE = ("goal_rosbot", "go_to_goal", ("cbf", "cbf+escape", "mpc", "mpc+escape"))
"""The demo's fourth panel, where the escape matters: (scenario, policy, filters), a go-to-goal
through clutter, each filter plain and with the deadlock escape."""


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (``safenav: error: ...``) and exit with code 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _say(message: str) -> None:
    print(message, flush=True)


def escaped(name: str, escape: bool) -> str:
    """The filter the CLI drives with: ``name`` wrapped in the deadlock escape when ``escape`` is set.

    Wherever safenav drives a robot on its own the escape is on (``--no-escape`` turns it off):
    its commands pass through the same filter, so only progress depends on it. ``"none"`` has no
    filter to wrap, and a name that already carries the escape is kept.

    Raises:
        InvalidConfig: ``name`` carries the escape and ``escape`` is off (a contradiction).
    """
    from safenav import filters

    if name.endswith(filters.ESCAPE_SUFFIX) and not escape:
        raise InvalidConfig(f"--filter {name} asks for the escape and --no-escape turns it off; expected "
                            f"--filter {filters.unescaped(name)} --no-escape, or no --no-escape")
    return filters.escaped(name) if escape else name


def _filter_names(names: Sequence[str]) -> str:
    from safenav.experiments import FILTER_LABELS

    return " vs ".join(FILTER_LABELS[name] for name in names)


# ---------------------------------------------------------------------------------------------- demo


def _demo(args: argparse.Namespace) -> int:
    from safenav.experiments import Cell, cell_records, episode_specs, outcome_table, reproducible_specs, run_specs
    from safenav.plots import overlay_figure
    from safenav.worlds import TUTORIALS

    out = writable_file("--out", args.out)
    escape_name, escape_policy, escape_filters = DEMO_ESCAPE_CASE
    cases = [(tutorial.name, tutorial.published_policy) for tutorial in TUTORIALS.values()]
    seeds = list(range(args.seed, args.seed + args.seeds))
    tutorial_filters = tuple(escaped(name, not args.no_escape) for name in DEMO_FILTERS)
    cells = [Cell(name, policy, filter_name) for name, policy in cases for filter_name in tutorial_filters]
    cells += [Cell(escape_name, escape_policy, filter_name) for filter_name in escape_filters]
    cases.append((escape_name, escape_policy))
    # Without the filters' compute budgets, as every sweep: the table is the same on any machine, however loaded.
    specs = reproducible_specs(episode_specs(cells, seeds, args.duration, record_seeds=[args.seed]))
    _say(f"safenav demo: the three tutorial robots, {_filter_names(tutorial_filters)}; and the deadlock escape in "
         f"{escape_name}, {_filter_names(escape_filters)}; {len(specs)} episodes "
         f"(seeds {seeds[0]}..{seeds[-1]}) on {args.workers or os.cpu_count()} processes")
    start = time.perf_counter()
    outcomes = run_specs(specs, args.workers, progress=not args.no_progress)
    records = cell_records(outcomes)
    _say("")
    _say(outcome_table(records, ["scenario", "robot", "policy", "filter", "episodes", "collisions",
                                 "clearance min / p5 / median [m]", "progress [m]", "goal reached", "stuck [s]",
                                 "escapes ok/started", "intervention"]))
    _say("")
    _say("clearance: smallest distance between the body and an obstacle (negative: overlap); progress: "
         "distance travelled (towards the goal in goal tasks); stuck: time the nominal wanted to move and the "
         "robot got nowhere (over the last second, under 2 cm and 0.05 rad a second: shaking in place counts); "
         "escapes: deadlock escapes after which the nominal made progress again / started.")
    totals = []
    for name in dict.fromkeys((*tutorial_filters, *escape_filters)):
        group = [r for r in records if r["filter"] == name]
        totals.append(f"{_filter_names([name])} {sum(r['collisions'] for r in group)} of "
                      f"{sum(r['episodes'] for r in group)}")
    _say("episodes that collided: " + ", ".join(totals))
    panels = [[o for o in outcomes if o.spec.seed == args.seed and (o.spec.scenario, o.spec.policy) == case]
              for case in cases]
    figure = overlay_figure(panels, title=f"safenav demo: the same start (seed {args.seed}); the tutorials "
                                          f"{_filter_names(tutorial_filters)}; {escape_name} with and without the "
                                          f"escape")
    figure.savefig(out)
    _say(f"wrote {out.resolve()} (trajectories of seed {args.seed}, one panel per tutorial and one for the escape) "
         f"in {time.perf_counter() - start:.0f} s")
    return 0


# ---------------------------------------------------------------------------------------------- run


def _run(args: argparse.Namespace) -> int:
    from safenav.experiments import EpisodeSpec, run_spec
    from safenav.experiments.runner import reproducible_settings
    from safenav.filters import filter_settings, unescaped
    from safenav.filters.cbf import BODIES as CBF_BODIES
    from safenav.filters.mpc.config import BODIES as MPC_BODIES
    from safenav.scenarios import scenario, scenario_name
    from safenav.sim_bullet import gui_problem

    if args.gui and gui_problem() is not None:
        raise InvalidConfig(f"--gui: {gui_problem()}")
    plot = None if args.plot is None else writable_file("--plot", args.plot)
    gif = None if args.gif is None else writable_file("--gif", args.gif)
    name = scenario_name(args.world, args.robot)
    task = scenario(name)
    policy = args.policy or task.policies[0]
    filter_name = escaped(args.filter, not args.no_escape)
    options = {}
    # The MPC's own options: (flag, MPCConfig field, what it sets, the value given or None).
    mpc_options = (("--mpc-reference", "reference", "what its plan tracks", args.mpc_reference),
                   ("--mpc-lookahead", "lookahead", "its look-ahead disk", args.mpc_lookahead or None))
    for flag, field, what, value in mpc_options:
        if value is None:
            continue
        if unescaped(filter_name) != "mpc":
            raise InvalidConfig(f"{flag} applies to --filter mpc ({what}); got --filter {args.filter}")
        options[field] = value
    sim_options = {}
    if args.body != "disk":
        bodies = {"cbf": CBF_BODIES, "mpc": MPC_BODIES}.get(unescaped(filter_name), ())
        if args.body not in bodies:
            raise InvalidConfig(f"--body {args.body} applies to --filter cbf ({', '.join(CBF_BODIES)}) or mpc "
                                f"({', '.join(MPC_BODIES)}); got --filter {args.filter}")
        options["body"] = args.body
        sim_options["truth"] = "footprint"      # the body the filter's guarantee is for
    options.update(reproducible_settings(filter_name))   # the same seed, the same episode on any machine (_demo)
    spec = EpisodeSpec(name, policy, filter_name, args.seed, args.duration, robot=args.robot, filter_options=options,
                       sim_options=sim_options, record=plot is not None or gif is not None,
                       record_scans=gif is not None, gui=args.gui)
    duration = task.duration if args.duration is None else args.duration
    reference = filter_settings(filter_name, **options).get("reference")    # with the escape's preset
    _say(f"{args.robot or task.robot_name} in world {args.world!r} (scenario {name}, seed {args.seed}), "
         f"policy {policy}, filter {filter_name}"
         f"{f' ({reference} reference)' if reference else ''}"
         f"{f' (look-ahead {args.mpc_lookahead:g} m)' if args.mpc_lookahead else ''}"
         f"{f' (body {args.body}; clearances of the footprint)' if args.body != 'disk' else ''}, up to {duration:g} s")
    outcome = run_spec(spec)
    _print_summary(outcome)
    title = f"{name}, seed {args.seed}\n{policy} + filter {filter_name}"
    if plot is not None or gif is not None:
        _draw(outcome, plot, gif, title)
    return 0


def _draw(outcome: EpisodeOutcome, plot: Path | None, gif: Path | None, title: str) -> None:
    from safenav.plots import plot_episode, save_gif
    from safenav.robot import preset

    robot, trajectory = preset(outcome.robot), outcome.trajectory
    if plot is not None:
        hit = outcome.collision_point()
        plot_episode(outcome.world, robot, trajectory.pose, collisions=None if hit is None else [hit], path=plot,
                     title=title)
        _say(f"wrote {plot.resolve()}")
    if gif is not None:
        stride = max(1, math.ceil(len(trajectory.pose) / 150))
        fps = 10.0
        speed = fps * stride * (trajectory.time[1] - trajectory.time[0]) if len(trajectory.time) > 1 else 1.0
        frames = save_gif(gif, outcome.world, robot, trajectory.pose, [*trajectory.scans, None], fps=fps,
                          stride=stride, title=title)
        _say(f"wrote {gif.resolve()} ({frames} frames, {speed:.1f}x real time)")


def _print_summary(outcome: EpisodeOutcome) -> None:
    from safenav.filters import ESCAPE_SUFFIX

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
    lines.append(("deadlocked", f"{metrics.deadlock_time:.1f} s (longest {metrics.longest_deadlock:.1f} s)"))
    if outcome.spec.filter.endswith(ESCAPE_SUFFIX):
        lines.append(("escapes", f"{metrics.escapes_started} started, {metrics.escapes_succeeded} handed back with "
                                 f"progress, {metrics.escape_time:.1f} s escaping"))
    lines.append(("filter statuses", ", ".join(f"{k} {v}" for k, v in sorted(metrics.statuses.items()))))
    lines.append(("fallbacks", str(metrics.fallbacks)))
    if metrics.filter_times.size:
        lines.append(("filter time", f"p50 {metrics.filter_p50_us:.0f} us, p99 {metrics.filter_p99_us:.0f} us"))
    width = max(len(label) for label, _ in lines)
    for label, value in lines:
        _say(f"  {label + ':':{width + 1}s} {value}")


# ---------------------------------------------------------------------------------------------- bench


def checkout_root(roots: Sequence[str | os.PathLike[str]] | None = None) -> Path | None:
    """The first of ``roots`` that holds a ``benchmarks`` package, or ``None``.

    Args:
        roots: folders to look in; by default the current directory, then the folder that holds
            the ``safenav`` package (an editable install or a source tree).
    """
    if roots is None:
        roots = (Path.cwd(), Path(__file__).resolve().parents[1])
    return next((Path(root) for root in roots if (Path(root) / "benchmarks" / "__init__.py").is_file()), None)


def benchmark_table(root: Path | None) -> Mapping[str, tuple[str, str]]:
    """Every benchmark ``safenav bench`` knows: name -> (module in ``benchmarks/``, first line of its docstring).

    The short names of :data:`BENCHMARKS` first, then every other module of ``root/benchmarks``
    (not ``common``) under its own name. The docstrings are read without importing anything;
    without a checkout the description is empty.
    """
    folder = None if root is None else root / "benchmarks"
    modules = sorted(path.stem for path in folder.glob("*.py")) if folder is not None else []
    extra = [module for module in modules if module not in BENCHMARKS.values() and module not in ("__init__", "common")]
    table = {}
    for name, module in [*BENCHMARKS.items(), *((module, module) for module in extra)]:
        source = None if folder is None else folder / f"{module}.py"
        text = ""
        if source is not None and source.is_file():
            docstring = ast.get_docstring(ast.parse(source.read_text(encoding="utf-8"))) or ""
            text = docstring.strip().splitlines()[0] if docstring.strip() else ""
        table[name] = (module, text)
    return table


def load_benchmark(module: str, roots: Sequence[str | os.PathLike[str]] | None = None) -> ModuleType:
    """Import ``benchmarks.<module>`` from a safenav checkout (the benchmarks are not part of the wheel).

    Args:
        module: the module name in ``benchmarks/`` (``"collision_rates"``, ``"filter_latency"``, ``"sim_speed"``).
        roots: folders to look in, first match wins (see :func:`checkout_root`).

    Raises:
        InvalidConfig: no root holds ``benchmarks/<module>.py``.
    """
    root = checkout_root(roots)
    if root is None or not (root / "benchmarks" / f"{module}.py").is_file():
        raise InvalidConfig(f"the benchmarks are not installed with the package: run `safenav bench` from a safenav "
                            f"checkout (a folder holding benchmarks/{module}.py)")
    if str(root) not in sys.path:
        sys.path.insert(0, str(root))
    return importlib.import_module(f"benchmarks.{module}")


def _bench(args: argparse.Namespace) -> int:
    table = benchmark_table(checkout_root())
    module = load_benchmark(table[args.benchmark][0])
    return int(module.main(list(args.arguments), prog=f"safenav bench {args.benchmark}"))


def _benchmark_lines(table: Mapping[str, tuple[str, str]]) -> str:
    width = max(len(name) for name in table)
    return "\n".join(f"  {name:{width}s}  {text or '(benchmarks/' + module + '.py)'}"
                     for name, (module, text) in table.items())


# ---------------------------------------------------------------------------------------------- parser


def build_parser() -> argparse.ArgumentParser:
    """The ``safenav`` argument parser (one sub-command per job)."""
    from safenav.filters import FILTER_NAMES
    from safenav.filters.cbf import BODIES as CBF_BODIES
    from safenav.filters.mpc.config import REFERENCES
    from safenav.reference import POLICY_NAMES
    from safenav.robot import PRESET_NAMES
    from safenav.scenarios import RANDOM_WORLDS
    from safenav.worlds import TUTORIAL_WORLDS

    def name_type(kind: str, known: Sequence[str]) -> object:
        return argument_type(choice, name=kind, text=True, known=tuple(known))

    benchmarks = benchmark_table(checkout_root())
    formatter = argparse.RawDescriptionHelpFormatter
    parser = _Parser(prog="safenav", description=__doc__, formatter_class=formatter,
                     epilog="benchmarks (safenav bench NAME, from a checkout):\n" + _benchmark_lines(benchmarks))
    parser.add_argument("--version", action="version", version=f"safenav {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_Parser)

    demo = commands.add_parser(
        "demo", help="the three tutorials: naive vs CBF vs MPC, a table and a PNG",
        description="The three tutorial scenarios -- stop_at_wall with the published (buggy) controller, "
                    "obstacle_avoidance and wall_follower -- each run naive, CBF-filtered and MPC-filtered "
                    "on the same seeds, with the deadlock escape around each filter unless --no-escape, and a "
                    "go-to-goal through clutter (goal_rosbot) with each filter plain and with the escape. Prints "
                    "a table of collisions, clearance, progress, goals and escapes, and writes one PNG with the "
                    "trajectories of the first seed side by side. The filters run without their compute "
                    "budgets, as in every sweep: the table is the same on any machine.")
    demo.add_argument("--seed", metavar="S", type=argument_type(integer, low=0), default=0,
                      help="first seed; its trajectories are drawn (default: 0)")
    demo.add_argument("--seeds", metavar="N", type=argument_type(integer, low=1), default=5,
                      help="seeds per scenario and filter (default: 5)")
    demo.add_argument("--out", metavar="PNG", default="safenav-demo.png",
                      help="the PNG to write (default: ./safenav-demo.png)")
    demo.add_argument("--workers", metavar="N", type=argument_type(integer, low=1), default=None,
                      help="processes running episodes (default: one per core)")
    demo.add_argument("--duration", metavar="T", type=argument_type(positive), default=None,
                      help="episode length [s] (default: each scenario's own: 12, 40 and 60 s)")
    demo.add_argument("--no-escape", action="store_true",
                      help="run the tutorials' filters without the deadlock escape (default: with it; the "
                           "go-to-goal panel always shows both)")
    demo.add_argument("--no-progress", action="store_true", help="no progress")
    demo.set_defaults(handler=_demo)

    worlds = (*TUTORIAL_WORLDS, *RANDOM_WORLDS)
    run = commands.add_parser(
        "run", formatter_class=formatter, help="one episode with a summary (and a PNG, a GIF or the GUI)",
        description="Run one closed-loop episode in PyBullet and print what happened.\n\n"
                    "Worlds: the tutorial worlds stop_at_wall, obstacle_avoidance, wall_follower (the start is\n"
                    "perturbed by the seed), clutter (a random 10 x 10 m arena with 30 obstacles drawn from the\n"
                    "seed) and goal (the same with a goal to reach). --robot defaults to the tutorial's robot\n"
                    "(rosbot, puzzlebot, m2wr) or to rosbot in a random world; --policy defaults to the world's\n"
                    "first policy (stop_at_wall, obstacle_avoidance, wall_follower, random_walk, go_to_goal).\n\n"
                    "The filters run without their compute budgets, as in every sweep: the same seed gives the\n"
                    "same episode on any machine.")
    run.add_argument("--robot", metavar="R", type=name_type("robot", PRESET_NAMES),
                     help=f"robot preset: {', '.join(PRESET_NAMES)}")
    run.add_argument("--world", metavar="W", type=name_type("world", worlds), default="stop_at_wall",
                     help=f"world: {', '.join(worlds)} (default: stop_at_wall)")
    run.add_argument("--policy", metavar="P", type=name_type("policy", POLICY_NAMES),
                     help=f"nominal policy: {', '.join(POLICY_NAMES)}")
    run.add_argument("--filter", metavar="F", type=name_type("filter", FILTER_NAMES), default="cbf",
                     help=f"safety filter: {', '.join(FILTER_NAMES)} (default: cbf); wrapped in the deadlock "
                          f"escape unless --no-escape")
    run.add_argument("--no-escape", action="store_true",
                     help="drive with the filter alone: no deadlock escape (default: the filter is wrapped in "
                          "safenav.filters.escape.Escape, whose commands pass through the filter)")
    run.add_argument("--mpc-reference", metavar="REF", type=name_type("MPC reference", REFERENCES), default=None,
                     help="with --filter mpc, what its plan tracks: nominal or cbf (the CBF's answer: it brakes "
                          "and steers as the CBF does) (default: cbf inside the escape, nominal with --no-escape)")
    run.add_argument("--mpc-lookahead", metavar="L", type=argument_type(number, low=0.0, high=10.0), default=0.0,
                     help="with --filter mpc, its look-ahead control disk [m] (MPCConfig.lookahead: planned, never "
                          "verified; it turns the plan round what is ahead) (default: 0, none)")
    run.add_argument("--body", metavar="B", type=name_type("body model", CBF_BODIES), default="disk",
                     help="with --filter cbf or mpc, the body its rows keep clear: disk (the circumscribed disk, "
                          "the default), polygon (the footprint; CBF only) or cover (disks covering it); the "
                          "simulator then measures the footprint's clearance")
    run.add_argument("--seed", metavar="S", type=argument_type(integer, low=0), default=0,
                     help="seed of the world, the start and the noise (default: 0)")
    run.add_argument("--duration", metavar="T", type=argument_type(positive), default=None,
                     help="episode length [s] (default: the world's own)")
    run.add_argument("--gui", action="store_true", help="watch it in the PyBullet GUI (real time; needs a display)")
    run.add_argument("--plot", metavar="PNG", help="write a top-down picture of the episode")
    run.add_argument("--gif", metavar="GIF", help="write an animation with the lidar rays")
    run.set_defaults(handler=_run)

    bench = commands.add_parser(
        "bench", formatter_class=formatter, help=f"the benchmarks: {', '.join(benchmarks)}",
        description="Run a benchmark from a safenav checkout (the benchmarks are not part of the wheel):\n\n"
                    + _benchmark_lines(benchmarks)
                    + "\n\nEverything after the name goes to the benchmark: safenav bench collisions --help.")
    bench.add_argument("benchmark", choices=tuple(benchmarks), metavar="NAME", help=f"one of: {', '.join(benchmarks)}")
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
