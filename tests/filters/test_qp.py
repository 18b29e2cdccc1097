"""The QP back-ends on problems recorded from the filters."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from safenav.filters.qp import QPData, make_backend

DATA = Path(__file__).resolve().parents[1] / "data"


def recorded_cycling_qp() -> QPData:
    """An SQP step of the MPC for the m2wr stopped in front of obstacles (goal_m2wr, seed 1, t = 29.15 s).

    At DAQP's feasibility tolerance of 1e-10 its active-set iteration cycles on this problem
    (exit flag -2): the filter fell back to its last plan twice in that episode.
    """
    data = np.load(DATA / "daqp_cycling.npz")
    return QPData(data["P"], data["q"], data["G"], data["h"], data["lb"], data["ub"],
                  data["h_lower"] if data["h_lower"].size else None)


def test_the_recorded_problem_makes_plain_daqp_cycle():
    daqp = pytest.importorskip("daqp")
    qp = recorded_cycling_qp()
    upper = np.concatenate((qp.ub, qp.h))
    lower = np.concatenate((qp.lb, qp.h_lower))
    sense = np.where(lower == upper, 5, 0).astype(np.int32)
    *_, exitflag, _ = daqp.solve(qp.P.copy(), qp.q.copy(), qp.G.copy(), upper, lower, sense, primal_tol=1e-10)
    assert exitflag == -2


def test_direct_daqp_solves_a_problem_it_first_cycles_on():
    qp = recorded_cycling_qp()
    outcome = make_backend("daqp").solve(qp)
    assert outcome.x is not None, outcome.status
    x = outcome.x
    assert np.all(qp.G @ x <= qp.h + 1e-8) and np.all(qp.G @ x >= qp.h_lower - 1e-8)
    assert np.all(x >= qp.lb - 1e-8) and np.all(x <= qp.ub + 1e-8)
    reference = make_backend("quadprog").solve(qp) if "quadprog" in _installed() else None
    if reference is not None and reference.x is not None:
        cost = 0.5 * x @ qp.P @ x + qp.q @ x
        best = 0.5 * reference.x @ qp.P @ reference.x + qp.q @ reference.x
        assert cost <= best + 1e-6 * max(1.0, abs(best))


def test_direct_daqp_solves_a_problem_it_cycles_on_from_cold_at_a_tight_tolerance():
    """An SQP step of the MPC for the m2wr standing at its margin in the dead end (dead_end_m2wr, seed 2,
    t = 22.75 s): DAQP cycles on it from a cold start at 1e-10 and at 1e-9 (the filter fell back to its last
    plan, and the slow closed-loop test of that cell failed on it); at 1e-8 it solves."""
    data = np.load(DATA / "daqp_cycling_cold.npz")
    qp = QPData(data["P"], data["q"], data["G"], data["h"], data["lb"], data["ub"],
                data["h_lower"] if data["h_lower"].size else None)
    daqp = pytest.importorskip("daqp")
    upper, lower = np.concatenate((qp.ub, qp.h)), np.concatenate((qp.lb, qp.h_lower))
    sense = np.where(lower == upper, 5, 0).astype(np.int32)
    for tolerance in (1e-10, 1e-9):
        *_, exitflag, _ = daqp.solve(qp.P.copy(), qp.q.copy(), qp.G.copy(), upper, lower, sense.copy(),
                                     primal_tol=tolerance)
        assert exitflag == -2, (tolerance, exitflag)
    outcome = make_backend("daqp").solve(qp)
    assert outcome.x is not None, outcome.status
    x = outcome.x
    assert np.all(qp.G @ x <= qp.h + 1e-8) and np.all(qp.G @ x >= qp.h_lower - 1e-8)
    assert np.all(x >= qp.lb - 1e-8) and np.all(x <= qp.ub + 1e-8)


def _installed() -> tuple[str, ...]:
    from safenav.filters import available_solvers

    return tuple(available_solvers())


def test_direct_daqp_recovers_from_a_warm_start_that_runs_out_of_iterations():
    """An SQP step of the MPC for the m2wr in the dead end (dead_end_m2wr, seed 0, t = 7.1 s): warm-started
    from the previous active set DAQP hits its iteration limit (the filter fell back once); from cold it
    solves in about 50 iterations."""
    data = np.load(DATA / "daqp_warm_iteration_limit.npz")
    qp = QPData(data["P"], data["q"], data["G"], data["h"], data["lb"], data["ub"],
                data["h_lower"] if data["h_lower"].size else None, data["guess"])
    outcome = make_backend("daqp").solve(qp)
    assert outcome.x is not None, outcome.status
    x = outcome.x
    assert np.all(qp.G @ x <= qp.h + 1e-8) and np.all(x >= qp.lb - 1e-8) and np.all(x <= qp.ub + 1e-8)
    if qp.h_lower is not None:
        assert np.all(qp.G @ x >= qp.h_lower - 1e-8)
