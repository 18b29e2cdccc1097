"""Collision rates and liveness: every scenario x nominal policy x safety filter, N seeded episodes per cell.

The matrix is the scenario registry (``safenav.scenarios``): the three tutorial scenarios
(each with its own robot and world, the first also with the published buggy controller),
random cluttered arenas for every preset (random walk and the robot's tutorial controller),
go-to-goal tasks through clutter, through a door 2 (R + margin) + 5 cm wide, and round a
U-shaped dead end; each (scenario, policy) pair runs with every filter, each filter next to
itself wrapped in the deadlock escape (none, zones, zones+escape, cbf, cbf+escape, mpc,
mpc+escape) on seeds 0..N-1. A seed draws the world and the start, so every filter of a row
faces the same episodes.

Per cell: episodes, collisions, collision rate with a 95 % Wilson interval, minimum body
clearance (min, 5th percentile, median over the episodes), mean intervention ||u - u_nom||,
distance travelled or goal progress, goal success and time to goal, stuck time (the nominal
wants to move and the robot gets nowhere: over the last second, under 2 cm and 0.05 rad a second, so that
shaking back and forth in place counts), fallbacks, the filter's call time p50/p99 pooled over
the cell, and liveness (``safenav.episode.liveness``): episodes with a deadlock longer than 5 s
(the commands keep under a tenth of the nominal's progress; a failed escape counts), mean
deadlocked time, escapes succeeded / started, chatter (mean |Δω|/dt of the commands) and sign
changes of v per second. Printed: the safety table, the liveness table, a summary per kind of
scenario and filter, and the wall-clock times. Every table but the last is the same for the
same seeds whatever the number of workers.

Run ``python -m benchmarks.collision_rates --help`` (or ``safenav bench collisions --help``)::

    python -m benchmarks.collision_rates --quick                 # the CI smoke subset
    python -m benchmarks.collision_rates --json rates.json --plots plots/   # the full sweep
"""

from __future__ import annotations

import sys
from pathlib import Path

if __package__ in (None, ""):   # python benchmarks/NAME.py: import from this checkout
    sys.path[0] = str(Path(__file__).resolve().parents[1])

import argparse
import csv
import dataclasses
import os
from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import Any

from benchmarks.common import names, opt_in_settings, run_cli, run_sweep, sweep_parser, where, write_json
from safenav._checks import argument_type, integer, number, positive, writable_file
from safenav.errors import InvalidConfig
from safenav.experiments import (
    EpisodeOutcome,
    EpisodeSpec,
    cell_records,
    episode_specs,
    matrix,
    outcome_table,
    run_spec,
    timing_table,
)
from safenav.experiments.runner import reproducible_specs, spec_cost
from safenav.experiments.stats import pooled_records
from safenav.experiments.tables import LIVENESS_COLUMNS, SAFETY_COLUMNS, summary_table
from safenav.filters import FILTER_NAMES, FILTERS, unescaped
from safenav.filters.cbf import BODIES as CBF_BODIES
from safenav.filters.mpc.config import BODIES as MPC_BODIES
from safenav.filters.mpc.config import REFERENCES
from safenav.scenarios import scenario
from safenav.sim_bullet import TRUTH_BODIES, SimConfig

FULL_SEEDS = 20
"""Seeds per cell of the default sweep: 19 (scenario, policy) pairs x 7 filters x 20 = 2660 episodes."""

DEFAULT_FILTERS = tuple(name for base in FILTERS for name in (base, f"{base}+escape") if name in FILTER_NAMES)
"""The filters of the default sweep: each filter, then the same filter with the deadlock escape."""

QUICK: Mapping[str, Any] = MappingProxyType(
    {"scenarios": ("stop_at_wall", "clutter_m2wr", "goal_rosbot"), "seeds": 3, "duration": 10.0})
"""The ``--quick`` subset: the buggy tutorial that always crashes, a cluttered arena and a goal task."""

def build_parser(prog: str = "collision_rates") -> argparse.ArgumentParser:
    """The benchmark's options."""
    return sweep_parser(prog, __doc__, _add_options, real_time=True)


