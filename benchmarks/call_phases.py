"""Where a filter call's time goes: each phase of the calls of issue 18's closed loop, and the share in compiled code.

Every call of the deadline scenario of ``filter_latency`` (a wall just out of the path, a full-speed
turning nominal, a base ramping at its acceleration limits; every preset), timed phase by phase: each
phase is a set of the filter's functions, and its time is theirs less the time of the other phases'
functions they call (exclusive time), so the phases add up to the call. The phases:

* ``template``: the call's own steps around the filter's work (the checks of the inputs, the scan's
  motion compensation, moving the memory, the deadlock watch, the result);
* ``perception``: the scans to the view (points, memory, the edges of what obstacles hide, the frontier);
* ``rows`` (CBF): the barrier, braking and sweep rows, the gap and blind rows, the box of commands;
* ``problem`` (MPC): the bounds, ramps, radii and reach of the plan; ``plan checks``: the rollout of a
  plan and every body disk at every knot against every point; ``point slots``: the points of the NLP;
* ``SQP`` (MPC): the direct SQP's own steps (the rows of each iterate, the row generation, the step);
* ``decision``: the rest of the filter's work (the fast path, pruning, the slack tiers, the answer's
  verification, the reason and the result);
* ``QP set-up``: the QP back-end's conversion of each QP to DAQP's arrays;
* compiled code: ``QP solver (DAQP)`` (with its Cython wrapper), ``model (casadi)`` (the plan's poses and
  their Jacobian), ``kernels (numba)`` (:mod:`safenav.filters.kernels`).

The table gives each phase's mean time per call [µs] (means add up; medians do not) and its share of
the call, and the share of the call spent in compiled code. Timing a function costs about a microsecond
per call of it: the same episodes run untimed first, and the table gives the median CPU time of a call
both ways. The filters run without a compute budget (no call gives up), the kernels as configured
(``SAFENAV_KERNELS``). Each row is the timed repeat (``--repeat``) with the smallest total.

Run from a checkout::

    python -m benchmarks.call_phases --json phases.json
    python benchmarks/call_phases.py --robots m2wr --dt 0.02 --filters mpc
"""

from __future__ import annotations

import argparse
import functools
import inspect
import math
import sys
import time
from collections import defaultdict
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any

import numpy as np

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1]))

from benchmarks.common import markdown_table, write_json
from benchmarks.filter_latency import reach_case, reach_scenes, wall_episodes
from safenav.filters import CBFSafetyFilter, MPCSafetyFilter, SafetyFilter, kernels, qp
from safenav.filters.mpc import nlp, sqp
from safenav.robot import PRESET_NAMES, RobotSpec, preset
from safenav.scan import LaserScan

COMPILED = ("QP solver (DAQP)", "model (casadi)", "kernels (numba)")
"""The phases that run in compiled code."""

DEADLINE = "deadline"
"""The scene name of issue 18's closed loop (``filter_latency --deadline``)."""

FILTERS: dict[str, type[SafetyFilter]] = {"cbf": CBFSafetyFilter, "mpc": MPCSafetyFilter}


def _targets(name: str) -> list[tuple[Any, str, str]]:
    """``(owner, attribute, phase)`` of every function timed for the filter ``name``."""
    targets: list[tuple[Any, str, str]] = [
        (SafetyFilter, "filter", "template"), (SafetyFilter, "_observe", "perception"),
        (qp.DirectDAQP, "solve", "QP set-up")]
    if name == "cbf":
        targets += [(CBFSafetyFilter, "_constraints", "rows"), (CBFSafetyFilter, "_filter", "decision")]
    else:
        targets += [(MPCSafetyFilter, "filter", "template"), (MPCSafetyFilter, "_filter", "decision"),
                    (MPCSafetyFilter, "_problem", "problem"),
                    (MPCSafetyFilter, "check_plan", "plan checks"), (MPCSafetyFilter, "_select", "point slots"),
                    (sqp.DirectSQP, "solve", "SQP"), (nlp.PlanModel, "evaluate", "model (casadi)")]
    return targets


