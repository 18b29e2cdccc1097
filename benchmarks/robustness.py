"""Robustness: collision rates and intervention under sensor and actuator faults, and the margin that restores safety.

The filters' guarantee assumes exact-enough scans, an actuator that does what it is told
and a lidar where the robot description says it is. This benchmark breaks one assumption
at a time in the simulator, in the adversarial cells (a random walk through clutter on
every robot, go-to-goal through clutter), and measures, per filter and per clearance
margin: collisions (with a 95 % Wilson interval), the smallest body clearance, the mean
intervention and the progress. The last table names, per fault level, the smallest margin
tried with no collision and no negative clearance.

Faults (one at a time, everything else nominal):

* ``range_noise``: Gaussian range noise of std 0, 1, 3, 5 cm;
* ``dropout``: each beam reads NaN with probability 10 %, 30 %;
* ``scan_latency``: scans delivered 1, 2 control periods late (the filters compensate with
  the odometry velocity);
* ``actuation_noise``: the executed velocity off by a relative 5 %, 10 % (std, per period);
* ``mount_yaw_error``: the lidar turned by 1, 3 degrees from where the robot description says.

Run ``python -m benchmarks.robustness --help`` (or ``safenav bench robustness``); ``--quick``
runs one seed of short episodes at the default margin, ``--faults`` and ``--scenarios`` a part.
"""

from __future__ import annotations

import sys
from pathlib import Path

if __package__ in (None, ""):   # python benchmarks/NAME.py: import from this checkout
    sys.path[0] = str(Path(__file__).resolve().parents[1])

import argparse
import math
from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import Any

from benchmarks.common import markdown_table, names, numbers, run_cli, run_sweep, sweep_parser, where, write_json
from safenav._checks import argument_type, choice, integer, number, positive
from safenav.experiments import Cell, EpisodeSpec, cell_record, run_spec
from safenav.experiments.runner import spec_cost
from safenav.filters import default_margin
from safenav.scenarios import scenario

FAULTS: Mapping[str, tuple[float, ...]] = MappingProxyType({
    "range_noise": (0.0, 0.01, 0.03, 0.05),
    "dropout": (0.1, 0.3),
    "scan_latency": (1, 2),
    "actuation_noise": (0.05, 0.10),
    "mount_yaw_error": (math.radians(1.0), math.radians(3.0)),
})
"""Fault name (a :class:`~safenav.sim_bullet.SimConfig` field) and the levels tried."""

CELLS = (("clutter_rosbot", "random_walk"), ("clutter_puzzlebot", "random_walk"), ("clutter_m2wr", "random_walk"),
         ("goal_rosbot", "go_to_goal"))
"""(scenario, policy) pairs every configuration runs on."""

EXTRA_MARGINS = (0.0, 0.02, 0.05)
"""Added to each filter's default margin [m]."""


def level_label(fault: str, level: float) -> str:
    """A readable level: centimetres, percent, periods or degrees."""
    if fault == "range_noise":
        return f"{100 * level:.0f} cm"
    if fault in ("dropout", "actuation_noise"):
        return f"{100 * level:.0f} %"
    if fault == "scan_latency":
        return f"{int(level)} periods"
    if fault == "mount_yaw_error":
        return f"{math.degrees(level):.0f} deg"
    return "nominal"


def configurations(filters: Sequence[str], extra_margins: Sequence[float],
                   faults: Sequence[str] = tuple(FAULTS)) -> list[dict[str, Any]]:
    """Every (fault, level, filter, extra margin), starting with the nominal conditions."""
    levels = [("nominal", None)] + [(fault, level) for fault in faults for level in FAULTS[fault]]
    return [{"fault": fault, "level": level, "filter": name, "extra_margin": extra}
            for fault, level in levels for name in filters for extra in extra_margins]


def specs_for(configuration: dict[str, Any], seeds: Sequence[int], duration: float,
              cells: Sequence[tuple[str, str]] = CELLS) -> list[EpisodeSpec]:
    """The episodes of one configuration: every cell and seed, the filter at its default margin plus the extra."""
    sim_options = () if configuration["fault"] == "nominal" else ((configuration["fault"], configuration["level"]),)
    specs = []
    for scenario_name, policy in cells:
        margin = default_margin(scenario(scenario_name).robot) + configuration["extra_margin"]
        for seed in seeds:
            specs.append(EpisodeSpec(scenario_name, policy, configuration["filter"], seed, duration=duration,
                                     sim_options=sim_options, filter_options=(("margin", margin),)))
    return specs


def build_parser(prog: str = "robustness") -> argparse.ArgumentParser:
    """The benchmark's options."""
    return sweep_parser(prog, __doc__, _add_options)


