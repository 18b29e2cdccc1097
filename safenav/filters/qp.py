"""QP back-ends for the filters: any qpsolvers solver by name, and OSQP with a persistent workspace.

Every back-end takes a :class:`qpsolvers.Problem` (``min 1/2 x'Px + q'x`` s.t.
``Gx <= h``, ``lb <= x <= ub``) and returns the solution vector or ``None``. The
caller checks the answer against the constraints itself: qpsolvers returns
``None`` on failure, and OSQP can report "solved" at low accuracy.
"""

from __future__ import annotations

import time
from typing import NamedTuple, Protocol

import numpy as np
import qpsolvers
import scipy.sparse as sp

from safenav.errors import UnknownName

__all__ = ["QPOutcome", "QPBackend", "QpsolversBackend", "DirectDAQP", "PersistentOSQP", "make_backend",
           "available_solvers"]

#: Solver options that make answers feasible to well below the filters' verification tolerance.
TIGHT_OPTIONS: dict[str, dict[str, float]] = {"daqp": {"primal_tol": 1e-10}, "proxqp": {"eps_abs": 1e-10}}

#: Row count a persistent OSQP workspace starts with; it grows (set-up again) when exceeded.
OSQP_INITIAL_CAPACITY = 128


class QPOutcome(NamedTuple):
    """What a back-end returned."""

    x: np.ndarray | None
    """The solution, or ``None`` when the solver reports failure."""
    status: str
    """The solver's own status word."""
    solve_time: float
    """Wall time of the solve [s]."""


class QPBackend(Protocol):
    """A QP solver the filters can call repeatedly."""

    name: str

    def solve(self, problem: qpsolvers.Problem) -> QPOutcome:
        """Solve ``problem``; ``x`` is ``None`` when the solver reports failure."""


def available_solvers() -> list[str]:
    """Names accepted by :func:`make_backend` on this machine."""
    return sorted(set(qpsolvers.available_solvers))


class QpsolversBackend:
    """A solver called through :func:`qpsolvers.solve_problem`, set up on every call.

    Args:
        name: a solver in :data:`qpsolvers.available_solvers` (``"daqp"``, ``"quadprog"``, ...).
        options: keyword options passed to the solver.
    """

    def __init__(self, name: str, **options: float | int | bool) -> None:
        self.name = name
        self.options = options

    def solve(self, problem: qpsolvers.Problem) -> QPOutcome:
        start = time.perf_counter()
        try:
            solution = qpsolvers.solve_problem(problem, solver=self.name, **self.options)
        except (ValueError, ArithmeticError, qpsolvers.SolverError) as error:  # a back-end that raises on bad input
            return QPOutcome(None, f"error: {error}", time.perf_counter() - start)
        elapsed = time.perf_counter() - start
        if not solution.found or solution.x is None:
            return QPOutcome(None, "not found", elapsed)
        return QPOutcome(np.asarray(solution.x, dtype=float), "found", elapsed)


class PersistentOSQP:
    """OSQP with one workspace kept across calls and updated in place.

    The constraint matrix ``[I; G]`` is stored with a fixed dense sparsity pattern
    (explicit zeros included) of ``capacity`` rows for ``G``, so every call is an
    ``update(q, l, u, Px, Ax)`` followed by a warm-started solve. Unused rows are
    left unbounded. A problem with more rows, or a different number of variables,
    sets the workspace up again with a larger capacity.

    Args:
        eps: absolute and relative tolerance [problem units]; tight, because the caller
            verifies the answer to 1e-7.
        max_iter: iteration limit per solve.
    """

    name = "osqp"

    def __init__(self, eps: float = 1e-9, max_iter: int = 20000) -> None:
        import osqp  # imported here: only this back-end needs it

        self._osqp = osqp
        self.settings = dict(eps_abs=eps, eps_rel=eps, polishing=True, verbose=False, max_iter=max_iter,
                             warm_starting=True)
        self._solver = None
        self._n_vars = -1
        self._capacity = 0
        self.setups = 0
        """How many times a workspace was set up (1 unless the problem outgrew it)."""

    def _setup(self, n_vars: int, capacity: int) -> None:
        rows = n_vars + capacity
        # Column j holds the identity entry (row j) then all capacity rows of G: a dense pattern.
        indices = np.concatenate([np.concatenate(([j], np.arange(n_vars, rows))) for j in range(n_vars)])
        indptr = np.arange(0, (capacity + 1) * n_vars + 1, capacity + 1)
        data = np.zeros(indices.size)
        data[indptr[:-1]] = 1.0
        matrix = sp.csc_matrix((data, indices, indptr), shape=(rows, n_vars))
        self._solver = self._osqp.OSQP()
        self._solver.setup(P=sp.eye(n_vars, format="csc"), q=np.zeros(n_vars), A=matrix,
                           l=np.full(rows, -np.inf), u=np.full(rows, np.inf), **self.settings)
        self._n_vars, self._capacity = n_vars, capacity
        self.setups += 1

    def solve(self, problem: qpsolvers.Problem) -> QPOutcome:
        start = time.perf_counter()
        P = problem.P.toarray() if sp.issparse(problem.P) else np.asarray(problem.P)
        if np.count_nonzero(P - np.diag(np.diag(P))):
            raise ValueError("PersistentOSQP handles diagonal cost matrices only")
        n_vars = P.shape[0]
        G = np.zeros((0, n_vars)) if problem.G is None else np.asarray(problem.G, dtype=float)
        h = np.zeros(0) if problem.h is None else np.asarray(problem.h, dtype=float)
        m = G.shape[0]
        if self._solver is None or n_vars != self._n_vars or m > self._capacity:
            capacity = max(OSQP_INITIAL_CAPACITY, self._capacity)
            while capacity < m:
                capacity *= 2
            self._setup(n_vars, capacity)
        capacity = self._capacity
        block = np.zeros((capacity, n_vars))
        block[:m] = G
        Ax = np.column_stack((np.ones(n_vars), block.T)).ravel()
        lower = np.full(n_vars + capacity, -np.inf)
        upper = np.full(n_vars + capacity, np.inf)
        lower[:n_vars] = -np.inf if problem.lb is None else problem.lb
        upper[:n_vars] = np.inf if problem.ub is None else problem.ub
        upper[n_vars:n_vars + m] = h
        self._solver.update(q=np.asarray(problem.q, dtype=float), l=lower, u=upper, Px=np.diag(P).copy(), Ax=Ax)
        result = self._solver.solve(raise_error=False)
        elapsed = time.perf_counter() - start
        status = str(result.info.status)
        x = np.asarray(result.x, dtype=float)
        # "solved inaccurate" is returned too: the filter's own verification decides.
        usable = result.info.status_val in (1, 2) and x.shape == (n_vars,) and np.all(np.isfinite(x))
        return QPOutcome(x if usable else None, status, elapsed)