class PhaseTimer:
    """Exclusive time per phase: each timed function's time, less that of the timed functions it calls."""

    def __init__(self, clock: Callable[[], float] = time.perf_counter) -> None:
        self.clock = clock
        self.totals: dict[str, float] = defaultdict(float)
        self.counts: dict[str, int] = defaultdict(int)
        self.calls: list[float] = []    # each outermost timed call's time [s]
        self._inner: list[float] = []   # per open timed call: the time of the timed calls inside it

    def wrap(self, phase: str, function: Callable[..., Any]) -> Callable[..., Any]:
        """``function``, its time counted to ``phase`` less that of the timed calls it makes."""
        inner, totals, counts, calls, clock = self._inner, self.totals, self.counts, self.calls, self.clock

        @functools.wraps(function)
        def timed(*args: Any, **kwargs: Any) -> Any:
            inner.append(0.0)
            start = clock()
            try:
                return function(*args, **kwargs)
            finally:
                elapsed = clock() - start
                totals[phase] += elapsed - inner.pop()
                counts[phase] += 1
                if inner:
                    inner[-1] += elapsed
                else:
                    calls.append(elapsed)
        return timed

    @contextmanager
    def attached(self, targets: Sequence[tuple[Any, str, str]]) -> Iterator[None]:
        """Every target timed while the block runs, restored after it."""
        restore = []
        try:
            for owner, attribute, phase in targets:
                original = inspect.getattr_static(owner, attribute)
                if inspect.isclass(owner) and attribute not in vars(owner):
                    continue    # inherited: timed where it is defined
                function = original.__func__ if isinstance(original, staticmethod) else original
                timed = self.wrap(phase, function)
                setattr(owner, attribute, staticmethod(timed) if isinstance(original, staticmethod) else timed)
                restore.append((owner, attribute, original))
            yield
        finally:
            for owner, attribute, original in reversed(restore):
                setattr(owner, attribute, original)


def _kernel_targets() -> list[tuple[Any, str, str]]:
    """The compiled kernels the filters use (none when they run numpy)."""
    compiled = kernels.select("auto")
    if compiled is None:
        return []
    return [(compiled, name, "kernels (numba)") for name in vars(compiled) if callable(getattr(compiled, name))]


def _daqp_target() -> list[tuple[Any, str, str]]:
    import daqp
    return [(daqp, "solve", "QP solver (DAQP)")]


OnCall = Callable[[LaserScan, float, Any], None]
Runner = Callable[[Callable[[], SafetyFilter], OnCall], None]


def fixed_scene(robot: RobotSpec, scene: str, calls: int) -> Runner:
    """``calls`` calls of one filter on the fixed scan of a scene of ``filter_latency --reach`` (the nominal and
    the velocity 30 % of the top speed, straight ahead)."""
    scan, command = reach_case(robot, scene)

    def run(make: Callable[[], SafetyFilter], on_call: OnCall) -> None:
        safety = make()
        for _ in range(calls):
            started = time.process_time()
            result = safety.filter(command, scan, velocity=command)
            on_call(scan, time.process_time() - started, result)
    return run


def _deadline_episodes(robot: RobotSpec, dt: float, seed: int, make: Callable[[], SafetyFilter], on_call: OnCall
                       ) -> None:
    wall_episodes(robot, dt, make, seed, on_call)


def phases(robot_name: str, filter_name: str, dt: float, seed: int, repeat: int, scene: str = DEADLINE,
           calls: int = 2000) -> dict[str, Any]:
    """The phases of every call of the deadline scenario (or ``calls`` calls on the fixed scan of ``scene``) for
    one robot, filter and period."""
    robot = preset(robot_name)
    kind = FILTERS[filter_name]

    def make() -> SafetyFilter:
        return kind(robot, dt, budget=math.inf)

    run: Runner = (functools.partial(_deadline_episodes, robot, dt, seed) if scene == DEADLINE
                   else fixed_scene(robot, scene, calls))
    make()      # what is built once per shape (and the kernels' compilation), outside the timed calls
    run(make, lambda scan, cpu, result: None)    # warm-up
    untimed: list[float] = []
    run(make, lambda scan, cpu, result: untimed.append(cpu))
    best: tuple[PhaseTimer, list[float]] | None = None
    targets = _targets(filter_name) + _kernel_targets() + _daqp_target()
    for _ in range(repeat):
        timer, cpu_times = PhaseTimer(), []
        with timer.attached(targets):
            run(make, lambda scan, cpu, result, into=cpu_times: into.append(cpu))
        if best is None or sum(timer.totals.values()) < sum(best[0].totals.values()):
            best = timer, cpu_times
    assert best is not None
    timer, timed = best
    count = len(timer.calls)
    total = sum(timer.totals.values())
    per_call = {phase: 1e6 * seconds / count for phase, seconds in sorted(timer.totals.items(),
                                                                             key=lambda item: -item[1])}
    return {"robot": robot_name, "filter": filter_name, "dt": dt, "scene": scene, "calls": count,
            "mean_us": 1e6 * total / count,
            "untimed_median_cpu_us": 1e6 * float(np.median(untimed)),
            "timed_median_cpu_us": 1e6 * float(np.median(timed)),
            "phases_us": per_call, "timed_calls_per_call": {phase: timer.counts[phase] / count for phase in per_call},
            "compiled_share": sum(timer.totals.get(phase, 0.0) for phase in COMPILED) / total}


