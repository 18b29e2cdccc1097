"""The filter contract (safenav.filters.check_filter) on every filter safenav ships, and on broken ones."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from safenav.filters import (
    CBFSafetyFilter,
    FilterContractError,
    FilterResult,
    FilterStatus,
    MPCSafetyFilter,
    SafetyFilter,
    ZonesFilter,
    check_filter,
)


@pytest.mark.parametrize("make", [
    lambda robot, dt: CBFSafetyFilter(robot, dt),
    lambda robot, dt: CBFSafetyFilter(robot, dt, body="cover"),
    lambda robot, dt: MPCSafetyFilter(robot, dt),
    lambda robot, dt: MPCSafetyFilter(robot, dt, reference="cbf"),
    lambda robot, dt: ZonesFilter(robot, dt),
], ids=["cbf", "cbf-cover", "mpc", "mpc-cbf-reference", "zones"])
def test_every_shipped_filter_meets_the_contract(make):
    checked = check_filter(make)
    assert len(checked) == 3


class ReturnsNaN(SafetyFilter):
    name = "nan"

    def _filter(self, u_nom, view, velocity, period):
        return FilterResult(u=np.array([np.nan, 0.0]), u_nom=u_nom, status=FilterStatus.OK)


class SilentlyChanges(SafetyFilter):
    name = "silent"

    def _filter(self, u_nom, view, velocity, period):
        return FilterResult(u=0.5 * u_nom, u_nom=u_nom, status=FilterStatus.OK)


def test_a_filter_returning_nan_is_turned_into_braking_by_the_template():
    # Never NaN (clause 2 holds: the template brakes with FALLBACK), but braking in free space breaks clause 3.
    with pytest.raises(FilterContractError) as caught:
        check_filter(lambda robot, dt: ReturnsNaN(robot, dt))
    clauses = {failure.split(":")[0] for failure in caught.value.failures}
    assert clauses == {"3 minimal"}


def test_a_filter_that_changes_the_command_without_saying_why_fails_the_contract():
    with pytest.raises(FilterContractError, match=r"contract clauses failed:\n  ") as caught:
        check_filter(lambda robot, dt: SilentlyChanges(robot, dt))
    assert isinstance(caught.value, AssertionError)
    clauses = {failure.split(":")[0] for failure in caught.value.failures}
    assert {"4 says why", "3 minimal", "2 limits"} <= clauses
    again = pickle.loads(pickle.dumps(caught.value))
    assert again.failures == caught.value.failures
