"""Filter latency: end-to-end time from a 720-beam LaserScan to the filtered command.

For every QP back-end of the CBF filter (and the MPC filter when asked), on the
same cluttered scenes: the time of ``filter(u_nom, scan)`` (median and p99 over all
calls, and over the calls that needed a QP), and the QP solve alone. In the same
run, the straightforward way as a baseline: every one of the 720 points as a
constraint, ``qpsolvers.solve_qp(..., solver="osqp")`` set up on every call.
Optionally the same on every scan of the real recordings in ``shared/data/lidar``.

``--deadline`` adds the closed-loop scenario of issue 18 (real time at every control
period): a wall just out of the path and a full-speed turning nominal, in an analytic
simulator of this module (exact ray casting, the exact unicycle in sub-steps, a base
ramping at its acceleration limits, the lidar's range noise), so that the time measured
is the filter's. Every preset, both filters (the CBF given the velocity) and the MPC tracking the CBF's
answer (``reference="cbf"``, the MPC inside the deadlock escape: a CBF call in each call), ``dt`` 0.02,
0.05 and 0.1 s: median, p99, p99.9 and max of every call, the share of calls longer than
half a period (the filters' default compute budget; with ``--deadline-budget``, that share of the
period, which both filters are then given) and longer than the period, the CPU time of the calls
(which a busy machine's scheduling does not inflate), the calls that gave up at the deadline, and
the MPC's solving calls apart; the straightforward baseline (no budget) timed on the CBF's own
scans of the same run.

``--reach`` times the CBF (given the velocity) by what lies within its reach, every preset, one
fixed scan each: nothing in range, a 4 m room, a wall 2 m ahead, a wall 0.6 m ahead, a wall
0.15 m beside the body; the nominal and the velocity are 30 % of the top speed, straight ahead; each
scan fresh and 0.1 s old (as a ROS node's scans arrive: the filter first moves them into the current frame).

``--gc`` times a full garbage collection in a process that has built the filters (a CBF and an MPC of the
m2wr at 20 ms): with the numpy kernels or numba's, with the heap as built or frozen by the first filter
(:mod:`safenav.filters.heap`), each in a fresh process: how many objects a collection visits, its median and
largest pause. Such a pause lands in whichever control call the allocations trigger it in.

``--startup`` times what a robot's control process pays before its first command, each run in a fresh process
(the filters' own imports only, not the simulator's): importing :mod:`safenav.filters`, building a CBF and an MPC
filter of the ROSbot at 50 ms (numba's kernels loaded from its cache), and the first call of each on a wall 0.5 m
ahead; median and max over the runs, and which ``safenav`` was measured (``--startup-tree`` picks another tree's).

Run ``python -m benchmarks.filter_latency --help`` (or ``safenav bench latency``)::

    python -m benchmarks.filter_latency --deadline --json latency.json
    python benchmarks/filter_latency.py --deadline --only-deadline
    python -m benchmarks.filter_latency --only-deadline --deadline-budget 0.1 --deadline-robots m2wr
    python -m benchmarks.filter_latency --reach --only-reach
    python -m benchmarks.filter_latency --gc --only-gc
    python -m benchmarks.filter_latency --only-startup --startup-runs 20
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import subprocess
import sys
import tempfile
import textwrap
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import qpsolvers

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1]))

import safenav
from benchmarks.common import markdown_table, summary, write_json
from safenav.filters import CBFSafetyFilter, FilterStatus, MPCSafetyFilter, SafetyFilter, available_solvers
from safenav.filters.defaults import BUDGET_FRACTION
from safenav.geometry import Pose2D, unicycle_step
from safenav.robot import PRESET_NAMES, LidarSpec, RobotSpec, preset
from safenav.scan import LaserScan
from safenav.synthetic import Scene, Segment, synthetic_scan
from safenav.worlds import random_world

DT = 0.05


def cluttered_cases(robot: RobotSpec, n_scenes: int, per_scene: int, seed: int
                    ) -> list[tuple[LaserScan, np.ndarray]]:
    """Scans from random 30-obstacle worlds, taken near obstacles, each with random nominal commands."""
    rng = np.random.default_rng(seed)
    cases = []
    for scene_index in range(n_scenes):
        world = random_world(seed * 100_003 + scene_index, robot, n_obstacles=30)
        scene = world.scene()
        xmin, ymin, xmax, ymax = world.bounds
        for _ in range(1000):
            pose = Pose2D(rng.uniform(xmin, xmax), rng.uniform(ymin, ymax), rng.uniform(-math.pi, math.pi))
            if 0.02 <= world.clearance(pose, robot.radius) <= 0.6:
                break
        scan = synthetic_scan(robot, scene, pose)
        for _ in range(per_scene):
            cases.append((scan, rng.uniform(robot.lower, robot.upper)))
    return cases


def straightforward_cbf(filt: CBFSafetyFilter) -> Callable[[np.ndarray, LaserScan], np.ndarray | None]:
    """The baseline: every point of the scan a row, OSQP set up on every call through qpsolvers."""
    robot, dt, ell = filt.robot, filt.dt, filt.lookahead
    weights = np.diag([1.0 / robot.v_max**2, 1.0 / robot.omega_max**2])

    def solve(u_nom: np.ndarray, scan: LaserScan) -> np.ndarray | None:
        points = scan.points()
        d = np.array([ell, 0.0]) - points
        distance = np.hypot(d[:, 0], d[:, 1])
        n = d / distance[:, None]
        barrier = distance - (robot.radius + ell + filt.margin)
        G = -dt * np.column_stack((n[:, 0], ell * n[:, 1]))
        h = filt.gamma * barrier
        return qpsolvers.solve_qp(weights, -weights @ u_nom, G, h, lb=robot.lower, ub=robot.upper,
                                  solver="osqp", verbose=False)

    return solve


def time_filter(filt: SafetyFilter, cases: Sequence[tuple[LaserScan, np.ndarray]], repeat: int = 1
                ) -> dict[str, Any]:
    """End-to-end and solver-only timings of ``filt`` over ``cases`` (each ``repeat`` times)."""
    total, qp_total, solve = [], [], []
    statuses: dict[str, int] = {}
    for _ in range(repeat):
        for scan, u_nom in cases:
            start = time.perf_counter()
            result = filt.filter(u_nom, scan)
            elapsed = time.perf_counter() - start
            total.append(elapsed)
            if result.solver:
                qp_total.append(elapsed)
                solve.append(result.solve_time)
            statuses[result.status.value] = statuses.get(result.status.value, 0) + 1
    return {"end_to_end": summary(total), "qp_calls": summary(qp_total), "solve": summary(solve),
            "qp_fraction": len(qp_total) / max(len(total), 1), "statuses": statuses}


class NLPSolves:
    """Times every NLP solve of an MPC filter (its back-end's ``solve``), apart by whether each point had its own
    slack; :meth:`detach` gives the filter its back-end back."""

    def __init__(self, mpc: MPCSafetyFilter) -> None:
        self.mpc, self.solve = mpc, mpc.backend.solve
        self.times: dict[str, list[float]] = {"shared": [], "per_point": []}

        def timed(nlp: Any, *args: Any, **kwargs: Any) -> Any:
            outcome = self.solve(nlp, *args, **kwargs)
            self.times["shared" if nlp.slack_groups is None else "per_point"].append(outcome.solve_time)
            return outcome

        mpc.backend.solve = timed  # type: ignore[method-assign]

    def detach(self) -> None:
        self.mpc.backend.solve = self.solve  # type: ignore[method-assign]

    def summary(self, solving_calls: int) -> dict[str, Any]:
        """Median, p99 and max of every solve and of each kind, and the solves per solving call."""
        def stats(samples: list[float]) -> dict[str, float]:
            return {**summary(samples), "max_us": float(np.max(samples) * 1e6) if samples else float("nan")}

        every = self.times["shared"] + self.times["per_point"]
        return {"all": stats(every), "shared": stats(self.times["shared"]),
                "per_point": stats(self.times["per_point"]), "per_solving_call": len(every) / max(solving_calls, 1)}


def time_baseline(solve: Callable[[np.ndarray, LaserScan], Any], cases: Sequence[tuple[LaserScan, np.ndarray]]
                  ) -> dict[str, Any]:
    samples = []
    for scan, u_nom in cases:
        start = time.perf_counter()
        solve(u_nom, scan)
        samples.append(time.perf_counter() - start)
    return {"end_to_end": summary(samples), "samples_s": samples}


def real_recordings(robot: RobotSpec, solver: str, per_scan: int, seed: int) -> list[dict[str, Any]]:
    """End-to-end timing of the CBF filter on every scan of the real recordings."""
    from safenav.datasets import lidar_data_dir, load_recording, recording_files

    folder = lidar_data_dir()
    if folder is None:
        print("real recordings not found (set SAFENAV_LIDAR_DATA); skipped")
        return []
    rng = np.random.default_rng(seed)
    rows = []
    for name, path in recording_files(folder).items():
        records = load_recording(path)
        first = records[0].scan
        # The robot carries the recording's own lidar (the filter checks every scan against it).
        recorded = robot.replace(lidar=LidarSpec.from_scan(first, mount=None if first.mount_given else Pose2D()))
        cases = [(record.scan, rng.uniform(robot.lower, robot.upper)) for record in records for _ in range(per_scan)]
        # How long an answer takes, so no compute budget cuts a slow call short (the deadline scenario keeps it).
        result = time_filter(CBFSafetyFilter(recorded, DT, solver=solver, budget=math.inf), cases)
        beams = records[0].scan.n_beams
        rows.append({"recording": name, "scans": len(records), "beams": beams, **result})
    return rows


CLOSED_LOOP_CELLS = (("clutter_rosbot", "random_walk"), ("goal_rosbot", "go_to_goal"), ("clutter_m2wr", "random_walk"))
"""(scenario, policy) pairs of the closed-loop timing."""


class CallRecorder:
    """An episode callback that keeps every filter call's time, solve time and status."""

    def __init__(self) -> None:
        self.total: list[float] = []
        self.solving: list[float] = []
        self.solve: list[float] = []
        self.statuses: dict[str, int] = {}

    def __call__(self, index: int, state: Any, result: Any) -> None:
        self.total.append(result.filter_time)
        if result.solver and result.solve_time > 0.0:
            self.solving.append(result.filter_time)
            self.solve.append(result.solve_time)
        self.statuses[result.status.value] = self.statuses.get(result.status.value, 0) + 1


def closed_loop(filters: Sequence[str], seeds: int, duration: float = 20.0) -> list[dict[str, Any]]:
    """Per-call times of each filter over closed-loop episodes (warm starts and all), in this process."""
    from safenav.episode import EpisodeConfig, run_episode
    from safenav.filters import make_filter
    from safenav.scenarios import scenario

    rows = []
    for name in filters:
        recorder = CallRecorder()
        for scenario_name, policy_name in CLOSED_LOOP_CELLS:
            task = scenario(scenario_name)
            for seed in range(seeds):
                world = task.world(seed)
                safety_filter = make_filter(name, task.robot, DT)
                run_episode(world, task.robot, task.policy(policy_name, world, seed), safety_filter,
                            config=EpisodeConfig(duration=duration), seed=seed, callback=recorder)
        rows.append({"filter": name, "calls": len(recorder.total), "end_to_end": summary(recorder.total),
                     "solving_calls": summary(recorder.solving), "solve": summary(recorder.solve),
                     "solve_fraction": len(recorder.solving) / max(len(recorder.total), 1),
                     "statuses": recorder.statuses})
    return rows


def reach_scenes(robot: RobotSpec) -> dict[str, Scene]:
    """The scenes of ``--reach``, in the robot's base frame at the origin."""
    r = robot.radius
    return {
        "nothing in range": Scene(),
        "4 m room": Scene.of(Segment((2.0, -2.0), (2.0, 2.0)), Segment((2.0, 2.0), (-2.0, 2.0)),
                             Segment((-2.0, 2.0), (-2.0, -2.0)), Segment((-2.0, -2.0), (2.0, -2.0))),
        "wall 2 m ahead": Scene.of(Segment((r + 2.0, -3.0), (r + 2.0, 3.0))),
        "wall 0.6 m ahead": Scene.of(Segment((r + 0.6, -3.0), (r + 0.6, 3.0))),
        "wall 0.15 m beside": Scene.of(Segment((-1.0, r + 0.15), (3.0, r + 0.15))),
    }


LATE_SCAN = 0.1
"""Age of the late scan the ``--reach`` table also times [s] (up to 9 % older, varying from call to call): a ROS
node's scans always arrive late, and the filter first moves them into the current base frame
(``SafetyFilter.latent_motion``)."""


def reach_case(robot: RobotSpec, scene: str) -> tuple[LaserScan, np.ndarray]:
    """The fixed scan of one scene of :func:`reach_scenes` (no range noise) and the nominal (also the velocity):
    30 % of the top speed, straight ahead."""
    return (synthetic_scan(robot, reach_scenes(robot)[scene], Pose2D(), noise_std=0.0),
            np.array([0.3 * robot.v_max, 0.0]))


def reach_latency(robots: Sequence[str], calls: int) -> list[dict[str, Any]]:
    """The CBF's time per call (velocity given) on one fixed scan of each scene of :func:`reach_scenes`, fresh and
    :data:`LATE_SCAN` old."""
    rows = []
    for name in robots:
        robot = preset(name)
        for scene_name in reach_scenes(robot):
            scan, command = reach_case(robot, scene_name)
            timed = {}
            for age in (0.0, LATE_SCAN):
                safety = CBFSafetyFilter(robot, DT, budget=math.inf)     # its whole time, never cut short
                samples, statuses = [], {}
                for call in range(calls + 20):
                    start = time.perf_counter()
                    # A late scan's age varies a little from call to call (as a ROS node's do), so that each call
                    # moves it into the current frame by a motion of its own, nothing cached from the call before.
                    result = safety.filter(command, scan, velocity=command, scan_age=age * (1.0 + 0.01 * (call % 10)))
                    elapsed = time.perf_counter() - start
                    if call >= 20:   # the first calls fill the memory and the caches
                        samples.append(elapsed)
                        statuses[result.status.value] = statuses.get(result.status.value, 0) + 1
                timed[age] = (summary(samples), statuses, bool(result.modified))
            (fresh, statuses, modified), (late, _, _) = timed[0.0], timed[LATE_SCAN]
            rows.append({"robot": name, "scene": scene_name, "points": len(scan.points()), "end_to_end": fresh,
                         "late_scan": late, "statuses": statuses, "modified": modified})
    return rows


DEADLINE_PERIODS = (0.02, 0.05, 0.1)
"""Control periods of the closed-loop deadline scenario [s]."""
WALL_GAPS = (0.06, 0.12, 0.2, 0.35)
"""How far the wall beside the path is from the body disk at the start [m]."""
DEADLINE_DURATION = 6.0
"""Simulated time of each episode of the deadline scenario [s]."""


def tail(samples_s: Sequence[float], dt: float, budget: float) -> dict[str, float]:
    """Median, p99, p99.9 and max [us], and the shares of samples over ``budget`` and over ``dt``."""
    values = np.asarray(samples_s, dtype=float)
    if values.size == 0:
        nan = float("nan")
        return {"n": 0, "median_us": nan, "p99_us": nan, "p999_us": nan, "max_us": nan, "over_budget": nan,
                "over_period": nan}
    return {"n": int(values.size), "median_us": float(np.median(values) * 1e6),
            "p99_us": float(np.percentile(values, 99) * 1e6), "p999_us": float(np.percentile(values, 99.9) * 1e6),
            "max_us": float(values.max() * 1e6), "over_budget": float(np.mean(values > budget)),
            "over_period": float(np.mean(values > dt))}


def wall_episodes(robot: RobotSpec, dt: float, make: Callable[[], SafetyFilter], seed: int,
                  on_call: Callable[[LaserScan, float, Any], None]) -> None:
    """Issue 18's closed loop: a wall just out of the path on either side, the nominal turning into it
    at full speed. ``on_call(scan, cpu_seconds, result)`` sees every call and the CPU time it took."""
    rng = np.random.default_rng(seed)
    noise = robot.lidar.noise_std
    for gap in WALL_GAPS:
        for side in (1.0, -1.0):
            y = side * (robot.radius + gap)
            scene = Scene.of(Segment((0.16, y), (4.0, y)))
            safety = make()
            pose, velocity = Pose2D(), np.zeros(2)
            nominal = np.array([robot.v_max, side * robot.omega_max])
            for _ in range(round(DEADLINE_DURATION / dt)):
                scan = synthetic_scan(robot, scene, pose, noise_std=noise, rng=rng)
                started = time.process_time()
                result = safety.filter(nominal, scan, velocity=velocity)
                on_call(scan, time.process_time() - started, result)
                for _ in range(10):
                    velocity = robot.clip(result.u, velocity, dt / 10)
                    pose = unicycle_step(pose, float(velocity[0]), float(velocity[1]), dt / 10)


class DeadlineRecorder:
    """Every call's time and status in the deadline scenario, and the first scans (for the baseline)."""

    def __init__(self, keep_scans: int) -> None:
        self.calls: list[float] = []
        self.cpu: list[float] = []
        self.solving: list[float] = []
        self.solver: list[float] = []
        self.statuses: dict[str, int] = {}
        self.deadline = 0
        self.scans: list[LaserScan] = []
        self.keep_scans = keep_scans

    def __call__(self, scan: LaserScan, cpu: float, result: Any) -> None:
        self.calls.append(result.filter_time)
        self.cpu.append(cpu)
        if result.solver and result.solve_time > 0.0:
            self.solving.append(result.filter_time)
            self.solver.append(result.solve_time)
        self.statuses[result.status.value] = self.statuses.get(result.status.value, 0) + 1
        self.deadline += result.timed_out
        if len(self.scans) < self.keep_scans:
            self.scans.append(scan)


def deadline_scenario(robots: Sequence[str], dts: Sequence[float], seed: int,
                      budget_fraction: float | None = None) -> list[dict[str, Any]]:
    """Per robot, period and filter: every call's time in issue 18's closed loop (see the module docstring);
    the filters' compute budget ``budget_fraction * dt`` (default: theirs)."""
    rows = []
    settings = {} if budget_fraction is None else {"budget_fraction": budget_fraction}

    def budgeted(kind: type[SafetyFilter]) -> Callable[..., SafetyFilter]:
        def make(robot: RobotSpec, dt: float, **kwargs: Any) -> SafetyFilter:
            if budget_fraction is not None:
                kwargs["budget"] = budget_fraction * dt
            return kind(robot, dt, **kwargs)
        return make

    cbf, mpc = budgeted(CBFSafetyFilter), budgeted(MPCSafetyFilter)
    # "mpc (cbf reference)": the MPC inside the escape (safenav.filters.ESCAPE_PRESETS), a CBF call in each call.
    makers: dict[str, Callable[[RobotSpec, float], SafetyFilter]] = {
        "cbf": cbf, "mpc": mpc, "mpc (cbf reference)": lambda robot, dt: mpc(robot, dt, reference="cbf")}
    for name in robots:
        robot = preset(name)
        for dt in dts:
            budget = (budget_fraction if budget_fraction is not None else BUDGET_FRACTION) * dt   # the yardstick
            for filter_name, maker in makers.items():
                recorder = DeadlineRecorder(keep_scans=400 if filter_name == "cbf" else 0)
                maker(robot, dt)    # builds (and caches) what is built once per shape, outside the timed calls
                wall_episodes(robot, dt, functools.partial(maker, robot, dt), seed, recorder)
                row = {"robot": name, "dt": dt, "filter": filter_name, "budget_s": budget, **settings,
                       "calls": tail(recorder.calls, dt, budget), "cpu": tail(recorder.cpu, dt, budget),
                       "solving_calls": tail(recorder.solving, dt, budget),
                       "solver": tail(recorder.solver, dt, budget),
                       "solving_share": len(recorder.solving) / max(len(recorder.calls), 1),
                       "statuses": recorder.statuses, "deadline_fallbacks": recorder.deadline}
                if filter_name == "cbf":
                    baseline = straightforward_cbf(CBFSafetyFilter(robot, dt))
                    rng = np.random.default_rng(seed)
                    cases = [(scan, rng.uniform(robot.lower, robot.upper)) for scan in recorder.scans]
                    row["baseline"] = tail(time_baseline(baseline, cases)["samples_s"], dt, budget)
                rows.append(row)
                print(f"  {name} dt={dt} {filter_name}: {len(recorder.calls)} calls, median "
                      f"{row['calls']['median_us']:.0f} us, max {row['calls']['max_us']:.0f} us", flush=True)
    return rows


_GC_SCRIPT = textwrap.dedent("""
    import gc, json, sys, time
    from safenav import preset
    from safenav.filters import CBFSafetyFilter, MPCSafetyFilter
    kernels = sys.argv[1]
    CBFSafetyFilter(preset("m2wr"), 0.02, kernels=kernels)
    MPCSafetyFilter(preset("m2wr"), 0.02, kernels=kernels)
    visited = len(gc.get_objects())
    pauses = []
    for _ in range(int(sys.argv[2])):
        start = time.perf_counter()
        gc.collect()
        pauses.append(time.perf_counter() - start)
    print(json.dumps({"visited": visited, "frozen": gc.get_freeze_count(), "pauses_s": pauses}))
""")
GC_SETTINGS = (("numpy", False), ("numba", False), ("numpy", True), ("numba", True))
"""(kernels, heap frozen) of the --gc table."""


def gc_pauses(repeat: int = 20) -> list[dict[str, Any]]:
    """A full collection's pause in a fresh process per setting of :data:`GC_SETTINGS` (see the module docstring)."""
    rows = []
    for kernels, frozen in GC_SETTINGS:
        env = {**os.environ, "SAFENAV_GC_FREEZE": "1" if frozen else "0"}
        output = subprocess.run([sys.executable, "-c", _GC_SCRIPT, kernels, str(repeat)], env=env, check=True,
                                capture_output=True, text=True).stdout
        measured = json.loads(output.strip().splitlines()[-1])
        pauses = np.asarray(measured["pauses_s"]) * 1e3
        rows.append({"kernels": kernels, "frozen": frozen, "visited": measured["visited"],
                     "frozen_objects": measured["frozen"], "median_ms": float(np.median(pauses)),
                     "max_ms": float(pauses.max())})
    return rows


_STARTUP_SCRIPT = textwrap.dedent("""
    import json, time
    start = time.perf_counter()
    import safenav.filters
    imported = time.perf_counter()
    from safenav import preset
    from safenav.synthetic import Scene, synthetic_scan, wall
    robot = preset("rosbot")
    scan = synthetic_scan(robot, Scene.of(wall(distance=0.5)))
    marks = {"import": imported - start}
    for name, make in (("cbf", safenav.filters.CBFSafetyFilter), ("mpc", safenav.filters.MPCSafetyFilter)):
        begin = time.perf_counter()
        filt = make(robot, 0.05)
        built = time.perf_counter()
        filt.filter((0.5, 0.0), scan, velocity=(0.1, 0.0))
        marks[name + "_build"], marks[name + "_first_call"] = built - begin, time.perf_counter() - built
    marks["total"] = time.perf_counter() - start
    print(json.dumps({"safenav": safenav.__file__, "times_s": marks}))
""")
STARTUP_PHASES = ("import", "cbf_build", "cbf_first_call", "mpc_build", "mpc_first_call", "total")
"""The phases of the --startup table, in the order a process goes through them."""


def startup(runs: int = 10, tree: str | None = None) -> dict[str, Any]:
    """Each phase of a fresh process's start in seconds (see the module docstring): median and max over ``runs``;
    ``tree``: the directory holding the ``safenav`` package measured (default: the one this module imports)."""
    tree = tree or os.path.dirname(os.path.dirname(os.path.abspath(safenav.__file__)))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, (tree, os.environ.get("PYTHONPATH"))))}
    samples: dict[str, list[float]] = {phase: [] for phase in STARTUP_PHASES}
    measured = ""
    for _ in range(runs):
        # From the system's temporary directory, so that the working directory's safenav is not the one taken.
        output = subprocess.run([sys.executable, "-c", _STARTUP_SCRIPT], cwd=tempfile.gettempdir(), env=env,
                                check=True, capture_output=True, text=True).stdout
        report = json.loads(output.strip().splitlines()[-1])
        measured = os.path.dirname(report["safenav"])
        for phase in STARTUP_PHASES:
            samples[phase].append(report["times_s"][phase])
    return {"safenav": measured, "runs": runs,
            "phases": {phase: {"median_s": float(np.median(values)), "max_s": float(np.max(values))}
                       for phase, values in samples.items()}}