PHASE_ORDER = ("template", "perception", "rows", "problem", "plan checks", "point slots", "decision", "SQP",
               "QP set-up", *COMPILED)
"""The order of the table's columns: the call from its outside in, compiled code last."""


def phase_table(rows: Sequence[dict[str, Any]]) -> str:
    """One table per filter: each row's phases (mean µs per call and share of the call)."""
    tables = []
    for filter_name in dict.fromkeys(row["filter"] for row in rows):
        group = [row for row in rows if row["filter"] == filter_name]
        seen = {phase for row in group for phase in row["phases_us"]}
        names = [phase for phase in PHASE_ORDER if phase in seen] + sorted(seen - set(PHASE_ORDER))
        table = []
        for row in group:
            mean = row["mean_us"]
            table.append([row["robot"], row["scene"], row["dt"], f"{row['untimed_median_cpu_us']:.0f}",
                          f"{row['timed_median_cpu_us']:.0f}", f"{mean:.0f}"]
                         + [f"{row['phases_us'][name]:.0f} ({100 * row['phases_us'][name] / mean:.0f}%)"
                            if name in row["phases_us"] else "–" for name in names]
                         + [f"{100 * row['compiled_share']:.0f}%"])
        tables.append(f"{filter_name}:\n\n" + markdown_table(
            ["robot", "scene", "dt [s]", "CPU median µs, untimed", "timed", "mean µs", *names, "compiled"],
            table))
    return "\n\n".join(tables)


def main(argv: Sequence[str] | None = None, prog: str = "call_phases") -> int:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", default=",".join(PRESET_NAMES), help="presets (default: all)")
    parser.add_argument("--filters", default="cbf,mpc", help="filters among cbf, mpc (default: both)")
    parser.add_argument("--dt", type=float, default=0.05, help="control period [s] (default: 0.05)")
    parser.add_argument("--repeat", type=int, default=3, help="timed repeats per row; the fastest is kept (default: 3)")
    parser.add_argument("--scene", default=DEADLINE,
                        help=f"{DEADLINE!r} (issue 18's closed loop, the default) or a fixed scan of filter_latency "
                             f"--reach: {', '.join(repr(name) for name in reach_scenes(preset('rosbot')))}")
    parser.add_argument("--calls", type=int, default=2000, help="calls on a fixed scene's scan (default: 2000)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the lidar's range noise (default: 0)")
    parser.add_argument("--json", metavar="PATH", help="write the results as JSON")
    args = parser.parse_args(argv)
    unknown = [name for name in args.filters.split(",") if name not in FILTERS]
    if unknown:
        parser.error(f"unknown filter(s) {unknown}; expected some of {sorted(FILTERS)}")
    scenes = [DEADLINE, *reach_scenes(preset("rosbot"))]
    if args.scene not in scenes:
        parser.error(f"unknown scene {args.scene!r}; expected one of {scenes}")
    rows = []
    for robot_name in args.robots.split(","):
        for filter_name in args.filters.split(","):
            rows.append(phases(robot_name, filter_name, args.dt, args.seed, args.repeat, args.scene, args.calls))
            print(f"  {robot_name} {filter_name}: {rows[-1]['calls']} calls, mean {rows[-1]['mean_us']:.0f} µs",
                  flush=True)
    print()
    print(phase_table(rows))
    write_json(args.json, {"config": vars(args), "rows": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
