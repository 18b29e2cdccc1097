"""QP back-ends for the filters: any qpsolvers solver by name, DAQP called directly, and OSQP with a
persistent workspace. One interface serves both filters: the CBF solves one QP per call, the MPC one
QP per iteration of its sequential quadratic programming (:mod:`safenav.filters.mpc.sqp`).

Every back-end takes a :class:`QPData` (``min 1/2 x'Px + q'x`` s.t. ``h_lower <= Gx <= h``,
``lb <= x <= ub``, the same QP as :meth:`QPData.problem`'s :class:`qpsolvers.Problem`)
and returns the solution vector or ``None``. The caller checks the answer against
the constraints itself: qpsolvers returns ``None`` on failure, and OSQP can report
"solved" at low accuracy.
"""

from __future__ import annotations

import importlib.util
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, NamedTuple, Protocol

import numpy as np

from safenav._kernels import plain
from safenav.errors import UnknownName

if TYPE_CHECKING:
    import qpsolvers

# qpsolvers and scipy.sparse are imported where used: the default back-end (DAQP, called directly) needs neither,
# and together they are half a second of a robot process's start (benchmarks.filter_latency --startup).

__all__ = [
    "DirectDAQP",
    "PersistentOSQP",
    "QPBackend",
    "QPData",
    "QPOutcome",
    "QpsolversBackend",
    "available_solvers",
    "make_backend",
    "solver_installed",
]

#: Solver options that make answers feasible to well below the filters' verification tolerance.
TIGHT_OPTIONS: dict[str, dict[str, float]] = {"daqp": {"primal_tol": 1e-10}, "proxqp": {"eps_abs": 1e-10}}

#: Row count a persistent OSQP workspace starts with; it grows (set-up again) when exceeded.
OSQP_INITIAL_CAPACITY = 64
#: DAQP's constraint-type flags (see ``daqp.solve``): active (a warm start), at the lower bound, equality.
DAQP_ACTIVE, DAQP_LOWER, DAQP_EQUALITY = 1, 2, 5
#: DAQP's exit flags for a detected cycle and for the iteration limit (both retried from cold).
DAQP_CYCLING, DAQP_ITERATION_LIMIT = -2, -4
#: DAQP's flag for each warm-start entry of :attr:`QPData.guess` (-1, 0, 1), indexed by the entry plus one.
_GUESS_SENSE = np.array([DAQP_ACTIVE | DAQP_LOWER, 0, DAQP_ACTIVE], dtype=np.int32)
_NO_BOUNDS, _NO_GUESS = np.zeros(0), np.zeros(0, dtype=np.int8)   # no lower bounds on the rows, no warm start


def _int8(array: np.ndarray) -> np.ndarray:
    """A warm start as the kernels take it (C-contiguous, writable int8; another integer type by its signs)."""
    return plain(array if array.dtype == np.int8 else np.sign(array), np.int8)


class QPOutcome(NamedTuple):
    """What a back-end returned."""

    x: np.ndarray | None
    """The solution, or ``None`` when the solver reports failure."""
    status: str
    """The solver's own status word."""
    solve_time: float
    """Wall time of the solve [s]."""
    active: np.ndarray | None = None
    """Which constraints hold with a nonzero multiplier, simple bounds first, then the rows: 1 at
    the upper bound, -1 at the lower bound, 0 inactive (``None`` when the back-end does not say)."""


class QPData(NamedTuple):
    """A QP ``min 1/2 x'Px + q'x`` s.t. ``h_lower <= Gx <= h``, ``lb <= x <= ub`` as plain arrays.

    The filters hand this to their back-end on every call; :meth:`problem` turns it into
    the equivalent :class:`qpsolvers.Problem` for inspection or for qpsolvers back-ends.
    ``h_lower`` (``None``: no lower bound, the CBF's one-sided rows) gives two-sided rows;
    a row with ``h_lower == h`` is an equality. ``guess`` is a warm start of the active set
    in the encoding of :attr:`QPOutcome.active` (a solve of a similar QP); back-ends that
    cannot use one ignore it, and it never changes the answer, only the work.
    """

    P: np.ndarray
    q: np.ndarray
    G: np.ndarray
    h: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    h_lower: np.ndarray | None = None
    guess: np.ndarray | None = None

    def one_sided(self) -> tuple[np.ndarray, np.ndarray]:
        """The rows as ``G' x <= h'`` only: each finite lower bound becomes a row ``-G x <= -h_lower``."""
        if self.h_lower is None:
            return self.G, self.h
        bounded = np.isfinite(self.h_lower)
        return np.vstack((self.G, -self.G[bounded])), np.concatenate((self.h, -self.h_lower[bounded]))

    def problem(self) -> qpsolvers.Problem:
        """The same QP as a :class:`qpsolvers.Problem`.

        Two-sided rows become two one-sided ones, and equalities (rows or bounds with equal
        limits) the rows ``A x = b``: active-set solvers such as quadprog fail on an equality
        written as two opposite inequalities.
        """
        import qpsolvers

        if self.h_lower is None and not np.any(self.lb == self.ub):
            return qpsolvers.Problem(self.P, self.q, self.G, self.h, lb=self.lb, ub=self.ub)
        equal_rows = np.zeros(self.h.size, dtype=bool) if self.h_lower is None else self.h_lower == self.h
        fixed = self.lb == self.ub
        rest = self._replace(G=self.G[~equal_rows], h=self.h[~equal_rows],
                             h_lower=None if self.h_lower is None else self.h_lower[~equal_rows])
        G, h = rest.one_sided()
        A = np.vstack((self.G[equal_rows], np.eye(self.lb.size)[fixed]))
        b = np.concatenate((self.h[equal_rows], self.lb[fixed]))
        lb, ub = np.where(fixed, -np.inf, self.lb), np.where(fixed, np.inf, self.ub)
        return qpsolvers.Problem(self.P, self.q, G if G.size else None, h if h.size else None,
                                 A if A.size else None, b if b.size else None, lb=lb, ub=ub)