def _add_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--filters", type=names, default=["cbf", "mpc"], metavar="A,B",
                        help="comma-separated filters with a margin (default: cbf,mpc)")
    parser.add_argument("--faults", type=names, default=list(FAULTS), metavar="A,B",
                        help=f"comma-separated faults (default: all: {','.join(FAULTS)}); nominal always runs")
    parser.add_argument("--scenarios", type=names, default=[name for name, _ in CELLS], metavar="A,B",
                        help="comma-separated cells by scenario (default: " + ",".join(name for name, _ in CELLS) + ")")
    parser.add_argument("--seeds", type=argument_type(integer, low=1), default=4,
                        help="seeds per cell and configuration (default: 4)")
    parser.add_argument("--duration", type=argument_type(positive), default=20.0,
                        help="episode length [s] (default: 20)")
    parser.add_argument("--margins", type=numbers(number, low=0.0), default=list(EXTRA_MARGINS), metavar="A,B",
                        help="comma-separated extra margins [m] added to each filter's default (default: 0,0.02,0.05)")
    parser.add_argument("--quick", action="store_true", help="one seed, 8 s episodes, the default margin only")


def main(argv: Sequence[str] | None = None, prog: str = "robustness") -> int:
    """Run the fault sweep; print the tables; write the JSON asked for: exit code 0, or 2 on bad usage."""
    return run_cli(build_parser(prog), argv, _sweep)


def _sweep(args: argparse.Namespace) -> int:
    if args.quick:
        args.seeds, args.duration, args.margins = 1, 8.0, [0.0]
    filters = [choice("filter with a margin", name, ("cbf", "mpc")) for name in args.filters]
    faults = [choice("fault", name, tuple(FAULTS)) for name in args.faults]
    cell_names = dict(CELLS)
    cells = [(name, cell_names[choice("robustness cell", name, tuple(cell_names))]) for name in args.scenarios]
    configs = configurations(filters, args.margins, faults)
    seeds = range(args.seeds)
    specs = [spec for config in configs for spec in specs_for(config, seeds, args.duration, cells)]
    print(f"{len(configs)} configurations x {len(cells)} cells x {args.seeds} seeds = {len(specs)} episodes, "
          f"on {where(args)}")
    outcomes, _ = run_sweep(args, run_spec, specs, description="robustness", cost=spec_cost)

    per_config = len(cells) * args.seeds
    records = []
    for index, config in enumerate(configs):
        chunk = outcomes[index * per_config:(index + 1) * per_config]
        margin = chunk[0].spec.filter_options[0][1]
        record = cell_record(Cell("adversarial cells", "random_walk/go_to_goal", config["filter"]), "all",
                             [outcome.metrics for outcome in chunk], seeds=[outcome.spec.seed for outcome in chunk])
        lowest_margin_gap = min(outcome.metrics.min_clearance - dict(outcome.spec.filter_options)["margin"]
                                for outcome in chunk)
        records.append({**config, "level_label": level_label(config["fault"], config["level"] or 0.0),
                        "margin_mean": margin, "below_margin_worst": lowest_margin_gap,
                        **{key: record[key] for key in ("episodes", "collisions", "collision_rate",
                                                         "collision_rate_ci", "min_clearance", "intervention",
                                                         "progress", "stuck_time", "fallbacks", "statuses")}})

    rows = [[r["fault"], r["level_label"], r["filter"], f"+{100 * r['extra_margin']:.0f} cm",
             f"{r['collisions']}/{r['episodes']}",
             f"[{r['collision_rate_ci'][0]:.2f}, {r['collision_rate_ci'][1]:.2f}]",
             f"{r['min_clearance']['min']:.3f}", f"{r['min_clearance']['p5']:.3f}", f"{r['below_margin_worst']:+.3f}",
             f"{r['intervention']:.3f}", f"{r['stuck_time']:.1f}", r["fallbacks"]] for r in records]
    print()
    print(markdown_table(["fault", "level", "filter", "extra margin", "collisions", "95% CI", "min clearance [m]",
                          "p5 clearance [m]", "worst clearance - margin [m]", "intervention", "stuck [s]",
                          "fallbacks"], rows))

    print()
    print("smallest extra margin tried with no collision and no negative clearance:")
    restore = []
    for fault, level in dict.fromkeys((r["fault"], r["level"]) for r in records):
        for name in filters:
            tried = sorted((r for r in records if r["fault"] == fault and r["level"] == level and r["filter"] == name),
                           key=lambda r: r["extra_margin"])
            safe = [r for r in tried if r["collisions"] == 0 and r["min_clearance"]["min"] >= 0.0]
            restore.append([fault, level_label(fault, level or 0.0), name,
                            f"+{100 * safe[0]['extra_margin']:.0f} cm" if safe else "none tried"])
    print(markdown_table(["fault", "level", "filter", "extra margin needed"], restore))
    write_json(args.json, {"records": records, "restore": restore, "config": vars(args),
                           "cells": [list(cell) for cell in cells]})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