def _add_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--quick", action="store_true",
                        help=f"the smoke subset: scenarios {', '.join(QUICK['scenarios'])}, every filter, "
                             f"{QUICK['seeds']} seeds, {QUICK['duration']:g} s episodes (explicit options win)")
    parser.add_argument("--seeds", metavar="N", type=argument_type(integer, low=1), default=None,
                        help=f"seeds 0..N-1 per cell (default: {FULL_SEEDS}; {QUICK['seeds']} with --quick)")
    parser.add_argument("--first-seed", metavar="S", type=argument_type(integer, low=0), default=0,
                        help="start the seeds at S: seeds S..S+N-1 (more episodes of the same cells, default 0)")
    parser.add_argument("--scenarios", type=names, default=None, metavar="A,B",
                        help="comma-separated scenarios (default: all)")
    parser.add_argument("--policies", type=names, default=None, metavar="A,B",
                        help="comma-separated nominal policies (default: every scenario's own)")
    parser.add_argument("--filters", type=names, default=None, metavar="A,B",
                        help=f"comma-separated filters of {','.join(FILTER_NAMES)} (default: all, each next to "
                             f"itself with the escape: {','.join(DEFAULT_FILTERS)})")
    parser.add_argument("--duration", metavar="T", type=argument_type(positive), default=None,
                        help="episode length [s] for every scenario (default: each scenario's own)")
    parser.add_argument("--odometry", action="store_true",
                        help="also give the filters the odometry pose (default: the measured velocity only, "
                             "so remembered points are carried by dead reckoning)")
    parser.add_argument("--range-noise", metavar="STD", type=argument_type(number, low=0.0, high=1.0), default=None,
                        help="std of the simulated lidars' Gaussian range noise [m] instead of each preset's own "
                             "(the filters' margins stay the preset's: how much of a narrow door the noise takes)")
    parser.add_argument("--mpc-reference", choices=REFERENCES, default=None,
                        help="what the MPC rows track: nominal or cbf (MPCConfig.reference='cbf': the CBF's "
                             "answer) (default: the filter's own: nominal for mpc, cbf for mpc+escape)")
    parser.add_argument("--mpc-lookahead", metavar="L", type=argument_type(number, low=0.0, high=10.0), default=0.0,
                        help="the MPC rows' look-ahead control disk [m] (MPCConfig.lookahead; 0: none, the default "
                             "filter)")
    parser.add_argument("--mpc-no-hold", action="store_true",
                        help="the MPC rows without the hold (MPCConfig.hold_stop=False): a plan that would only "
                             "reverse in the next period keeps its first linear command instead of standing")
    parser.add_argument("--cbf-smoothing", metavar="S", type=argument_type(number, low=0.0, high=100.0),
                        default=0.0, help="the CBF rows' penalty on the change from the previous command, relative "
                                          "to the nominal's (CBFConfig.smoothing; 0: none, the default filter)")
    parser.add_argument("--body", choices=CBF_BODIES, default="disk",
                        help="the CBF and MPC rows' body model (CBFConfig / MPCConfig.body; the MPC has disk and "
                             "cover) (default: disk)")
    parser.add_argument("--truth", choices=TRUTH_BODIES, default=None,
                        help="what body the simulator's clearance and collisions are measured for "
                             "(SimConfig.truth): footprint, disk (the circumscribed disk) or auto (default: the "
                             "convex footprint, else the disk)")
    parser.add_argument("--csv", metavar="PATH", help="write one row per cell as CSV")
    parser.add_argument("--plots", metavar="DIR", help="write PNGs: collision rates, clearance histogram, "
                                                       "one trajectory overlay per scenario")


def main(argv: Sequence[str] | None = None, prog: str = "collision_rates") -> int:
    """Run the sweep; print the tables; write the JSON, CSV and PNGs asked for.

    Returns:
        The exit code: 0, or 2 on bad usage (an unknown name, an unwritable output).
    """
    return run_cli(build_parser(prog), argv, _sweep)