class QPBackend(Protocol):
    """A QP solver the filters can call repeatedly."""

    name: str
    direct_rows: int
    """Up to this many rows the filters pass every candidate row at once; above it they use
    a working set with constraint generation (first-order solvers prefer small QPs)."""

    def solve(self, qp: QPData) -> QPOutcome:
        """Solve ``qp``; ``x`` is ``None`` when the solver reports failure."""


def available_solvers() -> list[str]:
    """Names accepted by :func:`make_backend` on this machine."""
    import qpsolvers

    return sorted(set(qpsolvers.available_solvers))


def _own_backend(name: Any) -> bool:
    """Whether ``name`` is a solver :func:`make_backend` calls through its own API, and it is installed (found without
    loading qpsolvers)."""
    return isinstance(name, str) and name in _OWN_BACKENDS and importlib.util.find_spec(name) is not None


def solver_installed(name: str) -> bool:
    """Whether :func:`make_backend` accepts ``name`` (a solver name, or ``"qpsolvers:<name>"``); the solvers it
    calls directly are found without loading qpsolvers."""
    if _own_backend(name):
        return True
    known = available_solvers()
    return name in known or (name.startswith("qpsolvers:") and name.partition(":")[2] in known)


class QpsolversBackend:
    """A solver called through :func:`qpsolvers.solve_problem`, set up on every call.

    Args:
        name: a solver in :data:`qpsolvers.available_solvers` (``"daqp"``, ``"quadprog"``, ...).
        options: keyword options passed to the solver.
    """

    direct_rows = 512

    def __init__(self, name: str, **options: float | int | bool) -> None:
        self.name = name
        self.options = options

    def solve(self, qp: QPData) -> QPOutcome:
        import qpsolvers

        start = time.perf_counter()
        try:
            solution = qpsolvers.solve_problem(qp.problem(), solver=self.name, **self.options)
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
    left unbounded. One workspace is kept per number of variables (the filters' QPs
    with and without slack); a problem with more rows than the capacity sets that
    workspace up again with twice the capacity.

    The filters' QPs have many nearly parallel rows (the points of a wall), on which
    ADMM needs hundreds to thousands of iterations to reach the accuracy the filters
    verify (1e-6): OSQP gives the same answers as the active-set solvers but is one to
    two orders of magnitude slower (see BENCHMARKS.md), so the filters hand it a small
    working set and generate constraints (:attr:`direct_rows` = 0).

    Args:
        eps: absolute and relative tolerance [problem units].
        max_iter: iteration limit per solve.
    """

    name = "osqp"
    direct_rows = 0

    def __init__(self, eps: float = 1e-9, max_iter: int = 10000) -> None:
        import osqp  # imported here: only this back-end needs it

        self._osqp = osqp
        # No polishing: at this tolerance it adds nothing the caller's check needs, and OSQP 1.x
        # prints "Polishing not needed" on stdout even with verbose=False.
        self.settings = dict(eps_abs=eps, eps_rel=eps, polishing=False, verbose=False, max_iter=max_iter,
                             warm_starting=True)
        self._workspaces: dict[int, tuple[Any, int]] = {}
        self.setups = 0
        """How many workspaces were set up (one per problem size, plus one per growth)."""

    def _setup(self, n_vars: int, capacity: int) -> Any:
        rows = n_vars + capacity
        # Column j holds the identity entry (row j) then all capacity rows of G: a dense pattern.
        indices = np.concatenate([np.concatenate(([j], np.arange(n_vars, rows))) for j in range(n_vars)])
        indptr = np.arange(0, (capacity + 1) * n_vars + 1, capacity + 1)
        data = np.zeros(indices.size)
        data[indptr[:-1]] = 1.0
        import scipy.sparse as sp

        matrix = sp.csc_matrix((data, indices, indptr), shape=(rows, n_vars))
        solver = self._osqp.OSQP()
        solver.setup(P=sp.eye(n_vars, format="csc"), q=np.zeros(n_vars), A=matrix,
                     l=np.full(rows, -np.inf), u=np.full(rows, np.inf), **self.settings)
        self._workspaces[n_vars] = (solver, capacity)
        self.setups += 1
        return solver

    def solve(self, qp: QPData) -> QPOutcome:
        start = time.perf_counter()
        P = qp.P
        if np.count_nonzero(P - np.diag(np.diag(P))):
            raise ValueError("PersistentOSQP handles diagonal cost matrices only")
        n_vars = P.shape[0]
        G, h = qp.G, qp.h
        m = G.shape[0]
        solver, capacity = self._workspaces.get(n_vars, (None, 0))
        if solver is None or m > capacity:
            capacity = max(OSQP_INITIAL_CAPACITY, capacity)
            while capacity < m:
                capacity *= 2
            solver = self._setup(n_vars, capacity)
        block = np.zeros((capacity, n_vars))
        block[:m] = G
        Ax = np.column_stack((np.ones(n_vars), block.T)).ravel()
        lower = np.full(n_vars + capacity, -np.inf)
        upper = np.full(n_vars + capacity, np.inf)
        lower[:n_vars] = qp.lb
        upper[:n_vars] = qp.ub
        upper[n_vars:n_vars + m] = h
        if qp.h_lower is not None:
            lower[n_vars:n_vars + m] = qp.h_lower
        solver.update(q=qp.q, l=lower, u=upper, Px=np.diag(P).copy(), Ax=Ax)
        result = solver.solve(raise_error=False)
        if not self._acceptable(result, qp):
            # A warm start from an unrelated previous problem can stall ADMM: start cold, allow longer.
            solver.warm_start(x=np.zeros(n_vars), y=np.zeros(n_vars + capacity))
            solver.update_settings(max_iter=10 * self.settings["max_iter"])
            result = solver.solve(raise_error=False)
            solver.update_settings(max_iter=self.settings["max_iter"])
        elapsed = time.perf_counter() - start
        status = str(result.info.status)
        x = np.asarray(result.x, dtype=float)
        # "solved inaccurate" is returned too: the filter's own verification decides.
        usable = result.info.status_val in (1, 2) and x.shape == (n_vars,) and np.all(np.isfinite(x))
        return QPOutcome(x if usable else None, status, elapsed)

    @staticmethod
    def _acceptable(result: Any, qp: QPData, tolerance: float = 1e-8) -> bool:
        """Solved, finite, and inside the rows and bounds to ``tolerance``."""
        x = np.asarray(result.x, dtype=float)
        if result.info.status_val != 1 or x.shape != qp.q.shape or not np.all(np.isfinite(x)):
            return False
        G, h = qp.one_sided()
        return bool(np.all(G @ x <= h + tolerance) and np.all(x >= qp.lb - tolerance)
                    and np.all(x <= qp.ub + tolerance))


class DirectDAQP:
    """DAQP called through its own Python API, skipping qpsolvers' per-call conversions.

    Same answers as ``QpsolversBackend("daqp")`` (the latency benchmark compares both);
    used by default because the filters call it at every control step. Two-sided rows go
    to DAQP as they are (one row, not two), and rows with equal bounds as equalities.

    Args:
        primal_tol: feasibility tolerance of the active-set iterations.
        iter_limit: largest number of active-set iterations per solve.
    """

    name = "daqp"
    direct_rows = 512

    def __init__(self, primal_tol: float = 1e-10, iter_limit: int = 2000) -> None:
        import daqp  # imported here: only this back-end needs it

        self._solve = daqp.solve
        self.primal_tol = primal_tol
        self.iter_limit = iter_limit
        #: The compiled kernels (:func:`safenav.filters.kernels.load`) that build DAQP's arrays and read its answer
        #: (``daqp_arrays``, ``daqp_answer``), or ``None``: numpy (the reference; the same arrays). The filters set
        #: their own.
        self.kernels: Any = None

    def solve(self, qp: QPData) -> QPOutcome:
        start = time.perf_counter()
        if self.kernels is not None:
            upper, lower, sense = self.kernels.daqp_arrays(
                plain(qp.lb), plain(qp.ub), plain(qp.h), _NO_BOUNDS if qp.h_lower is None else plain(qp.h_lower),
                _NO_GUESS if qp.guess is None else _int8(qp.guess), _GUESS_SENSE, DAQP_EQUALITY)
        else:
            upper, lower, sense = self._arrays(qp)
        # DAQP takes writable C-ordered float arrays (it copies nothing); copy only what is not.
        P, q, G = plain(qp.P), plain(qp.q), plain(qp.G)
        x, _, exitflag, info = self._solve(P, q, G, upper, lower, sense, primal_tol=self.primal_tol,
                                           iter_limit=self.iter_limit)
        if exitflag in (DAQP_CYCLING, DAQP_ITERATION_LIMIT):
            # Near-degenerate vertices (many rows through one point, e.g. a stopped base) can make the
            # active-set iteration cycle, or a warm start wander, at a feasibility tolerance near
            # round-off: solve again from a cold start, then with the tolerance ten and a hundred times
            # looser (1e-8 by default: still a hundred times below every filter's own check of the answer;
            # the m2wr's MPC standing at its margin cycled at 1e-10 and 1e-9 even from cold).
            cold = np.where(sense == DAQP_EQUALITY, DAQP_EQUALITY, 0).astype(np.int32)
            for tolerance in (self.primal_tol, 10.0 * self.primal_tol, 100.0 * self.primal_tol):
                x, _, exitflag, info = self._solve(P, q, G, upper, lower, cold.copy(), primal_tol=tolerance,
                                                   iter_limit=self.iter_limit)
                if exitflag in (1, 2):
                    break
        elapsed = time.perf_counter() - start
        # exitflag 1: optimal; 2: optimal with soft constraints; negative: infeasible, cycling, ...
        if exitflag not in (1, 2):
            return QPOutcome(None, f"exitflag {exitflag}", elapsed)
        if self.kernels is not None:
            finite, active = self.kernels.daqp_answer(plain(x), plain(info["lam"]))
        else:
            finite = bool(np.isfinite(x).all())
            active = np.sign(info["lam"]).astype(np.int8) if finite else None
        if not finite:
            return QPOutcome(None, f"exitflag {exitflag}", elapsed)
        return QPOutcome(x, "optimal", elapsed, active)

    @staticmethod
    def _arrays(qp: QPData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """DAQP's upper and lower bounds (the simple bounds, then the rows; +-1e30 for infinity) and their flags."""
        n_vars = qp.lb.size
        # Simple bounds first, then the rows (DAQP's convention); +-1e30 stands for infinity. Filled in
        # place, without temporaries: a control call's QPs are small, and building these arrays cost
        # about half of DAQP's own time.
        upper = np.empty(n_vars + qp.h.size)
        upper[:n_vars] = qp.ub
        upper[n_vars:] = qp.h
        np.minimum(upper, 1e30, out=upper)
        lower = np.empty_like(upper)
        lower[:n_vars] = qp.lb
        lower[n_vars:] = -1e30 if qp.h_lower is None else qp.h_lower
        np.maximum(lower, -1e30, out=lower)
        if qp.guess is None:
            sense = np.zeros(upper.size, dtype=np.int32)
        else:   # DAQP's flags: 1 active (warm start), 2 at the lower bound
            sense = _GUESS_SENSE[np.sign(qp.guess).astype(np.intp) + 1]
        equal = lower == upper
        if equal.any():
            sense[equal] = DAQP_EQUALITY
        return upper, lower, sense


