"""The filters' compute budget: when a call must end, and when its solver must stop to let it.

A call's budget counts from the call's start (the perception, the MPC's reference's call, the
solve, the verification of the answer and the result). The solver works in *steps* (an SQP
iteration, or one more round of rows for its QP; for the CBF, each QP), checking the clock
before each: it begins a
step only when the step can end before the solver's deadline, taking the step to last as
long as the longest step of the filter's last :data:`TAIL_WINDOW` solving calls or of this
call so far (:attr:`CallBudget.step`). The solver's deadline is the call's end less a
*reserve* for what follows the solver's last return: verifying its answer (or, when it gave
up, the stored plan) and building the result, as long as the longest that took in those
calls. Both estimates from earlier calls are at most :data:`RESERVE_SHARE` of the budget, so a
preemption in one call does not make the solver of every later call give up early (the
estimates recover as the window moves on). Until a step, or a tail, has been measured (a new
filter's first solving calls), it is taken to last that share.

So a call ends within its budget unless what comes before the solver already takes it (only
the solve is cut short), one of its steps takes longer than that estimate (a step longer than
every step before it, or longer than the share), or its tail longer than the reserve (a tail
longer than every tail before it, or than the share) -- the first solving calls of a new filter
included.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable

__all__ = ["RESERVE_SHARE", "TAIL_WINDOW", "CallBudget", "StepClock"]

TAIL_WINDOW = 32
"""Solving calls whose longest steps and tails (the solver's last return to the call's end) the estimates cover."""
RESERVE_SHARE = 0.25
"""The largest share of the budget each estimate from earlier calls (a step, the reserve) takes."""


class CallBudget:
    """One filter's compute budget per call [s], measured with ``clock``.

    Args:
        budget: the compute budget of one call [s] (``math.inf``: none).
        clock: the clock the budget is measured with [s].
    """

    def __init__(self, budget: float, clock: Callable[[], float]) -> None:
        self.budget = float(budget)
        self.clock = clock
        self.start: float | None = None
        """When the current call began [s] (``None`` between calls)."""
        self._returned: float | None = None
        # Each estimate from earlier calls: at most, and until one is measured, RESERVE_SHARE of the budget.
        self._share = RESERVE_SHARE * self.budget if math.isfinite(self.budget) else 0.0
        self._recent = 0.0      # the longest step of the recent calls
        self._longest = 0.0     # the longest step of the current call
        self._steps: deque[float] = deque(maxlen=TAIL_WINDOW)
        self._tails: deque[float] = deque(maxlen=TAIL_WINDOW)

    def begin(self) -> None:
        """A call begins now."""
        self.start, self._returned, self._longest = self.clock(), None, 0.0
        self._recent = min(max(self._steps, default=self._share), self._share)

    def end(self) -> None:
        """The call ends now: if the solver ran, the time since its last return is kept, and its longest
        step if it began one."""
        if self._returned is not None:
            self._tails.append(max(0.0, self.clock() - self._returned))
            if self._longest > 0.0:
                self._steps.append(self._longest)
        self.start, self._returned = None, None

    @property
    def step(self) -> float:
        """How long the solver's next step is taken to last [s]: the longest of the recent calls' (at most,
        and until one is measured, :data:`RESERVE_SHARE` of the budget) or of the current call so far."""
        return max(self._recent, self._longest)

    @property
    def reserve(self) -> float:
        """Time kept after the solver's last return for the verification and the result [s]: the longest
        such time of the recent calls (at most, and until one is measured, :data:`RESERVE_SHARE` of the budget)."""
        return min(max(self._tails, default=self._share), self._share)

    @property
    def deadline(self) -> float:
        """When the current call must end [s] (outside a call: ``budget`` from now)."""
        return (self.start if self.start is not None else self.clock()) + self.budget

    def solver_deadline(self) -> float:
        """When the solver's last step must have ended [s]: :attr:`deadline` less :attr:`reserve`."""
        return self.deadline - self.reserve if math.isfinite(self.budget) else math.inf

    def spent(self) -> float:
        """Time since the call began [s]."""
        return self.clock() - (self.start if self.start is not None else self.clock())

    def returned(self, longest_step: float) -> None:
        """The solver returned now; its longest step took ``longest_step`` [s] (measured, not estimated;
        0 when it began none)."""
        self._longest = max(self._longest, float(longest_step))
        self._returned = self.clock()


class StepClock:
    """A solver's view of its deadline: whether the next step can still end before it.

    Args:
        deadline: when the solver's last step must have ended [s].
        clock: the clock [s].
        step: how long a step is taken to last before one of this solve has been timed [s].
    """

    __slots__ = ("_checked", "_running", "clock", "deadline", "longest", "step")

    def __init__(self, deadline: float, clock: Callable[[], float], step: float = 0.0) -> None:
        self.deadline, self.clock, self.step = deadline, clock, float(step)
        self.longest = 0.0
        """The longest step of this solve so far [s]."""
        self._checked: float | None = None
        self._running = False   # whether a step was begun at the last check

    def late(self) -> bool:
        """Checked before each step: ``True`` when it would end after the deadline, lasting the longer of
        ``step`` and :attr:`longest`."""
        now = self.clock()
        if self._running:
            self.longest = max(self.longest, now - self._checked)
        self._checked = now
        self._running = now + max(self.step, self.longest) <= self.deadline
        return not self._running

    def finished(self) -> float:
        """The solver returns now: :attr:`longest`, counting the step begun at the last check, if one was [s]
        (0 when none was begun)."""
        if self._running:
            self.longest = max(self.longest, self.clock() - self._checked)
            self._running = False
        return self.longest