def _sweep(args: argparse.Namespace) -> int:
    seeds = args.seeds or (QUICK["seeds"] if args.quick else FULL_SEEDS)
    duration = args.duration or (QUICK["duration"] if args.quick else None)
    scenarios = args.scenarios or (list(QUICK["scenarios"]) if args.quick else None)
    cells = matrix(scenarios, args.policies, args.filters or list(DEFAULT_FILTERS))
    filters = list(dict.fromkeys(cell.filter for cell in cells))
    for what, path in (("--csv", args.csv),
                       ("--plots", args.plots and Path(args.plots) / "collision_rates.png")):
        if path:
            writable_file(what, path)
    seed_range = range(args.first_seed, args.first_seed + seeds)
    specs = episode_specs(cells, seed_range, duration, record_seeds=[seed_range[0]] if args.plots else ())
    if args.odometry:
        specs = [dataclasses.replace(spec, odometry=True) for spec in specs]
    if not args.real_time:   # the same seed, the same episode, whatever the machine's load
        specs = reproducible_specs(specs)
    if args.range_noise is not None:
        specs = [dataclasses.replace(spec, sim_options={**dict(spec.sim_options), "range_noise": args.range_noise})
                 for spec in specs]
    truth = args.truth or ("auto" if args.body == "disk" else "footprint")
    if args.body not in MPC_BODIES and any(unescaped(name) == "mpc" for name in filters):
        raise InvalidConfig(f"--body {args.body}: the MPC's body models are {', '.join(MPC_BODIES)}; "
                            "leave the mpc filters out (--filters) or choose another body")
    if truth != "auto":
        specs = [dataclasses.replace(spec, sim_options={**dict(spec.sim_options), "truth": truth}) for spec in specs]
    specs = tuned(specs, mpc_reference=args.mpc_reference, mpc_lookahead=args.mpc_lookahead,
                  cbf_smoothing=args.cbf_smoothing, body=args.body, mpc_hold=not args.mpc_no_hold)
    pairs = len({(cell.scenario, cell.policy) for cell in cells})
    print(f"{len(specs)} episodes: {pairs} scenario x policy pairs x {len(filters)} filters ({', '.join(filters)}) "
          f"x {seeds} seeds{f' from {args.first_seed}' if args.first_seed else ''}, on {where(args)}; the filters get "
          f"the measured velocity"
          f"{' and the odometry pose' if args.odometry else ' only'}"
          f"{f'; lidar range noise {args.range_noise:g} m' if args.range_noise is not None else ''}"
          f"{f'; the MPC rows track the {args.mpc_reference} reference' if args.mpc_reference else ''}"
          f"{f'; the MPC plans a look-ahead of {args.mpc_lookahead:g} m' if args.mpc_lookahead else ''}"
          f"{'; the MPC without its hold' if args.mpc_no_hold else ''}"
          f"{f'; the CBF smooths its commands by {args.cbf_smoothing:g}' if args.cbf_smoothing else ''}"
          f"{f'; body model {args.body}' if args.body != 'disk' else ''}"
          f"; clearance measured for the {'footprint (the disk of a round robot)' if truth == 'auto' else truth}")
    outcomes, wall_time = run_sweep(args, run_spec, specs, description="episodes", cost=spec_cost)
    records = cell_records(outcomes)
    summary = pooled_records(records, lambda record: (scenario(record["scenario"]).world_kind, record["filter"]))

    print()
    print(outcome_table(records, SAFETY_COLUMNS))
    print()
    print("liveness (deadlock: the commands keep under a tenth of the nominal's progress; see safenav.episode):")
    print(outcome_table(records, LIVENESS_COLUMNS))
    print()
    print("per kind of scenario and filter (every preset and policy pooled):")
    print(summary_table(summary, ["scenarios", "filter"]))
    print()
    print("wall-clock times (they vary with the machine and its load):")
    print(timing_table(records))
    print()
    print(f"{len(specs)} episodes in {wall_time:.0f} s on {where(args)} "
          f"({sum(o.wall_time for o in outcomes):.0f} s of episode time)")

    scenario_names = list(dict.fromkeys(cell.scenario for cell in cells))
    config = {
        "quick": args.quick,
        "seeds": list(seed_range),
        "scenarios": scenario_names,
        "policies": sorted({cell.policy for cell in cells}),
        "filters": filters,
        "duration": duration,
        "durations": {name: duration or scenario(name).duration for name in scenario_names},
        "control_dt": SimConfig().control_dt,
        "odometry": args.odometry,
        "range_noise": args.range_noise,
        "mpc_reference": args.mpc_reference,
        "mpc_lookahead": args.mpc_lookahead,
        "mpc_hold": not args.mpc_no_hold,
        "cbf_smoothing": args.cbf_smoothing,
        "body": args.body,
        "truth": truth,
        "episodes": len(specs),
        "workers": args.workers,
        "backend": args.backend,
        "address": args.address,
        "wall_time_s": wall_time,
        "episode_time_s": sum(o.wall_time for o in outcomes),
    }
    write_json(args.json, {"cells": records, "summary": summary, "config": config})
    if args.csv:
        write_csv(args.csv, records)
        print(f"wrote {args.csv}")
    if args.plots:
        for path in write_plots(Path(args.plots), records, outcomes):
            print(f"wrote {path}")
    return 0


