"""The direct SQP gives the answers of the reference (casadi's sqpmethod) on 500 recorded closed-loop problems.

``tests/data/mpc_replay.npz`` holds every problem that needed a solve in a few seeded closed
loops (the obstacle points to millimetres, the velocity, the nominal, the warm start, the
call period, the unknown-region flags), recorded once with::

    python tests/filters/test_mpc_replay.py --record

The test rebuilds each problem with the filter's current code and solves it twice through
the same filter pipeline (point slots, swapping, verification): with the direct SQP over DAQP
(the default) and with casadi's ``sqpmethod``, on the same 32 point slots. Both must succeed
or fail together, and agree on the plan to within the solvers' tolerance.
"""

from __future__ import annotations

import argparse
import functools
import math
import sys
from pathlib import Path

import numpy as np
import pytest

if __name__ == "__main__":  # run as a script to record: make this checkout's safenav importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from safenav import Pose2D, preset, unicycle_step
from safenav.filters import MPCSafetyFilter
from safenav.filters.base import View
from safenav.filters.mpc import MPCProblem
from safenav.filters.perception import Frontier
from safenav.synthetic import Circle, Scene, Segment, box, synthetic_scan, wall

DATA = Path(__file__).resolve().parents[1] / "data" / "mpc_replay.npz"
SLOTS = 32
"""Point slots of both solvers (the reference's default): the same NLP for both."""
TOLERANCE = 1e-4
"""Largest difference of any planned command [m/s, rad/s]: the direct SQP stops when a step moves no
command by more than 1e-5 (``sqp.STEP_TOLERANCE``; it contracts about linearly, so the distance to
the solution can be a few steps more), the reference at 1e-9 on its dual residual."""

#: (robot, dt, settings) of the recorded closed loops; the index is stored with each problem.
CONFIGS = (
    ("rosbot", 0.05, {}),
    ("puzzlebot", 0.05, {}),
    ("m2wr", 0.05, {}),
    ("rosbot", 0.05, {"body": "cover"}),
    ("m2wr", 0.05, {"body": "cover", "n_disks": 5}),
    ("rosbot", 0.02, {}),
    ("m2wr", 0.05, {"time_constant": 0.05}),
)


@functools.cache
def make(config: int, solver: str) -> MPCSafetyFilter:
    name, dt, settings = CONFIGS[config]
    return MPCSafetyFilter(preset(name), dt, solver=solver, n_points=SLOTS, budget=math.inf, max_iter=200,
                           **settings)


# ---------------------------------------------------------------------------------------------- recording


def _scenes(rng: np.random.Generator, robot_radius: float) -> list[Scene]:
    """A wall just out of the path (issue 18), a door, and cluttered squares."""
    side = robot_radius + 0.12
    scenes = [Scene.of(Segment((0.16, side), (3.0, side))),
              Scene.of(Segment((1.0, 0.33), (1.0, 3.0)), Segment((1.0, -0.33), (1.0, -3.0)), wall(2.2))]
    for _ in range(3):
        items = [wall(2.5, angle, 5.0) for angle in (0.0, math.pi / 2, math.pi, -math.pi / 2)]
        while len(items) < 16:
            centre = tuple(rng.uniform(-2.2, 2.2, 2))
            if math.hypot(*centre) < 0.8:
                continue
            items += [Circle(centre, rng.uniform(0.05, 0.3))] if rng.random() < 0.5 else list(
                box(centre, tuple(rng.uniform(0.1, 0.6, 2)), rng.uniform(-3.0, 3.0)))
        scenes.append(Scene.of(*items))
    return scenes