def deadline_table(rows: Sequence[dict[str, Any]]) -> str:
    table = []
    for row in rows:
        calls, solving = row["calls"], row["solving_calls"]
        ratio = row["baseline"]["median_us"] / calls["median_us"] if "baseline" in row else float("nan")
        cpu = row["cpu"]
        table.append([row["robot"], row["dt"], row["filter"], calls["n"], calls["median_us"], calls["p99_us"],
                      calls["p999_us"], calls["max_us"], f"{100 * calls['over_budget']:.1f}%",
                      f"{100 * calls['over_period']:.1f}%", f"{cpu['median_us']:.0f} / {cpu['p99_us']:.0f} / "
                      f"{cpu['max_us']:.0f}", f"{100 * row['solving_share']:.0f}%", row["deadline_fallbacks"],
                      solving["median_us"], solving["p99_us"], solving["max_us"],
                      f"{ratio:.1f}x" if math.isfinite(ratio) else "–"])
    return markdown_table(["robot", "dt [s]", "filter", "calls", "median µs", "p99 µs", "p99.9 µs", "max µs",
                           "over budget", "over dt", "CPU median / p99 / max µs", "solving", "deadline fallbacks",
                           "solving median µs",
                           "solving p99 µs", "solving max µs", "baseline / median"], table)