def tuned(specs: Sequence[EpisodeSpec], *, mpc_reference: str | None = None, mpc_lookahead: float = 0.0,
          cbf_smoothing: float = 0.0, body: str = "disk", mpc_hold: bool = True) -> list[EpisodeSpec]:
    """The specs with the sweep's opt-in filter settings: the MPC rows' reference, look-ahead and hold, the CBF
    rows' smoothing, both filters' body model (with or without the escape); the defaults leave every spec as it
    is."""
    tuned_specs = []
    for spec in specs:
        extra = opt_in_settings(spec.filter, mpc_reference=mpc_reference, mpc_lookahead=mpc_lookahead,
                                cbf_smoothing=cbf_smoothing, body=body, mpc_hold=mpc_hold)
        tuned_specs.append(dataclasses.replace(spec, filter_options={**dict(spec.filter_options), **extra})
                           if extra else spec)
    return tuned_specs


# ---------------------------------------------------------------------------------------------- CSV


_NESTED: Mapping[str, tuple[str, ...]] = MappingProxyType({
    "collision_rate_ci": ("low", "high"), "deadlock_rate_ci": ("low", "high"), "min_clearance": ("min", "p5", "median"),
    "time_to_goal": ("mean", "median")})
"""Record fields that become several CSV columns."""


def csv_row(record: dict[str, Any]) -> dict[str, Any]:
    """A cell record as one flat CSV row (nested values get ``<field>_<part>`` columns)."""
    row: dict[str, Any] = {}
    for key, value in record.items():
        if key in _NESTED:
            parts = dict(zip(_NESTED[key], value, strict=True)) if isinstance(value, list) else (value or {})
            row.update({f"{key}_{part}": parts.get(part) for part in _NESTED[key]})
        elif isinstance(value, dict):
            row[key] = ";".join(f"{k}={v}" for k, v in value.items())
        elif isinstance(value, list):
            row[key] = " ".join(str(item) for item in value)
        else:
            row[key] = value
    return row


def write_csv(path: str | os.PathLike[str], records: Sequence[dict[str, Any]]) -> None:
    """Write one row per cell."""
    rows = [csv_row(record) for record in records]
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    with target.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


# ---------------------------------------------------------------------------------------------- plots


def write_plots(folder: Path, records: Sequence[dict[str, Any]], outcomes: Sequence[EpisodeOutcome]) -> list[Path]:
    """Write the collision-rate bars, the clearance histogram and one trajectory overlay per scenario.

    Returns:
        The paths written.
    """
    from safenav.plots import clearance_figure, collision_rate_figure, overlay_figure

    folder.mkdir(parents=True, exist_ok=True)
    paths = [folder / "collision_rates.png", folder / "clearance_histogram.png"]
    collision_rate_figure(records).savefig(paths[0])
    clearance_figure(outcomes).savefig(paths[1])
    recorded = [o for o in outcomes if o.trajectory is not None]
    for name in dict.fromkeys(o.spec.scenario for o in recorded):
        runs = [o for o in recorded if o.spec.scenario == name]
        seed = runs[0].spec.seed
        panels = [[o for o in runs if o.spec.policy == policy and o.spec.seed == seed]
                  for policy in dict.fromkeys(o.spec.policy for o in runs)]
        path = folder / f"trajectories_{name}.png"
        overlay_figure(panels, title=f"{name}: naive vs each filter, seed {seed}").savefig(path)
        paths.append(path)
    return paths


if __name__ == "__main__":
    raise SystemExit(main())