class DirectDAQP:
    """DAQP called through its own Python API, skipping qpsolvers' per-call conversions.

    Same answers as ``QpsolversBackend("daqp")`` (the latency benchmark compares both);
    used by default because the filters call it at every control step.

    Args:
        primal_tol: feasibility tolerance of the active-set iterations.
    """

    name = "daqp"

    def __init__(self, primal_tol: float = 1e-10) -> None:
        import daqp  # imported here: only this back-end needs it

        self._solve = daqp.solve
        self.primal_tol = primal_tol

    def solve(self, problem: qpsolvers.Problem) -> QPOutcome:
        start = time.perf_counter()
        n = problem.P.shape[0]
        G = np.zeros((0, n)) if problem.G is None else problem.G
        upper = np.concatenate((np.full(n, np.inf) if problem.ub is None else problem.ub,
                                np.zeros(0) if problem.h is None else problem.h))
        lower = np.concatenate((np.full(n, -np.inf) if problem.lb is None else problem.lb,
                                np.full(G.shape[0], -1e30)))
        np.clip(upper, -1e30, 1e30, out=upper)
        np.clip(lower, -1e30, 1e30, out=lower)
        sense = np.zeros(upper.size, dtype=np.int32)
        x, _, exitflag, _ = self._solve(np.asarray(problem.P, dtype=float), np.asarray(problem.q, dtype=float),
                                        np.ascontiguousarray(G, dtype=float), upper, lower, sense,
                                        primal_tol=self.primal_tol)
        elapsed = time.perf_counter() - start
        # exitflag 1: optimal; 2: optimal with soft constraints; negative: infeasible, cycling, ...
        if exitflag not in (1, 2) or not np.all(np.isfinite(x)):
            return QPOutcome(None, f"exitflag {exitflag}", elapsed)
        return QPOutcome(np.asarray(x, dtype=float), "optimal", elapsed)


def make_backend(name: str) -> QPBackend:
    """The back-end for a solver name.

    ``"osqp"`` gets a persistent workspace (:class:`PersistentOSQP`), ``"daqp"`` is called
    directly (:class:`DirectDAQP`), every other installed qpsolvers solver goes through
    :func:`qpsolvers.solve_problem` (:class:`QpsolversBackend`); ``"qpsolvers:daqp"``
    forces the qpsolvers route for any solver.

    Raises:
        UnknownName: the solver is not installed (the message lists the installed ones).
    """
    known = available_solvers()
    if isinstance(name, str) and name.startswith("qpsolvers:") and name[len("qpsolvers:"):] in known:
        solver = name[len("qpsolvers:"):]
        return QpsolversBackend(solver, **TIGHT_OPTIONS.get(solver, {}))
    if name not in known:
        raise UnknownName("QP solver", name, known,
                          hint=f"install it with: pip install qpsolvers[{name}]" if isinstance(name, str) else "")
    if name == "osqp":
        return PersistentOSQP()
    if name == "daqp":
        return DirectDAQP()
    # The filters verify answers to 1e-6: ask the active-set solvers for tighter feasibility.
    return QpsolversBackend(name, **TIGHT_OPTIONS.get(name, {}))
