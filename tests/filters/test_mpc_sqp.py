"""The direct SQP's model and steps: the knots' model is the every-period model through ``B``, its
Jacobian is the model's derivative, and extrapolating contracting steps leaves the answers where the
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


@pytest.mark.parametrize("name, dt", [("rosbot", 0.05), ("m2wr", 0.02)])
def test_extrapolating_contracting_steps_ends_where_the_plain_sqp_ends(name, dt, monkeypatch):
    safety, problems = wall_problems(name, dt, 40)
    extrapolated = [safety.backend.solve(nlp) for nlp in problems]
    monkeypatch.setattr(sqp, "EXTRAPOLATION_WINDOW", 0.0)
    plain = [safety.backend.solve(nlp) for nlp in problems]
    for fast, slow in zip(extrapolated, plain, strict=True):
        assert fast.status == slow.status == "converged"
        assert fast.iterations <= slow.iterations + 1
        # Both stop on a step of 1e-5 while contracting about linearly: a few steps apart at most.
        np.testing.assert_allclose(fast.knots, slow.knots, rtol=0.0, atol=1e-4)
    # ... and it does extrapolate here: fewer iterations in all.
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
