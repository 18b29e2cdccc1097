"""The direct SQP's model and steps: the knots' model is the every-period model through ``B``, its
Jacobian is the model's derivative, and the secant's jumps (a slow tail, a cycle) leave the answers where the
plain SQP ends (tests/filters/test_mpc_replay.py checks both against casadi's sqpmethod)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from safenav import Pose2D, preset, unicycle_step
from safenav.filters import MPCSafetyFilter
from safenav.filters.mpc import BaseModel, PlanLayout, PlanModel, sqp
from safenav.filters.mpc.plan import block_ramp
from safenav.synthetic import Scene, Segment, synthetic_scan

LAYOUTS = [(20, 20, 1), (51, 20, 1), (51, 20, 3), (12, 5, 1)]


@pytest.mark.parametrize("periods, max_commands, hold", LAYOUTS)
@pytest.mark.parametrize("time_constant", [0.0, 0.05])
def test_the_knots_model_is_the_every_period_model_through_the_interpolation(periods, max_commands, hold,
                                                                             time_constant):
    layout = PlanLayout.of(periods, max_commands, hold)
    base = BaseModel(0.02, time_constant)
    rng = np.random.default_rng(periods + hold)
    knots = rng.uniform(-1.0, 1.0, (layout.n_knots, 2))
    velocity = rng.uniform(-0.5, 0.5, 2)
    poses, jacobian = PlanModel(periods, base, layout)(knots, velocity)
    # A late call's blocks without a lag: the every-period model at the velocities the base reaches, each block
    # ramped over its length (u -> R u + r w_0).
    through = layout.interpolation
    if hold > 1 and time_constant == 0.0:
        through = block_ramp(periods, hold)[0] @ through
    every_poses, every_jacobian = PlanModel(periods, base)(base.reached(layout.expand(knots), velocity, hold),
                                                           velocity)
    assert poses.shape == every_poses.shape == (periods + (time_constant > 0.0), 3)
    np.testing.assert_allclose(poses, every_poses, rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(jacobian, every_jacobian @ np.kron(through, np.eye(2)), rtol=0.0, atol=1e-12)
    # ... and the model's derivative (central differences).
    step = 1e-6
    for index in rng.choice(knots.size, 5, replace=False):
        moved = knots.ravel().copy()
        moved[index] += step
        ahead = PlanModel(periods, base, layout)(moved, velocity)[0]
        moved[index] -= 2 * step
        behind = PlanModel(periods, base, layout)(moved, velocity)[0]
        np.testing.assert_allclose(jacobian[..., index], (ahead - behind) / (2 * step), rtol=0.0, atol=1e-7)


def test_model_evaluations_share_their_buffers_and_calls_return_copies():
    model = PlanModel(20, BaseModel(0.05, 0.0))
    first, _ = model(np.full((20, 2), 0.5), np.zeros(2))
    view, _ = model.evaluate(np.full((20, 2), 0.2), np.zeros(2))
    assert not np.array_equal(first, view)
    model.evaluate(np.full((20, 2), 0.5), np.zeros(2))
    np.testing.assert_array_equal(first, view)      # the view shows the latest evaluation


def wall_problems(name: str, dt: float, count: int) -> tuple[MPCSafetyFilter, list[sqp.PlanNLP]]:
    """The NLPs an MPC solves with a wall just beside its turning path (issue 18's closed loop)."""
    robot = preset(name)
    safety = MPCSafetyFilter(robot, dt, budget=math.inf)
    problems: list[sqp.PlanNLP] = []
    solve = safety.backend.solve

    def recording(nlp, *args, **kwargs):
        problems.append(nlp)
        return solve(nlp, *args, **kwargs)

    safety.backend.solve = recording    # type: ignore[method-assign]
    rng = np.random.default_rng(3)
    scene = Scene.of(Segment((0.16, robot.radius + 0.12), (4.0, robot.radius + 0.12)))
    pose, velocity = Pose2D(), np.zeros(2)
    nominal = np.array([robot.v_max, robot.omega_max])
    while len(problems) < count:
        scan = synthetic_scan(robot, scene, pose, noise_std=robot.lidar.noise_std, rng=rng)
        result = safety.filter(nominal, scan, velocity=velocity)
        velocity = robot.clip(result.u, velocity, dt)
        pose = unicycle_step(pose, float(velocity[0]), float(velocity[1]), dt)
    safety.backend.solve = solve        # type: ignore[method-assign]
    return safety, problems


def test_the_secants_jump_ends_a_geometric_series_and_halves_a_cycle():
    """Anderson's acceleration with a memory of one on the two kinds of slow iterations of the SQP."""
    rng = np.random.default_rng(11)
    direction, start = rng.normal(size=6), rng.normal(size=6)
    # Steps d, r d, r^2 d, ... from start: the series ends at start + d / (1 - r). After two steps (the last
    # answer start + d + r d), the jump is the rest of the series.
    ratio = 0.8
    last_answer = start + direction
    answer = last_answer + ratio * direction
    jump = sqp._secant_jump(ratio * direction, direction, answer - last_answer)
    np.testing.assert_allclose(answer + jump, start + direction / (1.0 - ratio), rtol=0.0, atol=1e-12)
    # A cycle: from a to b (step b - a), then back from b to a (step a - b): the jump from a lands halfway.
    a, b = start, start + direction
    jump = sqp._secant_jump(a - b, b - a, a - b)
    np.testing.assert_allclose(a + jump, 0.5 * (a + b), rtol=0.0, atol=1e-12)
    # Nearly stalled steps (ratio 0.999: the series' end 1000 steps away) jump no farther than MAX_JUMP steps.
    jump = sqp._secant_jump(0.999 * direction, direction, 0.999 * direction)
    assert np.max(np.abs(jump)) == pytest.approx(sqp.MAX_JUMP * 0.999 * np.max(np.abs(direction)), rel=1e-12)
    np.testing.assert_allclose(jump / np.linalg.norm(jump), direction / np.linalg.norm(direction), atol=1e-12)
    # The same step twice: no secant, no jump.
    assert not np.any(sqp._secant_jump(direction, direction, direction))


def test_no_solve_of_the_puzzlebots_wall_loop_goes_round_to_the_iteration_limit():
    """Issue 18's closed loop (a wall beside the path, the nominal turning into it at full speed, a base ramping at
    its limits) on the Puzzlebot at dt 0.05, no compute budget. The extrapolation this replaced jumped along the
    last step by its geometric series, from a ratio measured on two steps: on two of these solves the jump
    overshot, the next step came back four times as large, shrank, was extrapolated again, and so on to the limit
    of 30 iterations (a command held from the last iterate, 7-15 ms). The secant through the last two iterates
    lands near the fixed point: 11 iterations at most when this was written."""
    from benchmarks.filter_latency import wall_episodes

    robot, dt = preset("puzzlebot"), 0.05
    outcomes: list[sqp.NLPOutcome] = []

    def make() -> MPCSafetyFilter:
        safety = MPCSafetyFilter(robot, dt, budget=math.inf)
        solve = safety.backend.solve

        def recording(nlp, *args, **kwargs):
            outcome = solve(nlp, *args, **kwargs)
            outcomes.append(outcome)
            return outcome

        safety.backend.solve = recording    # type: ignore[method-assign]
        return safety

    wall_episodes(robot, dt, make, 0, lambda scan, seconds, result: None)
    assert len(outcomes) > 200
    assert {outcome.status for outcome in outcomes} == {"converged"}
    assert max(outcome.iterations for outcome in outcomes) <= 15


def test_the_secant_takes_the_slack_problems_of_a_fast_slow_braking_robot_in_fewer_iterations():
    """The falsifier's fast, slow-braking robot (tests/data/falsifier_robots.json: a wall seen too late to brake
    clear of it, one slack for every row of 0.12 m): with full steps its SQP goes round cycles of steps of
    0.4-1.2 m/s turning back and forth (16 of the episode's 162 solves at the limit of 30 iterations on the tree
    before). Every NLP of the episode solved again with full steps and with the secant's jumps: the jumps take
    fewer iterations in all (1172 against 1400 when this was written), and every answer they converge to is a
    fixed point of the SQP (solved again from it, it stops at its first step)."""
    from benchmarks.sqp_iterations import scene_problems

    backend, problems = scene_problems("slack", "fast_slow_braking", 0, 0)
    assert len(problems) > 100
    jumping = [backend.solve(nlp) for nlp in problems]
    again = [backend.solve(nlp._replace(start=outcome.knots)) for nlp, outcome in zip(problems, jumping, strict=True)
             if outcome.status == "converged"]
    backend.secant = False
    full = [backend.solve(nlp) for nlp in problems]
    assert sum(outcome.iterations for outcome in jumping) < 0.9 * sum(outcome.iterations for outcome in full)
    assert len(again) >= 0.9 * len(problems)
    assert all(outcome.status == "converged" and outcome.iterations == 1 for outcome in again)


@pytest.mark.parametrize("name, dt", [("rosbot", 0.05), ("m2wr", 0.02)])
def test_the_secants_jumps_end_where_the_plain_sqp_ends(name, dt):
    safety, problems = wall_problems(name, dt, 40)
    extrapolated = [safety.backend.solve(nlp) for nlp in problems]
    safety.backend.secant = False
    plain = [safety.backend.solve(nlp) for nlp in problems]
    for fast, slow in zip(extrapolated, plain, strict=True):
        assert fast.status == slow.status == "converged"
        assert fast.iterations <= slow.iterations + 1
        # Both stop on a step of 1e-5 while contracting about linearly: a few steps apart at most.
        np.testing.assert_allclose(fast.knots, slow.knots, rtol=0.0, atol=1e-4)
    # ... and it does jump here: fewer iterations in all.
    assert sum(outcome.iterations for outcome in extrapolated) < sum(outcome.iterations for outcome in plain)


def test_a_slack_per_point_changes_nothing_where_no_slack_is_needed_and_relaxes_only_the_point_that_needs_it():
    safety, problems = wall_problems("rosbot", 0.05, 20)
    checked = 0
    for nlp in problems:
        shared = safety.backend.solve(nlp)
        one_group = safety.backend.solve(nlp._replace(slack_groups=np.zeros(nlp.points.shape[0], dtype=np.intp)))
        np.testing.assert_array_equal(one_group.knots, shared.knots)     # one group is the shared slack
        if abs(shared.slack) > 1e-12:
            continue
        split = safety.backend.solve(nlp._replace(slack_groups=np.arange(nlp.points.shape[0])))
        assert np.all(np.abs(split.point_slacks) < 1e-12)
        np.testing.assert_allclose(split.knots, shared.knots, rtol=0.0, atol=1e-6)
        checked += 1
    assert checked >= 15
    # A point inside the planned radius of every knot (it cannot be kept) next to one just clear of the path:
    # one slack lets the plan take from the clear point what the other needs; a slack per point does not.
    nlp = problems[0]
    points = np.array([[0.0, 0.0], [0.0, nlp.radii[0, 0] + 0.05]])
    stuck = nlp._replace(points=points, radii=nlp.radii[:2], relief=np.zeros_like(nlp.radii[:2]),
                         target=np.array([0.0, 3.0]))
    shared, split = (safety.backend.solve(stuck._replace(slack_groups=groups))
                     for groups in (None, np.arange(2)))
    assert shared.slack > 0.0 and split.point_slacks[0] > 0.0 and split.point_slacks[1] == pytest.approx(0.0)


def crowded_problems(count: int) -> tuple[MPCSafetyFilter, list[sqp.PlanNLP]]:
    """The m2wr's wall problems with their points pulled halfway towards the base and a slack per point: most
    points inside the planned radius of most knots, as when the MPC splits its slack beside a wall it is in."""
    safety, problems = wall_problems("m2wr", 0.02, count)
    return safety, [nlp._replace(points=0.5 * nlp.points, slack_groups=np.arange(nlp.points.shape[0]))
                    for nlp in problems]


def test_a_slack_per_point_solves_with_the_slacks_and_rows_it_needs_and_ends_where_every_one_would(monkeypatch):
    """With a slack per point each QP has the slacks of the points with a row in it, and each round adds a point's
    most violated row: the plans are those of QPs with every slack and every violated row added at once (numpy
    rows, the reductions taken out), from QPs a fraction of the size."""
    safety, problems = crowded_problems(12)
    safety.backend.kernels = None
    sizes: dict[str, list[tuple[int, int]]] = {"reduced": [], "every": []}
    solve = safety.backend.qp.solve
    for name in sizes:
        if name == "every":
            monkeypatch.setattr(sqp, "_most_missed_per_point", lambda missed, linearised: missed)
            monkeypatch.setattr(sqp._Variables, "select", lambda self, row_points: (None, self.slack_column))
        monkeypatch.setattr(safety.backend.qp, "solve",
                            lambda qp, name=name: sizes[name].append(qp.G.shape) or solve(qp))
        outcomes = [safety.backend.solve(nlp) for nlp in problems]
        if name == "reduced":
            reduced = outcomes
    for fast, full in zip(reduced, outcomes, strict=True):
        assert fast.status == full.status == "converged"
        np.testing.assert_allclose(fast.knots, full.knots, rtol=0.0, atol=1e-9)
        np.testing.assert_allclose(fast.point_slacks, full.point_slacks, rtol=0.0, atol=1e-9)
    assert max(rows for rows, _ in sizes["every"]) > 500
    assert max(rows for rows, _ in sizes["reduced"]) < 0.3 * max(rows for rows, _ in sizes["every"])
    assert min(columns for _, columns in sizes["reduced"]) < min(columns for _, columns in sizes["every"])


def test_the_compiled_sqp_plans_the_crowded_problems_as_numpy_does():
    safety, problems = crowded_problems(12)
    assert safety.backend.kernels is not None
    compiled = [safety.backend.solve(nlp) for nlp in problems]
    safety.backend.kernels = None
    for fast, reference in zip(compiled, [safety.backend.solve(nlp) for nlp in problems], strict=True):
        assert fast.status == reference.status == "converged"
        np.testing.assert_allclose(fast.knots, reference.knots, rtol=0.0, atol=1e-9)