def make_backend(name: str) -> QPBackend:
    """The back-end for a solver name.

    ``"osqp"`` gets a persistent workspace (:class:`PersistentOSQP`), ``"daqp"`` is called
    directly (:class:`DirectDAQP`), every other installed qpsolvers solver goes through
    :func:`qpsolvers.solve_problem` (:class:`QpsolversBackend`); ``"qpsolvers:daqp"``
    forces the qpsolvers route for any solver.

    Raises:
        UnknownName: the solver is not installed (the message lists the installed ones).
    """
    if _own_backend(name):   # no qpsolvers to load
        return _OWN_BACKENDS[name]()
    known = available_solvers()
    if isinstance(name, str) and name.startswith("qpsolvers:") and name[len("qpsolvers:"):] in known:
        solver = name[len("qpsolvers:"):]
        return QpsolversBackend(solver, **TIGHT_OPTIONS.get(solver, {}))
    if name not in known:
        raise UnknownName("QP solver", name, known,
                          hint=f"install it with: pip install qpsolvers[{name}]" if isinstance(name, str) else "")
    # The filters verify answers to 1e-6: ask the active-set solvers for tighter feasibility.
    return QpsolversBackend(name, **TIGHT_OPTIONS.get(name, {}))


_OWN_BACKENDS: dict[str, Callable[[], QPBackend]] = {"osqp": PersistentOSQP, "daqp": DirectDAQP}
"""The solvers :func:`make_backend` calls through their own API (no qpsolvers)."""
