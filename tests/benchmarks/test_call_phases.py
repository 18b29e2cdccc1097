"""Where a filter call's time goes (benchmarks/call_phases.py): exclusive times that add up to the call."""

import math

import pytest

from benchmarks import call_phases
from benchmarks.call_phases import COMPILED, PhaseTimer
from safenav.filters import CBFSafetyFilter, SafetyFilter, kernels


class _Clock:
    """A clock that moves only when told."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_each_phase_gets_its_own_time_less_that_of_the_timed_calls_inside_it():
    clock = _Clock()
    timer = PhaseTimer(clock)

    def inner(duration: float) -> None:
        clock.now += duration

    timed_inner = timer.wrap("inner", inner)

    def outer() -> None:
        clock.now += 1.0
        timed_inner(2.0)
        clock.now += 0.5
        timed_inner(3.0)

    timer.wrap("outer", outer)()
    timer.wrap("outer", outer)()
    assert dict(timer.totals) == {"inner": 10.0, "outer": 3.0}
    assert dict(timer.counts) == {"inner": 4, "outer": 2}
    assert timer.calls == [6.5, 6.5]      # each outermost call, whole


def test_an_exception_still_closes_its_phase():
    clock = _Clock()
    timer = PhaseTimer(clock)

    def failing() -> None:
        clock.now += 1.0
        raise ValueError("boom")

    with pytest.raises(ValueError, match="boom"):
        timer.wrap("failing", failing)()
    timer.wrap("after", lambda: None)()
    assert dict(timer.totals) == {"failing": 1.0, "after": 0.0}
    assert len(timer.calls) == 2       # the failed call closed; the next one is outermost again


class _Owner:
    @staticmethod
    def static(value):
        return value + 1

    def method(self, value):
        return value * 2


def test_the_timed_functions_are_put_back_even_when_the_block_fails():
    originals = {name: _Owner.__dict__[name] for name in ("static", "method")}
    timer = PhaseTimer()
    with pytest.raises(RuntimeError), timer.attached([(_Owner, "static", "a"), (_Owner, "method", "b"),
                                                      (CBFSafetyFilter, "filter", "inherited")]):
        assert _Owner.static(1) == 2 and _Owner().method(2) == 4     # still working, now timed
        assert "filter" not in vars(CBFSafetyFilter)                 # inherited: timed where it is defined
        raise RuntimeError
    assert dict(timer.counts) == {"a": 1, "b": 1}
    assert {name: _Owner.__dict__[name] for name in originals} == originals


@pytest.mark.parametrize("name", ["cbf", "mpc"])
def test_the_phases_of_the_closed_loop_add_up_to_its_calls(name):
    filter_before = SafetyFilter.__dict__["filter"]
    row = call_phases.phases("rosbot", name, 0.1, seed=0, repeat=1)
    assert SafetyFilter.__dict__["filter"] is filter_before
    assert row["calls"] == 480          # 4 gaps x 2 sides x 6 s / 0.1 s
    phases = row["phases_us"]
    assert math.isclose(sum(phases.values()), row["mean_us"], rel_tol=1e-9)
    assert all(value > 0.0 for value in phases.values()), phases
    expected = {"template", "perception", "decision", "QP set-up", "QP solver (DAQP)"}
    expected |= {"rows"} if name == "cbf" else {"problem", "plan checks", "SQP", "model (casadi)"}
    if kernels.select("auto") is not None:
        expected.add("kernels (numba)")
    assert expected <= set(phases), set(phases)
    compiled = sum(phases.get(phase, 0.0) for phase in COMPILED)
    assert math.isclose(row["compiled_share"], compiled / row["mean_us"], rel_tol=1e-9)
    assert 0.0 < row["compiled_share"] < 1.0
    assert row["timed_calls_per_call"]["template"] >= 1.0