def main(argv: Sequence[str] | None = None, prog: str = "filter_latency") -> int:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="rosbot", help="robot preset (default: rosbot, 720 beams)")
    parser.add_argument("--scenes", type=int, default=250, help="random cluttered scenes (default: 250)")
    parser.add_argument("--per-scene", type=int, default=20, help="nominal commands per scene (default: 20)")
    parser.add_argument("--solvers", default=",".join(s for s in ("daqp", "qpsolvers:daqp", "quadprog", "osqp")
                                                      if s.split(":")[-1] in available_solvers()),
                        help="comma-separated CBF back-ends (default: all fast ones installed)")
    parser.add_argument("--baseline-calls", type=int, default=1000,
                        help="calls of the straightforward baseline (default: 1000)")
    parser.add_argument("--mpc", action="store_true", help="also time the MPC filter (on --mpc-calls calls)")
    parser.add_argument("--mpc-calls", type=int, default=1000, help="MPC calls (default: 1000)")
    parser.add_argument("--real", action="store_true", help="also run on every real recorded scan")
    parser.add_argument("--closed-loop", action="store_true",
                        help="also time every call of closed-loop episodes in the simulator")
    parser.add_argument("--closed-loop-filters", default="cbf,mpc",
                        help="filters for --closed-loop (default: cbf,mpc)")
    parser.add_argument("--closed-loop-seeds", type=int, default=4,
                        help="seeds per cell for --closed-loop (default: 4)")
    parser.add_argument("--deadline", action="store_true",
                        help="also run issue 18's closed loop (wall beside the path, full-speed turning nominal) "
                             "at every period, preset and filter")
    parser.add_argument("--only-deadline", action="store_true", help="run the deadline scenario alone")
    parser.add_argument("--deadline-robots", default=",".join(PRESET_NAMES),
                        help="presets of the deadline scenario (default: all)")
    parser.add_argument("--deadline-dts", default=",".join(str(dt) for dt in DEADLINE_PERIODS),
                        help="control periods of the deadline scenario [s] (default: 0.02,0.05,0.1)")
    parser.add_argument("--deadline-budget", type=float, metavar="FRACTION",
                        help="the filters' compute budget in the deadline scenario, a fraction of dt (default: the "
                             "filter's, 0.5)")
    parser.add_argument("--reach", action="store_true",
                        help="also time the CBF by what lies within its reach (open space to a wall beside)")
    parser.add_argument("--only-reach", action="store_true", help="run the --reach table alone")
    parser.add_argument("--reach-calls", type=int, default=2000, help="calls per scene of --reach (default: 2000)")
    parser.add_argument("--gc", action="store_true", help="time a full garbage collection (see the docstring)")
    parser.add_argument("--only-gc", action="store_true", help="run the --gc table alone")
    parser.add_argument("--startup", action="store_true",
                        help="time a fresh process's import, filters' construction and first calls")
    parser.add_argument("--only-startup", action="store_true", help="run the --startup table alone")
    parser.add_argument("--startup-runs", type=int, default=10, help="fresh processes of --startup (default: 10)")
    parser.add_argument("--startup-tree", metavar="DIR",
                        help="the directory holding the safenav measured by --startup (default: this one's)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", metavar="PATH", help="write the results as JSON")
    args = parser.parse_args(argv)

    results: dict[str, Any] = {"config": vars(args)}
    if args.reach or args.only_reach:
        results["reach"] = reach_latency(PRESET_NAMES, args.reach_calls)
        print(f"the CBF by what lies within its reach (one fixed scan each, velocity given; the same scan "
              f"{LATE_SCAN:g} s old):")
        print(markdown_table(["robot", "scene", "obstacle points", "median µs", "p99 µs", "late: median µs",
                              "late: p99 µs", "command changed", "statuses"],
                             [[row["robot"], row["scene"], row["points"], row["end_to_end"]["median_us"],
                               row["end_to_end"]["p99_us"], row["late_scan"]["median_us"], row["late_scan"]["p99_us"],
                               "yes" if row["modified"] else "no", row["statuses"]]
                              for row in results["reach"]]))
        print()
        if args.only_reach:
            write_json(args.json, results)
            return 0
    if args.gc or args.only_gc:
        results["gc"] = gc_pauses()
        print("a full garbage collection in a process that has built the filters (m2wr, dt 0.02, CBF and MPC):")
        print(markdown_table(["kernels", "heap", "objects visited", "frozen objects", "median ms", "max ms"],
                             [[row["kernels"], "frozen" if row["frozen"] else "as built", row["visited"],
                               row["frozen_objects"], row["median_ms"], row["max_ms"]] for row in results["gc"]]))
        print()
        if args.only_gc:
            write_json(args.json, results)
            return 0
    if args.startup or args.only_startup:
        results["startup"] = startup(args.startup_runs, args.startup_tree)
        print(f"a fresh process's start, {args.startup_runs} runs (safenav from {results['startup']['safenav']}; "
              f"ROSbot, dt 0.05 s, a wall 0.5 m ahead):")
        print(markdown_table(["phase", "median s", "max s"],
                             [[phase, times["median_s"], times["max_s"]]
                              for phase, times in results["startup"]["phases"].items()]))
        print()
        if args.only_startup:
            write_json(args.json, results)
            return 0
    if args.deadline or args.only_deadline:
        print("issue 18's closed loop (wall beside the path, full-speed turning nominal, ramping base):", flush=True)
        results["deadline"] = deadline_scenario(args.deadline_robots.split(","),
                                                [float(dt) for dt in args.deadline_dts.split(",")], args.seed,
                                                args.deadline_budget)
        print()
        print(deadline_table(results["deadline"]))
        if args.only_deadline:
            write_json(args.json, results)
            return 0

    robot = preset(args.robot)
    cases = cluttered_cases(robot, args.scenes, args.per_scene, args.seed)
    points = [len(scan.points()) for scan, _ in cases[:: args.per_scene]]
    print(f"{len(cases)} calls on {args.scenes} cluttered scenes, {robot.lidar.n_beams} beams "
          f"({int(np.median(points))} obstacle points median), robot {robot.name}, dt {DT} s")
    results["cbf"] = {}
    for solver in args.solvers.split(","):
        filt = CBFSafetyFilter(robot, DT, solver=solver, budget=math.inf)     # its whole time, never cut short
        time_filter(filt, cases[:200])  # warm-up
        results["cbf"][solver] = time_filter(filt, cases)
    baseline_cases = cases[: args.baseline_calls]
    results["baseline"] = time_baseline(straightforward_cbf(CBFSafetyFilter(robot, DT)), baseline_cases)
    base = results["baseline"]["end_to_end"]["median_us"]

    rows = []
    for solver, result in results["cbf"].items():
        e2e, qp, solve = result["end_to_end"], result["qp_calls"], result["solve"]
        rows.append([f"cbf/{solver}", e2e["median_us"], e2e["p99_us"], qp["median_us"], qp["p99_us"],
                     solve["median_us"], solve["p99_us"], f"{100 * result['qp_fraction']:.0f}%",
                     f"{base / e2e['median_us']:.1f}x"])
    rows.append(["straightforward: 720 rows, qpsolvers osqp", base, results["baseline"]["end_to_end"]["p99_us"],
                 base, results["baseline"]["end_to_end"]["p99_us"], float("nan"), float("nan"), "100%", "1.0x"])

    if args.mpc:
        mpc = MPCSafetyFilter(robot, DT)
        mpc_cases = cases[: args.mpc_calls]
        time_filter(mpc, mpc_cases[:50])
        mpc.reset()
        nlp_solves = NLPSolves(mpc)
        result = time_filter(mpc, mpc_cases)
        nlp_solves.detach()
        results["mpc"] = {**result, "horizon": mpc.horizon, "points": mpc.config.n_points,
                          "nlp_solves": nlp_solves.summary(result["qp_calls"]["n"])}
        rows.append([f"mpc N={mpc.horizon} K={mpc.config.n_points} (independent calls)",
                     result["end_to_end"]["median_us"],
                     result["end_to_end"]["p99_us"], result["qp_calls"]["median_us"], result["qp_calls"]["p99_us"],
                     result["solve"]["median_us"], result["solve"]["p99_us"],
                     f"{100 * result['qp_fraction']:.0f}%", f"{base / result['end_to_end']['median_us']:.1f}x"])

    print()
    print(markdown_table(["filter", "median µs", "p99 µs", "QP-call median µs", "QP-call p99 µs",
                          "solve median µs", "solve p99 µs", "calls with QP", "speed-up vs baseline"], rows))
    if args.mpc:
        solves = results["mpc"]["nlp_solves"]
        print()
        print(f"the MPC's NLP solves (its SQP from a warm start; a solving call makes one or more: points swapped into "
              f"its slots, a slack per point), {solves['per_solving_call']:.2f} per solving call:")
        print(markdown_table(["NLP solves", "n", "median µs", "p99 µs", "max µs"],
                             [[name, solves[key]["n"], solves[key]["median_us"], solves[key]["p99_us"],
                               solves[key]["max_us"]]
                              for name, key in [("all", "all"), ("one slack for every row", "shared"),
                                                ("a slack per point", "per_point")]]))

    if args.closed_loop:
        results["closed_loop"] = closed_loop(args.closed_loop_filters.split(","), args.closed_loop_seeds)
        print()
        print(f"closed loop in the simulator (every call of the episodes, in order, velocity given), "
              f"{args.closed_loop_seeds} seeds of {', '.join('/'.join(cell) for cell in CLOSED_LOOP_CELLS)}:")
        print(markdown_table(["filter", "calls", "median µs", "p99 µs", "calls that solved", "solving-call median µs",
                              "solving-call p99 µs", "solver median µs", "solver p99 µs", "statuses"],
                             [[row["filter"], row["calls"], row["end_to_end"]["median_us"], row["end_to_end"]["p99_us"],
                               f"{100 * row['solve_fraction']:.0f}%", row["solving_calls"]["median_us"],
                               row["solving_calls"]["p99_us"], row["solve"]["median_us"], row["solve"]["p99_us"],
                               row["statuses"]] for row in results["closed_loop"]]))

    if args.real:
        default = args.solvers.split(",")[0]
        results["real"] = real_recordings(robot, default, per_scan=3, seed=args.seed)
        real_rows = [[row["recording"], row["scans"], row["beams"], row["end_to_end"]["median_us"],
                      row["end_to_end"]["p99_us"], row["qp_calls"]["median_us"], row["qp_calls"]["p99_us"],
                      f"{100 * row['qp_fraction']:.0f}%", row["statuses"].get(FilterStatus.FALLBACK.value, 0)]
                     for row in results["real"]]
        print()
        print(f"real recordings, cbf/{default}, 3 random nominal commands per scan:")
        print(markdown_table(["recording", "scans", "beams", "median µs", "p99 µs", "QP-call median µs",
                              "QP-call p99 µs", "calls with QP", "fallbacks"], real_rows))
    write_json(args.json, results)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