def record(path: Path = DATA, per_config: int = 76, seed: int = 3) -> int:
    """Run seeded closed loops and store the first ``per_config`` problems of each config that needed a solve."""
    rows: dict[str, list] = {key: [] for key in ("config", "u_nom", "velocity", "last", "hold", "flags", "count",
                                                   "points", "uncertainty", "warm", "candidate")}
    rng = np.random.default_rng(seed)
    for index, (name, dt, settings) in enumerate(CONFIGS):
        robot = preset(name)
        safety = MPCSafetyFilter(robot, dt, n_points=SLOTS, budget=math.inf, **settings)
        captured: list[tuple] = []
        original = safety._solve

        def capture(problem: MPCProblem, warm: np.ndarray, candidate: np.ndarray, deadline: float,
                    safety: MPCSafetyFilter = safety, original=original, captured=captured):
            captured.append((problem, warm.copy(), candidate.copy(), safety._last_command.copy()))
            return original(problem, warm, candidate, deadline)

        safety._solve = capture
        for scene in _scenes(rng, robot.radius):
            safety.reset()
            pose, velocity, now = Pose2D(), np.zeros(2), 0.0
            for step in range(int(8.0 / dt)):
                if step % int(0.75 / dt) == 0:
                    nominal = np.array([rng.uniform(0.5, 1.0) * robot.v_max, rng.uniform(-1.0, 1.0) * robot.omega_max])
                result = safety.filter(nominal, synthetic_scan(robot, scene, pose, stamp=now), velocity=velocity,
                                       now=now)
                # Now and then the next call comes a period late (the command is held two periods).
                held = 2 if index == 0 and step % 5 == 3 else 1
                for _ in range(5 * held):
                    velocity = robot.clip(result.u, velocity, dt / 5)
                    pose = unicycle_step(pose, float(velocity[0]), float(velocity[1]), dt / 5)
                now += held * dt
                if scene.clearance((pose.x, pose.y), robot.radius) < 0.0:
                    break
        for problem, warm, candidate, last in captured[:per_config]:
            frontier = problem.frontier
            rows["config"].append(index)
            rows["u_nom"].append(problem.u_nom)
            rows["velocity"].append(problem.velocity)
            rows["last"].append(last)
            rows["hold"].append(problem.hold)
            rows["flags"].append([frontier.forward, frontier.backward, frontier.gap_forward, frontier.gap_backward])
            rows["count"].append(problem.points.shape[0])
            rows["points"].append(np.rint(problem.points * 1000.0).astype(np.int16))
            rows["uncertainty"].append(np.rint(problem.uncertainty * 1e5).astype(np.uint16))
            rows["warm"].append(warm.astype(np.float32))
            rows["candidate"].append(candidate.astype(np.float32))
    arrays = {key: np.concatenate(value) if key in ("points", "uncertainty", "warm", "candidate") else np.array(value)
              for key, value in rows.items()}
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **arrays)
    return len(rows["config"])


# ---------------------------------------------------------------------------------------------- replay


def problems() -> list[dict]:
    data = np.load(DATA)
    ends = np.cumsum(data["count"])
    plans = np.cumsum([make(int(config), "daqp").horizon for config in data["config"]])
    out = []
    for i, config in enumerate(data["config"]):
        start, stop = ends[i] - data["count"][i], ends[i]
        safety = make(int(config), "daqp")
        first = plans[i] - safety.horizon
        out.append(dict(config=int(config), u_nom=data["u_nom"][i], velocity=data["velocity"][i], last=data["last"][i],
                        hold=int(data["hold"][i]), flags=tuple(bool(f) for f in data["flags"][i]),
                        points=data["points"][start:stop] / 1000.0, uncertainty=data["uncertainty"][start:stop] / 1e5,
                        warm=data["warm"][first:plans[i]].astype(float),
                        candidate=data["candidate"][first:plans[i]].astype(float)))
    return out


def solve(case: dict, solver: str):
    """Rebuild the recorded problem for ``solver``'s filter and solve it through the filter's pipeline."""
    safety = make(case["config"], solver)
    safety.reset()
    safety._last_command = case["last"].copy()
    empty = np.empty((0, 2))
    frontier = Frontier(empty, empty, *case["flags"])
    view = View((), case["points"], case["uncertainty"], case["points"].shape[0], frontier)
    problem = safety._problem(case["u_nom"], view, case["velocity"], case["hold"])
    warm = np.clip(case["warm"], problem.lower, problem.upper)
    return problem, safety._solve(problem, warm, case["candidate"])


@pytest.mark.skipif(not DATA.exists(), reason="tests/data/mpc_replay.npz is missing (record it with --record)")
def test_the_direct_sqp_answers_every_recorded_problem_as_the_reference_does():
    cases = problems()
    assert len(cases) >= 500
    assert len({case["config"] for case in cases}) == len(CONFIGS)
    differences, solved = [], 0
    for case in cases:
        _, direct = solve(case, "daqp")
        _, reference = solve(case, "sqpmethod")
        assert (direct.commands is None) == (reference.commands is None), (case["config"], direct.message,
                                                                           reference.message)
        if direct.commands is None:
            continue
        solved += 1
        differences.append(float(np.max(np.abs(direct.commands - reference.commands))))
        # Both verified against every point: the same status follows.
        assert (direct.check.clearance < -1e-6) == (reference.check.clearance < -1e-6)
    assert solved >= 490
    assert max(differences) <= TOLERANCE, (max(differences), int(np.argmax(differences)))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--record", action="store_true", help=f"record the problems into {DATA}")
    if parser.parse_args().record:
        print(f"{record()} problems written to {DATA}")
